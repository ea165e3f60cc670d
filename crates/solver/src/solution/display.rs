//! Leaves split for what viewers see: where the direct light across a leaf has a shape its
//! corners cannot show.
//!
//! Viewers interpolate the corners' values linearly over each patch, and the corners gather
//! direct light exactly; what is left of the direct light's error is its shape inside leaves
//! too coarse for it (a ground of 10 m^2 leaves across a building's penumbra). The links do
//! not need those leaves finer (the knob bounds the errors of what links carry, and on large
//! models the link budget stops them first), so such a leaf is split for the display alone
//! (Lischinski, Tampieri, Greenberg 1993 refine the receiving mesh for the final gather the
//! same way): its pieces keep their parent's links and gather at their own corners. Where to
//! split needs no estimate: the corners' and the centroid's exact gathers already disagree
//! there ([`CornerLight::direct_misfit`]).

use super::vertices::{CornerIndirect, CornerLight};
use crate::Progress;
use crate::hierarchy::{Hierarchy, HierarchySettings, finest_radius};
use crate::mesh::Mesh;
use crate::sampling::Seed;
use crate::scene::{Rgb, Scene};
use crate::visibility::Occluders;
use std::collections::BTreeSet;

/// How far a leaf's centroid's direct light may lie from its corners' mean, relative to the
/// mean reflected radiosity, before the leaf is split for the display. Measured
/// (docs/BENCHMARKS.md): the monastery piece at knob 0.9 read 3.40% smooth RMS unsplit, 2.84%
/// split once at 0.3 (+15% time); the Cornell box splits nothing at 0.3 from knob 0.3 to
/// 0.05, and a tolerance of the knob itself split it at 0.05 where the gather's noise, not the
/// light, makes corners and centroid disagree (1.39% -> 1.48%). With two generations of
/// splits, 0.2 against 0.3: the monastery (`--check off`, seeds 0-2) 5.18 -> 4.97% mean, the
/// teddy bear 2.26 -> 1.64%, the furnished room 3.98 -> 3.74%, the Cornell box at 0.05 the
/// same to the digit; at 0.15 the monastery's room was spent on smaller misfits (5.42%).
const MISFIT_TOLERANCE: f64 = 0.2;

/// How much finer than refinement's finest element ([`finest_radius`]) a display split may
/// make a leaf: one level more. Refinement stops there because finer elements need links the
/// budget cannot afford everywhere; a display split adds leaves and no links, and the leaf
/// budget bounds it. Measured (docs/BENCHMARKS.md): at refinement's finest, the monastery
/// could split 10,046 of its 62,104 leaves whose light curves (7.71% smooth RMS); one level
/// finer, 47,694 (6.96%), and the monastery piece at knob 0.9 read 2.84 -> 2.46%.
const DISPLAY_FINEST_SHARE: f64 = 0.5;

/// The share of the leaf budget left after refinement that display splits may take. Their
/// pieces that straddle the edge of where light reaches split on ([`Hierarchy::split_for_display`])
/// in generations that each must fit the budget whole: given all of it, the monastery's display
/// splits used it up, its ground's pieces at the foot of the walls stayed whole, and the ground
/// read 2.80% smooth RMS instead of 2.06% with half.
const DISPLAY_ROOM_SHARE: f64 = 0.5;

/// What viewers are shown: the leaves, their solution and their corners' light.
pub(super) struct Displayed {
    /// The leaves as a mesh.
    pub(super) mesh: Mesh,
    /// The solution carried to them, one value per leaf.
    pub(super) radiosity: Vec<Rgb>,
    /// Their corners' light, with the last bounces gathered.
    pub(super) light: CornerLight,
}

/// How many times leaves are split for the display, each generation deciding on the light
/// its pieces gathered: one split of a 16 m^2 floor leaf across a shadow's edge leaves pieces
/// that still straddle it. Measured (docs/BENCHMARKS.md, `--check off`, seeds 0-2): the
/// monastery read 5.70 / 5.44 / 5.45% smooth RMS after one, 5.33 / 5.14 / 5.06% after two
/// (+25k leaves; 4.7 s of a 63 s solve on a slow machine) and 5.23 / 5.21 / 5.11% after
/// three; split until nothing is left to split, 13 generations used the room up at 5.24%
/// and cost 20 s more. The tolerance was chosen with two ([`MISFIT_TOLERANCE`]).
const DISPLAY_GENERATIONS: usize = 2;

