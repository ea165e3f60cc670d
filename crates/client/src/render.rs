//! A small software rasterizer: z-buffered triangles with the vertices' radiosity interpolated
//! smoothly, textured surfaces modulated by `texel / mean` (docs/PROTOCOL.md), tone-mapped to
//! 8-bit sRGB as [`wire::display`] documents.

use anyhow::{Context, bail};
use glam::{Vec2, Vec3};
use std::path::Path;
use wire::display::{corners, exposure, srgb_byte, srgb_to_linear, tone_map};
use wire::{ColourBuffer, Geometry};

/// A pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// Eye position, scene units.
    pub eye: Vec3,
    /// Point looked at.
    pub target: Vec3,
    /// Up direction.
    pub up: Vec3,
    /// Vertical field of view, degrees.
    pub vertical_fov_degrees: f32,
}

impl View {
    /// Parses `ex,ey,ez,tx,ty,tz,ux,uy,uz,fov` (eye, target, up, vertical fov in degrees).
    pub fn parse(text: &str) -> anyhow::Result<View> {
        let numbers: Vec<f32> = text
            .split(',')
            .map(|s| {
                s.trim()
                    .parse::<f32>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .with_context(|| format!("camera '{text}': '{s}' is not a finite number"))
            })
            .collect::<Result<_, _>>()?;
        let [ex, ey, ez, tx, ty, tz, ux, uy, uz, fov] = numbers[..] else {
            bail!(
                "camera '{text}' needs 10 numbers: eye x,y,z, target x,y,z, up x,y,z, fov degrees"
            );
        };
        let view = View {
            eye: Vec3::new(ex, ey, ez),
            target: Vec3::new(tx, ty, tz),
            up: Vec3::new(ux, uy, uz),
            vertical_fov_degrees: fov,
        };
        if view.eye == view.target
            || view.up.cross(view.target - view.eye) == Vec3::ZERO
            || !(fov > 0.0 && fov < 180.0)
        {
            bail!(
                "camera '{text}': eye must differ from target, up must not be parallel to the view, fov must be in (0, 180)"
            );
        }
        Ok(view)
    }

    /// The scene's own suggested view, or one that frames its bounding box from -z.
    pub fn for_scene(geometry: &Geometry) -> View {
        if let Some(c) = geometry.camera {
            return View {
                eye: c.eye.into(),
                target: c.target.into(),
                up: c.up.into(),
                vertical_fov_degrees: c.vertical_fov_degrees,
            };
        }
        let (lo, hi) = geometry.positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(Vec3::from(*p)), hi.max(Vec3::from(*p))),
        );
        let (centre, radius) = (
            (lo + hi) * 0.5,
            ((hi - lo).length() * 0.5).max(f32::MIN_POSITIVE),
        );
        let fov: f32 = 45.0;
        let distance = 1.1 * radius / (fov.to_radians() * 0.5).sin();
        View {
            eye: centre - Vec3::Z * distance,
            target: centre,
            up: Vec3::Y,
            vertical_fov_degrees: fov,
        }
    }
}

/// An 8-bit sRGB image.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major RGB bytes.
    pub rgb: Vec<u8>,
}

impl Image {
    /// The pixel at column `x`, row `y` (row 0 at the top).
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        let i = 3 * (y * self.width + x) as usize;
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    /// Writes a PNG.
    pub fn write_png(&self, path: &Path) -> anyhow::Result<()> {
        let file = std::fs::File::create(path)
            .with_context(|| format!("{}: cannot create", path.display()))?;
        let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), self.width, self.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder
            .write_header()?
            .write_image_data(&self.rgb)
            .with_context(|| format!("{}: writing PNG", path.display()))
    }
}

/// A texture as a viewer shows it: linear RGB texels, row by row from the top.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureImage {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Linear RGB (sRGB bytes decoded), row-major.
    pub texels: Vec<Vec3>,
}

