//! Linear solvers for the radiosity system `B = E + rho * (F B)` (per channel), all on any
//! [`Transport`] and all stopping on the same residual, so their answers can be compared.
//!
//! The residual is `r = E + rho * F B - B`; a solve stops when the area-weighted relative norm
//! `sqrt(sum_i A_i |r_i|^2) / sqrt(sum_i A_i |E_i|^2)` falls to the tolerance. Its error bound is
//! `|B - B*| <= |r| / (1 - max rho)`, which is why bright scenes need a small tolerance.

use crate::scene::Rgb;
use crate::transport::{Entries, Transport};
use crate::{Progress, Unconverged};
use rayon::prelude::*;
use std::fmt;
use std::str::FromStr;

/// The iterative method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Jacobi sweeps, the original prototype's method: error shrinks like `rho^k`.
    Jacobi,
    /// Gauss-Seidel sweeps with over-relaxation `omega` (SOR; `omega = 1` is plain Gauss-Seidel).
    GaussSeidel,
    /// Progressive refinement (Cohen et al. 1988): shoot the patch with the most unshot power.
    Progressive,
    /// Restarted GMRES (Saad, Schultz 1986): a Krylov method, fast for bright enclosures.
    Gmres,
}

impl Method {
    /// Every method, for sweeps and help texts.
    pub const ALL: [Method; 4] = [
        Method::Jacobi,
        Method::GaussSeidel,
        Method::Progressive,
        Method::Gmres,
    ];

    /// The name used on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Method::Jacobi => "jacobi",
            Method::GaussSeidel => "gauss-seidel",
            Method::Progressive => "progressive",
            Method::Gmres => "gmres",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                let names: Vec<_> = Method::ALL.iter().map(|m| m.name()).collect();
                format!(
                    "unknown method '{s}' (expected one of: {})",
                    names.join(", ")
                )
            })
    }
}

/// When and how to stop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolverSettings {
    /// The method.
    pub method: Method,
    /// Stop when the relative residual is at most this.
    pub tolerance: f64,
    /// Give up after this many iterations (sweeps, shots or matrix-vector products).
    pub max_iterations: usize,
    /// SOR relaxation factor for Gauss-Seidel, in (0, 2).
    pub relaxation: f64,
}

impl Default for SolverSettings {
    fn default() -> Self {
        SolverSettings {
            method: Method::Gmres,
            tolerance: 1e-6,
            max_iterations: 100_000,
            relaxation: 1.0,
        }
    }
}

/// The per-patch data of the system.
#[derive(Clone, Copy, Debug)]
pub struct System<'a> {
    /// Diffuse reflectance per patch.
    pub reflectance: &'a [Rgb],
    /// Emitted radiosity per patch, W/m^2.
    pub emission: &'a [Rgb],
    /// Patch areas, the weights of the residual norm.
    pub area: &'a [f64],
}

/// A solver's answer.
#[derive(Clone, Debug, PartialEq)]
pub struct SolveOutcome {
    /// Radiosity per patch, W/m^2.
    pub radiosity: Vec<Rgb>,
    /// Iterations done: sweeps (Jacobi, Gauss-Seidel), shots (progressive) or matrix-vector
    /// products (GMRES).
    pub iterations: usize,
    /// Final relative residual.
    pub residual: f64,
    /// Whether the residual reached the tolerance.
    pub converged: bool,
}

impl System<'_> {
    /// `r = E + rho * F B - B` into `r`.
    fn residual_into(&self, transport: &dyn Transport, radiosity: &[Rgb], r: &mut [Rgb]) {
        transport.gather(radiosity, r);
        r.par_iter_mut()
            .enumerate()
            .for_each(|(i, r)| *r = self.emission[i] + self.reflectance[i] * *r - radiosity[i]);
    }

    /// `sqrt(sum_i A_i |v_i|^2)`.
    fn weighted_norm(&self, v: &[Rgb]) -> f64 {
        v.iter()
            .zip(self.area)
            .map(|(x, a)| a * x.length_squared())
            .sum::<f64>()
            .sqrt()
    }
}

/// A method that updates one patch at a time asked of a transport that has no single entries.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "{0} updates one patch at a time and needs single form-factor rows; this transport only offers whole products (use jacobi or gmres)"
)]
pub struct NeedsEntries(pub Method);