/// Splits the leaves of `hierarchy` (built from `scene`, solved as `radiosity`) whose
/// centroid's reflected direct light lies further than [`MISFIT_TOLERANCE`] times the mean
/// reflected radiosity from its corners' mean, in up to [`DISPLAY_GENERATIONS`] generations,
/// down to one level below refinement's finest element ([`DISPLAY_FINEST_SHARE`]) and within
/// a share of what `settings.max_leaves` leaves ([`DISPLAY_ROOM_SHARE`]); then gathers the
/// corners' light of the leaves as they are (the direct light gathered to decide is kept
/// where nothing split), each pass of rays reporting its `progress`.
pub(super) fn split_where_direct_light_curves(
    hierarchy: &mut Hierarchy,
    radiosity: Vec<Rgb>,
    scene: &Scene,
    occluders: &Occluders,
    (settings, seed): (&HierarchySettings, Seed),
    lights: &BTreeSet<u32>,
    progress: &(dyn Fn(Progress) + Sync),
) -> Displayed {
    let finest = finest_radius(scene, settings.max_leaves);
    let mut mesh = hierarchy.leaf_mesh();
    let averaged = CornerIndirect::Averaged;
    let reached = (&mesh, hierarchy.reached_corners());
    let mut light = CornerLight::new(scene, reached, occluders, lights, averaged, seed, progress);
    let mut radiosity = radiosity;
    let left = settings.max_leaves.saturating_sub(mesh.patches.len());
    let mut misfits = Misfits {
        display_finest: finest * DISPLAY_FINEST_SHARE,
        room: (left as f64 * DISPLAY_ROOM_SHARE) as usize,
    };
    for _ in 0..DISPLAY_GENERATIONS {
        let chosen = misfits.worst_fitting(hierarchy, &mesh, &light, &radiosity);
        if chosen.is_empty() {
            break;
        }
        radiosity = hierarchy.split_for_display(
            &chosen,
            &radiosity,
            occluders,
            finest,
            settings.max_leaves,
        );
        let split = hierarchy.leaf_mesh();
        // Most points are where they were: they keep the direct light gathered to decide.
        let (meshes, reached) = ((&mesh, &split), hierarchy.reached_corners());
        light = light.after_splits(scene, meshes, reached, occluders, lights, progress);
        mesh = split;
    }
    Displayed {
        light: light.with_gathered_bounces(scene, &mesh, occluders, progress),
        mesh,
        radiosity,
    }
}

/// Which leaves a generation of display splits takes.
struct Misfits {
    /// The smallest radius a split may make.
    display_finest: f64,
    /// Leaves the splits may still add.
    room: usize,
}

