//! The self-check: a solution's error estimated against probes path-traced for it, with a seed
//! of their own (never a stored reference), the tracing's own noise taken out.
//!
//! The path tracer depends on no mesh, so it can judge any solve of any scene. At each probe
//! the squared error it measures is the solution's squared error plus the probe's variance;
//! subtracting the variance (and from the reference's own square) leaves an unbiased ratio,
//! `R = sum(|B - B^|^2 - s^2) / sum(|B^|^2 - s^2)`, whose square root is the relative RMS. Its
//! interval is the ratio estimator's (delta method, Cochran 1977, "Sampling Techniques" 6.3)
//! at three standard errors.

use crate::Progress;
use crate::accuracy::{read_at, stats};
use crate::mesh::Mesh;
use crate::reference::{place_probes, trace_probes};
use crate::sampling::splitmix64;
use crate::scene::{Rgb, Scene};
use crate::visibility::Occluders;
use serde::Serialize;

/// How many probes and paths the check traces, and its seed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CheckSettings {
    /// Probe points at most, spread over the non-emitting surfaces by area.
    pub probes: usize,
    /// Paths per probe.
    pub samples: u32,
    /// Seed of the probes and paths: not the shipped references' (1).
    pub seed: u64,
    /// Seconds the check may take, about: past its first [`FIRST_PROBES`] it traces more a
    /// [`CHECK_CHUNK`] at a time until they are spent (all `probes` when `None`).
    pub seconds: Option<f64>,
}

impl Default for CheckSettings {
    fn default() -> Self {
        CheckSettings {
            probes: 256,
            samples: 1024,
            seed: 0x5e1f_c4ec,
            seconds: None,
        }
    }
}

impl CheckSettings {
    /// The check run after a solve that took `solve_seconds`: up to [`AFTER_SOLVE_PROBES`]
    /// probes, as many past the first [`FIRST_PROBES`] as [`AFTER_SOLVE_SHARE`] of the solve's
    /// time allows.
    pub fn after_solve(solve_seconds: f64) -> Self {
        CheckSettings {
            probes: AFTER_SOLVE_PROBES,
            seconds: Some(AFTER_SOLVE_SHARE * solve_seconds),
            ..CheckSettings::default()
        }
    }
}

/// The share of a solve's time the check after it may take past its first probes.
pub const AFTER_SOLVE_SHARE: f64 = 0.1;
/// The most probes the check after a solve traces: on the monastery (67 s) 4,096 take 3.6 s
/// and give an interval 3 points wide that held the reference's figure, where 1,024 gave one
/// 5 points wide that missed it once.
pub const AFTER_SOLVE_PROBES: usize = 4096;
/// The smooth RMS error past which a check's lower bound says the answer is bad.
pub const WARN_ABOVE: f64 = 0.05;

/// Probes the check traces between looks at the time it may take: on the monastery about a
/// third of a second.
const CHECK_CHUNK: usize = 256;

/// Probes the check always traces: its interval is already within a few points of the RMS
/// there (the plates: ±0.4% at 10%).
pub const FIRST_PROBES: usize = 64;

/// One reading's estimated error, relative to the scene's RMS radiosity at the probes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ReadingEstimate {
    /// The relative RMS error, noise taken out.
    pub rms: f64,
    /// Lower end of its interval (three standard errors).
    pub low: f64,
    /// Upper end of its interval.
    pub high: f64,
    /// `sum B / sum B^ - 1` over the probes: the energy balance.
    pub energy: f64,
}

/// What the self-check found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Estimate {
    /// What viewers see: corner values interpolated.
    pub smooth: ReadingEstimate,
    /// Patch values.
    pub flat: ReadingEstimate,
    /// The tracing's own relative RMS noise, taken out of both.
    pub noise: f64,
    /// Probes that counted (on non-emitting faces).
    pub probes: usize,
    /// Seconds the check took.
    pub seconds: f64,
}

impl Estimate {
    /// What to tell the user when the check says the answer is bad (see [`warning`]).
    pub fn warning(&self) -> Option<String> {
        warning(self.smooth.rms, self.smooth.low)
    }
}

