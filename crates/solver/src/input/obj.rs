//! Wavefront OBJ + MTL input, read with `tobj` after line checks of our own (tobj panics on
//! some malformed colour lines and its messages name no line).

use super::{SceneError, read_scene_file};
use crate::scene::texture::Texture;
use crate::scene::{
    MAX_COORDINATE, MAX_REFLECTANCE, MAX_TEXTURE_COORDINATE, Material, Rgb, Scene, View,
    clamp_reflectance,
};
use glam::DVec3;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Loads an OBJ file and the MTL libraries it names (relative to the OBJ's folder).
pub fn load_obj(path: &Path) -> Result<Scene, SceneError> {
    let text = read_scene_file(path)?;
    let folder = path.parent().unwrap_or(Path::new("."));
    let (models, materials) = parse(path, &text)?;
    let mtl_path = first_mtllib(&text)
        .map(|m| folder.join(m))
        .unwrap_or_else(|| path.into());
    let RadiosityMaterials {
        materials: checked,
        textures,
        warnings: load_warnings,
    } = radiosity_materials(&mtl_path, &materials)?;
    let mut scene = Scene {
        view: find_view(path, &text)?,
        textures,
        load_warnings,
        ..Scene::default()
    };
    let mut object_ids: HashMap<String, u32> = HashMap::new();
    for model in &models {
        if model.mesh.indices.is_empty() {
            continue;
        }
        let Some((material, texture)) = model.mesh.material_id.map(|id| checked[id]) else {
            return Err(SceneError::NoMaterial {
                path: path.into(),
                object: model.name.clone(),
            });
        };
        let object = *object_ids
            .entry(model.name.clone())
            .or_insert_with(|| scene.add_object(model.name.clone()));
        add_faces(&mut scene, object, &model.mesh, material, texture);
    }
    super::finish(scene, path)
}

/// The models and materials of the OBJ `text` (from `path`), its lines and its MTL libraries
/// checked first: our messages name the line, tobj's do not.
fn parse(path: &Path, text: &str) -> Result<(Vec<tobj::Model>, Vec<tobj::Material>), SceneError> {
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
    match loaded {
        Ok((models, materials)) => {
            if let Some(error) = mtl_failure.take() {
                return Err(error);
            }
            let materials = materials.map_err(|e| SceneError::Parse {
                path: path.into(),
                reason: e.to_string(),
            })?;
            lint_obj(path, text, Some(&materials))?;
            Ok((models, materials))
        }
        Err(e) => {
            if let Some(error) = mtl_failure.take() {
                return Err(error);
            }
            lint_obj(path, text, None)?;
            Err(SceneError::Parse {
                path: path.into(),
                reason: e.to_string(),
            })
        }
    }
}

/// A material and the index of its `map_Kd` texture, if it has one.
type TexturedMaterial = (Material, Option<u32>);

/// The MTL materials as radiosity takes them ([`radiosity_materials`]).
struct RadiosityMaterials {
    /// One per MTL material, in its order.
    materials: Vec<TexturedMaterial>,
    /// The textures they name, each once.
    textures: Vec<Texture>,
    /// What was changed to take them as shipped.
    warnings: Vec<String>,
}

/// Each MTL material as radiosity takes it (with the index of its `map_Kd` texture), the
/// textures they name, each loaded once, and what was changed to take them as shipped: a `Kd`
/// of 1 read as [`MAX_REFLECTANCE`], a `map_Kd` file that is not there left out (exporters
/// write the absolute path of the author's machine).
fn radiosity_materials(
    mtl_path: &Path,
    materials: &[tobj::Material],
) -> Result<RadiosityMaterials, SceneError> {
    let mut textures: Vec<(PathBuf, Texture)> = Vec::new();
    let mut warnings = Vec::new();
    let checked = materials
        .iter()
        .map(|m| {
            let rgb = |c: Option<[f32; 3]>, absent: Rgb| {
                c.map(|c| Rgb::from(c.map(f64::from))).unwrap_or(absent)
            };
            // map_Kd: Kd (1 when absent) times the texture's linear mean.
            let texture = match m.diffuse_texture.as_deref().and_then(texture_file) {
                Some(name) => {
                    let file = mtl_path.parent().unwrap_or(Path::new(".")).join(name);
                    match textures.iter().position(|(path, _)| *path == file) {
                        Some(index) => Some(index as u32),
                        None if !file.exists() => {
                            warnings.push(format!(
                                "{}: material '{}': map_Kd {} is not there: Kd alone is used",
                                mtl_path.display(),
                                m.name,
                                file.display()
                            ));
                            None
                        }
                        None => {
                            textures.push((file.clone(), super::image::load_texture(&file)?));
                            Some(textures.len() as u32 - 1)
                        }
                    }
                }
                None => None,
            };
            let reflectance = match texture {
                Some(index) => rgb(m.diffuse, Rgb::ONE) * textures[index as usize].1.mean,
                None => rgb(m.diffuse, Rgb::ZERO),
            };
            let reflectance = match clamp_reflectance(reflectance) {
                Some(clamped) => {
                    warnings.push(format!(
                        "{}: material '{}': Kd {:?} read as {:?} (at most {MAX_REFLECTANCE})",
                        mtl_path.display(),
                        m.name,
                        reflectance.to_array(),
                        clamped.to_array()
                    ));
                    clamped
                }
                None => reflectance,
            };
            let material = Material {
                reflectance,
                emission: rgb(m.emissive, Rgb::ZERO),
            };
            material
                .validate()
                .map(|()| (material, texture))
                .map_err(|reason| SceneError::Material {
                    path: mtl_path.into(),
                    material: m.name.clone(),
                    reason,
                })
        })
        .collect::<Result<_, _>>()?;
    Ok(RadiosityMaterials {
        materials: checked,
        textures: textures.into_iter().map(|(_, texture)| texture).collect(),
        warnings,
    })
}

/// Adds the faces of `mesh` to `object`, textured where `texture` is given and the mesh has a
/// coordinate per vertex.
fn add_faces(
    scene: &mut Scene,
    object: u32,
    mesh: &tobj::Mesh,
    material: Material,
    texture: Option<u32>,
) {
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
            return parse_view(words)
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

/// Parses the words after `#@view`.
fn parse_view(words: &str) -> Result<View, String> {
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
    let mut defined = Defined::default();
    for (number, line) in text.lines().enumerate() {
        lint_line(line, &mut defined, materials).map_err(|reason| SceneError::Line {
            path: path.into(),
            line: number + 1,
            reason,
        })?;
    }
    Ok(())
}

/// What the lines so far have defined, for the indices of the next.
#[derive(Default)]
struct Defined {
    vertices: i64,
    texture_coordinates: i64,
}

/// Why `line` is wrong, given what came before it (counted into `defined`).
fn lint_line(
    line: &str,
    defined: &mut Defined,
    materials: Option<&[tobj::Material]>,
) -> Result<(), String> {
    let mut words = line.split_whitespace();
    match words.next() {
        Some("v") => {
            defined.vertices += 1;
            let vertex = defined.vertices;
            words
                .take(3)
                .try_for_each(|word| match word.parse::<f64>() {
                    Ok(x) if x.is_finite() => Ok(()),
                    _ => Err(format!(
                        "vertex {vertex} has coordinate '{word}', which is not a finite number"
                    )),
                })
        }
        Some("vt") => {
            defined.texture_coordinates += 1;
            let coordinate = defined.texture_coordinates;
            words.take(2).try_for_each(|word| match word.parse::<f64>() {
                Ok(x) if x.abs() <= MAX_TEXTURE_COORDINATE => Ok(()),
                _ => Err(format!(
                    "texture coordinate {coordinate} has '{word}', which is not a finite number within ±{MAX_TEXTURE_COORDINATE:e}"
                )),
            })
        }
        Some("f") => words.try_for_each(|word| lint_face_vertex(word, defined)),
        Some("usemtl") => {
            let name = line.trim_start().trim_start_matches("usemtl").trim();
            match materials {
                Some(materials) if !materials.iter().any(|m| m.name == name) => {
                    Err(format!("material '{name}' is not defined in any mtllib"))
                }
                _ => Ok(()),
            }
        }
        _ => Ok(()),
    }
}

/// Why a face's `v/vt/vn` word is wrong: not an index, or one past what is `defined`.
fn lint_face_vertex(word: &str, defined: &Defined) -> Result<(), String> {
    // OBJ indices are one-based; negative ones count back from the last one defined.
    let resolve = |index: i64, count: i64| match index < 0 {
        true => count + 1 + index,
        false => index,
    };
    if let Some(Ok(index)) = word
        .split('/')
        .nth(1)
        .filter(|t| !t.is_empty())
        .map(str::parse::<i64>)
    {
        let count = defined.texture_coordinates;
        if !(1..=count).contains(&resolve(index, count)) {
            return Err(format!(
                "face refers to texture coordinate {index}, but only {count} are defined before it"
            ));
        }
    }
    let index_text = word.split('/').next().unwrap_or_default();
    let Ok(index) = index_text.parse::<i64>() else {
        return Err(format!("face vertex '{word}' is not an index"));
    };
    let count = defined.vertices;
    if !(1..=count).contains(&resolve(index, count)) {
        return Err(format!(
            "face refers to vertex {index}, but only {count} vertices are defined before it"
        ));
    }
    Ok(())
}

/// The file of a texture statement (what follows `map_Kd`): its options, each with its
/// arguments (the MTL spec's `-o`, `-s` and `-t` take up to three numbers, `-mm` two, the rest
/// one), come first, and the rest is the file name, spaces and all (`C:/Documents and
/// Settings/...`, as exporters write it).
fn texture_file(statement: &str) -> Option<&str> {
    let mut rest = statement.trim();
    while rest.starts_with('-') {
        let (option, after) = rest.split_once(char::is_whitespace).unwrap_or((rest, ""));
        let (least, most) = match option {
            "-o" | "-s" | "-t" => (1, 3),
            "-mm" => (2, 2),
            _ => (1, 1),
        };
        rest = after.trim_start();
        for taken in 0..most {
            let (word, after) = rest.split_once(char::is_whitespace).unwrap_or((rest, ""));
            if taken >= least && word.parse::<f64>().is_err() {
                break;
            }
            rest = after.trim_start();
        }
    }
    (!rest.is_empty()).then_some(rest)
}

#[cfg(test)]
mod tests {
    use super::texture_file;

    #[test]
    fn a_texture_file_is_what_follows_the_options_spaces_and_all() {
        assert_eq!(texture_file("wood.png"), Some("wood.png"));
        assert_eq!(
            texture_file(" -bm 0.5 -clamp on wood.png "),
            Some("wood.png")
        );
        assert_eq!(texture_file("-s 2 2 1 -o 0.5 wood.png"), Some("wood.png"));
        assert_eq!(texture_file("-s 2 my wood.png"), Some("my wood.png"));
        assert_eq!(texture_file("-mm 0 1 wood.png"), Some("wood.png"));
        assert_eq!(
            texture_file("C:/Documents and Settings/jeremy/oak.jpg"),
            Some("C:/Documents and Settings/jeremy/oak.jpg")
        );
        assert_eq!(texture_file("-clamp on"), None);
        assert_eq!(texture_file(""), None);
    }
}