impl Method {
    /// Whether the method reads single rows or columns ([`Transport::entries`]).
    pub fn needs_entries(self) -> bool {
        matches!(self, Method::GaussSeidel | Method::Progressive)
    }
}

/// Solves `system` on `transport` from `initial` (or zero), reporting each iteration.
pub fn solve(
    transport: &dyn Transport,
    system: &System,
    settings: &SolverSettings,
    initial: Option<&[Rgb]>,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<SolveOutcome, NeedsEntries> {
    let start = initial
        .map(<[Rgb]>::to_vec)
        .unwrap_or_else(|| vec![Rgb::ZERO; transport.patch_count()]);
    let mut outcome = solve_unclamped(
        transport,
        system,
        settings,
        (GMRES_RESTART, progress),
        start,
    )?;
    // The exact solution is a sum of non-negative terms; clamp round-off below zero.
    (outcome.radiosity.iter_mut()).for_each(|b| *b = b.max(Rgb::ZERO));
    Ok(outcome)
}

/// [`solve`] from `start`, GMRES restarted every `restart` products (its basis is `restart +
/// 1` vectors of the system's size), each iteration reported to `progress`, leaving what dips
/// below zero as it is: for a system whose answer may, and must stay linear in the emission up
/// to the tolerance (the vertices' last bounces, `solution::vertices`).
pub fn solve_unclamped(
    transport: &dyn Transport,
    system: &System,
    settings: &SolverSettings,
    (restart, progress): (usize, &(dyn Fn(Progress) + Sync)),
    start: Vec<Rgb>,
) -> Result<SolveOutcome, NeedsEntries> {
    let entries = transport.entries();
    if settings.method.needs_entries() && entries.is_none() {
        return Err(NeedsEntries(settings.method));
    }
    let emission_norm = system.weighted_norm(system.emission);
    if emission_norm == 0.0 {
        // No light: the answer is exactly zero, not 0/0.
        return Ok(SolveOutcome {
            radiosity: vec![Rgb::ZERO; start.len()],
            iterations: 0,
            residual: 0.0,
            converged: true,
        });
    }
    let mut run = Run {
        transport,
        system,
        settings,
        emission_norm,
        progress,
        restart,
    };
    let mut radiosity = start;
    let (iterations, residual) = match (settings.method, entries) {
        (Method::GaussSeidel, Some(entries)) => run.gauss_seidel(entries, &mut radiosity),
        (Method::Progressive, Some(entries)) => run.progressive(entries, &mut radiosity),
        (Method::Jacobi, _) => run.jacobi(&mut radiosity),
        // GMRES; a per-patch method without entries was refused above.
        _ => run.gmres(&mut radiosity),
    };
    Ok(SolveOutcome {
        radiosity,
        iterations,
        residual,
        converged: residual <= settings.tolerance,
    })
}

/// Products between GMRES restarts for the radiosity system: its basis is `31 n` values.
const GMRES_RESTART: usize = 30;

/// Channel-wise `x / y`, zero where `y` is zero (a channel with no light, or a converged one).
fn safe_div(x: Rgb, y: Rgb) -> Rgb {
    Rgb::select(y.cmpeq(Rgb::ZERO), Rgb::ZERO, x / y)
}

struct Run<'a> {
    transport: &'a dyn Transport,
    system: &'a System<'a>,
    settings: &'a SolverSettings,
    emission_norm: f64,
    progress: &'a (dyn Fn(Progress) + Sync),
    /// Products between GMRES restarts.
    restart: usize,
}

