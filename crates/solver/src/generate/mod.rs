//! Generated scenes for scaling measurements, as OBJ + MTL text: the generators ship instead of
//! large files. [`furnished_room`]: a closed room of axis-aligned furniture under many lamps;
//! [`town`]: triangle soup of buildings and trees under a sky, the statistics of a real model.

mod room;
mod town;

pub use room::furnished_room;
pub use town::town;

use crate::sampling::unit_interval;
use glam::DVec3;
use rand_core::{RngCore, SeedableRng};
use rand_pcg::Pcg64Mcg;
use std::fmt::Write;

/// A scene as the two files that describe it.
pub struct GeneratedScene {
    /// The OBJ text; it names its MTL file `mtl_name`.
    pub obj: String,
    /// The MTL text.
    pub mtl: String,
}

/// A material: name, diffuse reflectance (`Kd`) and emitted radiosity (`Ke`, W/m^2).
type MaterialLine = (&'static str, [f64; 3], [f64; 3]);

/// The MTL text for `materials`, under a `title` comment.
fn materials(title: &str, materials: &[MaterialLine]) -> String {
    let mut mtl = format!("# radcast generate: {title}\n");
    for (name, kd, ke) in materials {
        // Writing to a String cannot fail.
        let _ = writeln!(
            mtl,
            "newmtl {name}\nKd {} {} {}\nKe {} {} {}\n",
            kd[0], kd[1], kd[2], ke[0], ke[1], ke[2]
        );
    }
    mtl
}

/// OBJ text being written, and the seeded random numbers that place what goes in it.
struct Writer {
    obj: String,
    rng: Pcg64Mcg,
}

impl Writer {
    fn new(seed: u64) -> Writer {
        Writer {
            obj: String::new(),
            rng: Pcg64Mcg::seed_from_u64(seed),
        }
    }

    fn unit(&mut self) -> f64 {
        unit_interval(self.rng.next_u64())
    }

    fn between(&mut self, low: f64, high: f64) -> f64 {
        low + (high - low) * self.unit()
    }

    fn object(&mut self, name: &str, material: &str) {
        let _ = write!(self.obj, "o {name}\nusemtl {material}\n");
    }

    /// A face through `corners` (counter-clockwise about its front), with vertices of its own.
    fn face(&mut self, corners: &[DVec3]) {
        for p in corners {
            let _ = writeln!(self.obj, "v {:.4} {:.4} {:.4}", p.x, p.y, p.z);
        }
        self.obj.push('f');
        for k in (1..=corners.len()).rev() {
            let _ = write!(self.obj, " -{k}");
        }
        self.obj.push('\n');
    }

    /// The parallelogram `origin, origin + u, origin + u + v, origin + v`, front `u x v`.
    fn quad(&mut self, origin: DVec3, u: DVec3, v: DVec3) {
        self.face(&[origin, origin + u, origin + u + v, origin + v]);
    }

    /// An axis-aligned box from `lo` to `hi` with outward faces; the bottom only if it floats.
    fn cuboid(&mut self, lo: DVec3, hi: DVec3) {
        let size = hi - lo;
        let (x, y, z) = (DVec3::X * size.x, DVec3::Y * size.y, DVec3::Z * size.z);
        self.quad(lo + y, z, x);
        self.quad(lo, z, y);
        self.quad(lo + x, y, z);
        self.quad(lo, y, x);
        self.quad(lo + z, x, y);
        if lo.y > 0.0 {
            self.quad(lo, x, z);
        }
    }
}