impl TextureImage {
    /// Decodes a PNG (any colour type and depth; alpha is ignored).
    pub fn from_png(bytes: &[u8]) -> anyhow::Result<TextureImage> {
        let mut decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        decoder.set_transformations(png::Transformations::normalize_to_color8());
        let mut reader = decoder.read_info().context("not a PNG")?;
        let mut data = vec![0; reader.output_buffer_size().context("PNG too large")?];
        let frame = reader.next_frame(&mut data).context("decoding the PNG")?;
        let channels = frame.color_type.samples();
        let texels = data[..frame.buffer_size()]
            .chunks_exact(channels)
            .map(|t| match channels {
                1 | 2 => Vec3::splat(srgb_to_linear(t[0])),
                _ => Vec3::new(
                    srgb_to_linear(t[0]),
                    srgb_to_linear(t[1]),
                    srgb_to_linear(t[2]),
                ),
            })
            .collect();
        Ok(TextureImage {
            width: frame.width,
            height: frame.height,
            texels,
        })
    }

    /// The texel under `(u, v)` (glTF's convention: `(0, 0)` the top-left corner), repeating.
    fn nearest(&self, uv: Vec2) -> Vec3 {
        let wrap =
            |t: f32, n: u32| ((t - t.floor()) * n as f32).min(n as f32 - 1.0).max(0.0) as u32;
        let (x, y) = (wrap(uv.x, self.width), wrap(uv.y, self.height));
        self.texels[(y * self.width + x) as usize]
    }
}

/// What a viewer draws the colours on.
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    /// The geometry from `/api/scene`.
    pub geometry: Geometry,
    /// The texels of each texture its texture section names.
    pub textures: Vec<TextureImage>,
    /// Per object, whether it emits (`/api/objects`): emitters are left out of the exposure.
    pub emitting: Vec<bool>,
}

impl Model {
    /// `geometry` alone: no textures, no object known to emit.
    pub fn plain(geometry: Geometry) -> Model {
        Model {
            geometry,
            textures: Vec::new(),
            emitting: Vec::new(),
        }
    }
}

/// A corner as the rasterizer carries it: camera-space position, radiosity, texture coordinates.
#[derive(Clone, Copy)]
struct Corner {
    at: Vec3,
    radiosity: Vec3,
    uv: Vec2,
}

/// How a triangle's pixels are shaded: its texture and `1 / mean` per channel (0 where the mean
/// is 0), or none.
type Shading<'a> = Option<(&'a TextureImage, Vec3)>;

/// Renders the patches from `view`, each textured patch showing its texture as the geometry's
/// texture section says; both sides of every face are drawn.
pub fn render(model: &Model, buffer: &ColourBuffer, view: &View, width: u32, height: u32) -> Image {
    let Model {
        geometry,
        textures,
        emitting,
    } = model;
    let radiosity = buffer.radiosity();
    let colours: Vec<Vec3> = radiosity.iter().map(|&rgb| Vec3::from(rgb)).collect();
    let k = exposure(geometry, &radiosity, emitting);
    let camera = Camera::new(view, geometry, width, height);
    let mut inverse_depth = vec![0.0f32; (width * height) as usize];
    let mut linear = vec![Vec3::ZERO; (width * height) as usize];
    let surface = geometry.textures.as_ref();
    for (p, patch) in geometry.patches.iter().enumerate() {
        let shading: Shading = surface.and_then(|s| {
            let t = s.patch_textures[p];
            let image = textures.get(t as usize)?;
            Some((image, Vec3::from(s.modulation(t, [1.0; 3]))))
        });
        let uv = |i: u32| surface.map_or(Vec2::ZERO, |s| Vec2::from(s.uvs[i as usize]));
        let c = corners(patch);
        for k in 1..c.len() - 1 {
            let triangle = [c[0], c[k], c[k + 1]].map(|i| Corner {
                at: camera.to_camera(Vec3::from(geometry.positions[i as usize])),
                radiosity: colours[i as usize],
                uv: uv(i),
            });
            let polygon = clip_near(&triangle, camera.near);
            for j in 1..polygon.len().saturating_sub(1) {
                camera.raster(
                    &[polygon[0], polygon[j], polygon[j + 1]],
                    shading,
                    &mut inverse_depth,
                    &mut linear,
                );
            }
        }
    }
    let rgb = linear
        .iter()
        .flat_map(|c| tone_map(c.to_array(), k).map(srgb_byte))
        .collect();
    Image { width, height, rgb }
}