impl Run<'_> {
    /// GMRES's iterate `x0 + D^-1 V y` for the cycle so far, where `H y = g` (back-substitution
    /// on the rotated upper-triangular Hessenberg columns).
    fn iterate(
        &self,
        start: &[Rgb],
        hessenberg: &[Vec<Rgb>],
        g: &[Rgb],
        basis: &[Vec<Rgb>],
        scale: &[f64],
    ) -> Vec<Rgb> {
        let m = hessenberg.len();
        let mut y = vec![Rgb::ZERO; m];
        for i in (0..m).rev() {
            let tail = (i + 1..m).map(|j| hessenberg[j][i] * y[j]).sum::<Rgb>();
            y[i] = safe_div(g[i] - tail, hessenberg[i][i]);
        }
        start
            .iter()
            .enumerate()
            .map(|(i, b)| *b + (0..m).map(|k| y[k] * basis[k][i]).sum::<Rgb>() / scale[i])
            .collect()
    }

    /// Reports and says whether to stop.
    fn done(&self, iteration: usize, residual: f64, radiosity: &[Rgb]) -> bool {
        (self.progress)(Progress::Solve {
            iteration,
            residual,
        });
        let current = || radiosity.to_vec();
        (self.progress)(Progress::Estimate {
            radiosity: Unconverged::new(&current),
        });
        residual <= self.settings.tolerance
            || iteration >= self.settings.max_iterations
            || !residual.is_finite()
    }

    fn relative_residual(&self, radiosity: &[Rgb], r: &mut [Rgb]) -> f64 {
        self.system.residual_into(self.transport, radiosity, r);
        self.system.weighted_norm(r) / self.emission_norm
    }

    fn jacobi(&mut self, radiosity: &mut [Rgb]) -> (usize, f64) {
        let mut r = vec![Rgb::ZERO; radiosity.len()];
        let mut iteration = 0;
        loop {
            let residual = self.relative_residual(radiosity, &mut r);
            if self.done(iteration, residual, radiosity) {
                return (iteration, residual);
            }
            // B + r = E + rho F B: one Jacobi sweep.
            radiosity.iter_mut().zip(&r).for_each(|(b, r)| *b += *r);
            iteration += 1;
        }
    }

    fn gauss_seidel(&mut self, entries: &dyn Entries, radiosity: &mut [Rgb]) -> (usize, f64) {
        let (system, omega) = (self.system, self.settings.relaxation);
        let mut r = vec![Rgb::ZERO; radiosity.len()];
        let mut iteration = 0;
        loop {
            let residual = self.relative_residual(radiosity, &mut r);
            if self.done(iteration, residual, radiosity) {
                return (iteration, residual);
            }
            for i in 0..radiosity.len() {
                let updated =
                    system.emission[i] + system.reflectance[i] * entries.gather_row(i, radiosity);
                radiosity[i] += (updated - radiosity[i]) * omega;
            }
            iteration += 1;
        }
    }

    fn progressive(&mut self, entries: &dyn Entries, radiosity: &mut [Rgb]) -> (usize, f64) {
        let system = self.system;
        // Southwell iteration: r is kept equal to the true residual, so shooting patch j's
        // unshot radiosity r_j adds rho_i F_ij r_j to every other residual.
        let mut r = vec![Rgb::ZERO; radiosity.len()];
        self.system.residual_into(self.transport, radiosity, &mut r);
        let mut iteration = 0;
        loop {
            let (mut shooter, mut most_power, mut norm_sq) = (0, -1.0, 0.0);
            for (j, (r, a)) in r.iter().zip(system.area).enumerate() {
                norm_sq += a * r.length_squared();
                let power = a * r.abs().element_sum();
                if power > most_power {
                    (shooter, most_power) = (j, power);
                }
            }
            if self.done(iteration, norm_sq.sqrt() / self.emission_norm, radiosity) {
                return (iteration, norm_sq.sqrt() / self.emission_norm);
            }
            let unshot = std::mem::take(&mut r[shooter]);
            radiosity[shooter] += unshot;
            entries.for_each_in_column(shooter, &mut |i, f| {
                r[i] += system.reflectance[i] * unshot * f
            });
            iteration += 1;
        }
    }

    /// Restarted GMRES on the area-scaled system `D M D^-1 (D B) = D E`, `D = diag(sqrt(A))`,
    /// `M = I - rho F`, so that its minimised 2-norm is our weighted residual norm. The three
    /// channels run as three Krylov processes sharing each matrix-vector product.
    fn gmres(&mut self, radiosity: &mut [Rgb]) -> (usize, f64) {
        let system = self.system;
        let n = radiosity.len();
        let scale: Vec<f64> = system.area.iter().map(|a| a.sqrt()).collect();
        let dot = |a: &[Rgb], b: &[Rgb]| a.iter().zip(b).map(|(x, y)| *x * *y).sum::<Rgb>();
        let norm = |a: &[Rgb]| dot(a, a).map(f64::sqrt);
        let target = self.settings.tolerance * self.emission_norm;
        let mut unscaled = vec![Rgb::ZERO; n];
        let mut product = vec![Rgb::ZERO; n];
        let mut iteration = 0;
        let mut stalled = Stall::default();
        loop {
            // Scaled residual of the current iterate.
            let mut r = vec![Rgb::ZERO; n];
            self.system.residual_into(self.transport, radiosity, &mut r);
            r.iter_mut().zip(&scale).for_each(|(r, s)| *r *= *s);
            let beta = norm(&r);
            let residual = beta.length() / self.emission_norm;
            if self.done(iteration, residual, radiosity) || stalled.after_cycle(residual) {
                return (iteration, residual);
            }
            let mut basis: Vec<Vec<Rgb>> = vec![r.iter().map(|x| safe_div(*x, beta)).collect()];
            let mut hessenberg: Vec<Vec<Rgb>> = Vec::new();
            let (mut cosines, mut sines): (Vec<Rgb>, Vec<Rgb>) = (Vec::new(), Vec::new());
            let mut g = vec![beta];
            for k in 0..self.restart {
                // w = D M D^-1 v_k
                unscaled
                    .iter_mut()
                    .zip(&basis[k])
                    .zip(&scale)
                    .for_each(|((u, v), s)| *u = *v / *s);
                self.transport.gather(&unscaled, &mut product);
                let mut w: Vec<Rgb> = (0..n)
                    .map(|i| (unscaled[i] - system.reflectance[i] * product[i]) * scale[i])
                    .collect();
                iteration += 1;
                // Modified Gram-Schmidt.
                let mut column = Vec::with_capacity(k + 2);
                for v in &basis {
                    let h = dot(&w, v);
                    w.iter_mut().zip(v).for_each(|(w, v)| *w -= h * *v);
                    column.push(h);
                }
                let next_norm = norm(&w);
                column.push(next_norm);
                basis.push(w.iter().map(|x| safe_div(*x, next_norm)).collect());
                // Earlier Givens rotations, then a new one to zero the subdiagonal.
                for i in 0..k {
                    let (a, b) = (column[i], column[i + 1]);
                    column[i] = cosines[i] * a + sines[i] * b;
                    column[i + 1] = -sines[i] * a + cosines[i] * b;
                }
                let radius = (column[k] * column[k] + column[k + 1] * column[k + 1]).map(f64::sqrt);
                let cosine = Rgb::select(
                    radius.cmpeq(Rgb::ZERO),
                    Rgb::ONE,
                    safe_div(column[k], radius),
                );
                let sine = safe_div(column[k + 1], radius);
                column[k] = cosine * column[k] + sine * column[k + 1];
                column[k + 1] = Rgb::ZERO;
                g.push(-sine * g[k]);
                g[k] *= cosine;
                cosines.push(cosine);
                sines.push(sine);
                hessenberg.push(column);
                let estimate = g[k + 1].length();
                (self.progress)(Progress::Solve {
                    iteration,
                    residual: estimate / self.emission_norm,
                });
                let stop = estimate <= target || iteration >= self.settings.max_iterations;
                if stop {
                    break;
                }
                // The iterate so far, for progressive display, worked out if it is read.
                let current = || self.iterate(radiosity, &hessenberg, &g, &basis, &scale);
                (self.progress)(Progress::Estimate {
                    radiosity: Unconverged::new(&current),
                });
            }
            let next = self.iterate(radiosity, &hessenberg, &g, &basis, &scale);
            radiosity.copy_from_slice(&next);
        }
    }
}

