//! The town: buildings, domes and trees on open ground under a large emitting sky, every
//! surface cut into small triangles with vertices of their own (triangle soup) — the make-up of
//! a real third-party model: many faces smaller than any element a solution needs, curved
//! surfaces as facets, one large area light.

use super::{GeneratedScene, MaterialLine, Writer, materials};
use glam::{DVec3, dvec3};
use std::f64::consts::PI;
use std::fmt::Write;

/// Materials: diffuse reflectance (`Kd`) and emitted radiosity (`Ke`, W/m^2).
const MATERIALS: [MaterialLine; 7] = [
    ("ground", [0.25, 0.24, 0.20], [0.0; 3]),
    ("concrete", [0.60, 0.58, 0.55], [0.0; 3]),
    ("brick", [0.50, 0.28, 0.22], [0.0; 3]),
    ("copper", [0.30, 0.55, 0.45], [0.0; 3]),
    ("leaves", [0.12, 0.35, 0.10], [0.0; 3]),
    ("bark", [0.30, 0.20, 0.12], [0.0; 3]),
    ("sky", [0.0; 3], [1.0, 1.1, 1.3]),
];

/// Side of the square of ground, metres.
const GROUND: f64 = 60.0;
/// Height of the sky quad above the ground, metres.
const SKY_HEIGHT: f64 = 40.0;
/// Buildings along each side of the town's grid.
const BLOCKS: usize = 3;

/// A surface before it is cut into triangles of about one edge length.
enum Shape {
    /// The parallelogram `origin + s u + t v`, front `u x v`.
    Parallelogram { origin: DVec3, u: DVec3, v: DVec3 },
    /// A sphere (`full`) or the upper half of one, facing out.
    Sphere {
        centre: DVec3,
        radius: f64,
        full: bool,
    },
    /// The side of an upright cylinder from `base` up `height`, facing out.
    Cylinder {
        base: DVec3,
        radius: f64,
        height: f64,
    },
}

/// One object: its name, material and shapes.
struct Part {
    name: String,
    material: &'static str,
    shapes: Vec<Shape>,
}

/// A town of about `triangles` triangles (the tessellation is chosen to come within a few per
/// cent): a 3 x 3 grid of buildings (some with domes) and trees on 60 m of ground, under a
/// 60 m emitting sky quad 40 m up (the one face that is not cut). The same `seed` gives the same
/// town; the OBJ refers to `mtl_name`.
pub fn town(triangles: usize, seed: u64, mtl_name: &str) -> GeneratedScene {
    let parts = layout(seed);
    let target = triangles.max(100) as f64;
    // Triangles go as area / edge^2: start from that, then correct on the counts.
    let area: f64 = parts.iter().flat_map(|p| &p.shapes).map(shape_area).sum();
    let mut edge = (2.0 * area / target).sqrt();
    for _ in 0..3 {
        let count: usize = parts
            .iter()
            .flat_map(|p| &p.shapes)
            .map(|s| cut(s, edge).len())
            .sum();
        edge *= (count as f64 / target).sqrt();
    }
    let mut w = Writer::new(seed);
    let _ = writeln!(
        w.obj,
        "# radcast generate --town {triangles} --seed {seed}: buildings and trees under a sky, triangle soup\nmtllib {mtl_name}"
    );
    for part in &parts {
        w.object(&part.name, part.material);
        for triangle in part.shapes.iter().flat_map(|s| cut(s, edge)) {
            w.face(&triangle);
        }
    }
    w.object("sky", "sky");
    let half = GROUND / 2.0;
    w.quad(
        dvec3(-half, SKY_HEIGHT, -half),
        DVec3::X * GROUND,
        DVec3::Z * GROUND,
    );
    GeneratedScene {
        obj: w.obj,
        mtl: materials("materials of the town", &MATERIALS),
    }
}

