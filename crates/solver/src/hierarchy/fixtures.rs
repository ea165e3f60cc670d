//! Scenes and a build helper for the hierarchy's unit tests.

use super::{BuiltHierarchy, Hierarchy, HierarchySettings, PastLinkBudget};
use crate::geometry::{Polygon, point_to_polygon_form_factor};
use crate::pair::FormFactorSettings;
use crate::reference::Probe;
use crate::scene::{Material, Rgb, Scene};
use crate::solve::SolverSettings;
use crate::visibility::Occluders;
use glam::{DVec3, dvec3};

/// The grey of the test scenes' walls and floors: reflectance 0.5, no emission.
pub(crate) const GREY: Material = Material {
    reflectance: Rgb::splat(0.5),
    emission: Rgb::ZERO,
};

/// A closed unit cube, faces inwards, every face emitting 1 with reflectance 0.5.
pub(crate) fn closed_cube() -> Scene {
    let mut scene = Scene::default();
    let material = Material {
        reflectance: Rgb::splat(0.5),
        emission: Rgb::ONE,
    };
    let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
    for (origin, u, v) in [
        (DVec3::ZERO, z, x),
        (y, x, z),
        (DVec3::ZERO, y, z),
        (x, z, y),
        (DVec3::ZERO, x, y),
        (z, y, x),
    ] {
        add_parallelogram(&mut scene, "wall", (origin, u, v), material);
    }
    scene
}

/// A unit square lamp 10 m above a unit square floor, and a screen at `height` that hides
/// the lamp beyond `edge` (in x) from the floor's view straight up.
pub(crate) fn screened_lamp(height: f64, edge: f64) -> Scene {
    let mut scene = Scene::default();
    let lamp = Material {
        emission: Rgb::ONE,
        ..GREY
    };
    let (x, y) = (DVec3::X, DVec3::Y);
    add_parallelogram(&mut scene, "floor", (DVec3::ZERO, x, y), GREY);
    add_parallelogram(&mut scene, "lamp", (dvec3(0.0, 0.0, 10.0), y, x), lamp);
    add_parallelogram(
        &mut scene,
        "screen",
        (dvec3(-5.0, -5.0, height), y * 10.0, x * (5.0 + edge)),
        GREY,
    );
    scene
}

/// The hierarchy of `scene` built at error knob `error`, other settings at their defaults.
pub(crate) fn build(scene: &Scene, error: f64) -> Hierarchy {
    build_and_solve(scene, error).hierarchy
}

/// [`build`], with the solution its refinement ended on.
pub(crate) fn build_and_solve(scene: &Scene, error: f64) -> BuiltHierarchy {
    let occluders = Occluders::new(scene);
    let settings = HierarchySettings {
        error,
        ..HierarchySettings::default()
    };
    Hierarchy::build(
        scene,
        &occluders,
        (&settings, PastLinkBudget::Sampled),
        FormFactorSettings::default(),
        &SolverSettings::default(),
        &crate::no_progress,
    )
    .expect("gmres needs no entries")
}

/// A 4 x 4 room (faces inwards) lit by its ceiling, with a closed box of five faces standing
/// on the floor over [1, 2] x [1, 2]: lattice lines of the floor at depth 2.
pub(crate) fn room_with_a_box() -> Scene {
    let mut scene = Scene::default();
    let lamp = Material {
        reflectance: Rgb::splat(0.5),
        emission: Rgb::ONE,
    };
    let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
    let s = 4.0;
    add_parallelogram(&mut scene, "floor", (DVec3::ZERO, z * s, x * s), GREY);
    add_parallelogram(&mut scene, "ceiling", (y * s, x * s, z * s), lamp);
    for sides in [
        (DVec3::ZERO, y * s, z * s),
        (x * s, z * s, y * s),
        (DVec3::ZERO, x * s, y * s),
        (z * s, y * s, x * s),
    ] {
        add_parallelogram(&mut scene, "wall", sides, GREY);
    }
    for sides in unit_box(dvec3(1.0, 0.0, 1.0)) {
        add_parallelogram(&mut scene, "box", sides, GREY);
    }
    scene
}

/// A unit square floor (facing up) under a unit square lamp 10 m above it, cut through by a
/// closed box 10 cm tall above the floor and 50 cm below it, wider than the floor: the floor
/// beyond `x = edge` lies inside the box, where no light reaches.
pub(crate) fn floor_cut_by_a_box(edge: f64) -> Scene {
    floor_and_a_box(dvec3(edge, -0.5, -0.5), dvec3(1.0, 0.6, 2.0))
}

/// A unit square floor (x and z in [0, 1], facing up) under a unit square lamp 10 m above it,
/// and a closed box of least corner `corner` and extent `size`.
pub(crate) fn floor_and_a_box(corner: DVec3, size: DVec3) -> Scene {
    let mut scene = Scene::default();
    let lamp = Material {
        emission: Rgb::ONE,
        ..GREY
    };
    let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
    add_parallelogram(&mut scene, "floor", (DVec3::ZERO, z, x), GREY);
    add_parallelogram(&mut scene, "lamp", (y * 10.0, x, z), lamp);
    let bottom = (corner, x, z);
    for (origin, u, v) in unit_box(corner).into_iter().chain([bottom]) {
        let sides = (corner + (origin - corner) * size, u * size, v * size);
        add_parallelogram(&mut scene, "box", sides, GREY);
    }
    scene
}

/// Adds an object `name` with one face: the parallelogram at `origin` spanned by `u` then `v`
/// (its front faces along `u x v`).
pub(crate) fn add_parallelogram(
    scene: &mut Scene,
    name: &str,
    (origin, u, v): (DVec3, DVec3, DVec3),
    material: Material,
) {
    let object = scene.add_object(name);
    scene.add_polygon(
        object,
        &[origin, origin + u, origin + u + v, origin + v],
        material,
    );
}

/// The top and four sides of a unit box standing at `corner` (its least x, y, z), facing
/// out, as (origin, u, v) for [`add_parallelogram`]: closed against a floor it stands on.
pub(crate) fn unit_box(corner: DVec3) -> [(DVec3, DVec3, DVec3); 5] {
    let (x, y, z, o) = (DVec3::X, DVec3::Y, DVec3::Z, corner);
    [
        (o + y, z, x),
        (o, z, y),
        (o + x, y, z),
        (o, y, x),
        (o + z, x, y),
    ]
}

/// Probes of face 0 (a floor of reflectance 0.5 facing `normal`) at `points`, each with its
/// exact radiosity where nothing but `lamp` (emitting 1, facing the floor) lights it: half
/// Lambert's point-to-polygon factor to the lamp.
pub(crate) fn probes_under_a_lamp(
    points: impl Iterator<Item = DVec3>,
    normal: DVec3,
    lamp: &Polygon,
) -> Vec<Probe> {
    points
        .map(|x| {
            let exact = 0.5 * point_to_polygon_form_factor(x, normal, lamp, -normal);
            Probe {
                position: x.to_array(),
                face: 0,
                object: "floor".into(),
                radiosity: [exact; 3],
                standard_error: [0.0; 3],
            }
        })
        .collect()
}