/// Restart cycles of GMRES in a row, each leaving the residual above [`STALLED_CYCLE_RATIO`]
/// times the last cycle's, after which the solve gives up: restarted GMRES on an operator
/// whose rows sum past one over the reflectance can make no headway at all, and the iteration
/// limit alone let such a solve run on for hours (docs/BENCHMARKS.md).
const STALLED_CYCLES: u32 = 4;

/// A cycle that does not take the residual below this share of the last cycle's has stalled.
const STALLED_CYCLE_RATIO: f64 = 0.99;

/// Stalled GMRES restart cycles in a row.
#[derive(Default)]
struct Stall {
    last: Option<f64>,
    cycles: u32,
}

impl Stall {
    /// Counts the cycle that ended at `residual`; whether the solve should give up.
    fn after_cycle(&mut self, residual: f64) -> bool {
        let stalled = self
            .last
            .is_some_and(|last| residual > STALLED_CYCLE_RATIO * last);
        self.cycles = if stalled { self.cycles + 1 } else { 0 };
        self.last = Some(residual);
        self.cycles >= STALLED_CYCLES
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small non-symmetric transport, `F` stored densely with single entries.
    struct Matrix(Vec<Vec<f64>>);

    impl Transport for Matrix {
        fn patch_count(&self) -> usize {
            self.0.len()
        }

        fn gather(&self, radiosity: &[Rgb], out: &mut [Rgb]) {
            for (o, row) in out.iter_mut().zip(&self.0) {
                *o = row.iter().zip(radiosity).map(|(f, b)| *b * *f).sum();
            }
        }

        fn entries(&self) -> Option<&dyn Entries> {
            Some(self)
        }
    }

    impl Entries for Matrix {
        fn gather_row(&self, i: usize, radiosity: &[Rgb]) -> Rgb {
            self.0[i].iter().zip(radiosity).map(|(f, b)| *b * *f).sum()
        }

        fn for_each_in_column(&self, j: usize, visit: &mut dyn FnMut(usize, f64)) {
            (0..self.0.len()).for_each(|i| visit(i, self.0[i][j]));
        }
    }

    /// Two patches facing each other with `F_01 = a`, `F_10 = b`: `B = (I - rho F)^-1 E` in
    /// closed form (Cramer's rule on the 2 x 2 system).
    #[test]
    fn every_method_solves_a_two_patch_system_exactly() {
        let (a, b, rho) = (0.6, 0.3, [0.9, 0.5]);
        let transport = Matrix(vec![vec![0.0, a], vec![b, 0.0]]);
        let emission = [Rgb::new(2.0, 1.0, 0.0), Rgb::ZERO];
        let reflectance = rho.map(Rgb::splat);
        let system = System {
            reflectance: &reflectance,
            emission: &emission,
            area: &[1.0, 2.0],
        };
        let determinant = 1.0 - rho[0] * a * rho[1] * b;
        let expected = [
            emission[0] / determinant,
            emission[0] * (rho[1] * b) / determinant,
        ];
        for method in Method::ALL {
            let settings = SolverSettings {
                method,
                tolerance: 1e-12,
                ..SolverSettings::default()
            };
            let outcome = solve(&transport, &system, &settings, None, &crate::no_progress)
                .expect("a matrix has entries");
            assert!(outcome.converged, "{method}");
            for (got, want) in outcome.radiosity.iter().zip(&expected) {
                assert!(
                    (*got - *want).abs().max_element() < 1e-9,
                    "{method}: {got} vs {want}"
                );
            }
        }
    }

    /// Three patches of reflectance 0.9 lit from the first: fewer than GMRES's restart, so its
    /// Krylov space spans their whole space within one cycle.
    struct ThreePatches {
        transport: Matrix,
        reflectance: [Rgb; 3],
        emission: [Rgb; 3],
    }

    impl ThreePatches {
        fn new() -> Self {
            ThreePatches {
                transport: Matrix(vec![
                    vec![0.0, 0.5, 0.4],
                    vec![0.3, 0.0, 0.6],
                    vec![0.2, 0.7, 0.0],
                ]),
                reflectance: [Rgb::splat(0.9); 3],
                emission: [Rgb::ONE, Rgb::ZERO, Rgb::ZERO],
            }
        }

        fn system(&self) -> System<'_> {
            System {
                reflectance: &self.reflectance,
                emission: &self.emission,
                area: &[1.0; 3],
            }
        }
    }