/// Where everything stands: ground, buildings on a grid, a dome on some, trees between.
fn layout(seed: u64) -> Vec<Part> {
    let mut w = Writer::new(seed);
    let half = GROUND / 2.0;
    let mut parts = vec![Part {
        name: "ground".into(),
        material: "ground",
        shapes: vec![Shape::Parallelogram {
            origin: dvec3(-half, 0.0, -half),
            u: DVec3::Z * GROUND,
            v: DVec3::X * GROUND,
        }],
    }];
    let cell = GROUND / BLOCKS as f64;
    for i in 0..BLOCKS {
        for j in 0..BLOCKS {
            let corner = dvec3(-half + i as f64 * cell, 0.0, -half + j as f64 * cell);
            let (width, depth, height) = (
                w.between(0.35, 0.6) * cell,
                w.between(0.35, 0.6) * cell,
                w.between(5.0, 18.0),
            );
            let lo = corner + dvec3(0.1 * cell, 0.0, 0.1 * cell);
            let (x, y, z) = (DVec3::X * width, DVec3::Y * height, DVec3::Z * depth);
            let material = if w.unit() < 0.5 { "concrete" } else { "brick" };
            parts.push(Part {
                name: format!("building_{i}_{j}"),
                material,
                shapes: [
                    (lo + y, z, x),
                    (lo, z, y),
                    (lo + x, y, z),
                    (lo, y, x),
                    (lo + z, x, y),
                ]
                .map(|(origin, u, v)| Shape::Parallelogram { origin, u, v })
                .into(),
            });
            if w.unit() < 0.4 {
                parts.push(Part {
                    name: format!("dome_{i}_{j}"),
                    material: "copper",
                    shapes: vec![Shape::Sphere {
                        centre: lo + dvec3(width / 2.0, height, depth / 2.0),
                        radius: 0.4 * width.min(depth),
                        full: false,
                    }],
                });
            }
            // A tree in the open part of the cell.
            let (trunk, crown) = (w.between(2.0, 4.0), w.between(1.2, 2.5));
            let base = corner + dvec3(0.8 * cell, 0.0, w.between(0.2, 0.8) * cell);
            parts.push(Part {
                name: format!("tree_{i}_{j}"),
                material: "bark",
                shapes: vec![Shape::Cylinder {
                    base,
                    radius: 0.25,
                    height: trunk,
                }],
            });
            parts.push(Part {
                name: format!("crown_{i}_{j}"),
                material: "leaves",
                shapes: vec![Shape::Sphere {
                    centre: base + DVec3::Y * (trunk + 0.8 * crown),
                    radius: crown,
                    full: true,
                }],
            });
        }
    }
    parts
}

/// Surface area of `shape`, m^2.
fn shape_area(shape: &Shape) -> f64 {
    match *shape {
        Shape::Parallelogram { u, v, .. } => u.cross(v).length(),
        Shape::Sphere { radius, full, .. } => {
            if full {
                4.0 * PI * radius * radius
            } else {
                2.0 * PI * radius * radius
            }
        }
        Shape::Cylinder { radius, height, .. } => 2.0 * PI * radius * height,
    }
}

