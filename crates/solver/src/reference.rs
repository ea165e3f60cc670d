//! A reference solution independent of any mesh: Monte Carlo estimates of the continuous
//! radiosity `B(x) = E(x) + rho(x) H(x)` at probe points, by diffuse path tracing with
//! next-event estimation on the emitters (Kajiya 1986, "The Rendering Equation"; pbrt 4e,
//! section 13.4 "A Better Path Tracer").
//!
//! Probes are spread over the surfaces by area. Each probe has its own random stream seeded from
//! (seed, probe index), so the result is the same for any thread count.

use crate::Progress;
use crate::sampling::{
    SphericalPolygon, cosine_direction, onto_plane, pick, running_sums, unit_interval,
};
use crate::scene::{Rgb, Scene};
use crate::visibility::Occluders;
use glam::DVec3;
use rand_core::{RngCore, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The least solid angle, steradians, an emitter must cover above a point for next-event
/// estimation to draw its point there by solid angle rather than by area. Drawn by area, a sky
/// over a village of eight monasteries weighs its points by a `cos cos / r^2` that varies
/// over orders of magnitude across it: the village's probes read 4.0% noise at 65,536 paths
/// (0.24% drawn by solid angle), the one monastery's 1.04% (0.23%; docs/BENCHMARKS.md, "A sky
/// drawn by solid angle in the reference"). Drawn by solid angle each weighs only its cosine
/// at the point; below a steradian (a lamp seen from afar) the kernel hardly varies, and the
/// spherical triangles' sampling loses precision as they shrink.
const MIN_SOLID_ANGLE: f64 = 1.0;

/// One probe and its estimate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Probe {
    /// Position, scene units.
    pub position: [f64; 3],
    /// The scene file's face it lies on ([`crate::scene::Face::source`]: faces as loaded,
    /// before contact lines cut them).
    pub face: u32,
    /// The face's object name.
    pub object: String,
    /// Estimated radiosity, W/m^2.
    pub radiosity: [f64; 3],
    /// Standard error of the estimate, per channel.
    pub standard_error: [f64; 3],
}

/// A reference file (`scenes/reference/*.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reference {
    /// The command that made it.
    pub command: String,
    /// Seed of the random streams.
    pub seed: u64,
    /// Paths per probe.
    pub samples: u32,
    /// The probes.
    pub probes: Vec<Probe>,
}

fn uniform(rng: &mut Pcg64Mcg) -> f64 {
    unit_interval(rng.next_u64())
}

/// `count` points spread uniformly by area over the scene's faces that do not emit: the error
/// measures count only those ([`crate::accuracy`]; an emitter's own emission is exact), and a
/// sky over a model would otherwise take most of them. All faces when every face emits.
pub fn place_probes(scene: &Scene, count: usize, seed: u64) -> Vec<(u32, DVec3)> {
    let reflecting_only = !scene.faces.iter().all(|f| f.emission.max_element() > 0.0);
    let cumulative = running_sums(scene.faces.iter().map(|f| {
        match reflecting_only && f.emission.max_element() > 0.0 {
            true => 0.0,
            false => f.polygon.area(),
        }
    }));
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    (0..count)
        .map(|_| {
            let face = pick(&cumulative, uniform(&mut rng));
            let (u, v, w) = (uniform(&mut rng), uniform(&mut rng), uniform(&mut rng));
            (
                face as u32,
                scene.faces[face].polygon.uniform_point(u, v, w),
            )
        })
        .collect()
}

struct Tracer<'a> {
    scene: &'a Scene,
    occluders: &'a Occluders,
    emitters: Vec<u32>,
    emitter_cumulative: Vec<f64>,
}

