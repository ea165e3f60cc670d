//! Scenes: named objects made of planar faces, each with a diffuse reflectance and an emitted
//! radiosity, loaded from Wavefront OBJ + MTL or built in code.

use crate::geometry::Polygon;
use crate::texture::{Texture, TextureMap};
use glam::DVec3;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// A linear RGB triple: radiosity in W/m^2 per channel, or a unitless reflectance.
pub type Rgb = DVec3;

/// Why a scene could not be loaded. Every variant names the file and, where one exists, the line.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The OBJ or MTL file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file that failed.
        path: PathBuf,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// The OBJ parser rejected the file.
    #[error("{path}: {reason}")]
    Parse {
        /// The OBJ file.
        path: PathBuf,
        /// The parser's reason.
        reason: String,
    },
    /// A line of the OBJ file is wrong: a bad number, an index out of range, an unknown material.
    #[error("{path}:{line}: {reason}")]
    Line {
        /// The OBJ file.
        path: PathBuf,
        /// One-based line number.
        line: usize,
        /// What is wrong on that line.
        reason: String,
    },
    /// A material has a value outside its physical range.
    #[error("{path}: material '{material}': {reason}")]
    Material {
        /// The file that defines the material.
        path: PathBuf,
        /// The material's name.
        material: String,
        /// What is wrong with it.
        reason: String,
    },
    /// Faces were given without any `usemtl`.
    #[error("{path}: object '{object}' has faces but no material (add `usemtl NAME`)")]
    NoMaterial {
        /// The OBJ file.
        path: PathBuf,
        /// The object's name.
        object: String,
    },
    /// An emitter has a face too small next to the scene to be solved: dropping it would
    /// silently darken the scene.
    #[error(
        "{path}: object '{object}' emits light from a face below 1e-14 of the scene's squared diagonal: too small next to the rest of the scene to solve"
    )]
    EmitterTooSmall {
        /// The OBJ file.
        path: PathBuf,
        /// The emitting object.
        object: String,
    },
    /// Nothing with a non-zero area is left to light.
    #[error("{path}: the scene has no faces with non-zero area")]
    Empty {
        /// The OBJ file.
        path: PathBuf,
    },
}

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
    /// before contact lines cut them ([`crate::contact`]). Reference probes name these, so a
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

