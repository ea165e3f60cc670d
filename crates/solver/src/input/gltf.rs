//! glTF 2.0 input (`.gltf` with its buffers and images, or `.glb`), read with the `gltf` crate.
//!
//! What a scene takes from it, in these units:
//! - geometry: every triangle primitive of the default scene (else the first), placed by its
//!   node's world transform; positions in the file's units (metres by the glTF spec);
//! - reflectance: `baseColorFactor` times the mean of `baseColorTexture` over its texels, in
//!   linear colour (sRGB texels decoded), at most [`MAX_REFLECTANCE`]; the texture itself, with
//!   the primitive's `TEXCOORD_n` of that texture, is what viewers show over it;
//! - emission, W/m²: π times `emissiveFactor` times `KHR_materials_emissive_strength` times the
//!   mean of `emissiveTexture`, reading the product as radiance (W/(m²·sr)); a Lambertian
//!   surface's exitance is π times its radiance;
//! - objects: one per node with a mesh, named after the node (else its mesh, else `node<N>`),
//!   made unique with `#2`, `#3`… as needed.
//!
//! A texture's mean stands for the whole surface in the solution; an emissive texture is not
//! shown (its mean scales the emission); samplers are not read (viewers repeat). Points,
//! lines and strips-of-lines primitives, and files whose external buffers or images are not
//! regular files, are refused with the reason.

use super::{SceneError, check_scene_file};
use crate::scene::texture::{Texture, mean, srgb_to_linear};
use crate::scene::{MAX_COORDINATE, MAX_REFLECTANCE, MAX_TEXTURE_COORDINATE, Material, Rgb, Scene};
use glam::{DMat4, DVec3};
use std::collections::HashMap;
use std::path::Path;

/// Loads the glTF file at `path`.
pub fn load_gltf(path: &Path) -> Result<Scene, SceneError> {
    let (gltf, buffers, images) = import(path)?;
    let document = &gltf.document;
    let Some(root) = document
        .default_scene()
        .or_else(|| document.scenes().next())
    else {
        return Err(parse_error(path, "the file has no scene".into()));
    };
    let mut builder = Builder {
        path,
        buffers: &buffers,
        images: &images,
        scene: Scene::default(),
        shown: HashMap::new(),
        image_means: HashMap::new(),
        names: HashMap::new(),
    };
    let mut stack: Vec<(gltf::Node, DMat4)> = root.nodes().map(|n| (n, DMat4::IDENTITY)).collect();
    while let Some((node, parent)) = stack.pop() {
        let local = node
            .transform()
            .matrix()
            .map(|column| column.map(f64::from));
        let world = parent * DMat4::from_cols_array_2d(&local);
        stack.extend(node.children().map(|child| (child, world)));
        if let Some(mesh) = node.mesh() {
            builder.add_mesh(&node, &mesh, world)?;
        }
    }
    super::finish(builder.scene, path)
}

fn parse_error(path: &Path, reason: String) -> SceneError {
    SceneError::Parse {
        path: path.into(),
        reason,
    }
}

/// The document at `path` with its buffers and images, external files checked like every
/// scene file before the crate reads them whole.
fn import(
    path: &Path,
) -> Result<(gltf::Gltf, Vec<gltf::buffer::Data>, Vec<gltf::image::Data>), SceneError> {
    let fail = |reason| parse_error(path, reason);
    check_scene_file(path)?;
    let bytes = std::fs::read(path).map_err(|source| SceneError::Io {
        path: path.into(),
        source,
    })?;
    let gltf = gltf::Gltf::from_slice(&bytes).map_err(|e| fail(e.to_string()))?;
    let folder = path.parent().unwrap_or(Path::new("."));
    let external = gltf
        .document
        .buffers()
        .filter_map(|b| match b.source() {
            gltf::buffer::Source::Uri(uri) => Some(uri.to_string()),
            gltf::buffer::Source::Bin => None,
        })
        .chain(gltf.document.images().filter_map(|i| match i.source() {
            gltf::image::Source::Uri { uri, .. } => Some(uri.to_string()),
            gltf::image::Source::View { .. } => None,
        }));
    for uri in external.filter(|u| !u.starts_with("data:")) {
        check_scene_file(&folder.join(&uri))?;
    }
    let buffers = gltf::import_buffers(&gltf.document, Some(folder), gltf.blob.clone())
        .map_err(|e| fail(format!("buffers: {e}")))?;
    let images = gltf::import_images(&gltf.document, Some(folder), &buffers)
        .map_err(|e| fail(format!("images: {e}")))?;
    Ok((gltf, buffers, images))
}

