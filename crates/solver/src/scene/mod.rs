//! The scene model: named objects made of planar faces, each with a diffuse reflectance and an
//! emitted radiosity, and the physical limits every value is checked against. No I/O: files
//! become scenes in [`crate::input`]; code builds them with [`Scene::add_polygon`].

pub mod motion;
pub mod texture;

use crate::geometry::Polygon;
use glam::{DAffine3, DVec3};
use texture::{Texture, TextureMap};

/// A linear RGB triple: radiosity in W/m^2 per channel, or a unitless reflectance.
pub type Rgb = DVec3;

/// One named object of the scene (an OBJ `o` or `g`).
#[derive(Clone, Debug, PartialEq)]
pub struct SceneObject {
    /// The name from the file, unique within the scene.
    pub name: String,
}

/// A planar face with its material.
#[derive(Clone, Debug, PartialEq)]
pub struct Face {
    /// The face's shape; light leaves and arrives on its front only.
    pub polygon: Polygon,
    /// Index into [`Scene::objects`].
    pub object: u32,
    /// Diffuse reflectance per channel, in [0, 1).
    pub reflectance: Rgb,
    /// Emitted radiosity per channel, W/m^2, finite and >= 0.
    pub emission: Rgb,
    /// The face of the scene file this is (a piece of): its index among the loaded faces
    /// before contact lines cut them (when a scene file is loaded). Reference probes name these, so a
    /// reference holds however the faces are cut.
    pub source: u32,
    /// Where the face's points fall in its texture, for a textured face (viewers show the
    /// texture; the solver uses its mean, already in `reflectance`).
    pub texture: Option<TextureMap>,
}

/// A suggested viewpoint, from a `#@view eye X Y Z target X Y Z up X Y Z fov DEGREES` line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// Eye position.
    pub eye: DVec3,
    /// Point looked at.
    pub target: DVec3,
    /// Up direction.
    pub up: DVec3,
    /// Vertical field of view, degrees.
    pub vertical_fov_degrees: f64,
}

/// A scene ready for meshing.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    /// The scene file's suggested viewpoint, if it has a `#@view` line.
    pub view: Option<View>,
    /// Named objects, in file order.
    pub objects: Vec<SceneObject>,
    /// All faces; quads stay quads when planar and convex, anything else becomes triangles.
    pub faces: Vec<Face>,
    /// Faces dropped because their area was zero (relative to the scene's size).
    pub skipped_degenerate_faces: usize,
    /// Faces cut into pieces along contact lines (when a scene file is loaded).
    pub faces_cut_at_contacts: usize,
    /// [`Scene::triangle_count`] before contact lines cut faces (what it reports once any is).
    pub triangles_before_cuts: usize,
    /// The textures faces refer to ([`Face::texture`]); empty for an untextured scene.
    pub textures: Vec<Texture>,
    /// What loading changed so that the file as shipped could be solved, each naming the
    /// material or file (a `Kd` of 1 clamped, a texture file that is not there).
    pub load_warnings: Vec<String>,
}

/// A material's physical values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Diffuse reflectance (`Kd`).
    pub reflectance: Rgb,
    /// Emitted radiosity (`Ke`).
    pub emission: Rgb,
}

impl Material {
    /// Checks the physical ranges: reflectance in [0, 1) and emission finite and >= 0.
    pub fn validate(&self) -> Result<(), String> {
        let r = self.reflectance.to_array();
        if !r.iter().all(|c| c.is_finite() && (0.0..1.0).contains(c)) {
            return Err(format!(
                "Kd {r:?} must have every channel in [0, 1] (1 is read as {MAX_REFLECTANCE})"
            ));
        }
        check_emission(self.emission.to_array()).map_err(|rule| format!("Ke {rule}"))
    }
}

/// The highest reflectance solved: a file's `Kd` (or glTF base colour) of 1, common in exported
/// assets ("white, let the texture decide"), is read as this, said in
/// [`Scene::load_warnings`]. No diffuse surface reflects all the light it gets (Spectralon, the
/// whitest made, 0.99), and at 1 a closed room has no solution.
pub const MAX_REFLECTANCE: f64 = 0.99;

