//! The furnished room: a closed room of tables, chairs and cabinets under a grid of ceiling
//! lamps, all axis-aligned quads (about 14 faces a piece).

use super::{GeneratedScene, MaterialLine, Writer, materials};
use glam::{DVec3, dvec3};
use rand_core::RngCore;
use std::fmt::Write;

/// Materials: diffuse reflectance (`Kd`) and emitted radiosity (`Ke`, W/m^2).
const MATERIALS: [MaterialLine; 8] = [
    ("plaster", [0.75, 0.73, 0.70], [0.0; 3]),
    ("floorboards", [0.45, 0.32, 0.20], [0.0; 3]),
    ("oak", [0.55, 0.40, 0.25], [0.0; 3]),
    ("walnut", [0.30, 0.20, 0.13], [0.0; 3]),
    ("fabric_red", [0.60, 0.12, 0.10], [0.0; 3]),
    ("fabric_blue", [0.12, 0.20, 0.55], [0.0; 3]),
    ("metal", [0.62, 0.62, 0.65], [0.0; 3]),
    ("lamp", [0.8, 0.8, 0.8], [20.0, 18.0, 15.0]),
];

/// Room height, metres.
const HEIGHT: f64 = 3.0;
/// Floor space per piece of furniture, metres along each side.
const CELL: f64 = 1.5;

/// A closed room with `pieces` pieces of furniture (tables, chairs, cabinets) on a grid, lit by
/// a grid of ceiling lamps; the same `seed` gives the same room. The OBJ refers to `mtl_name`.
pub fn furnished_room(pieces: usize, seed: u64, mtl_name: &str) -> GeneratedScene {
    let per_side = (pieces as f64).sqrt().ceil().max(1.0) as usize;
    let side = per_side as f64 * CELL + 2.0;
    let mut w = Writer::new(seed);
    let _ = writeln!(
        w.obj,
        "# radcast generate --pieces {pieces} --seed {seed}: a furnished room, {side:.1} x {side:.1} x {HEIGHT} m\nmtllib {mtl_name}"
    );
    let (x, y, z) = (DVec3::X * side, DVec3::Y * HEIGHT, DVec3::Z * side);
    w.object("floor", "floorboards");
    w.quad(DVec3::ZERO, z, x);
    w.object("ceiling", "plaster");
    w.quad(y, x, z);
    w.object("walls", "plaster");
    w.quad(DVec3::ZERO, y, z);
    w.quad(x, z, y);
    w.quad(DVec3::ZERO, x, y);
    w.quad(z, y, x);
    // One 0.6 m lamp per 4 x 4 m of ceiling, 1 cm below it, facing down.
    let lamps = (side / 4.0).round().max(1.0) as usize;
    for i in 0..lamps {
        for j in 0..lamps {
            let centre = dvec3(
                (i as f64 + 0.5) * side / lamps as f64,
                HEIGHT - 0.01,
                (j as f64 + 0.5) * side / lamps as f64,
            );
            w.object(&format!("lamp_{i}_{j}"), "lamp");
            w.quad(
                centre - dvec3(0.3, 0.0, 0.3),
                DVec3::X * 0.6,
                DVec3::Z * 0.6,
            );
        }
    }
    for piece in 0..pieces {
        let cell = dvec3(
            1.0 + (piece % per_side) as f64 * CELL,
            0.0,
            1.0 + (piece / per_side) as f64 * CELL,
        );
        let (width, depth) = (w.between(0.4, 1.2), w.between(0.4, 1.2));
        let corner = cell
            + dvec3(
                w.between(0.0, CELL - width),
                0.0,
                w.between(0.0, CELL - depth),
            );
        let wood = if w.unit() < 0.5 { "oak" } else { "walnut" };
        match w.rng.next_u32() % 3 {
            0 => {
                w.object(&format!("table_{piece}"), wood);
                let top = w.between(0.7, 0.8);
                w.cuboid(
                    corner + DVec3::Y * top,
                    corner + dvec3(width, top + 0.04, depth),
                );
                for (dx, dz) in [
                    (0.0, 0.0),
                    (width - 0.05, 0.0),
                    (0.0, depth - 0.05),
                    (width - 0.05, depth - 0.05),
                ] {
                    w.cuboid(
                        corner + dvec3(dx, 0.0, dz),
                        corner + dvec3(dx + 0.05, top, dz + 0.05),
                    );
                }
            }
            1 => {
                let fabric = if w.unit() < 0.5 {
                    "fabric_red"
                } else {
                    "fabric_blue"
                };
                w.object(&format!("chair_{piece}"), fabric);
                let (seat, size) = (0.45, width.min(depth).min(0.6));
                w.cuboid(corner, corner + dvec3(size, seat, size));
                w.cuboid(
                    corner + dvec3(0.0, seat, 0.0),
                    corner + dvec3(size, seat + 0.5, 0.08),
                );
            }
            _ => {
                let finish = if w.unit() < 0.5 { "metal" } else { wood };
                w.object(&format!("cabinet_{piece}"), finish);
                let height = w.between(0.8, 2.2);
                w.cuboid(corner, corner + dvec3(width, height, depth.min(0.6)));
            }
        }
    }
    GeneratedScene {
        obj: w.obj,
        mtl: materials("materials of the furnished room", &MATERIALS),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_seed_gives_the_same_room_and_another_seed_another() {
        let a = furnished_room(50, 7, "room.mtl");
        assert_eq!(a.obj, furnished_room(50, 7, "room.mtl").obj);
        assert_ne!(a.obj, furnished_room(50, 8, "room.mtl").obj);
        let pieces = ["table_", "chair_", "cabinet_"]
            .iter()
            .map(|kind| a.obj.matches(&format!("o {kind}")).count())
            .sum::<usize>();
        assert_eq!(pieces, 50);
    }

    #[test]
    fn every_piece_stands_inside_the_room() {
        let room = furnished_room(40, 3, "room.mtl");
        let side = (40f64.sqrt().ceil()) * CELL + 2.0;
        for line in room.obj.lines().filter(|l| l.starts_with("v ")) {
            let p: Vec<f64> = line[2..].split(' ').map(|x| x.parse().unwrap()).collect();
            assert!(
                p[0] >= 0.0
                    && p[0] <= side
                    && p[2] >= 0.0
                    && p[2] <= side
                    && p[1] >= 0.0
                    && p[1] <= HEIGHT,
                "{line}"
            );
        }
    }
}