    #[test]
    fn the_estimates_read_between_gmres_iterations_move_from_the_start_to_the_answer() {
        // Worked out only when read, each estimate is the iterate at that point: the first is
        // the start (zero), the one after the first product has moved, the last is the answer.
        let patches = ThreePatches::new();
        let (transport, system) = (&patches.transport, patches.system());
        let read = std::sync::Mutex::new(Vec::new());
        let progress = |p: Progress| {
            if let Progress::Estimate { radiosity } = p {
                read.lock().unwrap().push(radiosity.read());
            }
        };
        let settings = SolverSettings {
            tolerance: 1e-10,
            ..SolverSettings::default()
        };
        let answer = solve(transport, &system, &settings, None, &progress).unwrap();
        let read = read.into_inner().unwrap();
        assert!(read.len() >= 3, "{} estimates", read.len());
        assert_eq!(read[0], vec![Rgb::ZERO; 3]);
        assert_ne!(read[1], read[0]);
        assert_eq!(read.last(), Some(&answer.radiosity));
    }

    #[test]
    fn gmres_is_exact_within_one_cycle_on_a_small_system_and_jacobi_takes_rho_to_the_k() {
        // n = 3 < the restart length: GMRES's Krylov space spans the whole space in 3 steps.
        let patches = ThreePatches::new();
        let (transport, system) = (&patches.transport, patches.system());
        let run = |method| {
            let settings = SolverSettings {
                method,
                tolerance: 1e-10,
                ..SolverSettings::default()
            };
            solve(transport, &system, &settings, None, &crate::no_progress).unwrap()
        };
        let (gmres, jacobi) = (run(Method::Gmres), run(Method::Jacobi));
        assert!(gmres.iterations <= 3, "{}", gmres.iterations);
        assert!(jacobi.iterations > 50, "{}", jacobi.iterations);
        for (g, j) in gmres.radiosity.iter().zip(&jacobi.radiosity) {
            assert!((*g - *j).abs().max_element() < 1e-8);
        }
    }