impl View {
    /// Parses the words after `#@view`.
    fn parse(words: &str) -> Result<View, String> {
        let w: Vec<&str> = words.split_whitespace().collect();
        let number = |i: usize| -> Result<f64, String> {
            w.get(i)
                .and_then(|s| s.parse::<f64>().ok())
                .filter(|x| x.abs() <= MAX_COORDINATE)
                .ok_or_else(|| {
                    format!(
                        "expected a finite number within ±{MAX_COORDINATE:e} at word {}",
                        i + 1
                    )
                })
        };
        let vector = |label: &str, at: usize| -> Result<DVec3, String> {
            if w.get(at) != Some(&label) {
                return Err(format!("expected '{label}' at word {}", at + 1));
            }
            Ok(DVec3::new(
                number(at + 1)?,
                number(at + 2)?,
                number(at + 3)?,
            ))
        };
        let (eye, target, up) = (vector("eye", 0)?, vector("target", 4)?, vector("up", 8)?);
        if w.get(12) != Some(&"fov") || w.len() != 14 {
            return Err("expected `#@view eye X Y Z target X Y Z up X Y Z fov DEGREES`".into());
        }
        let vertical_fov_degrees = number(13)?;
        // Viewers build a camera frame from these in f32: the direction and up must stay
        // apart there, not only in f64.
        let (forward, up_f32) = ((target - eye).as_vec3(), up.as_vec3());
        if !(vertical_fov_degrees > 0.0 && vertical_fov_degrees < 180.0)
            || forward.normalize_or_zero() == glam::Vec3::ZERO
            || forward.cross(up_f32).normalize_or_zero() == glam::Vec3::ZERO
        {
            return Err(
                "the view needs eye != target, an up not along the view direction and a fov in (0, 180)"
                    .into(),
            );
        }
        Ok(View {
            eye,
            target,
            up,
            vertical_fov_degrees,
        })
    }
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
    /// Faces cut into pieces along contact lines ([`Scene::split_at_contacts`]).
    pub faces_cut_at_contacts: usize,
    /// [`Scene::triangle_count`] before contact lines cut faces (what it reports once any is).
    pub triangles_before_cuts: usize,
    /// The textures faces refer to ([`Face::texture`]); empty for an untextured scene.
    pub textures: Vec<Texture>,
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
            return Err(format!("Kd {r:?} must have every channel in [0, 1)"));
        }
        check_emission(self.emission.to_array()).map_err(|rule| format!("Ke {rule}"))
    }
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
        for polygon in crate::contact::convex_polygons(corners) {
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
        for polygon in crate::contact::convex_polygons(corners) {
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
    pub fn translate_object(&mut self, object: u32, offset: DVec3) {
        for face in self.faces.iter_mut().filter(|f| f.object == object) {
            face.polygon = face.polygon.translated(offset);
            face.texture = face.texture.as_ref().map(|map| map.translated(offset));
        }
    }

    /// Loads an OBJ file and the MTL libraries it names (relative to the OBJ's folder).
    pub fn load_obj(path: &Path) -> Result<Scene, SceneError> {
        let text = read_scene_file(path)?;
        let folder = path.parent().unwrap_or(Path::new("."));
        let mtl_failure = std::cell::RefCell::new(None);
        let options = tobj::LoadOptions {
            triangulate: false,
            single_index: true,
            ignore_lines: true,
            ignore_points: true,
        };
        let loaded = tobj::load_obj_buf(&mut text.as_bytes(), &options, |mtl| {
            let mtl_path = folder.join(mtl);
            // Read and checked here, never by tobj: it panics on a colour line with fewer than
            // three numbers and reads whatever the path names (`/dev/zero`) to the end.
            read_scene_file(&mtl_path)
                .and_then(|text| lint_mtl(&mtl_path, &text).map(|()| text))
                .map_err(|error| {
                    *mtl_failure.borrow_mut() = Some(error);
                    tobj::LoadError::OpenFileFailed
                })
                .and_then(|text| tobj::load_mtl_buf(&mut text.as_bytes()))
        });
        // Check lines first: our messages name the line, tobj's do not.
        let (models, materials) = match loaded {
            Ok((models, materials)) => {
                if let Some(error) = mtl_failure.take() {
                    return Err(error);
                }
                let materials = materials.map_err(|e| SceneError::Parse {
                    path: path.into(),
                    reason: e.to_string(),
                })?;
                lint_obj(path, &text, Some(&materials))?;
                (models, materials)
            }
            Err(e) => {
                if let Some(error) = mtl_failure.take() {
                    return Err(error);
                }
                lint_obj(path, &text, None)?;
                return Err(SceneError::Parse {
                    path: path.into(),
                    reason: e.to_string(),
                });
            }
        };
        let mtl_path = first_mtllib(&text)
            .map(|m| folder.join(m))
            .unwrap_or_else(|| path.into());
        let mut textures: Vec<(PathBuf, Texture)> = Vec::new();
        let checked: Vec<(Material, Option<u32>)> = materials
            .iter()
            .map(|m| {
                let rgb = |c: Option<[f32; 3]>, absent: Rgb| {
                    c.map(|c| Rgb::from(c.map(f64::from))).unwrap_or(absent)
                };
                // map_Kd: Kd (1 when absent) times the texture's linear mean; its options come
                // before the file name, which is the last word.
                let texture = match m
                    .diffuse_texture
                    .as_deref()
                    .and_then(|t| t.split_whitespace().last())
                {
                    Some(name) => {
                        let file = mtl_path.parent().unwrap_or(Path::new(".")).join(name);
                        let index = match textures.iter().position(|(path, _)| *path == file) {
                            Some(index) => index,
                            None => {
                                textures.push((file.clone(), Texture::load(&file)?));
                                textures.len() - 1
                            }
                        };
                        Some(index as u32)
                    }
                    None => None,
                };
                let reflectance = match texture {
                    Some(index) => rgb(m.diffuse, Rgb::ONE) * textures[index as usize].1.mean,
                    None => rgb(m.diffuse, Rgb::ZERO),
                };
                let material = Material {
                    reflectance,
                    emission: rgb(m.emissive, Rgb::ZERO),
                };
                material
                    .validate()
                    .map(|()| (material, texture))
                    .map_err(|reason| SceneError::Material {
                        path: mtl_path.clone(),
                        material: m.name.clone(),
                        reason,
                    })
            })
            .collect::<Result<_, _>>()?;

        let mut scene = Scene {
            view: find_view(path, &text)?,
            textures: textures.into_iter().map(|(_, texture)| texture).collect(),
            ..Scene::default()
        };
        let mut object_ids: HashMap<String, u32> = HashMap::new();
        for model in &models {
            let mesh = &model.mesh;
            if mesh.indices.is_empty() {
                continue;
            }
            let Some((material, texture)) = mesh.material_id.map(|id| checked[id]) else {
                return Err(SceneError::NoMaterial {
                    path: path.into(),
                    object: model.name.clone(),
                });
            };
            let object = *object_ids
                .entry(model.name.clone())
                .or_insert_with(|| scene.add_object(model.name.clone()));
            let position = |i: u32| {
                let p = &mesh.positions[3 * i as usize..3 * i as usize + 3];
                DVec3::new(p[0].into(), p[1].into(), p[2].into())
            };
            let mut start = 0;
            let arities = if mesh.face_arities.is_empty() {
                vec![3; mesh.indices.len() / 3]
            } else {
                mesh.face_arities.clone()
            };
            // OBJ's `vt` has v up from the image's bottom row; the scene keeps glTF's v down.
            let uv = |i: u32| {
                let t = &mesh.texcoords[2 * i as usize..2 * i as usize + 2];
                [f64::from(t[0]), 1.0 - f64::from(t[1])]
            };
            let mapped = texture.filter(|_| mesh.texcoords.len() == mesh.positions.len() / 3 * 2);
            for arity in arities {
                let indices = &mesh.indices[start..start + arity as usize];
                let corners: Vec<DVec3> = indices.iter().map(|&i| position(i)).collect();
                start += arity as usize;
                match mapped {
                    Some(texture) => {
                        let uvs: Vec<[f64; 2]> = indices.iter().map(|&i| uv(i)).collect();
                        scene.add_textured_polygon(object, &corners, &uvs, material, texture)
                    }
                    None => scene.add_polygon(object, &corners, material),
                }
            }
        }
        scene.finish(path)
    }

    /// Loads an OBJ (with its MTL) or a glTF 2.0 file (`.gltf`, `.glb`), by extension.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let extension = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match extension.as_deref() {
            Some("gltf" | "glb") => crate::gltf_input::load_gltf(path),
            _ => Scene::load_obj(path),
        }
    }

    /// What every loader ends with: degenerate faces dropped (an emitter among them is an
    /// error), a scene left with nothing to light refused, and faces cut along the contact
    /// lines of what stands on them ([`Scene::split_at_contacts`]).
    pub(crate) fn finish(mut self, path: &Path) -> Result<Scene, SceneError> {
        if let Some(object) = self.drop_degenerate_faces() {
            return Err(SceneError::EmitterTooSmall {
                path: path.into(),
                object,
            });
        }
        if self.faces.is_empty() {
            return Err(SceneError::Empty { path: path.into() });
        }
        self.split_at_contacts();
        Ok(self)
    }

    /// Cuts every face along the contact lines of the faces standing on it
    /// ([`crate::contact`]); each face's [`Face::source`] becomes its index before the cut.
    pub fn split_at_contacts(&mut self) {
        for (index, face) in self.faces.iter_mut().enumerate() {
            face.source = index as u32;
        }
        let triangles = self.triangle_count();
        let (faces, cut) = crate::contact::split_at_contacts(std::mem::take(&mut self.faces));
        (self.faces, self.faces_cut_at_contacts) = (faces, cut);
        self.triangles_before_cuts = triangles;
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

/// The largest scene or material file read: far past any real model, short of what a
/// mistaken path (a device, a disk image) would make the loader swallow.
pub const MAX_SCENE_FILE_BYTES: u64 = 4 << 30;

/// Reads a scene or material file as text: a regular file of at most
/// [`MAX_SCENE_FILE_BYTES`].
pub fn read_scene_file(path: &Path) -> Result<String, SceneError> {
    check_scene_file(path)?;
    std::fs::read_to_string(path).map_err(|source| SceneError::Io {
        path: path.into(),
        source,
    })
}

/// Checks, without reading it, that `path` is a regular file of at most
/// [`MAX_SCENE_FILE_BYTES`]: not a device that never ends, not a disk image.
pub fn check_scene_file(path: &Path) -> Result<(), SceneError> {
    let io = |source| SceneError::Io {
        path: path.into(),
        source,
    };
    let metadata = std::fs::metadata(path).map_err(io)?;
    let refuse = |reason: String| SceneError::Parse {
        path: path.into(),
        reason,
    };
    if !metadata.is_file() {
        return Err(refuse("not a regular file".into()));
    }
    if metadata.len() > MAX_SCENE_FILE_BYTES {
        return Err(refuse(format!(
            "{} bytes is more than a scene file may have ({MAX_SCENE_FILE_BYTES})",
            metadata.len()
        )));
    }
    Ok(())
}

/// Colour statements of an MTL file: each needs three numbers.
const MTL_COLOURS: [&str; 5] = ["Ka", "Kd", "Ks", "Ke", "Tf"];

/// Checks what tobj would panic on: a colour statement without three numbers.
fn lint_mtl(path: &Path, text: &str) -> Result<(), SceneError> {
    for (number, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next().filter(|k| MTL_COLOURS.contains(k)) else {
            continue;
        };
        let numbers: Vec<&str> = words.take(3).collect();
        if numbers.len() < 3 || numbers.iter().any(|n| n.parse::<f32>().is_err()) {
            return Err(SceneError::Line {
                path: path.into(),
                line: number + 1,
                reason: format!(
                    "{keyword} needs three numbers (r g b), found '{}'",
                    line.trim()
                ),
            });
        }
    }
    Ok(())
}

fn find_view(path: &Path, text: &str) -> Result<Option<View>, SceneError> {
    for (number, line) in text.lines().enumerate() {
        if let Some(words) = line.trim().strip_prefix("#@view") {
            return View::parse(words)
                .map(Some)
                .map_err(|reason| SceneError::Line {
                    path: path.into(),
                    line: number + 1,
                    reason,
                });
        }
    }
    Ok(None)
}

fn first_mtllib(text: &str) -> Option<&str> {
    text.lines()
        .find_map(|l| l.trim().strip_prefix("mtllib ").map(str::trim))
}

/// Line-level checks that the OBJ parser does not report with a line number: non-finite
/// coordinates, face indices out of range, and unknown materials (when the library loaded).
fn lint_obj(
    path: &Path,
    text: &str,
    materials: Option<&[tobj::Material]>,
) -> Result<(), SceneError> {
    let fail = |line: usize, reason: String| {
        Err(SceneError::Line {
            path: path.into(),
            line: line + 1,
            reason,
        })
    };
    let (mut vertex_count, mut texture_coordinate_count): (i64, i64) = (0, 0);
    for (number, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                vertex_count += 1;
                for word in words.take(3) {
                    match word.parse::<f64>() {
                        Ok(x) if x.is_finite() => {}
                        _ => {
                            return fail(
                                number,
                                format!(
                                    "vertex {vertex_count} has coordinate '{word}', which is not a finite number"
                                ),
                            );
                        }
                    }
                }
            }
            Some("vt") => {
                texture_coordinate_count += 1;
                for word in words.take(2) {
                    match word.parse::<f64>() {
                        Ok(x) if x.abs() <= MAX_TEXTURE_COORDINATE => {}
                        _ => {
                            return fail(
                                number,
                                format!(
                                    "texture coordinate {texture_coordinate_count} has '{word}', which is not a finite number within ±{MAX_TEXTURE_COORDINATE:e}"
                                ),
                            );
                        }
                    }
                }
            }
            Some("f") => {
                for word in words {
                    if let Some(Ok(index)) = word
                        .split('/')
                        .nth(1)
                        .filter(|t| !t.is_empty())
                        .map(str::parse::<i64>)
                    {
                        let resolved = match index < 0 {
                            true => texture_coordinate_count + 1 + index,
                            false => index,
                        };
                        if resolved < 1 || resolved > texture_coordinate_count {
                            return fail(
                                number,
                                format!(
                                    "face refers to texture coordinate {index}, but only {texture_coordinate_count} are defined before it"
                                ),
                            );
                        }
                    }
                    let index_text = word.split('/').next().unwrap_or_default();
                    let Ok(index) = index_text.parse::<i64>() else {
                        return fail(number, format!("face vertex '{word}' is not an index"));
                    };
                    // OBJ indices are one-based; negative ones count back from the last vertex.
                    let resolved = if index < 0 {
                        vertex_count + 1 + index
                    } else {
                        index
                    };
                    if resolved < 1 || resolved > vertex_count {
                        return fail(
                            number,
                            format!(
                                "face refers to vertex {index}, but only {vertex_count} vertices are defined before it"
                            ),
                        );
                    }
                }
            }
            Some("usemtl") => {
                let name = line.trim_start().trim_start_matches("usemtl").trim();
                if let Some(materials) = materials
                    && !materials.iter().any(|m| m.name == name)
                {
                    return fail(
                        number,
                        format!("material '{name}' is not defined in any mtllib"),
                    );
                }
            }
            _ => {}
        }
    }
    Ok(())
}
