//! Scenes with known answers, built in code, and the closed forms they are checked against.
#![allow(dead_code)] // each test binary uses its own subset

pub mod http;
pub mod viewer;

use glam::{DVec3, dvec3};
use solver::visibility::Occluders;
use solver::{
    DenseFormFactors, FormFactorSettings, Material, Mesh, PatchTarget, Rgb, Scene, Solved,
};
use std::f64::consts::PI;

/// A grey material.
pub fn grey(reflectance: f64, emission: f64) -> Material {
    Material {
        reflectance: Rgb::splat(reflectance),
        emission: Rgb::splat(emission),
    }
}

/// Adds the parallelogram `origin, origin + u, origin + u + v, origin + v`; its front is `u x v`.
pub fn add_rect(
    scene: &mut Scene,
    name: &str,
    origin: DVec3,
    u: DVec3,
    v: DVec3,
    material: Material,
) -> u32 {
    let object = scene.add_object(name);
    scene.add_polygon(
        object,
        &[origin, origin + u, origin + u + v, origin + v],
        material,
    );
    object
}

/// The closed cube [0, size]^3 with every face turned inwards, all of one material.
pub fn closed_cube(size: f64, material: Material) -> Scene {
    let mut scene = Scene::default();
    let (x, y, z) = (DVec3::X * size, DVec3::Y * size, DVec3::Z * size);
    add_rect(&mut scene, "floor", DVec3::ZERO, z, x, material);
    add_rect(&mut scene, "ceiling", y, x, z, material);
    add_rect(&mut scene, "wall_x0", DVec3::ZERO, y, z, material);
    add_rect(&mut scene, "wall_x1", x, z, y, material);
    add_rect(&mut scene, "wall_z0", DVec3::ZERO, x, y, material);
    add_rect(&mut scene, "wall_z1", z, y, x, material);
    scene
}

/// The closed room [0, 3]^3 with a closed box [1, 2]^3 (outward faces, object "block") floating
/// inside; everything of one material: a furnace with an occluder.
pub fn occluded_furnace(material: Material) -> Scene {
    let mut scene = closed_cube(3.0, material);
    let o = dvec3(1.0, 1.0, 1.0);
    let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
    for (origin, u, v) in [
        (o, x, z),
        (o + y, z, x),
        (o, z, y),
        (o + x, y, z),
        (o, y, x),
        (o + z, x, y),
    ] {
        add_rect(&mut scene, "block", origin, u, v, material);
    }
    scene
}

/// Two closed unit rooms "a" and "b" side by side, sharing a wall made of two back-to-back
/// faces; only room a has a lamp.
pub fn two_rooms_one_lamp() -> Scene {
    let mut scene = Scene::default();
    let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
    for (room, origin) in [("a", DVec3::ZERO), ("b", x)] {
        for (corner, u, v) in [
            (origin, z, x),
            (origin + y, x, z),
            (origin, y, z),
            (origin + x, z, y),
            (origin, x, y),
            (origin + z, y, x),
        ] {
            add_rect(&mut scene, room, corner, u, v, grey(0.7, 0.0));
        }
    }
    add_rect(
        &mut scene,
        "lamp",
        dvec3(0.4, 0.999, 0.4),
        DVec3::X * 0.2,
        DVec3::Z * 0.2,
        grey(0.0, 10.0),
    );
    scene
}

/// Area-weighted mean radiosity of `object` in a solved scene.
pub fn mean_of(solved: &Solved, object: &str) -> Rgb {
    let o = solved
        .report
        .objects
        .iter()
        .find(|o| o.name == object)
        .expect("object exists");
    Rgb::from(o.radiosity)
}

/// The largest channel of every patch of `object`.
pub fn brightness_of(solved: &Solved, object: &str) -> Vec<f64> {
    solved
        .mesh
        .patches
        .iter()
        .zip(&solved.radiosity)
        .filter(|(p, _)| solved.scene.objects[p.object as usize].name == object)
        .map(|(_, b)| b.max_element())
        .collect()
}

/// Two directly opposed `a x b` rectangles a distance `c` apart: "receiver" at z = 0 facing +z,
/// "emitter" at z = c facing -z.
pub fn parallel_plates(a: f64, b: f64, c: f64, receiver: Material, emitter: Material) -> Scene {
    let mut scene = Scene::default();
    add_rect(
        &mut scene,
        "receiver",
        DVec3::ZERO,
        DVec3::X * a,
        DVec3::Y * b,
        receiver,
    );
    add_rect(
        &mut scene,
        "emitter",
        dvec3(0.0, 0.0, c),
        DVec3::Y * b,
        DVec3::X * a,
        emitter,
    );
    scene
}

