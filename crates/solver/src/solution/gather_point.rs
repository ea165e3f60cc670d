//! Where the display's values are gathered: a mesh corner or a patch's centroid, with the
//! points around it that rays start from; and what each such point reads, as sparse weights.

use crate::Progress;
use crate::mesh::{Mesh, corner_reading_point};
use crate::sampling::splitmix64;
use crate::scene::Rgb;
use glam::DVec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Where the unoccluded factor is evaluated: this fraction of the way from the corner toward
/// the centre of a patch that uses it. A corner on an edge shared with a perpendicular face
/// lies in that face's plane, where the factor drops to zero; just inside, it has its limit.
const LIMIT_INSET: f64 = 1e-6;

/// A point where light is gathered (a mesh corner or a patch's centroid), and the points
/// around it that rays start from.
pub(super) struct GatherPoint {
    /// The point itself, a corner moved [`LIMIT_INSET`] into its first patch.
    pub(super) limit: DVec3,
    pub(super) normal: DVec3,
    pub(super) face: u32,
    /// Up to four points, one in each patch that uses the corner where its light is read
    /// ([`corner_reading_point`]; the centroid itself for a centroid): rays start from them
    /// in turn, so a corner on a contact line sees the mean of both sides.
    pub(super) insides: Insides,
}

/// The points a gather point's rays start from: up to four, held in place (a list on the heap
/// for each of a million points cost as many allocations, made one at a time).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Insides {
    points: [DVec3; 4],
    count: usize,
}

impl Insides {
    /// Just `point`.
    pub(super) fn one(point: DVec3) -> Insides {
        let mut insides = Insides::default();
        insides.push(point);
        insides
    }

    /// Adds `point` where there is room for it.
    fn push(&mut self, point: DVec3) {
        if let Some(slot) = self.points.get_mut(self.count) {
            *slot = point;
            self.count += 1;
        }
    }
}

impl std::ops::Deref for Insides {
    type Target = [DVec3];

    fn deref(&self) -> &[DVec3] {
        &self.points[..self.count]
    }
}

impl GatherPoint {
    /// One per corner of `mesh` (`None`: a corner no patch uses).
    pub(super) fn corners_of(mesh: &Mesh) -> Vec<Option<GatherPoint>> {
        let mut corners: Vec<Option<GatherPoint>> =
            (0..mesh.positions.len()).map(|_| None).collect();
        for patch in &mesh.patches {
            for &c in &patch.corners[..patch.corner_count()] {
                let position = mesh.positions[c as usize];
                let corner = corners[c as usize].get_or_insert_with(|| GatherPoint {
                    limit: position + (patch.centroid - position) * LIMIT_INSET,
                    normal: patch.normal,
                    face: patch.face,
                    insides: Insides::default(),
                });
                (corner.insides).push(corner_reading_point(position, patch.centroid));
            }
        }
        corners
    }

    /// The point to the bit (place, facing, face and its rays' origins) in 128 bits: two
    /// chained hashes of them, so that two different points of a mesh share it with odds of
    /// about `n^2 / 2^129`.
    pub(super) fn fingerprint(&self) -> u128 {
        let vectors = [self.limit, self.normal]
            .into_iter()
            .chain(self.insides.iter().copied());
        let words = vectors
            .flat_map(|v| v.to_array().map(f64::to_bits))
            .chain([u64::from(self.face)]);
        let (mut a, mut b) = (0x243F_6A88_85A3_08D3u64, 0x1319_8A2E_0370_7344u64);
        for word in words {
            a = splitmix64(a ^ word);
            b = splitmix64(b.rotate_left(17) ^ word);
        }
        u128::from(a) << 64 | u128::from(b)
    }

    /// One per patch of `mesh`, at its centroid.
    pub(super) fn centroids_of(mesh: &Mesh) -> Vec<Option<GatherPoint>> {
        (mesh.patches.iter())
            .map(|patch| {
                Some(GatherPoint {
                    limit: patch.centroid,
                    normal: patch.normal,
                    face: patch.face,
                    insides: Insides::one(patch.centroid),
                })
            })
            .collect()
    }
}

/// Gather points between two progress reports: a report a point would cost more than the
/// point's rays on a small scene, and a million points report a thousand times.
const POINTS_PER_REPORT: usize = 1024;

/// One pass of rays over a mesh's gather points (its corners', then its centroids'), counting
/// the points done and reporting them as [`Progress::Gathering`].
pub(super) struct Tally<'a> {
    pass: &'static str,
    total: usize,
    done: AtomicUsize,
    progress: &'a (dyn Fn(Progress) + Sync),
}

impl<'a> Tally<'a> {
    /// A pass named `pass` over the corners and centroids of `mesh`.
    pub(super) fn over(
        mesh: &Mesh,
        pass: &'static str,
        progress: &'a (dyn Fn(Progress) + Sync),
    ) -> Tally<'a> {
        Tally {
            pass,
            total: mesh.positions.len() + mesh.patches.len(),
            done: AtomicUsize::new(0),
            progress,
        }
    }

    /// Counts one point done, and reports every [`POINTS_PER_REPORT`]th and the last.
    fn point_done(&self) {
        let done = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        if done % POINTS_PER_REPORT == 0 || done == self.total {
            (self.progress)(Progress::Gathering {
                pass: self.pass,
                done,
                total: self.total,
            });
        }
    }
}