/// A pinhole camera's orthonormal basis and image plane.
struct Camera {
    eye: Vec3,
    right: Vec3,
    up: Vec3,
    forward: Vec3,
    /// Pixels per unit of `x / depth` at the image plane.
    focal_pixels: f32,
    near: f32,
    width: u32,
    height: u32,
}

impl Camera {
    fn new(view: &View, geometry: &Geometry, width: u32, height: u32) -> Camera {
        let forward = (view.target - view.eye).normalize();
        let right = forward.cross(view.up).normalize();
        let up = right.cross(forward);
        let extent = geometry
            .positions
            .iter()
            .map(|p| (Vec3::from(*p) - view.eye).length())
            .fold(0.0, f32::max);
        Camera {
            eye: view.eye,
            right,
            up,
            forward,
            focal_pixels: 0.5 * height as f32
                / (0.5 * view.vertical_fov_degrees.to_radians()).tan(),
            near: (extent * 1e-4).max(f32::MIN_POSITIVE),
            width,
            height,
        }
    }

    /// (right, up, depth) coordinates.
    fn to_camera(&self, p: Vec3) -> Vec3 {
        let d = p - self.eye;
        Vec3::new(d.dot(self.right), d.dot(self.up), d.dot(self.forward))
    }

    /// Fills one camera-space triangle (depth >= near) with perspective-correct colours (and
    /// texture coordinates), keeping the nearest surface per pixel.
    fn raster(
        &self,
        triangle: &[Corner; 3],
        shading: Shading,
        inverse_depth: &mut [f32],
        linear: &mut [Vec3],
    ) {
        let (w, h) = (self.width as f32, self.height as f32);
        let screen = triangle.map(|Corner { at: p, .. }| {
            Vec3::new(
                0.5 * w + self.focal_pixels * p.x / p.z,
                0.5 * h - self.focal_pixels * p.y / p.z,
                1.0 / p.z,
            )
        });
        let edge =
            |a: Vec3, b: Vec3, x: f32, y: f32| (b.x - a.x) * (y - a.y) - (b.y - a.y) * (x - a.x);
        let area = edge(screen[0], screen[1], screen[2].x, screen[2].y);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        let bound = |f: fn(f32, f32) -> f32, start: f32, axis: fn(&Vec3) -> f32| {
            screen.iter().map(axis).fold(start, f)
        };
        let min_x = bound(f32::min, f32::INFINITY, |p| p.x).floor().max(0.0) as u32;
        let max_x = bound(f32::max, f32::NEG_INFINITY, |p| p.x)
            .ceil()
            .clamp(0.0, w) as u32;
        let min_y = bound(f32::min, f32::INFINITY, |p| p.y).floor().max(0.0) as u32;
        let max_y = bound(f32::max, f32::NEG_INFINITY, |p| p.y)
            .ceil()
            .clamp(0.0, h) as u32;
        for y in min_y..max_y {
            for x in min_x..max_x {
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                let b = [
                    edge(screen[1], screen[2], px, py) / area,
                    edge(screen[2], screen[0], px, py) / area,
                    edge(screen[0], screen[1], px, py) / area,
                ];
                if b.iter().any(|&v| v < 0.0) {
                    continue;
                }
                // 1/depth is linear in screen space; larger is nearer.
                let weights = [b[0] * screen[0].z, b[1] * screen[1].z, b[2] * screen[2].z];
                let inverse = weights[0] + weights[1] + weights[2];
                let index = (y * self.width + x) as usize;
                if inverse <= inverse_depth[index] {
                    continue;
                }
                inverse_depth[index] = inverse;
                let radiosity = (triangle[0].radiosity * weights[0]
                    + triangle[1].radiosity * weights[1]
                    + triangle[2].radiosity * weights[2])
                    / inverse;
                linear[index] = match shading {
                    Some((image, inverse_mean)) => {
                        let uv = (triangle[0].uv * weights[0]
                            + triangle[1].uv * weights[1]
                            + triangle[2].uv * weights[2])
                            / inverse;
                        radiosity * image.nearest(uv) * inverse_mean
                    }
                    None => radiosity,
                };
            }
        }
    }
}