/// What to tell the user about an answer whose relative smooth RMS error is estimated at
/// `rms`, at least `low`: a warning when even `low` is past [`WARN_ABOVE`].
pub fn warning(rms: f64, low: f64) -> Option<String> {
    (low > WARN_ABOVE).then(|| {
        format!(
            "the self-check estimates {:.1}% smooth RMS error (at least {:.1}%), past {}%: refine further (a smaller --error or more --patches)",
            100.0 * rms,
            100.0 * low,
            100.0 * WARN_ABOVE
        )
    })
}

/// Estimates the error of a solution of `scene` on `mesh`: `radiosity` per patch, `corners`
/// per mesh corner.
pub fn self_check(
    scene: &Scene,
    occluders: &Occluders,
    mesh: &Mesh,
    (radiosity, corners): (&[Rgb], &[Rgb]),
    settings: &CheckSettings,
    progress: &(dyn Fn(Progress) + Sync),
) -> Estimate {
    let started = std::time::Instant::now();
    let placed = place_probes(scene, settings.probes, settings.seed);
    let total = placed.len();
    // The first probes always, then chunks while the time allows: the clock, not a count
    // extrapolated from the first probes' pace (whose paths may be shorter than the rest's),
    // says when to stop. Each chunk's paths have a seed of their own (the tracer seeds each
    // probe by its index in the list it is given).
    let mut probes = Vec::with_capacity(total);
    let mut start = 0;
    while start < total {
        let end = match start {
            0 => FIRST_PROBES,
            _ => start + CHECK_CHUNK,
        }
        .min(total);
        let seed = match start {
            0 => settings.seed,
            _ => splitmix64(settings.seed ^ start as u64),
        };
        let counted = |p: Progress| {
            if let Progress::Probes { done, .. } = p {
                progress(Progress::Probes {
                    purpose: "self-check",
                    done: start + done,
                    total,
                });
            }
        };
        let chunk = &placed[start..end];
        probes.extend(trace_probes(
            scene,
            occluders,
            chunk,
            settings.samples,
            seed,
            &counted,
        ));
        start = end;
        if settings
            .seconds
            .is_some_and(|seconds| started.elapsed().as_secs_f64() >= seconds)
        {
            break;
        }
    }
    let readings = read_at(scene, mesh, radiosity, corners, &probes);
    Estimate {
        smooth: estimate(&readings.smooth, &readings.variance),
        flat: estimate(&readings.flat, &readings.variance),
        noise: readings.noise(),
        probes: readings.flat.len(),
        seconds: started.elapsed().as_secs_f64(),
    }
}

/// The noise-corrected relative RMS of `pairs` (solution, traced), with `variance` per probe,
/// and its interval (see the module notes).
fn estimate(pairs: &[(Rgb, Rgb)], variance: &[f64]) -> ReadingEstimate {
    let n = pairs.len();
    let error: Vec<f64> = pairs
        .iter()
        .zip(variance)
        .map(|((b, r), s)| (*b - *r).length_squared() - s)
        .collect();
    let scale: Vec<f64> = pairs
        .iter()
        .zip(variance)
        .map(|((_, r), s)| r.length_squared() - s)
        .collect();
    let (error_sum, scale_sum): (f64, f64) = (error.iter().sum(), scale.iter().sum());
    if n < 2 || scale_sum <= 0.0 {
        return ReadingEstimate::default();
    }
    let ratio = error_sum / scale_sum;
    // var(R) ~ n / (sum b)^2 * sum (d - R b)^2 / (n - 1).
    let spread: f64 = error
        .iter()
        .zip(&scale)
        .map(|(d, b)| (d - ratio * b).powi(2))
        .sum();
    let standard_error = (n as f64 * spread / (n - 1) as f64).sqrt() / scale_sum;
    let root = |x: f64| x.max(0.0).sqrt();
    ReadingEstimate {
        rms: root(ratio),
        low: root(ratio - 3.0 * standard_error),
        high: root(ratio + 3.0 * standard_error),
        energy: stats(pairs).energy,
    }
}
