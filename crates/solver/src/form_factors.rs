//! Form factors between patches, and the [`Transport`] interface the solvers iterate on.
//!
//! `F_ij` (the fraction of light leaving patch `i` that reaches patch `j`, equivalently the
//! share of `j`'s radiosity that `i` gathers) is the receiver-area average of the analytic
//! point-to-polygon form factor to `j`, times the fraction of shadow rays between the two
//! patches that no other face blocks. The quadrature on the receiver is refined for near pairs,
//! where the integrand varies fastest; far pairs use the centroid.

use crate::Progress;
use crate::geometry::bounds;
use crate::mesh::{Mesh, Patch};
use crate::pair::{
    FormFactorSettings, mutually_facing, near_pair_level, rays_for_pair, unoccluded_form_factor,
};
use crate::sampling::{pair_seed, splitmix64, stratified_uv};
use crate::scene::Rgb;
use crate::transport::{Entries, Transport};
use crate::visibility::Occluders;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

/// Marks a pair that cannot exchange light at all in the clear-ray matrix (counts are at most
/// [`MAX_RAYS_PER_PAIR`]).
const NOT_FACING: u8 = u8::MAX;

/// The `rays` shadow segments between `p` and `q`: stratified points on both, decorrelated per
/// pair, the same every time for the same pair.
fn pair_segments<'a>(
    p: &'a Patch,
    q: &'a Patch,
    pair: (usize, usize),
    rays: u32,
) -> impl Iterator<Item = (DVec3, DVec3)> + 'a {
    let seed = pair_seed(pair.0, pair.1);
    let (seed_p, seed_q) = (seed, splitmix64(seed));
    (0..rays).map(move |k| {
        let (u, v) = stratified_uv(k, seed_p);
        let (s, t) = stratified_uv(k, seed_q);
        (p.polygon.point_at(u, v), q.polygon.point_at(s, t))
    })
}

/// How many of `rays` segments between `p` and `q` nothing blocks.
fn clear_rays(p: &Patch, q: &Patch, pair: (usize, usize), rays: u32, occluders: &Occluders) -> u32 {
    pair_segments(p, q, pair, rays)
        .filter(|(a, b)| occluders.segment_is_clear(*a, *b, [p.face, q.face]))
        .count() as u32
}

/// Whether the segment from `a` to `b` meets the box `(lo, hi)` (the slab method).
fn segment_meets_box(a: DVec3, b: DVec3, (lo, hi): (DVec3, DVec3)) -> bool {
    let d = b - a;
    let (mut enter, mut exit) = (0.0f64, 1.0f64);
    for axis in 0..3 {
        if d[axis] == 0.0 {
            if a[axis] < lo[axis] || a[axis] > hi[axis] {
                return false;
            }
            continue;
        }
        let (t0, t1) = (
            (lo[axis] - a[axis]) / d[axis],
            (hi[axis] - a[axis]) / d[axis],
        );
        enter = enter.max(t0.min(t1));
        exit = exit.min(t0.max(t1));
        if enter > exit {
            return false;
        }
    }
    true
}

/// Copies each `m[j][i]` (j < i) to `m[i][j]` in cache-sized blocks.
fn mirror_upper_triangle(m: &mut [u8], n: usize) {
    const BLOCK: usize = 64;
    for bi in (0..n).step_by(BLOCK) {
        for bj in (0..=bi).step_by(BLOCK) {
            for i in bi..(bi + BLOCK).min(n) {
                for j in bj..(bj + BLOCK).min(i) {
                    m[i * n + j] = m[j * n + i];
                }
            }
        }
    }
}

/// All `n^2` form factors in one row-major f32 matrix: the baseline, exact up to quadrature and
/// ray sampling, and quadratic in time and memory. The clear-ray counts stay beside it, so a
/// moved object costs only the pairs it can affect ([`DenseFormFactors::update_moved`]).
pub struct DenseFormFactors {
    n: usize,
    values: Vec<f32>,
    /// Clear shadow rays per pair (both triangles filled), or [`NOT_FACING`].
    clear: Vec<u8>,
    /// Per row, the factor its integrated values were multiplied by (1, or 1/sum for a
    /// closed view), so single entries can be updated without integrating the row again.
    row_scale: Vec<f64>,
    settings: FormFactorSettings,
    /// Shadow rays cast while computing.
    pub rays_cast: u64,
}

/// What an incremental update recomputed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UpdateStats {
    /// Patch pairs whose visibility was traced again.
    pub pairs: usize,
    /// Rows (receivers) with at least one changed entry.
    pub rows: usize,
    /// Form-factor entries integrated again (of n^2).
    pub entries: usize,
}