impl Tracer<'_> {
    /// Irradiance at `x` on face `face` straight from one emitter point (next-event estimation),
    /// over pi. The point is drawn uniformly over the solid angle the emitter covers above `x`'s
    /// horizon where that is at least [`MIN_SOLID_ANGLE`], else over its area.
    fn direct(&self, x: DVec3, normal: DVec3, face: u32, rng: &mut Pcg64Mcg) -> Rgb {
        if self.emitters.is_empty() {
            return Rgb::ZERO;
        }
        let k = pick(&self.emitter_cumulative, uniform(rng));
        let emitter = &self.scene.faces[self.emitters[k] as usize];
        let total = self.emitter_cumulative[self.emitter_cumulative.len() - 1];
        let probability = (self.emitter_cumulative[k]
            - if k == 0 {
                0.0
            } else {
                self.emitter_cumulative[k - 1]
            })
            / total;
        let (corners, emitter_normal) = (emitter.polygon.corners(), emitter.polygon.normal());
        let view = (emitter.polygon.solid_angle_bound(x) >= MIN_SOLID_ANGLE)
            .then(|| SphericalPolygon::seen_above(x, normal, corners))
            .flatten()
            .filter(|view| view.solid_angle() >= MIN_SOLID_ANGLE);
        // The point and its cosine-weighted measure over the pdf it was drawn with: the
        // solid angle `cos_x * Omega`, or the area's `cos_x cos_y / r^2 * A`.
        let (y, factor) = match view {
            Some(view) => {
                let w = view.direction(uniform(rng), uniform(rng));
                let y = onto_plane(x, w, corners[0], emitter_normal);
                let facing = -emitter_normal.dot(w) > 0.0;
                (
                    y,
                    if facing {
                        normal.dot(w) * view.solid_angle()
                    } else {
                        0.0
                    },
                )
            }
            None => {
                let y = emitter
                    .polygon
                    .uniform_point(uniform(rng), uniform(rng), uniform(rng));
                let to_light = y - x;
                let distance_sq = to_light.length_squared();
                let direction = to_light / distance_sq.sqrt();
                let cosines = normal.dot(direction) * (-emitter_normal.dot(direction)).max(0.0);
                (y, cosines / distance_sq * emitter.polygon.area())
            }
        };
        if self.emitters[k] == face || !(factor > 0.0 && y.is_finite()) {
            return Rgb::ZERO;
        }
        if !self
            .occluders
            .segment_is_clear(x, y, [face, self.emitters[k]])
        {
            return Rgb::ZERO;
        }
        // Radiance of a Lambertian emitter is E / pi; the emitter was picked with p_k.
        emitter.emission / PI * factor / probability
    }

    /// One path's estimate of the radiosity leaving `x`.
    fn sample(&self, face: u32, x: DVec3, rng: &mut Pcg64Mcg) -> Rgb {
        let start = &self.scene.faces[face as usize];
        let (mut point, mut normal, mut on) = (x, start.polygon.normal(), face);
        let (mut throughput, mut irradiance) = (Rgb::ONE, Rgb::ZERO);
        for depth in 0.. {
            irradiance += throughput * self.direct(point, normal, on, rng);
            let direction = cosine_direction(normal, uniform(rng), uniform(rng));
            let Some(hit) = self.occluders.closest_hit(point, direction, on) else {
                break;
            };
            if !hit.front {
                break; // the back of a one-sided surface absorbs
            }
            let next = &self.scene.faces[hit.face as usize];
            // Cosine sampling makes each bounce's weight the reflectance alone.
            throughput *= next.reflectance;
            if depth >= 3 {
                // Russian roulette (Arvo, Kirk 1990) keeps the estimator unbiased.
                let survive = throughput.max_element().min(0.95);
                if survive <= 0.0 || uniform(rng) >= survive {
                    break;
                }
                throughput /= survive;
            }
            (point, normal, on) = (
                point + direction * hit.distance,
                next.polygon.normal(),
                hit.face,
            );
        }
        start.emission + start.reflectance * irradiance
    }
}

/// Estimates the radiosity at every probe with `samples` paths each.
pub fn trace_probes(
    scene: &Scene,
    occluders: &Occluders,
    probes: &[(u32, DVec3)],
    samples: u32,
    seed: u64,
    progress: &(dyn Fn(Progress) + Sync),
) -> Vec<Probe> {
    let emitters: Vec<u32> = (0..scene.faces.len() as u32)
        .filter(|&f| scene.faces[f as usize].emission.max_element() > 0.0)
        .collect();
    // Emitters are chosen by emitted power, so bright lights get the samples.
    let emitter_cumulative = running_sums(emitters.iter().map(|&f| {
        let face = &scene.faces[f as usize];
        face.polygon.area() * face.emission.max_element()
    }));
    let tracer = Tracer {
        scene,
        occluders,
        emitters,
        emitter_cumulative,
    };
    let done = AtomicUsize::new(0);
    probes
        .par_iter()
        .enumerate()
        .map(|(index, &(face, position))| {
            let mut rng =
                Pcg64Mcg::seed_from_u64(seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
            let (mut sum, mut sum_sq) = (Rgb::ZERO, Rgb::ZERO);
            for _ in 0..samples {
                let b = tracer.sample(face, position, &mut rng);
                sum += b;
                sum_sq += b * b;
            }
            let n = samples.max(1) as f64;
            let mean = sum / n;
            let variance = ((sum_sq / n - mean * mean) * (n / (n - 1.0).max(1.0))).max(Rgb::ZERO);
            let finished = done.fetch_add(1, Ordering::Relaxed) + 1;
            progress(Progress::Probes {
                purpose: "reference",
                done: finished,
                total: probes.len(),
            });
            Probe {
                position: position.to_array(),
                face: scene.faces[face as usize].source,
                object: scene.objects[scene.faces[face as usize].object as usize]
                    .name
                    .clone(),
                radiosity: mean.to_array(),
                standard_error: (variance / n).to_array().map(f64::sqrt),
            }
        })
        .collect()
}
