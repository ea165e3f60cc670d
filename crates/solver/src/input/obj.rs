//! Wavefront OBJ + MTL input, read with `tobj` after line checks of our own (tobj panics on
//! some malformed colour lines and its messages name no line).

use super::{SceneError, read_scene_file};
use crate::scene::texture::Texture;
use crate::scene::{MAX_COORDINATE, MAX_TEXTURE_COORDINATE, Material, Rgb, Scene, View};
use glam::DVec3;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

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
                            textures.push((file.clone(), super::image::load_texture(&file)?));
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
    super::finish(scene, path)
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