/// A scene as the document's nodes are added to it.
struct Builder<'a> {
    path: &'a Path,
    buffers: &'a [gltf::buffer::Data],
    images: &'a [gltf::image::Data],
    scene: Scene,
    /// Image index -> index into `scene.textures`, for the base-colour images faces show.
    shown: HashMap<usize, u32>,
    /// Image index -> its linear mean, computed once however many materials use the image.
    image_means: HashMap<usize, Rgb>,
    /// How many objects took each name so far.
    names: HashMap<String, usize>,
}

impl Builder<'_> {
    fn fail(&self, reason: String) -> SceneError {
        parse_error(self.path, reason)
    }

    /// Adds `mesh`, placed by `world`, as an object named after `node` (made unique).
    fn add_mesh(
        &mut self,
        node: &gltf::Node,
        mesh: &gltf::Mesh,
        world: DMat4,
    ) -> Result<(), SceneError> {
        let base = node
            .name()
            .or(mesh.name())
            .map_or_else(|| format!("node{}", node.index()), str::to_string);
        let seen = self.names.entry(base.clone()).or_insert(0);
        *seen += 1;
        let name = match *seen {
            1 => base,
            n => format!("{base}#{n}"),
        };
        let object = self.scene.add_object(name.clone());
        for (index, primitive) in mesh.primitives().enumerate() {
            let at = format!("object '{name}' primitive {index}");
            self.add_primitive(object, &primitive, world)
                .map_err(|reason| self.fail(format!("{at}: {reason}")))?;
        }
        Ok(())
    }

    /// Adds the triangles of `primitive` to `object`; the reason names what is wrong.
    fn add_primitive(
        &mut self,
        object: u32,
        primitive: &gltf::Primitive,
        world: DMat4,
    ) -> Result<(), String> {
        if primitive.mode() != gltf::mesh::Mode::Triangles {
            return Err(format!(
                "mode {:?} is not supported (triangles only)",
                primitive.mode()
            ));
        }
        let buffers = self.buffers;
        let reader = primitive.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let positions: Vec<DVec3> = reader
            .read_positions()
            .ok_or("no POSITION attribute")?
            .map(|p| world.transform_point3(DVec3::from(p.map(f64::from))))
            .collect();
        if let Some(bad) = positions
            .iter()
            .position(|p| !p.is_finite() || p.abs().max_element() > MAX_COORDINATE)
        {
            return Err(format!(
                "vertex {bad} lies at {}, not a finite point within ±{MAX_COORDINATE:e}",
                positions[bad]
            ));
        }
        let indices: Vec<u32> = match reader.read_indices() {
            Some(indices) => indices.into_u32().collect(),
            None => (0..positions.len() as u32).collect(),
        };
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= positions.len()) {
            return Err(format!("index {bad} past its {} vertices", positions.len()));
        }
        let base_texture = primitive
            .material()
            .pbr_metallic_roughness()
            .base_color_texture();
        let mapped = match base_texture {
            Some(info) => {
                let set = info.tex_coord();
                let uvs = reader.read_tex_coords(set).map(|t| {
                    t.into_f32()
                        .map(|uv| uv.map(f64::from))
                        .collect::<Vec<[f64; 2]>>()
                });
                match uvs {
                    Some(uvs) => {
                        check_texture_coordinates(&uvs, positions.len())
                            .map_err(|reason| format!("TEXCOORD_{set}: {reason}"))?;
                        Some((self.shown_texture(info.texture().source().index())?, uvs))
                    }
                    None => None,
                }
            }
            None => None,
        };
        let material = material_of(&primitive.material(), self.images, &mut self.image_means)?;
        for triangle in indices.chunks_exact(3) {
            let corners: Vec<DVec3> = triangle.iter().map(|&i| positions[i as usize]).collect();
            match &mapped {
                Some((texture, uvs)) => {
                    let uvs: Vec<[f64; 2]> = triangle.iter().map(|&i| uvs[i as usize]).collect();
                    self.scene
                        .add_textured_polygon(object, &corners, &uvs, material, *texture)
                }
                None => self.scene.add_polygon(object, &corners, material),
            }
        }
        Ok(())
    }

    /// The index in `scene.textures` of image `image`, shown as a base colour (made once).
    fn shown_texture(&mut self, image: usize) -> Result<u32, String> {
        if let Some(&texture) = self.shown.get(&image) {
            return Ok(texture);
        }
        let texture =
            texture_of(&self.images[image]).map_err(|reason| format!("image {image}: {reason}"))?;
        self.image_means.insert(image, texture.mean);
        self.scene.textures.push(texture);
        let index = self.scene.textures.len() as u32 - 1;
        self.shown.insert(image, index);
        Ok(index)
    }
}