impl Misfits {
    /// The leaves of `hierarchy` (as `mesh`, solved as `radiosity`, its corners' `light`)
    /// whose direct light misfits past the tolerance and that can split, worst first (by that
    /// misfit squared times the leaf's area: its share of what viewers see wrong), as many as
    /// the room left holds; the room is spent on them.
    fn worst_fitting(
        &mut self,
        hierarchy: &Hierarchy,
        mesh: &Mesh,
        light: &CornerLight,
        radiosity: &[Rgb],
    ) -> Vec<usize> {
        let misfit = light.direct_misfit(mesh, &hierarchy.leaf_emission());
        let tolerance = MISFIT_TOLERANCE * hierarchy.mean_reflected(radiosity);
        let mut worst: Vec<(f64, usize)> = (0..mesh.patches.len())
            .filter(|&i| misfit[i] > tolerance && hierarchy.can_split_leaf(i, self.display_finest))
            .map(|i| (misfit[i] * misfit[i] * mesh.patches[i].area, i))
            .collect();
        worst.sort_unstable_by(|a, b| b.0.total_cmp(&a.0));
        let room = &mut self.room;
        (worst.into_iter())
            .map(|(_, i)| i)
            .take_while(|&i| {
                let added = hierarchy.leaves_added_by_splitting(i);
                room.checked_sub(added).map(|left| *room = left).is_some()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::{Displayed, split_where_direct_light_curves};
    use crate::accuracy::evaluate;
    use crate::hierarchy::fixtures::{GREY, add_parallelogram, probes_under_a_lamp};
    use crate::hierarchy::{Hierarchy, HierarchySettings, PastLinkBudget};
    use crate::mesh::Mesh;
    use crate::pair::FormFactorSettings;
    use crate::sampling::Seed;
    use crate::scene::{Material, Rgb, Scene};
    use crate::solution::vertices::{CornerIndirect, CornerLight};
    use crate::solve::SolverSettings;
    use crate::visibility::Occluders;
    use glam::{DVec3, dvec3};
    use std::collections::BTreeSet;

    /// An 8 x 8 floor (reflectance 0.5) under a square lamp of side `side` facing down at
    /// `height` over its centre, emitting 1 and reflecting nothing: the floor sees nothing but
    /// the lamp, so its exact radiosity at `x` is 0.5 times the factor from `x` to the lamp.
    fn floor_under_a_lamp(side: f64, height: f64) -> Scene {
        let mut scene = Scene::default();
        let (x, y) = (DVec3::X, DVec3::Y);
        let floor = (dvec3(-4.0, -4.0, 0.0), x * 8.0, y * 8.0);
        add_parallelogram(&mut scene, "floor", floor, GREY);
        let lamp = Material {
            reflectance: Rgb::ZERO,
            emission: Rgb::ONE,
        };
        let corner = dvec3(-side / 2.0, -side / 2.0, height);
        add_parallelogram(&mut scene, "lamp", (corner, y * side, x * side), lamp);
        scene
    }

    /// What the display shows of a floor under a lamp (the smooth reading's RMS error and
    /// energy against the exact radiosity), unsplit and split.
    struct Shown {
        unsplit: (usize, f64, f64),
        split: (usize, f64, f64),
        /// Links before and after the split.
        links: (usize, usize),
    }

    /// `scene` (a [`floor_under_a_lamp`]) refined at a coarse knob, as the link budget leaves a
    /// large model's, solved, and shown as its leaves are and as split for the display.
    fn shown(scene: &Scene) -> Shown {
        let occluders = Occluders::new(scene);
        let (settings, solver) = (
            HierarchySettings {
                error: 0.5,
                ..HierarchySettings::default()
            },
            SolverSettings::default(),
        );
        let (rays, past) = (FormFactorSettings::default(), PastLinkBudget::Sampled);
        let no_progress = &crate::no_progress;
        let built = Hierarchy::build(
            scene,
            &occluders,
            (&settings, past),
            rays,
            &solver,
            no_progress,
        )
        .expect("gmres needs no entries");
        let mut hierarchy = built.hierarchy;
        let emission = hierarchy.leaf_emission();
        let radiosity = (hierarchy.solve(&emission, Some(&built.radiosity), &solver, no_progress))
            .expect("gmres needs no entries")
            .radiosity;
        let (links, lights) = (hierarchy.stats().links, BTreeSet::from([1]));
        let mesh = hierarchy.leaf_mesh();
        let gathered = CornerIndirect::Gathered;
        let seed = Seed::default();
        let light = CornerLight::new(
            scene,
            (&mesh, hierarchy.reached_corners()),
            &occluders,
            &lights,
            gathered,
            seed,
            &no_progress,
        );
        let unsplit = floor_error(scene, &hierarchy, &mesh, &radiosity, &light);
        let split = split_where_direct_light_curves(
            &mut hierarchy,
            radiosity,
            scene,
            &occluders,
            (&settings, seed),
            &lights,
            &no_progress,
        );
        let Displayed {
            mesh,
            radiosity,
            light,
        } = &split;
        Shown {
            unsplit,
            split: floor_error(scene, &hierarchy, mesh, radiosity, light),
            links: (links, hierarchy.stats().links),
        }
    }

    /// The leaves, and the smooth reading's RMS error and energy on a 32 x 32 grid of the floor
    /// against the exact radiosity, for the solution `radiosity` of `mesh` shown with `light`.
    fn floor_error(
        scene: &Scene,
        hierarchy: &Hierarchy,
        mesh: &Mesh,
        radiosity: &[Rgb],
        light: &CornerLight,
    ) -> (usize, f64, f64) {
        let emission = hierarchy.leaf_emission();
        let corners = light.linear_corner_radiosity(mesh, hierarchy, radiosity, &emission);
        let at = |i: usize| -4.0 + 8.0 * (i as f64 + 0.5) / 32.0;
        let grid = (0..32 * 32).map(|k| dvec3(at(k % 32), at(k / 32), 0.0));
        let probes = probes_under_a_lamp(grid, DVec3::Z, &scene.faces[1].polygon);
        let error = evaluate(scene, mesh, radiosity, &corners, &probes);
        (mesh.patches.len(), error.smooth.rms, error.smooth.energy)
    }

    #[test]
    fn leaves_split_for_the_display_show_a_lamps_peak_with_no_new_link() {
        // A 1 x 1 lamp 2 above the floor: its direct light is a peak across four coarse
        // leaves. Split where their centroids disagree with their corners, and their pieces
        // again where theirs still do, the floor shows the peak's shape, against Lambert's
        // exact factor at each of 1,024 points: RMS 38.8% -> 7.0%, energy -4.8% -> -0.05%
        // (one generation of splits alone: 17 leaves, 14.9%, -0.6%).
        let shown = shown(&floor_under_a_lamp(1.0, 2.0));
        let (unsplit, split) = (shown.unsplit, shown.split);
        println!(
            "(leaves, RMS, energy) {unsplit:?} -> {split:?}, links {:?}",
            shown.links
        );
        assert_eq!(shown.links.0, shown.links.1, "the display adds no link");
        let floor_leaves = unsplit.0 - 1;
        let split_once = unsplit.0 + 3 * floor_leaves;
        assert!(
            split.0 > split_once,
            "{} leaves: pieces split again",
            split.0
        );
        assert!(split.1 < 0.25 * unsplit.1, "{split:?} against {unsplit:?}");
        assert!(split.2.abs() < 0.01, "energy {:+}", split.2);
    }

    #[test]
    fn nothing_is_split_where_the_direct_light_is_flat() {
        // Under a lamp a thousand times the floor's size, just above it, the floor's factor is
        // one but for round-off: no leaf's corners miss anything, so none is split (and the
        // gather made to decide is the one kept), and what viewers see is exact.
        let shown = shown(&floor_under_a_lamp(8000.0, 0.5));
        println!(
            "(leaves, RMS, energy) {:?} -> {:?}",
            shown.unsplit, shown.split
        );
        assert_eq!(shown.split, shown.unsplit);
        assert!(shown.split.1 < 1e-3, "{:?}", shown.split);
    }
}