/// Clear-ray count of pair `(i, j)`, or [`NOT_FACING`]; and the rays cast.
fn pair_visibility(
    patches: &[Patch],
    i: usize,
    j: usize,
    occluders: &Occluders,
    settings: &FormFactorSettings,
) -> (u8, u64) {
    let (p, q) = (&patches[i], &patches[j]);
    if !mutually_facing(p, q) {
        return (NOT_FACING, 0);
    }
    let rays = rays_for_pair(p, q, settings);
    (clear_rays(p, q, (i, j), rays, occluders) as u8, rays as u64)
}

/// One entry before normalisation: the receiver-integrated analytic factor times the clear
/// fraction of shadow rays.
fn raw_entry(
    patches: &[Patch],
    i: usize,
    j: usize,
    clear: u8,
    settings: &FormFactorSettings,
) -> f64 {
    if clear == NOT_FACING || clear == 0 || i == j {
        return 0.0;
    }
    let (p, q) = (&patches[i], &patches[j]);
    let level = near_pair_level(p, q).unwrap_or(0);
    unoccluded_form_factor(p, q, level) * clear as f64 / rays_for_pair(p, q, settings) as f64
}

/// Writes `raw` into `row` normalised: a receiver whose view is closed (all its hemisphere
/// rays meet a front face) sends all its light to patches, so its row sums to one; closed
/// enclosures stay exact for bright surfaces (rho -> 1) and with occluders, whatever the
/// sampling noise of visibility. Returns the factor applied.
fn normalise_row(
    patches: &[Patch],
    i: usize,
    raw: impl Iterator<Item = f64>,
    occluders: &Occluders,
    row: &mut [f32],
) -> f64 {
    let mut sum = 0.0;
    for (value, r) in row.iter_mut().zip(raw) {
        *value = r as f32;
        sum += r;
    }
    let scale = match occluders.closed_view_share(&patches[i], i) {
        Some(share) if sum > 0.0 => share / sum,
        _ => 1.0,
    };
    if scale != 1.0 {
        row.iter_mut()
            .for_each(|value| *value = (*value as f64 * scale) as f32);
    }
    scale
}

impl DenseFormFactors {
    /// Bytes the form factors and clear-ray counts for `n` patches need.
    pub fn memory_bytes(n: usize) -> u64 {
        (n as u64).pow(2) * (std::mem::size_of::<f32>() + 1) as u64
    }

