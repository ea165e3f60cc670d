//! Texture images in (PNG, JPEG), decoded with the `image` crate to linear texels.

use super::{SceneError, check_scene_file};
use crate::scene::Rgb;
use crate::scene::texture::{Texture, srgb_to_linear};
use std::path::Path;

/// The image file at `path` (PNG or JPEG), checked like every scene file before it is read.
pub(crate) fn load_texture(path: &Path) -> Result<Texture, SceneError> {
    let fail = |reason: String| SceneError::Parse {
        path: path.into(),
        reason,
    };
    check_scene_file(path)?;
    let image = image::ImageReader::open(path)
        .and_then(|reader| reader.with_guessed_format())
        .map_err(|source| SceneError::Io {
            path: path.into(),
            source,
        })?
        .decode()
        .map_err(|e| fail(format!("not an image radcast reads (PNG, JPEG): {e}")))?;
    let float = matches!(
        image.color(),
        image::ColorType::Rgb32F | image::ColorType::Rgba32F
    );
    let decode = |c: f32| match float {
        true => f64::from(c),
        false => srgb_to_linear(f64::from(c)),
    };
    let texels = image.to_rgb32f();
    Texture::from_linear(
        texels.width(),
        texels.height(),
        texels
            .pixels()
            .map(|p| Rgb::new(decode(p[0]), decode(p[1]), decode(p[2]))),
    )
    .map_err(fail)
}