    #[test]
    fn gmres_gives_up_where_its_restarts_make_no_headway() {
        // `M = I - F` a cyclic shift of 100 patches, lit at the first: M B = E needs B at
        // the last, which no Krylov space of fewer than 100 steps reaches, so GMRES(30)
        // restarts stay at residual one (Nachtigal, Reddy, Trefethen 1992, "How fast are
        // nonsymmetric matrix iterations?": the shift on which GMRES stagnates).
        // `F = I - shift`, with rows summing to zero, is no physical transport, but real ones
        // with rows past one over the reflectance stalled the same way.
        struct ShiftComplement(usize);
        impl Transport for ShiftComplement {
            fn patch_count(&self) -> usize {
                self.0
            }
            fn gather(&self, radiosity: &[Rgb], out: &mut [Rgb]) {
                for (i, o) in out.iter_mut().enumerate() {
                    *o = radiosity[i] - radiosity[(i + 1) % self.0];
                }
            }
        }
        let n = 100;
        let mut emission = vec![Rgb::ZERO; n];
        emission[0] = Rgb::ONE;
        let system = System {
            reflectance: &vec![Rgb::ONE; n],
            emission: &emission,
            area: &vec![1.0; n],
        };
        let settings = SolverSettings::default();
        let outcome = solve(
            &ShiftComplement(n),
            &system,
            &settings,
            None,
            &crate::no_progress,
        )
        .expect("gmres needs no entries");
        assert!(!outcome.converged);
        assert!(
            (outcome.residual - 1.0).abs() < 1e-9,
            "{}",
            outcome.residual
        );
        // Every cycle stalled: it gave up after the few it allows, not at the iteration limit.
        assert_eq!(outcome.iterations, 30 * STALLED_CYCLES as usize);
    }

    #[test]
    fn no_light_is_exactly_dark_and_a_matrix_free_transport_refuses_per_patch_methods() {
        struct Product;
        impl Transport for Product {
            fn patch_count(&self) -> usize {
                1
            }
            fn gather(&self, _: &[Rgb], out: &mut [Rgb]) {
                out[0] = Rgb::ZERO;
            }
        }
        let system = System {
            reflectance: &[Rgb::splat(0.5)],
            emission: &[Rgb::ZERO],
            area: &[1.0],
        };
        let dark = solve(
            &Product,
            &system,
            &SolverSettings::default(),
            None,
            &crate::no_progress,
        )
        .unwrap();
        assert_eq!((dark.radiosity[0], dark.residual), (Rgb::ZERO, 0.0));
        let gauss_seidel = SolverSettings {
            method: Method::GaussSeidel,
            ..SolverSettings::default()
        };
        assert_eq!(
            solve(&Product, &system, &gauss_seidel, None, &crate::no_progress).err(),
            Some(NeedsEntries(Method::GaussSeidel))
        );
    }
}