    /// Computes every form factor of `mesh`, reporting rows done through `progress`.
    pub fn compute(
        mesh: &Mesh,
        occluders: &Occluders,
        settings: &FormFactorSettings,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Self {
        let patches = &mesh.patches;
        let n = patches.len();
        let rows_done = AtomicUsize::new(0);
        let report = || {
            let done = rows_done.fetch_add(1, Ordering::Relaxed) + 1;
            if done % 64 == 0 || done == 2 * n {
                progress(Progress::FormFactors { done, total: 2 * n });
            }
        };
        // Pass 1: visibility is symmetric, so rays are cast once per unordered pair (i < j),
        // then mirrored so pass 2 reads rows sequentially.
        let rays_cast = AtomicU64::new(0);
        let mut clear = vec![NOT_FACING; n * n];
        clear
            .par_chunks_mut(n.max(1))
            .enumerate()
            .for_each(|(i, row)| {
                let cast: u64 = (i + 1..n)
                    .map(|j| {
                        let (count, rays) = pair_visibility(patches, i, j, occluders, settings);
                        row[j] = count;
                        rays
                    })
                    .sum();
                rays_cast.fetch_add(cast, Ordering::Relaxed);
                report();
            });
        mirror_upper_triangle(&mut clear, n);
        // Pass 2: each row integrates its receiver's view, far sources at the centroid, near
        // ones with their own finer rule.
        let mut values = vec![0f32; n * n];
        let mut row_scale = vec![1.0; n];
        values
            .par_chunks_mut(n.max(1))
            .zip(row_scale.par_iter_mut())
            .enumerate()
            .for_each(|(i, (row, scale))| {
                let clear_row = &clear[i * n..(i + 1) * n];
                *scale = normalise_row(
                    patches,
                    i,
                    (0..n).map(|j| raw_entry(patches, i, j, clear_row[j], settings)),
                    occluders,
                    row,
                );
                report();
            });
        DenseFormFactors {
            n,
            values,
            clear,
            row_scale,
            settings: *settings,
            rays_cast: rays_cast.into_inner(),
        }
    }

    /// Updates after the patches marked in `moved` changed place (`mesh` and `occluders` are
    /// already the new ones; `region` bounds the moved object before and after). A pair is
    /// traced again when it involves a moved patch, or when one of its own shadow segments
    /// crosses `region`: all geometry that changed lies there, so no other segment's answer can
    /// differ. Only changed entries are integrated again.
    pub fn update_moved(
        &mut self,
        mesh: &Mesh,
        occluders: &Occluders,
        moved: &[bool],
        region: (DVec3, DVec3),
    ) -> UpdateStats {
        let boxes: Vec<(DVec3, DVec3)> = mesh
            .patches
            .iter()
            .map(|p| bounds(p.polygon.corners().iter().copied()))
            .collect();
        // Grown by a relative hair, so that f32 ray tracing near the edge cannot disagree.
        let margin = 1e-6
            * (region.1 - region.0).length().max(
                boxes
                    .iter()
                    .map(|b| (b.1 - b.0).length())
                    .fold(0.0, f64::max),
            );
        let region = (
            region.0 - DVec3::splat(margin),
            region.1 + DVec3::splat(margin),
        );
        let (changed, pairs) = self.retrace_moved(mesh, occluders, moved, &boxes, region);
        let entries = self.reintegrate(mesh, occluders, moved, &changed);
        UpdateStats {
            pairs,
            rows: changed.iter().filter(|c| !c.is_empty()).count(),
            entries,
        }
    }

    /// Pass A of [`DenseFormFactors::update_moved`]: traces again the pairs that can have
    /// changed (a moved patch, or a shadow segment through `region`) and keeps their clear-ray
    /// counts; returns each row's changed columns and the pairs traced.
    fn retrace_moved(
        &mut self,
        mesh: &Mesh,
        occluders: &Occluders,
        moved: &[bool],
        boxes: &[(DVec3, DVec3)],
        region: (DVec3, DVec3),
    ) -> (Vec<Vec<u32>>, usize) {
        let (patches, n, settings) = (&mesh.patches, self.n, self.settings);
        let overlaps =
            |(lo, hi): (DVec3, DVec3)| lo.cmple(region.1).all() && hi.cmpge(region.0).all();
        let pairs = AtomicUsize::new(0);
        // Upper triangle; each row lists its changes.
        let changed_upper: Vec<Vec<u32>> = self
            .clear
            .par_chunks_mut(n.max(1))
            .enumerate()
            .map(|(i, row)| {
                let mut changed = Vec::new();
                for j in i + 1..n {
                    let pair_box = (boxes[i].0.min(boxes[j].0), boxes[i].1.max(boxes[j].1));
                    let crosses = || {
                        let (p, q) = (&patches[i], &patches[j]);
                        // Every segment from p to q stays within max(r_p, r_q) of the segment
                        // between their centroids: one slab test rules most pairs out.
                        let reach = DVec3::splat(p.radius.max(q.radius));
                        segment_meets_box(
                            p.centroid,
                            q.centroid,
                            (region.0 - reach, region.1 + reach),
                        ) && mutually_facing(p, q)
                            && pair_segments(p, q, (i, j), rays_for_pair(p, q, &settings))
                                .any(|(a, b)| segment_meets_box(a, b, region))
                    };
                    if !(moved[i] || moved[j] || (overlaps(pair_box) && crosses())) {
                        continue;
                    }
                    pairs.fetch_add(1, Ordering::Relaxed);
                    let (count, _) = pair_visibility(patches, i, j, occluders, &settings);
                    if count != row[j] || moved[i] || moved[j] {
                        row[j] = count;
                        changed.push(j as u32);
                    }
                }
                changed
            })
            .collect();
        // Mirror only what changed; the rest of the lower triangle still agrees.
        let mut changed: Vec<Vec<u32>> = vec![Vec::new(); n];
        for (i, columns) in changed_upper.iter().enumerate() {
            for &j in columns {
                self.clear[j as usize * n + i] = self.clear[i * n + j as usize];
                changed[i].push(j);
                changed[j as usize].push(i as u32);
            }
        }
        (changed, pairs.into_inner())
    }

    /// Pass B of [`DenseFormFactors::update_moved`]: integrates again only the `changed`
    /// entries of each row, a moved receiver's whole row, since its own quadrature moved. A
    /// row whose normalisation stays the same (an open view) is only written where it
    /// changed. Returns the entries integrated.
    fn reintegrate(
        &mut self,
        mesh: &Mesh,
        occluders: &Occluders,
        moved: &[bool],
        changed: &[Vec<u32>],
    ) -> usize {
        let (patches, n, settings) = (&mesh.patches, self.n, self.settings);
        let clear = &self.clear;
        let entries = AtomicUsize::new(0);
        self.values
            .par_chunks_mut(n.max(1))
            .zip(self.row_scale.par_iter_mut())
            .enumerate()
            .filter(|(i, _)| !changed[*i].is_empty())
            .for_each(|(i, (row, scale))| {
                let clear_row = &clear[i * n..(i + 1) * n];
                // A row scaled to zero (a closed view of back faces only: a patch under a box)
                // cannot be unscaled to its raw values; it is integrated whole, like a moved
                // receiver's.
                if moved[i] || *scale == 0.0 {
                    entries.fetch_add(n, Ordering::Relaxed);
                    *scale = normalise_row(
                        patches,
                        i,
                        (0..n).map(|j| raw_entry(patches, i, j, clear_row[j], &settings)),
                        occluders,
                        row,
                    );
                    return;
                }
                entries.fetch_add(changed[i].len(), Ordering::Relaxed);
                let updates: Vec<(usize, f64)> = changed[i]
                    .iter()
                    .map(|&j| {
                        (
                            j as usize,
                            raw_entry(patches, i, j as usize, clear_row[j as usize], &settings),
                        )
                    })
                    .collect();
                let old_raw_sum: f64 = row.iter().map(|v| *v as f64).sum::<f64>() / *scale;
                let raw_sum = old_raw_sum
                    + updates
                        .iter()
                        .map(|(j, raw)| raw - row[*j] as f64 / *scale)
                        .sum::<f64>();
                let new_scale = match occluders.closed_view_share(&patches[i], i) {
                    Some(share) if raw_sum > 0.0 => share / raw_sum,
                    _ => 1.0,
                };
                if new_scale == 1.0 && *scale == 1.0 {
                    updates.iter().for_each(|(j, raw)| row[*j] = *raw as f32);
                } else {
                    let mut raw: Vec<f64> = row.iter().map(|v| *v as f64 / *scale).collect();
                    updates.iter().for_each(|(j, value)| raw[*j] = *value);
                    *scale = normalise_row(patches, i, raw.into_iter(), occluders, row);
                }
            });
        entries.into_inner()
    }

    /// `F_ij`.
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.values[i * self.n + j] as f64
    }