/// Clamps a reflectance of at most 1 to [`MAX_REFLECTANCE`]; `None` when no channel needed it.
/// Values past 1 are left for [`Material::validate`] to refuse.
pub fn clamp_reflectance(reflectance: Rgb) -> Option<Rgb> {
    let r = reflectance.to_array();
    let clamped = r.map(|c| match c > MAX_REFLECTANCE && c <= 1.0 {
        true => MAX_REFLECTANCE,
        false => c,
    });
    (clamped != r).then(|| Rgb::from(clamped))
}

/// The brightest emission accepted, W/m^2. Frames hold radiosity up to about 8e34 W/m^2
/// (RGB9E5 with a scale of at most 2^100); this leaves a million-fold headroom for reflections
/// that multiply it (reflectance up to 0.999999), and is far past any real lamp.
pub const MAX_EMISSION: f64 = 1e24;

/// The largest texture coordinate accepted: a million repeats of a texture, far past any
/// real model.
pub const MAX_TEXTURE_COORDINATE: f64 = 1e6;

/// The farthest a coordinate (or a move) may reach from the origin, scene units: what f32
/// geometry holds with room for the differences and products viewers compute.
pub const MAX_COORDINATE: f64 = 1e30;

/// Checks an emission: every channel finite, >= 0 and at most [`MAX_EMISSION`]. The reason
/// names the value.
pub fn check_emission(emission: [f64; 3]) -> Result<(), String> {
    if emission
        .iter()
        .all(|c| c.is_finite() && (0.0..=MAX_EMISSION).contains(c))
    {
        Ok(())
    } else {
        Err(format!(
            "{emission:?} must have every value finite, >= 0 and <= {MAX_EMISSION:e}"
        ))
    }
}

/// Checks a translation: every component finite and at most [`MAX_COORDINATE`] in size.
pub fn check_translation(offset: [f64; 3]) -> Result<(), String> {
    if offset
        .iter()
        .all(|c| c.is_finite() && c.abs() <= MAX_COORDINATE)
    {
        Ok(())
    } else {
        Err(format!(
            "{offset:?} must have every value finite and within ±{MAX_COORDINATE:e}"
        ))
    }
}

impl Scene {
    /// Appends an object and returns its index; faces are added with [`Scene::add_polygon`].
    pub fn add_object(&mut self, name: impl Into<String>) -> u32 {
        self.objects.push(SceneObject { name: name.into() });
        (self.objects.len() - 1) as u32
    }

    /// Adds a polygon given by its corners (counter-clockwise seen from the front) to `object`.
    /// Planar convex quads stay quads; other polygons are split into a triangle fan. Each face
    /// is its own source.
    pub fn add_polygon(&mut self, object: u32, corners: &[DVec3], material: Material) {
        for polygon in crate::geometry::convex_pieces(corners) {
            self.push_face(object, polygon, material, None);
        }
    }

    /// [`Scene::add_polygon`] for a textured polygon: `uvs` are its corners' coordinates in
    /// texture `texture` (glTF's convention, `v` down). A quad whose coordinates are not an
    /// affine image of it is added as two triangles, so each face has one affine map.
    pub fn add_textured_polygon(
        &mut self,
        object: u32,
        corners: &[DVec3],
        uvs: &[[f64; 2]],
        material: Material,
        texture: u32,
    ) {
        let uv_of = |p: DVec3| uvs[corners.iter().position(|c| *c == p).unwrap_or(0)];
        for polygon in crate::geometry::convex_pieces(corners) {
            let c = polygon.corners();
            let map = TextureMap::of_triangle(
                texture,
                [c[0], c[1], c[2]],
                [0, 1, 2].map(|k| uv_of(c[k])),
            );
            let affine = |map: &TextureMap| {
                c.iter().all(|&p| {
                    let (want, got) = (uv_of(p), map.uv_at(p));
                    (want[0] - got[0]).abs().max((want[1] - got[1]).abs())
                        <= 1e-6 * (1.0 + want[0].abs().max(want[1].abs()))
                })
            };
            match map {
                Some(map) if !affine(&map) => {
                    for triangle in [[c[0], c[1], c[2]], [c[0], c[2], c[3]]] {
                        let map = TextureMap::of_triangle(texture, triangle, triangle.map(uv_of));
                        let [a, b, d] = triangle;
                        self.push_face(object, Polygon::triangle(a, b, d), material, map);
                    }
                }
                map => self.push_face(object, polygon, material, map),
            }
        }
    }