/// Clips a camera-space triangle to `depth >= near`; returns up to four corners.
fn clip_near(triangle: &[Corner; 3], near: f32) -> Vec<Corner> {
    let mut out = Vec::with_capacity(4);
    for k in 0..3 {
        let (a, b) = (triangle[k], triangle[(k + 1) % 3]);
        let (da, db) = (a.at.z - near, b.at.z - near);
        if da >= 0.0 {
            out.push(a);
        }
        if (da >= 0.0) != (db >= 0.0) {
            let t = da / (da - db);
            out.push(Corner {
                at: a.at.lerp(b.at, t),
                radiosity: a.radiosity.lerp(b.radiosity, t),
                uv: a.uv.lerp(b.uv, t),
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use wire::geometry::SurfaceTextures;
    use wire::{FrameInfo, FullFrame, ServerMessage};

    /// A 2 x 2 square at z = 0 facing a camera on -z, lit evenly at 1 W/m^2, textured with a
    /// white-black checker whose linear mean is 0.5.
    #[test]
    fn a_textured_patch_shows_its_light_times_texel_over_mean() {
        let geometry = Geometry {
            positions: vec![
                [-1.0, -1.0, 0.0],
                [1.0, -1.0, 0.0],
                [1.0, 1.0, 0.0],
                [-1.0, 1.0, 0.0],
            ],
            patches: vec![[0, 1, 2, 3]],
            patch_objects: vec![0],
            objects: vec!["square".into()],
            camera: None,
            // v down: y = 1 is the image's top row.
            textures: Some(SurfaceTextures {
                means: vec![[0.5; 3]],
                patch_textures: vec![0],
                uvs: vec![[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]],
            }),
        };
        let (white, black) = (Vec3::ONE, Vec3::ZERO);
        let checker = TextureImage {
            width: 2,
            height: 2,
            texels: vec![white, black, black, white],
        };
        let mut buffer = ColourBuffer::default();
        let info = FrameInfo {
            solution_version: 1,
            sent_at_unix_micros: 0,
            scale: 1.0,
            vertex_count: 4,
            is_final: true,
        };
        let colours = vec![wire::encode_colour([1.0; 3], 1.0); 4];
        buffer
            .apply(&ServerMessage::Full(FullFrame { info, colours }))
            .unwrap();
        let view = View::parse("0,0,-5,0,0,0,0,1,0,30").unwrap();
        let textured = Model {
            geometry: geometry.clone(),
            textures: vec![checker],
            emitting: vec![false],
        };
        let image = render(&textured, &buffer, &view, 64, 64);
        // Exposure 0.18 / 1 (every vertex at luminance 1); a white texel shows 1 / 0.5 of it.
        let lit = srgb_byte(tone_map([2.0; 3], 0.18)[0]);
        // Seen from -z, the image's left is the square's +x: its top-left quarter shows the
        // texture's top-right texel (black), its top-right quarter the top-left one (white).
        assert_eq!(image.pixel(16, 16), [0; 3]);
        assert_eq!(image.pixel(48, 16), [lit; 3]);
        assert_eq!(image.pixel(16, 48), [lit; 3]);
        assert_eq!(image.pixel(48, 48), [0; 3]);
        // Without its texture the square shows the light itself.
        let plain = render(&Model::plain(geometry), &buffer, &view, 64, 64);
        assert_eq!(
            plain.pixel(16, 16),
            [srgb_byte(tone_map([0.18; 3], 1.0)[0]); 3]
        );
    }

    #[test]
    fn a_png_decodes_to_linear_texels() {
        let image = Image {
            width: 2,
            height: 1,
            rgb: vec![255, 128, 0, 0, 0, 0],
        };
        let folder = std::env::temp_dir().join(format!("radcast-render-{}", std::process::id()));
        std::fs::create_dir_all(&folder).unwrap();
        let path = folder.join("t.png");
        image.write_png(&path).unwrap();
        let texture = TextureImage::from_png(&std::fs::read(&path).unwrap()).unwrap();
        std::fs::remove_dir_all(&folder).unwrap();
        assert_eq!((texture.width, texture.height), (2, 1));
        assert!(
            (texture.texels[0] - Vec3::new(1.0, 0.2158605, 0.0))
                .abs()
                .max_element()
                < 1e-6
        );
        assert_eq!(texture.texels[1], Vec3::ZERO);
        assert!(TextureImage::from_png(b"not a png").is_err());
    }
}