    /// Row `i`: `F_ij` for every `j`.
    pub fn row(&self, i: usize) -> &[f32] {
        &self.values[i * self.n..(i + 1) * self.n]
    }
}

/// `sum_j row_j * channel_j` for the three channels in one pass over the row (the product is
/// bound by reading the matrix), in f64 with eight independent partial sums per channel, a
/// shape compilers turn into SIMD (one running sum cannot be reordered, so it stays scalar).
fn dot3(row: &[f32], channels: &[Vec<f64>; 3]) -> Rgb {
    const LANES: usize = 8;
    let mut partial = [[0.0f64; LANES]; 3];
    let whole = row.len() / LANES * LANES;
    for start in (0..whole).step_by(LANES) {
        let f = &row[start..start + LANES];
        for (c, channel) in channels.iter().enumerate() {
            let v = &channel[start..start + LANES];
            for k in 0..LANES {
                partial[c][k] += f[k] as f64 * v[k];
            }
        }
    }
    let total = |c: usize| {
        partial[c].iter().sum::<f64>()
            + (whole..row.len())
                .map(|j| row[j] as f64 * channels[c][j])
                .sum::<f64>()
    };
    Rgb::new(total(0), total(1), total(2))
}

impl Transport for DenseFormFactors {
    fn patch_count(&self) -> usize {
        self.n
    }

    fn gather(&self, radiosity: &[Rgb], out: &mut [Rgb]) {
        // One channel at a time over contiguous arrays: the matrix-vector product dominates
        // every solver, and this layout lets it vectorise (about 2x the per-row Rgb sum).
        let channels: [Vec<f64>; 3] =
            std::array::from_fn(|c| radiosity.iter().map(|b| b[c]).collect());
        out.par_iter_mut()
            .enumerate()
            .for_each(|(i, o)| *o = dot3(self.row(i), &channels));
    }

    fn entries(&self) -> Option<&dyn Entries> {
        Some(self)
    }
}

impl Entries for DenseFormFactors {
    fn gather_row(&self, i: usize, radiosity: &[Rgb]) -> Rgb {
        self.row(i)
            .iter()
            .zip(radiosity)
            .map(|(&f, b)| *b * f as f64)
            .sum()
    }

    fn for_each_in_column(&self, j: usize, visit: &mut dyn FnMut(usize, f64)) {
        for i in 0..self.n {
            let f = self.values[i * self.n + j];
            if f != 0.0 {
                visit(i, f as f64);
            }
        }
    }
}
