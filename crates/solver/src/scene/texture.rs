//! Textures: the mean colour a surface takes from its texture (the solution is one value per
//! element, so the mean stands for the surface), the 8-bit sRGB PNG viewers are served to show
//! the detail, and where each face's points fall in its texture. 8- and 16-bit colour is
//! sRGB-encoded by convention (glTF's base colour, OBJ's `map_Kd`); float texels are linear.

use crate::scene::Rgb;
use glam::{DAffine3, DVec3};
use std::sync::Arc;

/// The sRGB transfer function inverted (IEC 61966-2-1).
pub fn srgb_to_linear(encoded: f64) -> f64 {
    if encoded <= 0.04045 {
        encoded / 12.92
    } else {
        ((encoded + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB transfer function (IEC 61966-2-1) of a linear value clamped to [0, 1], as a byte.
fn linear_to_srgb_byte(linear: f64) -> u8 {
    let c = linear.clamp(0.0, 1.0);
    let encoded = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (encoded * 255.0).round() as u8
}

/// The mean of `texels` (linear RGB), or why there is none.
pub fn mean(texels: impl Iterator<Item = Rgb>) -> Result<Rgb, String> {
    let (sum, count) = texels.fold((Rgb::ZERO, 0usize), |(sum, n), t| (sum + t, n + 1));
    match count {
        0 => Err("a texture with no texels".into()),
        n => Ok(sum / n as f64),
    }
}

/// A texture as the scene holds it: its linear mean (what the solver multiplies the
/// reflectance by) and the image viewers are served.
#[derive(Clone, PartialEq)]
pub struct Texture {
    /// The mean of the texels, linear RGB.
    pub mean: Rgb,
    /// The image as an 8-bit sRGB PNG (float texels clamped to [0, 1]; alpha dropped).
    pub png: Arc<[u8]>,
}

impl std::fmt::Debug for Texture {
    /// The mean and the PNG's size: the mean is all the solution depends on.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Texture")
            .field("mean", &self.mean)
            .field("png_bytes", &self.png.len())
            .finish()
    }
}

impl Texture {
    /// A texture of `width` × `height` linear texels, row by row from the top.
    pub fn from_linear(
        width: u32,
        height: u32,
        texels: impl Iterator<Item = Rgb>,
    ) -> Result<Texture, String> {
        let mut rgb = Vec::with_capacity(3 * width as usize * height as usize);
        let mean = mean(texels.inspect(|t| {
            rgb.extend(t.to_array().map(linear_to_srgb_byte));
        }))?;
        if rgb.len() != 3 * width as usize * height as usize {
            return Err(format!(
                "{} texels for a {width} x {height} image",
                rgb.len() / 3
            ));
        }
        let mut png = Vec::new();
        let mut encoder = png::Encoder::new(&mut png, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder
            .write_header()
            .and_then(|mut writer| writer.write_image_data(&rgb))
            .map_err(|e| format!("encoding the texture as PNG: {e}"))?;
        Ok(Texture {
            mean,
            png: png.into(),
        })
    }
}

/// Where a face's points fall in its texture: an affine map from the face's plane to texture
/// coordinates (glTF's convention: `(0, 0)` the image's top-left corner, `v` down). A file face
/// whose coordinates are not affine over it (a quad mapped to a trapezoid) is loaded as
/// triangles, each with its own map, so every piece of a face keeps its face's map.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureMap {
    /// Index into [`crate::Scene::textures`].
    pub texture: u32,
    /// A point of the face and its coordinates.
    origin: DVec3,
    origin_uv: [f64; 2],
    /// Gradients of `u` and `v` in the face's plane, per scene unit.
    du: DVec3,
    dv: DVec3,
}

impl TextureMap {
    /// The map that takes the corners `a, b, c` of a triangle to `uv_a, uv_b, uv_c`; `None`
    /// for a triangle without area.
    pub fn of_triangle(texture: u32, [a, b, c]: [DVec3; 3], uv: [[f64; 2]; 3]) -> Option<Self> {
        // Dual basis of (e1, e2) in their plane: p - a = (d·g1) e1 + (d·g2) e2.
        let (e1, e2) = (b - a, c - a);
        let (g11, g12, g22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
        let det = g11 * g22 - g12 * g12;
        if !det.is_finite() || det <= 0.0 {
            return None;
        }
        let g1 = (e1 * g22 - e2 * g12) / det;
        let g2 = (e2 * g11 - e1 * g12) / det;
        let gradient = |k: usize| g1 * (uv[1][k] - uv[0][k]) + g2 * (uv[2][k] - uv[0][k]);
        Some(TextureMap {
            texture,
            origin: a,
            origin_uv: uv[0],
            du: gradient(0),
            dv: gradient(1),
        })
    }

    /// Texture coordinates of point `p` of the face.
    pub fn uv_at(&self, p: DVec3) -> [f64; 2] {
        let d = p - self.origin;
        [
            self.origin_uv[0] + d.dot(self.du),
            self.origin_uv[1] + d.dot(self.dv),
        ]
    }

    /// The same map for the face moved rigidly by `motion`: the gradients turn with it.
    pub fn moved(&self, motion: &DAffine3) -> TextureMap {
        TextureMap {
            origin: motion.transform_point3(self.origin),
            du: motion.transform_vector3(self.du),
            dv: motion.transform_vector3(self.dv),
            ..self.clone()
        }
    }

    /// The same map for the face scaled about the origin by `factor`.
    pub fn scaled(&self, factor: f64) -> TextureMap {
        TextureMap {
            origin: self.origin * factor,
            du: self.du / factor,
            dv: self.dv / factor,
            ..self.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Material, Scene};
    use glam::dvec3;

    fn close(a: [f64; 2], b: [f64; 2]) -> bool {
        (a[0] - b[0]).abs().max((a[1] - b[1]).abs()) < 1e-12
    }

    #[test]
    fn a_triangle_map_gives_its_corners_coordinates_and_is_affine_between_them() {
        let corners = [
            dvec3(1.0, 2.0, 3.0),
            dvec3(4.0, 2.0, 3.0),
            dvec3(1.0, 2.0, 7.0),
        ];
        let uv = [[0.25, 0.5], [1.75, 0.5], [0.25, -1.5]];
        let map = TextureMap::of_triangle(0, corners, uv).expect("the triangle has area");
        for k in 0..3 {
            assert!(close(map.uv_at(corners[k]), uv[k]), "corner {k}");
        }
        // u = 0.25 + (x - 1) / 2, v = 0.5 - (z - 3) / 2 everywhere in the plane.
        let p = dvec3(2.2, 2.0, 4.6);
        assert!(close(map.uv_at(p), [0.85, -0.3]));
        // A point moved with its face keeps its coordinates, turned as well as shifted.
        let motion = crate::scene::motion::Motion {
            translate: [10.0, -1.0, 0.5],
            rotate: Some(crate::scene::motion::Rotation {
                axis: [1.0, 2.0, 3.0],
                degrees: 33.0,
            }),
            pivot: None,
        }
        .affine(dvec3(1.0, 2.0, 3.0));
        let moved = map.moved(&motion);
        assert!(close(moved.uv_at(motion.transform_point3(p)), [0.85, -0.3]));
        assert!(close(map.scaled(1e-3).uv_at(p * 1e-3), [0.85, -0.3]));
        let line = [corners[0], corners[1], corners[0] * 2.0 - corners[1]];
        assert_eq!(TextureMap::of_triangle(0, line, uv), None);
    }

    #[test]
    fn a_quad_keeps_one_map_when_its_coordinates_are_affine_and_is_split_when_not() {
        let grey = Material {
            reflectance: Rgb::splat(0.5),
            emission: Rgb::ZERO,
        };
        let square = [
            dvec3(0.0, 0.0, 0.0),
            dvec3(2.0, 0.0, 0.0),
            dvec3(2.0, 2.0, 0.0),
            dvec3(0.0, 2.0, 0.0),
        ];
        let mut scene = Scene::default();
        let object = scene.add_object("wall");
        let affine = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]];
        scene.add_textured_polygon(object, &square, &affine, grey, 0);
        assert_eq!(scene.faces.len(), 1);
        // The fourth corner's coordinates off the plane of the other three: two maps.
        let trapezoid = [[0.0, 1.0], [1.0, 1.0], [0.75, 0.0], [0.25, 0.0]];
        scene.add_textured_polygon(object, &square, &trapezoid, grey, 0);
        assert_eq!(scene.faces.len(), 3);
        for face in &scene.faces[1..] {
            let map = face.texture.as_ref().expect("textured");
            for &p in face.polygon.corners() {
                let k = square.iter().position(|c| *c == p).unwrap();
                assert!(close(map.uv_at(p), trapezoid[k]), "corner {k}");
            }
        }
    }

    #[test]
    fn pieces_cut_at_contact_lines_and_moved_faces_keep_their_texture_where_it_was() {
        let grey = Material {
            reflectance: Rgb::splat(0.5),
            emission: Rgb::ZERO,
        };
        let mut scene = Scene::default();
        let floor = scene.add_object("floor");
        let quad = |o: DVec3, u: DVec3, v: DVec3| [o, o + u, o + u + v, o + v];
        let corners = quad(DVec3::ZERO, DVec3::Z * 10.0, DVec3::X * 10.0);
        // u = x / 10, v = z / 10.
        let uvs: Vec<[f64; 2]> = corners.iter().map(|p| [p.x / 10.0, p.z / 10.0]).collect();
        scene.add_textured_polygon(floor, &corners, &uvs, grey, 0);
        let cube = scene.add_object("box");
        let lo = dvec3(2.0, 0.0, 3.0);
        for (o, u, v) in [
            (lo + DVec3::Y, DVec3::Z, DVec3::X),
            (lo, DVec3::Z, DVec3::Y),
            (lo + DVec3::X, DVec3::Y, DVec3::Z),
            (lo, DVec3::Y, DVec3::X),
            (lo + DVec3::Z, DVec3::X, DVec3::Y),
        ] {
            scene.add_polygon(cube, &quad(o, u, v), grey);
        }
        crate::input::contact::split_at_contacts(&mut scene);
        let pieces: Vec<_> = scene.faces.iter().filter(|f| f.object == floor).collect();
        assert!(pieces.len() > 1, "the floor is cut");
        for piece in &pieces {
            let map = piece.texture.as_ref().expect("every piece keeps the map");
            for &p in piece.polygon.corners() {
                assert!(close(map.uv_at(p), [p.x / 10.0, p.z / 10.0]), "{p}");
            }
        }
        let offset = DAffine3::from_translation(dvec3(1.0, 0.0, -2.0));
        let before = scene.faces[0]
            .texture
            .as_ref()
            .unwrap()
            .uv_at(scene.faces[0].polygon.corners()[0]);
        scene.move_object(floor, &offset);
        let face = &scene.faces[0];
        assert!(close(
            face.texture
                .as_ref()
                .unwrap()
                .uv_at(face.polygon.corners()[0]),
            before
        ));
        assert!(
            scene
                .faces
                .iter()
                .filter(|f| f.object == cube)
                .all(|f| f.texture.is_none())
        );
    }

    #[test]
    fn a_texture_is_served_as_the_srgb_bytes_of_its_linear_texels() {
        let texels = [
            Rgb::ONE,
            Rgb::ZERO,
            Rgb::splat(0.214_041_140_482_232_54),
            Rgb::new(2.0, 0.5, -1.0),
        ];
        let texture = Texture::from_linear(2, 2, texels.into_iter()).unwrap();
        assert!(
            (texture.mean - Rgb::new(0.8035, 0.4285, 0.0535))
                .abs()
                .max_element()
                < 1e-4
        );
        let mut reader = png::Decoder::new(std::io::Cursor::new(&texture.png[..]))
            .read_info()
            .unwrap();
        let mut bytes = vec![0; reader.output_buffer_size().unwrap()];
        reader.next_frame(&mut bytes).unwrap();
        // sRGB 0.5 is linear 0.2140; float texels past [0, 1] are clamped in the image only.
        assert_eq!(bytes, [255, 255, 255, 0, 0, 0, 128, 128, 128, 255, 188, 0]);
        let error = Texture::from_linear(3, 1, texels.into_iter()).unwrap_err();
        assert_eq!(error, "4 texels for a 3 x 1 image");
    }
}
