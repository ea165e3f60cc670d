//! A texture's mean colour, linear: what a scene takes from a texture (the solution is one
//! value per patch; a texture's mean stands for its surface). 8- and 16-bit colour is
//! sRGB-encoded by convention (glTF's base colour, OBJ's `map_Kd`); float texels are linear.

use crate::scene::{Rgb, SceneError, check_scene_file};
use std::path::Path;

/// The sRGB transfer function inverted (IEC 61966-2-1).
pub fn srgb_to_linear(encoded: f64) -> f64 {
    if encoded <= 0.04045 {
        encoded / 12.92
    } else {
        ((encoded + 0.055) / 1.055).powf(2.4)
    }
}

/// The mean of `texels` (linear RGB), or why there is none.
pub fn mean(texels: impl Iterator<Item = Rgb>) -> Result<Rgb, String> {
    let (sum, count) = texels.fold((Rgb::ZERO, 0usize), |(sum, n), t| (sum + t, n + 1));
    match count {
        0 => Err("a texture with no texels".into()),
        n => Ok(sum / n as f64),
    }
}

/// The linear mean colour of the image file at `path` (PNG or JPEG), checked like every scene
/// file before it is read.
pub fn file_mean(path: &Path) -> Result<Rgb, SceneError> {
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
    mean(
        texels
            .pixels()
            .map(|p| Rgb::new(decode(p[0]), decode(p[1]), decode(p[2]))),
    )
    .map_err(fail)
}
