//! Scenes and a build helper for the hierarchy's unit tests.

use super::{Hierarchy, HierarchySettings};
use crate::pair::FormFactorSettings;
use crate::scene::{Material, Rgb, Scene};
use crate::solve::SolverSettings;
use crate::visibility::Occluders;
use glam::{DVec3, dvec3};

pub(super) fn closed_cube() -> Scene {
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
        let object = scene.add_object("wall");
        scene.add_polygon(
            object,
            &[origin, origin + u, origin + u + v, origin + v],
            material,
        );
    }
    scene
}

pub(super) fn build(scene: &Scene, error: f64) -> Hierarchy {
    let occluders = Occluders::new(scene);
    let settings = HierarchySettings {
        error,
        ..HierarchySettings::default()
    };
    Hierarchy::build(
        scene,
        &occluders,
        &settings,
        FormFactorSettings::default(),
        &SolverSettings::default(),
        &crate::no_progress,
    )
    .expect("gmres needs no entries")
    .hierarchy
}

/// A 4 x 4 room (faces inwards) lit by its ceiling, with a closed box of five faces standing
/// on the floor over [1, 2] x [1, 2]: lattice lines of the floor at depth 2.
pub(super) fn room_with_a_box() -> Scene {
    let mut scene = Scene::default();
    let grey = Material {
        reflectance: Rgb::splat(0.5),
        emission: Rgb::ZERO,
    };
    let lamp = Material {
        reflectance: Rgb::splat(0.5),
        emission: Rgb::ONE,
    };
    let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
    let mut add = |name: &str, origin: DVec3, u: DVec3, v: DVec3, material: Material| {
        let object = scene.add_object(name);
        scene.add_polygon(
            object,
            &[origin, origin + u, origin + u + v, origin + v],
            material,
        );
    };
    let s = 4.0;
    add("floor", DVec3::ZERO, z * s, x * s, grey);
    add("ceiling", y * s, x * s, z * s, lamp);
    for (origin, u, v) in [
        (DVec3::ZERO, y * s, z * s),
        (x * s, z * s, y * s),
        (DVec3::ZERO, x * s, y * s),
        (z * s, y * s, x * s),
    ] {
        add("wall", origin, u, v, grey);
    }
    let o = dvec3(1.0, 0.0, 1.0);
    for (origin, u, v) in [
        (o + y, z, x),
        (o, z, y),
        (o + x, y, z),
        (o, y, x),
        (o + z, x, y),
    ] {
        add("box", origin, u, v, grey);
    }
    scene
}