/// Per gather point, a list (point `i`'s is `entries[offsets[i]..offsets[i + 1]]`).
pub(super) struct PointRows<T> {
    offsets: Vec<u32>,
    entries: Vec<T>,
}

/// Per gather point, the values it reads and with what weight: the emitting faces a point sees
/// and its factor to each (direct light).
pub(super) type PointWeights = PointRows<(u32, f32)>;

impl<T: Send> PointRows<T> {
    /// `count` points with empty lists.
    pub(super) fn none(count: usize) -> PointRows<T> {
        PointRows {
            offsets: vec![0; count + 1],
            entries: Vec::new(),
        }
    }

    /// Each of `points` with the list `list` (its index, the point) gives, in parallel; a
    /// `None` point gets an empty one. Each point counts as done in `tally`.
    pub(super) fn at_points(
        points: &[Option<GatherPoint>],
        tally: &Tally,
        list: impl Fn(usize, &GatherPoint) -> Vec<T> + Sync,
    ) -> PointRows<T> {
        let per_point: Vec<Vec<T>> = points
            .par_iter()
            .enumerate()
            .map(|(index, point)| {
                let row = point.as_ref().map_or(Vec::new(), |p| list(index, p));
                tally.point_done();
                row
            })
            .collect();
        let mut offsets = Vec::with_capacity(per_point.len() + 1);
        offsets.push(0);
        for list in &per_point {
            offsets.push(offsets.last().copied().unwrap_or(0) + list.len() as u32);
        }
        // Sized once and filled list by list, each freed as it is copied: a collected
        // flatten grew by doubling, three times the lists' memory at its peak (the bounce's
        // lists are most of a large model's).
        let mut entries = Vec::with_capacity(offsets.last().copied().unwrap_or(0) as usize);
        for list in per_point {
            entries.extend(list);
        }
        PointRows { offsets, entries }
    }
}

/// What one mesh's gather points gathered, found again by point: a mesh that shares most of
/// its points with it (the leaves after display splits) gathers only the others.
pub(super) struct GatheredAt<T> {
    rows: PointRows<T>,
    /// Each point's index by its fingerprint, in [`MAP_SHARDS`] maps.
    by_point: Vec<HashMap<u128, u32>>,
}

/// Maps a [`GatheredAt`]'s points are spread over by their fingerprints' top bits (hashes,
/// so evenly), each built on its own thread: one map of a million points was built on one
/// core while the other idled, between each generation of display splits.
const MAP_SHARDS: usize = 64;
const _: () = assert!(
    MAP_SHARDS.is_power_of_two(),
    "a shard is a fingerprint's top bits"
);

/// The map of [`GatheredAt::by_point`] that holds `fingerprint`.
fn map_shard(fingerprint: u128) -> usize {
    (fingerprint >> (128 - MAP_SHARDS.trailing_zeros())) as usize
}

impl<T> GatheredAt<T> {
    /// `rows`, gathered at `points`.
    pub(super) fn new(points: &[Option<GatherPoint>], rows: PointRows<T>) -> GatheredAt<T> {
        // Fingerprinted in parallel, as points are looked up: each generation of display
        // splits hashes every point of the leaves before it.
        let fingerprints: Vec<Option<u128>> = (points.par_iter())
            .map(|point| point.as_ref().map(GatherPoint::fingerprint))
            .collect();
        let mut shards: Vec<Vec<(u128, u32)>> = vec![Vec::new(); MAP_SHARDS];
        for (i, fingerprint) in fingerprints.into_iter().enumerate() {
            if let Some(fingerprint) = fingerprint {
                shards[map_shard(fingerprint)].push((fingerprint, i as u32));
            }
        }
        let by_point = (shards.into_par_iter())
            .map(|shard| shard.into_iter().collect())
            .collect();
        GatheredAt { rows, by_point }
    }

    /// What `point` gathered, if it is one of the points.
    pub(super) fn at(&self, point: &GatherPoint) -> Option<&[T]> {
        let fingerprint = point.fingerprint();
        let i = *self.by_point[map_shard(fingerprint)].get(&fingerprint)? as usize;
        Some(&self.rows.entries[self.rows.offsets[i] as usize..self.rows.offsets[i + 1] as usize])
    }
}

impl<T: Sync> PointRows<T> {
    /// Per point, `fold` of its list, in parallel.
    pub(super) fn map_rows(&self, fold: impl Fn(&[T]) -> Rgb + Sync) -> Vec<Rgb> {
        self.offsets
            .par_windows(2)
            .map(|range| fold(&self.entries[range[0] as usize..range[1] as usize]))
            .collect()
    }
}

impl PointWeights {
    /// Per point, the weighted sum of the `values` it reads.
    pub(super) fn read(&self, values: &[Rgb]) -> Vec<Rgb> {
        self.map_rows(|row| {
            row.iter()
                .map(|&(index, weight)| values[index as usize] * weight as f64)
                .sum()
        })
    }
}