    fn push_face(
        &mut self,
        object: u32,
        polygon: Polygon,
        material: Material,
        texture: Option<TextureMap>,
    ) {
        self.faces.push(Face {
            polygon,
            object,
            reflectance: material.reflectance,
            emission: material.emission,
            source: self.faces.len() as u32,
            texture,
        });
    }

    /// The axis-aligned box around every face, or `None` for a scene without faces.
    pub fn bounds(&self) -> Option<(DVec3, DVec3)> {
        (!self.faces.is_empty()).then(|| {
            crate::geometry::bounds(
                self.faces
                    .iter()
                    .flat_map(|f| f.polygon.corners().iter().copied()),
            )
        })
    }

    /// Drops faces whose area is negligible against the scene's size, counting them; returns
    /// the name of an emitting object that lost a face that way (its light would vanish).
    pub fn drop_degenerate_faces(&mut self) -> Option<String> {
        let diagonal_sq = self
            .bounds()
            .map_or(0.0, |(lo, hi)| (hi - lo).length_squared());
        let before = self.faces.len();
        // Area ratios down to 1e-12 of the scene are real geometry (issue: tiny next to huge).
        let kept = |f: &Face| f.polygon.area() > 1e-14 * diagonal_sq;
        let lost_light = self
            .faces
            .iter()
            .find(|f| !kept(f) && f.emission.max_element() > 0.0)
            .map(|f| self.objects[f.object as usize].name.clone());
        self.faces.retain(kept);
        self.skipped_degenerate_faces += before - self.faces.len();
        lost_light
    }

    /// Number of triangles the faces make as the scene file gave them: a quad counts two, and
    /// faces cut along contact lines count as they were before the cut.
    pub fn triangle_count(&self) -> usize {
        match self.faces_cut_at_contacts {
            0 => self
                .faces
                .iter()
                .map(|f| if f.polygon.is_quad() { 2 } else { 1 })
                .sum(),
            _ => self.triangles_before_cuts,
        }
    }

    /// True when some face emits light.
    pub fn has_emitter(&self) -> bool {
        self.faces.iter().any(|f| f.emission.max_element() > 0.0)
    }

    /// Uniform scale of every coordinate, for tests of scale invariance.
    pub fn scaled(&self, factor: f64) -> Scene {
        let mut scaled = self.clone();
        for face in &mut scaled.faces {
            let c: Vec<DVec3> = face.polygon.corners().iter().map(|p| *p * factor).collect();
            face.polygon = match *c.as_slice() {
                [a, b, c] => Polygon::triangle(a, b, c),
                [a, b, c, d] => Polygon::quad(a, b, c, d),
                _ => unreachable!("polygons have three or four corners"),
            };
            face.texture = face.texture.as_ref().map(|map| map.scaled(factor));
        }
        scaled
    }

    /// Moves every face of `object` by `offset`.
    pub fn move_object(&mut self, object: u32, motion: &DAffine3) {
        for face in self.faces.iter_mut().filter(|f| f.object == object) {
            face.polygon = face.polygon.moved(motion);
            face.texture = face.texture.as_ref().map(|map| map.moved(motion));
        }
    }

    /// The centre of `object`'s bounding box: where a rotation turns it about by default.
    pub fn object_centre(&self, object: u32) -> DVec3 {
        let (lo, hi) = crate::geometry::bounds(self.object_corners(object));
        (lo + hi) * 0.5
    }

    /// The corners of `object`'s faces.
    pub fn object_corners(&self, object: u32) -> impl Iterator<Item = DVec3> + '_ {
        self.faces
            .iter()
            .filter(move |f| f.object == object)
            .flat_map(|f| f.polygon.corners().iter().copied())
    }

    /// The number of faces as the scene file gave them (before contact lines cut them).
    pub fn source_face_count(&self) -> usize {
        self.faces
            .iter()
            .map(|f| f.source as usize + 1)
            .max()
            .unwrap_or(0)
    }
}