/// `shape` as triangles with edges of about `edge`, each counter-clockwise about its front.
fn cut(shape: &Shape, edge: f64) -> Vec<[DVec3; 3]> {
    let steps = |length: f64, least: usize| ((length / edge).ceil() as usize).max(least);
    let mut triangles = Vec::new();
    // The grid cell (a, b) of a surface `point(s, t)` as two triangles, front by the order.
    let mut grid = |nu: usize, nv: usize, point: &dyn Fn(f64, f64) -> DVec3| {
        for a in 0..nu {
            for b in 0..nv {
                let at = |da: usize, db: usize| {
                    point((a + da) as f64 / nu as f64, (b + db) as f64 / nv as f64)
                };
                let (p00, p10, p11, p01) = (at(0, 0), at(1, 0), at(1, 1), at(0, 1));
                for t in [[p00, p10, p11], [p00, p11, p01]] {
                    // Cells at a pole collapse one triangle to a line: left out.
                    if (t[1] - t[0]).cross(t[2] - t[0]).length_squared() > 0.0 {
                        triangles.push(t);
                    }
                }
            }
        }
    };
    match *shape {
        Shape::Parallelogram { origin, u, v } => {
            grid(steps(u.length(), 1), steps(v.length(), 1), &|s, t| {
                origin + u * s + v * t
            })
        }
        Shape::Sphere {
            centre,
            radius,
            full,
        } => {
            let lowest = if full { -PI / 2.0 } else { 0.0 };
            let around = steps(2.0 * PI * radius, 6);
            let up = steps((PI / 2.0 - lowest) * radius, 2);
            // (longitude, latitude) with longitude running so that the front faces out.
            grid(up, around, &|s, t| {
                let (latitude, longitude) = (lowest + (PI / 2.0 - lowest) * s, 2.0 * PI * t);
                centre
                    + radius
                        * dvec3(
                            latitude.cos() * longitude.cos(),
                            latitude.sin(),
                            latitude.cos() * longitude.sin(),
                        )
            })
        }
        Shape::Cylinder {
            base,
            radius,
            height,
        } => grid(steps(height, 1), steps(2.0 * PI * radius, 6), &|s, t| {
            let longitude = 2.0 * PI * t;
            base + dvec3(
                radius * longitude.cos(),
                height * s,
                -radius * longitude.sin(),
            )
        }),
    }
    triangles
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    fn loaded(triangles: usize, seed: u64) -> Scene {
        let town = town(triangles, seed, "town.mtl");
        let dir = std::env::temp_dir().join(format!("radcast-town-{triangles}-{seed}"));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("town.obj"), &town.obj).unwrap();
        std::fs::write(dir.join("town.mtl"), &town.mtl).unwrap();
        crate::input::load_obj(&dir.join("town.obj")).unwrap()
    }

    #[test]
    fn the_town_has_about_the_triangles_asked_for_and_one_emitter() {
        for asked in [2_000, 20_000] {
            let scene = loaded(asked, 1);
            let got = scene.triangle_count();
            assert!(
                (got as f64 / asked as f64 - 1.0).abs() < 0.05,
                "asked {asked}, got {got}"
            );
            let emitting: Vec<_> = scene
                .faces
                .iter()
                .filter(|f| f.emission.max_element() > 0.0)
                .collect();
            assert_eq!(emitting.len(), 1, "the sky alone emits");
            assert!((emitting[0].polygon.area() - GROUND * GROUND).abs() < 1e-6);
        }
    }

    #[test]
    fn every_face_but_the_sky_faces_away_from_the_solid_it_bounds() {
        // Outward: a sphere's or cylinder's facets face away from its axis, the ground and
        // roofs up; so every face but the sky's sees the sky's height from its front or is a
        // wall (normal horizontal).
        let scene = loaded(5_000, 2);
        for face in scene
            .faces
            .iter()
            .filter(|f| f.emission.max_element() == 0.0)
        {
            let n = face.polygon.normal();
            assert!(n.is_finite() && (n.length() - 1.0).abs() < 1e-9, "{n}");
        }
        let crowns: Vec<_> = scene
            .faces
            .iter()
            .filter(|f| scene.objects[f.object as usize].name == "crown_0_0")
            .collect();
        assert!(!crowns.is_empty());
        // A closed sphere: its facets' area-weighted normals sum to zero, and each faces away
        // from the centre of its crown's bounds.
        let centre =
            crowns.iter().map(|f| f.polygon.centroid()).sum::<DVec3>() / crowns.len() as f64;
        let outward = crowns
            .iter()
            .filter(|f| (f.polygon.centroid() - centre).dot(f.polygon.normal()) > 0.0)
            .count();
        assert!(
            outward * 10 >= crowns.len() * 9,
            "{outward} of {}",
            crowns.len()
        );
    }

    #[test]
    fn the_same_seed_gives_the_same_town() {
        assert_eq!(town(3_000, 5, "a.mtl").obj, town(3_000, 5, "a.mtl").obj);
        assert_ne!(town(3_000, 5, "a.mtl").obj, town(3_000, 6, "a.mtl").obj);
    }
}