/// Two rectangles at 90 degrees sharing an edge of length `l`: "floor" (width `w`, on y = 0)
/// and "wall" (height `h`, on x = 0).
pub fn hinge(w: f64, h: f64, l: f64, floor: Material, wall: Material) -> Scene {
    let mut scene = Scene::default();
    add_rect(
        &mut scene,
        "floor",
        DVec3::ZERO,
        DVec3::Z * l,
        DVec3::X * w,
        floor,
    );
    add_rect(
        &mut scene,
        "wall",
        DVec3::ZERO,
        DVec3::Y * h,
        DVec3::Z * l,
        wall,
    );
    scene
}

/// Howell's catalog C-11: directly opposed parallel `a x b` rectangles at distance `c`.
pub fn howell_parallel(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a / c, b / c);
    let (x2, y2) = (x * x, y * y);
    2.0 / (PI * x * y)
        * ((((1.0 + x2) * (1.0 + y2)) / (1.0 + x2 + y2)).sqrt().ln()
            + x * (1.0 + y2).sqrt() * (x / (1.0 + y2).sqrt()).atan()
            + y * (1.0 + x2).sqrt() * (y / (1.0 + x2).sqrt()).atan()
            - x * x.atan()
            - y * y.atan())
}

/// Howell's catalog C-14: from the rectangle of width `w` to the one of height `h`, at 90
/// degrees and sharing an edge of length `l`.
pub fn howell_perpendicular(w: f64, h: f64, l: f64) -> f64 {
    let (w, h) = (w / l, h / l);
    let (w2, h2) = (w * w, h * h);
    let root = (h2 + w2).sqrt();
    let log_term = ((1.0 + w2) * (1.0 + h2) / (1.0 + w2 + h2)).ln()
        + w2 * (w2 * (1.0 + w2 + h2) / ((1.0 + w2) * (w2 + h2))).ln()
        + h2 * (h2 * (1.0 + w2 + h2) / ((1.0 + h2) * (h2 + w2))).ln();
    1.0 / (PI * w)
        * (w * (1.0 / w).atan() + h * (1.0 / h).atan() - root * (1.0 / root).atan()
            + 0.25 * log_term)
}

/// Meshes `scene` and computes its dense form factors.
pub fn form_factors(scene: &Scene, target: PatchTarget) -> (Mesh, DenseFormFactors) {
    let mesh = Mesh::build(scene, target);
    let occluders = Occluders::new(scene);
    let factors = DenseFormFactors::compute(
        &mesh,
        &occluders,
        &FormFactorSettings::default(),
        &solver::no_progress,
    );
    (mesh, factors)
}

/// Area-weighted form factor from object `from` to object `to`: sum_i A_i sum_j F_ij / A_from.
pub fn object_form_factor(mesh: &Mesh, factors: &DenseFormFactors, from: u32, to: u32) -> f64 {
    let (mut weighted, mut area) = (0.0, 0.0);
    for (i, p) in mesh
        .patches
        .iter()
        .enumerate()
        .filter(|(_, p)| p.object == from)
    {
        area += p.area;
        weighted += p.area
            * mesh
                .patches
                .iter()
                .enumerate()
                .filter(|(_, q)| q.object == to)
                .map(|(j, _)| factors.get(i, j))
                .sum::<f64>();
    }
    weighted / area
}

/// The mean over `object`'s surface of what viewers show: the vertex values interpolated over
/// each patch's fan triangles, integrated exactly.
pub fn smooth_mean(solved: &Solved, object: &str) -> Rgb {
    let (mut sum, mut area) = (Rgb::ZERO, 0.0);
    for patch in &solved.mesh.patches {
        if solved.scene.objects[patch.object as usize].name != object {
            continue;
        }
        let ids = &patch.corners[..patch.corner_count()];
        let at = |k: usize| solved.mesh.positions[ids[k] as usize];
        let value = |k: usize| solved.vertex_radiosity[ids[k] as usize];
        for k in 1..ids.len() - 1 {
            let triangle = (at(k) - at(0)).cross(at(k + 1) - at(0)).length() / 2.0;
            sum += (value(0) + value(k) + value(k + 1)) / 3.0 * triangle;
            area += triangle;
        }
    }
    sum / area
}