/// The radiosity material of a glTF material (see the module notes).
fn material_of(
    material: &gltf::Material,
    images: &[gltf::image::Data],
    image_means: &mut HashMap<usize, Rgb>,
) -> Result<Material, String> {
    let mut texture_mean = |texture: Option<gltf::Texture>| -> Result<Rgb, String> {
        let Some(texture) = texture else {
            return Ok(Rgb::ONE);
        };
        let image = texture.source().index();
        if let Some(&mean) = image_means.get(&image) {
            return Ok(mean);
        }
        let mean = images
            .get(image)
            .ok_or_else(|| format!("texture {} has no image", texture.index()))
            .and_then(linear_mean)?;
        image_means.insert(image, mean);
        Ok(mean)
    };
    let pbr = material.pbr_metallic_roughness();
    let [r, g, b, _] = pbr.base_color_factor().map(f64::from);
    let base = Rgb::new(r, g, b) * texture_mean(pbr.base_color_texture().map(|t| t.texture()))?;
    let strength = f64::from(material.emissive_strength().unwrap_or(1.0));
    // Exitance of a Lambertian emitter: π times its radiance.
    let radiance = Rgb::from(material.emissive_factor().map(f64::from))
        * strength
        * texture_mean(material.emissive_texture().map(|t| t.texture()))?;
    let converted = Material {
        reflectance: base.min(Rgb::splat(MAX_REFLECTANCE)),
        emission: radiance * std::f64::consts::PI,
    };
    converted.validate().map(|()| converted)
}

/// Checks a primitive's texture coordinates: one per vertex, each finite within
/// ±[`MAX_TEXTURE_COORDINATE`].
fn check_texture_coordinates(uvs: &[[f64; 2]], vertices: usize) -> Result<(), String> {
    if uvs.len() != vertices {
        return Err(format!("{} coordinates for {vertices} vertices", uvs.len()));
    }
    match uvs
        .iter()
        .position(|uv| !uv.iter().all(|c| c.abs() <= MAX_TEXTURE_COORDINATE))
    {
        Some(bad) => Err(format!(
            "vertex {bad} has {:?}, not finite within ±{MAX_TEXTURE_COORDINATE:e}",
            uvs[bad]
        )),
        None => Ok(()),
    }
}

/// The mean colour of an image's texels, linear (see [`linear_texels`]).
fn linear_mean(image: &gltf::image::Data) -> Result<Rgb, String> {
    mean(linear_texels(image))
}

/// An image as a texture viewers are shown.
fn texture_of(image: &gltf::image::Data) -> Result<Texture, String> {
    Texture::from_linear(image.width, image.height, linear_texels(image))
}

/// An image's texels, linear, row by row from the top (8- and 16-bit channels sRGB-decoded,
/// float channels as they are). Alpha is ignored; grey formats spread grey over r, g and b.
fn linear_texels(image: &gltf::image::Data) -> impl Iterator<Item = Rgb> + '_ {
    use gltf::image::Format;
    let (channels, bytes_per_channel) = match image.format {
        Format::R8 => (1, 1),
        Format::R8G8 => (2, 1),
        Format::R8G8B8 => (3, 1),
        Format::R8G8B8A8 => (4, 1),
        Format::R16 => (1, 2),
        Format::R16G16 => (2, 2),
        Format::R16G16B16 => (3, 2),
        Format::R16G16B16A16 => (4, 2),
        Format::R32G32B32FLOAT => (3, 4),
        Format::R32G32B32A32FLOAT => (4, 4),
    };
    let channel = move |texel: &[u8], c: usize| -> f64 {
        let at = &texel[c * bytes_per_channel..(c + 1) * bytes_per_channel];
        match bytes_per_channel {
            1 => srgb_to_linear(f64::from(at[0]) / 255.0),
            2 => srgb_to_linear(f64::from(u16::from_le_bytes([at[0], at[1]])) / 65535.0),
            _ => f64::from(f32::from_le_bytes([at[0], at[1], at[2], at[3]])),
        }
    };
    image
        .pixels
        .chunks_exact(channels * bytes_per_channel)
        .map(move |texel| match channels {
            1 | 2 => Rgb::splat(channel(texel, 0)),
            _ => Rgb::new(channel(texel, 0), channel(texel, 1), channel(texel, 2)),
        })
}
