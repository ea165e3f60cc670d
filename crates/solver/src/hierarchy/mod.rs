//! Hierarchical radiosity with clustering: light moves along links between elements at the
//! level where the transfer is accurate enough, instead of through n^2 form factors on a
//! uniform mesh. The leaves of the element trees are the patches the server streams.
//!
//! - **Elements** (Hanrahan, Salzman, Aupperle 1991, "A Rapid Hierarchical Radiosity
//!   Algorithm"): each input face roots a quadtree (a quad into four quads, a triangle into four
//!   similar triangles; a long element in two, across its length), split only when a link asks
//!   for it.
//! - **Clusters** (Smits, Arvo, Greenberg 1994; Sillion 1995): a binary tree of median splits
//!   over the input faces sits above them, so refinement starts from one self-link of the root,
//!   not from faces^2 links: a face gathers from whole clusters while they are far enough. A
//!   cluster link carries a sampled factor, by reciprocity from the cluster's side (its points'
//!   analytic factors onto the receiving element, each bounded). Clusters only send: a receiving
//!   cluster would hand its irradiance to faces that cannot see the source.
//! - **Refinement** (BF with visibility): a link is kept when the radiosity error it can carry,
//!   `rho_R (B_S dF + F dB_S)`, is within the tolerance. `dF` is the spread of the factor over
//!   the receiver, kernel and visibility both (a bound, for a cluster), so partial occlusion
//!   refines while full visibility and full occlusion do not. Between elements the receiver
//!   splits for `dF` and the source for `dB_S`; with a cluster, the larger end splits.
//!   Refinement runs again on each new solution until no link changes. It is one pass: a
//!   generation of decisions that would pass a budget is decided again at a coarser knob (twice
//!   it for the leaf budget; for the link budget, the factor its pairs' errors say fits) and
//!   refinement goes on from there, keeping what is refined (no attempt is thrown away).
//! - **Visibility**: a shaft between the two elements (Haines, Wallace 1994, "Shaft Culling for
//!   Efficient Ray-Cast Radiosity") collects the faces that can block. None: clear, no rays. One
//!   face that separates the two and covers every segment between them: hidden, no rays. Else
//!   shadow rays.
//! - **Reach**: a point every cosine ray from which meets a back face (under a box on the
//!   floor, inside a wall through it) is buried; sources send their mean over the area light
//!   reaches, an element's gathered light is pushed down to its reached parts only, and a leaf
//!   that straddles the reach's edge (faces of real models pass through one another: its test
//!   points disagree, or a face crosses it between them) splits to the finest element after
//!   each refinement.
//! - **Solving**: pull (area-weighted means up the trees), gather along links, push (sums down
//!   to the leaves) is a linear operator on the leaves, so it is a [`Transport`] and the same
//!   GMRES and Jacobi solve it. No dense matrix anywhere: memory is O(elements + links).
//!
//! Files own their data: [`tree`] the trees ([`tree::Tree`]), [`reach`] how much of each node
//! light reaches ([`reach::Reach`]), [`shaft`] the blockers between a pair (a function of the
//! tree), [`factor`] a link's factor ([`factor::LinkFactors`]), [`refine`] the link decisions
//! ([`refine::Decider`], which holds the factors), the budgets and the splits that grow the
//! tree and the links; [`operator`] pull-gather-push on the leaves (the links indexed by
//! receiver, the row scales and slopes). This file holds the public API, the budget loop and
//! the refinement rounds; [`Hierarchy`] is the tree, its reach and its links together.

mod factor;
mod operator;
mod reach;
mod refine;
mod shaft;
mod tree;

#[cfg(test)]
pub(crate) mod fixtures;

use crate::Progress;
use crate::mesh::Mesh;
use crate::pair::FormFactorSettings;
use crate::scene::{Rgb, Scene};
use crate::solve::{NeedsEntries, SolveOutcome, SolverSettings, System, solve};
use crate::visibility::Occluders;
use operator::{Incoming, Slope};
use rayon::prelude::*;
use reach::Reach;
use refine::{Budget, Fineness, Pass};
use tree::Tree;

/// The one accuracy knob of the hierarchical path, and the budget that bounds its memory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HierarchySettings {
    /// Relative error: links are refined until `rho_R (B_S dF + F dB_S)` is at most `error`
    /// times the scene's mean reflected radiosity, and elements stop splitting at
    /// [`MIN_RADIUS_PER_ERROR`] `* error` times their input face's radius, capped at the
    /// scene's median face radius.
    pub error: f64,
    /// Refinement-and-solve rounds at most (each refines on the newest solution).
    pub max_rounds: usize,
    /// Leaves at most. A generation of link decisions that would pass it is decided again at
    /// twice the knob, and refinement goes on at that knob (the last one is reported as
    /// [`HierarchyStats::knob_used`]); past a knob of 0.5, elements stop splitting instead
    /// ([`HierarchyStats::leaf_budget_reached`]). It also sets the smallest element
    /// ([`refine::finest_radius`]). A leaf costs about 2.3 KB with the ten or so links a room
    /// scene gives it, so the default stays near 1.2 GB on a model of up to 250k faces.
    pub max_leaves: usize,
    /// Leaves a face of the scene the budget allows where that is more than `max_leaves`
    /// ([`HierarchySettings::fitted_to`]); 0 where `max_leaves` was asked for and holds as it
    /// is.
    pub leaves_per_face: usize,
    /// Links at most, about: the bound on memory where links per leaf run high (a model of many
    /// small faces made 85 a leaf, 4.1 GB at 354k leaves). Passing it coarsens the knob at once
    /// by the least power of two at which the generation's pairs, by their errors, fit; past
    /// 0.5 no pair splits further ([`HierarchyStats::link_budget_reached`]), so the last
    /// generation of pairs may add to it. About 250 bytes a link, all told
    /// (docs/BENCHMARKS.md).
    pub max_links: usize,
}

impl Default for HierarchySettings {
    fn default() -> Self {
        HierarchySettings {
            error: 0.03,
            max_rounds: 4,
            max_leaves: 500_000,
            leaves_per_face: LEAVES_PER_FACE,
            max_links: 10_000_000,
        }
    }
}

/// Leaves a face the default leaf budget allows on a model of more faces than its 500k leaves
/// allow for: each face starts as a leaf, so a budget of fewer leaves than faces stopped every
/// split, and the large faces among a million small ones stayed whole (a village of eight
/// monasteries, 1.01M faces: 13.5% smooth RMS at 500k, 6.2% at two a face; three a face read
/// the same 25% slower, docs/BENCHMARKS.md).
pub const LEAVES_PER_FACE: usize = 2;

/// Smallest element radius, as a fraction of `error` times its input face's radius capped at
/// the median face radius ([`smallest_scale`]; relative to geometry, so that a lamp far above
/// a floor does not coarsen the floor's shadows). Chosen by measurement on the Cornell box and
/// the shadow slab before the cap (docs/BENCHMARKS.md): 0.5 spent most leaves on contact lines
/// for little RMS; 2 left contact lines and shadow edges too coarse.
pub const MIN_RADIUS_PER_ERROR: f64 = 1.0;

/// What refinement does with the pairs still to decide once splitting them would pass the
/// link budget ([`HierarchySettings::max_links`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PastLinkBudget {
    /// Each is kept as it is, on a coarsely sampled factor, or dropped: the leaves' own system
    /// carries their light, for a display that reads it.
    Sampled,
    /// Each is left undecided: for a display whose corners gather every bounce themselves,
    /// which reads the leaves' system only as where their last bounces' solve starts. Deciding
    /// them was the monastery's last generation of refinement (11.6M pairs, 1.3M kept): 6 of
    /// its 41 s, for the same shown error to 0.001 points (docs/BENCHMARKS.md). A later step
    /// under a larger budget decides them first.
    Deferred,
}

/// A kept link: `receiver` gathers `factor * B(source)`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Link {
    receiver: u32,
    source: u32,
    /// The form factor, visibility included (a sampled estimate when a cluster takes part).
    factor: f32,
    /// The factor's possible spread over the receiver (see the module notes), kept so that a
    /// new solution can re-check the link without integrating it again.
    spread: f32,
    /// Where on the source the transfer is centred: the kernel-weighted mean of the source
    /// points the receiver sees, from the source's centroid, in the source's tangent frame. The
    /// link gathers the source's linear radiosity model there, not its mean.
    offset: [f32; 2],
}

/// A pair refinement decides: may `receiver` gather from `source`, and through which link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Pair {
    receiver: u32,
    source: u32,
    /// A shaft between elements holding these two found no face that could block a segment
    /// between them; pieces of a planar element lie within it, so none can block theirs.
    clear: bool,
}

impl Pair {
    /// A pair whose visibility nothing has shown yet.
    fn new(receiver: u32, source: u32) -> Pair {
        Pair {
            receiver,
            source,
            clear: false,
        }
    }
}

/// What refinement and solving cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct HierarchyStats {
    /// Leaf elements: the patches of the solution.
    pub elements: usize,
    /// Links kept.
    pub links: usize,
    /// Cluster nodes above the input faces.
    pub clusters: usize,
    /// Refinement-and-solve rounds run.
    pub rounds: usize,
    /// Links whose visibility a shaft decided without rays (clear or hidden; clear too where
    /// the pair's parent was).
    pub shaft_decided: u64,
    /// Shadow rays cast.
    #[serde(skip)]
    pub rays: u64,
    /// Solver iterations spent in the rounds before the final solve.
    pub refinement_iterations: usize,
    /// The error knob refinement ended at: the one asked for, or the coarser one it went on
    /// at when a generation would have passed a budget (the generations before it were
    /// decided at the finer knobs).
    pub knob_used: f64,
    /// Whether elements stopped splitting at [`HierarchySettings::max_leaves`] even at the
    /// coarsest knob tried, leaving some links coarser than it asks.
    pub leaf_budget_reached: bool,
    /// Whether links stopped splitting at [`HierarchySettings::max_links`] even at the coarsest
    /// knob tried.
    pub link_budget_reached: bool,
    /// Pairs left undecided there ([`PastLinkBudget::Deferred`]).
    pub deferred_pairs: usize,
}

/// The element and cluster trees of a scene, their links, and the link operator on the leaves.
pub struct Hierarchy {
    /// The cluster tree and the element quadtrees, their leaves the patches.
    tree: Tree,
    /// How much of each node light can reach.
    reach: Reach,
    /// Whether each input face's view is closed (its leaves' rows are normalised to one).
    face_closed: Vec<bool>,
    links: Vec<Link>,
    /// Links by receiver: `incoming[offsets[n]..offsets[n + 1]]` are node `n`'s.
    offsets: Vec<u32>,
    incoming: Vec<Incoming>,
    /// Per leaf, the factor its gathered irradiance is multiplied by (1, or 1/row sum).
    row_scale: Vec<f64>,
    /// Per element node, its linear radiosity model's weights ([`Hierarchy::slopes_of`]).
    slopes: Vec<Slope>,
    stats: HierarchyStats,
    /// What refinement does past the link budget.
    past_link_budget: PastLinkBudget,
    /// The pairs it left undecided there ([`PastLinkBudget::Deferred`]).
    deferred: Vec<Pair>,
}

impl Hierarchy {
    /// The cluster tree over `scene`'s faces, each face one unsplit element; no links yet.
    pub(super) fn cluster_tree(scene: &Scene) -> Hierarchy {
        let tree = Tree::over(scene);
        let clusters = tree.nodes.iter().filter(|n| n.element.is_none()).count();
        Hierarchy {
            face_closed: vec![false; tree.face_node.len()],
            tree,
            reach: Reach::default(),
            links: Vec::new(),
            offsets: Vec::new(),
            incoming: Vec::new(),
            row_scale: Vec::new(),
            slopes: Vec::new(),
            stats: HierarchyStats {
                clusters,
                ..HierarchyStats::default()
            },
            past_link_budget: PastLinkBudget::Sampled,
            deferred: Vec::new(),
        }
    }

    /// The leaves as a mesh: face by face, corners shared between the leaves of a face, but
    /// not across the edge of where light reaches ([`tree::Tree::leaf_mesh`]).
    pub fn leaf_mesh(&self) -> Mesh {
        self.tree
            .leaf_mesh(|leaf, corner| !self.reaches_corner(leaf, corner))
    }

    /// Per leaf (as [`Hierarchy::leaf_mesh`] lists them) and corner, whether light reaches
    /// where that corner's light is read: the sides the mesh keeps corners apart by, for
    /// viewers' corners to read light only where the mesh says it reaches.
    pub fn reached_corners(&self) -> Vec<[bool; 4]> {
        (self.tree.leaves.iter())
            .map(|&leaf| std::array::from_fn(|corner| self.reaches_corner(leaf, corner)))
            .collect()
    }

    /// Whether light reaches `leaf`'s `corner`: the leaf is not buried whole, nor the corner's
    /// reading point ([`reach::Reach::buried_corners`]).
    fn reaches_corner(&self, leaf: u32, corner: usize) -> bool {
        self.reach.seen_share[leaf as usize] != 0.0
            && !self.reach.buried_corners[leaf as usize][corner]
    }

    /// What refinement and solving cost so far.
    pub fn stats(&self) -> HierarchyStats {
        self.stats
    }

    /// Rebuilds the leaf list, the reached areas and the link operator: how the tests index
    /// the hierarchies they build by hand ([`Hierarchy::build`] has measured its leaves first).
    #[cfg(test)]
    fn index(&mut self, occluders: &Occluders) {
        self.tree.collect_leaves();
        self.reach.measure(&self.tree, occluders);
        self.index_links_and_slopes();
    }

    /// Splits the leaves that straddle the edge of where light reaches (a wall cutting through
    /// a floor, a roof running into a gable: real models are full of faces that pass through
    /// one another), until their pieces are buried or reached whole or reach the smallest
    /// element (`finest_radius`), within `max_leaves`; then indexes the tree. That edge is a
    /// discontinuity of the light as sharp as a contact line (Heckbert 1992): straddled, a
    /// leaf's corners inside the wall read dark and interpolation darkened the open part of it
    /// (on the monastery, roof slivers 25 m long read half their light).
    fn split_where_reach_ends(
        &mut self,
        occluders: &Occluders,
        finest_radius: f64,
        max_leaves: usize,
    ) {
        self.tree.collect_leaves();
        let unmeasured = self.reach.unmeasured(&self.tree);
        self.reach
            .measure_leaves(&self.tree, &unmeasured, occluders);
        // Each round splits every straddling leaf it may, so only the pieces it made can
        // straddle in the next: they alone are measured and looked at, and the leaves are
        // listed again (where a round split some) and their reached areas summed once, at
        // the end.
        let listed = self.tree.leaves.len();
        let (mut candidates, mut leaf_count) = (self.tree.leaves.clone(), listed);
        loop {
            let straddling: Vec<u32> = (candidates.into_iter())
                .filter(|&n| {
                    self.reach.straddles[n as usize]
                        && refine::can_split_to(&self.tree.nodes[n as usize], finest_radius)
                })
                .collect();
            let added: usize = (straddling.iter())
                .map(|&n| self.tree.children_if_split(n) - 1)
                .sum();
            if straddling.is_empty() || leaf_count + added > max_leaves {
                break;
            }
            let first_piece = self.tree.nodes.len() as u32;
            for n in straddling {
                self.tree.subdivide(n);
            }
            leaf_count += added;
            candidates = (first_piece..self.tree.nodes.len() as u32).collect();
            self.reach
                .measure_leaves(&self.tree, &candidates, occluders);
        }
        if leaf_count != listed {
            self.tree.collect_leaves();
        }
        self.reach.sum_reached_area(&self.tree);
        self.index_links_and_slopes();
    }

    /// Whether the `i`-th leaf (as [`Hierarchy::leaf_mesh`] lists them) is larger than the
    /// smallest element, of radius `finest_radius` ([`finest_radius`]).
    pub fn can_split_leaf(&self, i: usize, finest_radius: f64) -> bool {
        refine::can_split_to(
            &self.tree.nodes[self.tree.leaves[i] as usize],
            finest_radius,
        )
    }

    /// How many leaves splitting the `i`-th leaf (as [`Hierarchy::leaf_mesh`] lists them)
    /// adds: three, or one where it is long and splits across its length.
    pub fn leaves_added_by_splitting(&self, i: usize) -> usize {
        self.tree.children_if_split(self.tree.leaves[i]) - 1
    }

    /// Splits the leaves `chosen` (their indices, as [`Hierarchy::leaf_mesh`] lists them) for
    /// what viewers see alone: no link changes, so each piece receives what its parent's links
    /// bring, pushed down, and the solution keeps its light and its links; viewers get corners
    /// where the light across a leaf needs them. Pieces that straddle the edge of where light
    /// reaches split on as refinement's do, to `finest_radius` within `max_leaves`. Returns
    /// `radiosity` (per leaf) carried to the new leaves.
    pub fn split_for_display(
        &mut self,
        chosen: &[usize],
        radiosity: &[Rgb],
        occluders: &Occluders,
        finest_radius: f64,
        max_leaves: usize,
    ) -> Vec<Rgb> {
        let (before, inherited) = (self.tree.nodes.len(), self.pull(radiosity));
        for &i in chosen {
            self.tree.subdivide(self.tree.leaves[i]);
        }
        self.split_where_reach_ends(occluders, finest_radius, max_leaves);
        self.inherit(inherited, before)
    }

    /// The mean reflected radiosity (largest channel) over the area light reaches, W/m^2, of
    /// the solution `radiosity` (per leaf): the scale relative errors are measured against.
    pub fn mean_reflected(&self, radiosity: &[Rgb]) -> f64 {
        self.reach.mean_reflected(&self.tree, radiosity)
    }

    /// Rebuilds the link operator (and the stats) on the leaves as listed and measured.
    fn index_links_and_slopes(&mut self) {
        // A link decided before one of its ends was measured buried.
        let reach = &self.reach;
        (self.links).retain(|l| reach.reaches_both(l.receiver, l.source));
        self.fit_slopes();
        self.index_links();
        self.stats.elements = self.tree.leaves.len();
        self.stats.links = self.links.len();
    }

    /// Solves for the leaves' `emission` (one per leaf) from `initial`.
    pub fn solve(
        &self,
        emission: &[Rgb],
        initial: Option<&[Rgb]>,
        settings: &SolverSettings,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<SolveOutcome, NeedsEntries> {
        let reflectance: Vec<Rgb> = (0..self.tree.leaves.len())
            .map(|i| self.tree.leaf_patch(i).reflectance)
            .collect();
        let area: Vec<f64> = (0..self.tree.leaves.len())
            .map(|i| self.tree.leaf_patch(i).area)
            .collect();
        solve(
            self,
            &System {
                reflectance: &reflectance,
                emission,
                area: &area,
            },
            settings,
            initial,
            progress,
        )
    }

    /// The leaves' emission, W/m^2.
    pub fn leaf_emission(&self) -> Vec<Rgb> {
        (0..self.tree.leaves.len())
            .map(|i| self.tree.leaf_patch(i).emission)
            .collect()
    }

    /// Builds the hierarchy of `scene`: refines on an estimate, then, up to
    /// `settings.max_rounds` times, solves and refines the links the solution shows too coarse,
    /// treating pairs past the link budget as `past_link_budget` says (this build and every
    /// later refinement of it). Returns it with the last solution carried to its leaves, to
    /// start the final solve from.
    pub fn build(
        scene: &Scene,
        occluders: &Occluders,
        (settings, past_link_budget): (&HierarchySettings, PastLinkBudget),
        rays: FormFactorSettings,
        solver: &SolverSettings,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<BuiltHierarchy, NeedsEntries> {
        let name = format!("cluster tree over {} faces", scene.faces.len());
        progress(Progress::Stage { name: &name });
        let run = Rounds::new(scene, occluders, settings, rays, solver, progress);
        let mut unrefined = Hierarchy::cluster_tree(scene);
        unrefined.reach = Reach::spaced(run.finest_radius * REACH_TEST_SPACING);
        unrefined.past_link_budget = past_link_budget;
        unrefined.tree.collect_leaves();
        progress(Progress::Stage {
            name: "where light reaches: buried points and closed views",
        });
        unrefined.reach.measure(&unrefined.tree, occluders);
        // A face light reaches nowhere (a beam's end cut off inside a wall) gathers nothing:
        // its view is closed, to no share, without the closure's rays, each of which would
        // test its origin's burial (on the monastery's cut faces, 8% of the CPU).
        unrefined.face_closed = (unrefined.tree.face_node.par_iter().enumerate())
            .map(|(face, &n)| {
                unrefined.reach.seen_share[n as usize] == 0.0
                    || occluders
                        .closed_view_share(unrefined.tree.element_patch(n), face)
                        .is_some()
            })
            .collect();
        // The leaves are collected and measured above: only the link operator is left.
        unrefined.index_links_and_slopes();
        run.refine(unrefined, settings.error, settings.budget(), None)
    }

    /// Refines this hierarchy of `scene` further, at the finer error `knob` (the rest of
    /// `settings` as it was built with): the links that `radiosity` (solved, one value per
    /// leaf) shows too coarse for it, then round after round on each new solution, as
    /// [`Hierarchy::build`] does. Nothing is thrown away. Returns the hierarchy with its last
    /// solution on its (new) leaves.
    #[allow(clippy::too_many_arguments)]
    pub fn refine_further(
        self,
        scene: &Scene,
        occluders: &Occluders,
        settings: &HierarchySettings,
        rays: FormFactorSettings,
        solver: &SolverSettings,
        (knob, radiosity): (f64, Vec<Rgb>),
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<BuiltHierarchy, NeedsEntries> {
        let run = Rounds::new(scene, occluders, settings, rays, solver, progress);
        run.refine(self, knob, settings.budget(), Some(radiosity))
    }

    /// Lets refinement go on past the link budget it stopped at, `max_links` now: the links
    /// kept there, each on a coarse factor, are decided again in the next round, and the pairs
    /// left undecided there decided.
    pub fn raise_link_budget(&mut self, max_links: usize) {
        if self.links.len() < max_links {
            self.stats.link_budget_reached = false;
        }
    }

    /// Whether a finer knob could change anything: neither budget has stopped refinement.
    pub fn can_refine_further(&self) -> bool {
        !(self.stats.leaf_budget_reached || self.stats.link_budget_reached)
    }
}

impl HierarchySettings {
    /// These settings with the leaf budget fitted to `scene`: [`HierarchySettings::max_leaves`]
    /// or [`HierarchySettings::leaves_per_face`] a face, whichever is more.
    pub fn fitted_to(self, scene: &Scene) -> HierarchySettings {
        let per_face = self.leaves_per_face.saturating_mul(scene.faces.len());
        HierarchySettings {
            max_leaves: self.max_leaves.max(per_face),
            ..self
        }
    }

    fn budget(&self) -> Budget {
        Budget {
            max_leaves: self.max_leaves,
            max_links: self.max_links,
        }
    }
}

/// A refined hierarchy and the last solution of its refinement rounds, one value per leaf.
pub struct BuiltHierarchy {
    /// The elements, clusters and links.
    pub hierarchy: Hierarchy,
    /// Radiosity per leaf, W/m^2: a start for the final solve.
    pub radiosity: Vec<Rgb>,
}

/// What every refinement attempt of one build shares.
struct Rounds<'a> {
    occluders: &'a Occluders,
    rays: FormFactorSettings,
    solver: &'a SolverSettings,
    progress: &'a (dyn Fn(Progress) + Sync),
    max_rounds: usize,
    /// The ambient radiosity of the first estimate ([`ambient_estimate`]).
    estimate: Rgb,
    /// The smallest element radius the leaf budget affords ([`refine::finest_radius`]).
    finest_radius: f64,
}

impl<'a> Rounds<'a> {
    fn new(
        scene: &Scene,
        occluders: &'a Occluders,
        settings: &HierarchySettings,
        rays: FormFactorSettings,
        solver: &'a SolverSettings,
        progress: &'a (dyn Fn(Progress) + Sync),
    ) -> Self {
        Rounds {
            occluders,
            rays,
            solver,
            progress,
            max_rounds: settings.max_rounds,
            estimate: ambient_estimate(scene),
            finest_radius: finest_radius(scene, settings.max_leaves),
        }
    }

    /// Refines `hierarchy` (indexed) at error `knob`, coarser where `budget` asks for it:
    /// unrefined, first on the ambient estimate; refined already, on its `solved` radiosity;
    /// then on each new solution until no link needs refining or the rounds run out.
    fn refine(
        &self,
        mut hierarchy: Hierarchy,
        mut knob: f64,
        budget: Budget,
        solved: Option<Vec<Rgb>>,
    ) -> Result<BuiltHierarchy, NeedsEntries> {
        let resumed = solved.is_some();
        let mut radiosity: Vec<Rgb> = solved.unwrap_or_else(|| {
            (0..hierarchy.tree.leaves.len())
                .map(|i| {
                    let patch = hierarchy.tree.leaf_patch(i);
                    patch.emission + patch.reflectance * self.estimate
                })
                .collect()
        });
        let mut pending = if hierarchy.tree.nodes.is_empty() || resumed {
            Vec::new()
        } else {
            vec![Pair::new(0, 0)]
        };
        for round in 0..self.max_rounds.max(1) {
            // Past the link budget no pair splits: another round could change no link.
            let on_links = round > 0 || resumed;
            if on_links && hierarchy.stats.link_budget_reached {
                break;
            }
            if round > 0 {
                let solved = hierarchy.solve(
                    &hierarchy.leaf_emission(),
                    Some(&radiosity),
                    self.solver,
                    self.progress,
                )?;
                hierarchy.stats.refinement_iterations += solved.iterations;
                radiosity = solved.radiosity;
            }
            let sources = hierarchy.node_radiosity(&radiosity);
            let mut target = Fineness {
                tolerance: knob * hierarchy.reach.mean_reflected(&hierarchy.tree, &radiosity),
                smallest: MIN_RADIUS_PER_ERROR * knob,
                finest_radius: self.finest_radius,
            };
            if on_links {
                pending = hierarchy.take_links_to_redo(&sources, &target);
                pending.append(&mut hierarchy.deferred);
                hierarchy.stats.deferred_pairs = 0;
                if pending.is_empty() {
                    break;
                }
            }
            let (before, inherited) = (hierarchy.tree.nodes.len(), hierarchy.pull(&radiosity));
            let mut pass = Pass {
                budget,
                knob,
                round,
                leaves: hierarchy.tree.leaves.len(),
                last_overshoot: None,
                progress: self.progress,
            };
            hierarchy.refine(
                sources,
                &mut target,
                self.occluders,
                self.rays,
                std::mem::take(&mut pending),
                &mut pass,
            );
            knob = pass.knob;
            hierarchy.stats.rounds += 1;
            hierarchy.split_where_reach_ends(self.occluders, self.finest_radius, budget.max_leaves);
            radiosity = hierarchy.inherit(inherited, before);
        }
        hierarchy.stats.knob_used = knob;
        Ok(BuiltHierarchy {
            hierarchy,
            radiosity,
        })
    }
}

/// How far apart a large leaf's burial test points lie, in finest radii ([`finest_radius`],
/// [`Reach::spaced`]); a leaf up to this radius is tested at one quadrature cell's points.
/// Measured (docs/BENCHMARKS.md): the monastery over six seeds of its gathers read 3.47-4.21%
/// smooth RMS (mean 3.72%) against 3.57-5.19% (3.91%) at one cell a leaf (its ground under a
/// platform no longer lit at any seed), 2% more leaves, the burial test in the same time.
const REACH_TEST_SPACING: f64 = 8.0;

/// The smallest element radius the leaf budget `max_leaves` affords everywhere in `scene`
/// ([`refine::finest_radius`]).
pub fn finest_radius(scene: &Scene, max_leaves: usize) -> f64 {
    refine::finest_radius(receiving_area(scene), max_leaves)
}

/// The area of the faces that reflect light, scene units squared.
pub(super) fn receiving_area(scene: &Scene) -> f64 {
    scene
        .faces
        .iter()
        .filter(|f| f.reflectance.max_element() > 0.0)
        .map(|f| f.polygon.area())
        .sum()
}

/// The first estimate's ambient radiosity (Cohen, Chen, Wallace, Greenberg 1988): the emitted
/// power spread over all area, reflected by the mean reflectance; each leaf starts at its
/// emission plus its reflectance times this.
fn ambient_estimate(scene: &Scene) -> Rgb {
    let (mut power, mut reflected, mut total_area) = (Rgb::ZERO, Rgb::ZERO, 0.0);
    for f in &scene.faces {
        let a = f.polygon.area();
        (power, reflected, total_area) = (
            power + f.emission * a,
            reflected + f.reflectance * a,
            total_area + a,
        );
    }
    let total_area = total_area.max(f64::MIN_POSITIVE);
    power / (total_area * (Rgb::ONE - reflected / total_area).max(Rgb::splat(1e-3)))
}

#[cfg(test)]
mod tests {
    use super::fixtures::closed_cube;
    use super::*;

    /// Builds at `error` within `max_leaves`; returns the stats and every progress line but
    /// the estimates, in order.
    fn build_with(scene: &Scene, error: f64, max_leaves: usize) -> (HierarchyStats, Vec<String>) {
        build_within(
            scene,
            HierarchySettings {
                error,
                max_leaves,
                ..HierarchySettings::default()
            },
        )
    }

    fn build_within(scene: &Scene, settings: HierarchySettings) -> (HierarchyStats, Vec<String>) {
        let occluders = Occluders::new(scene);
        let rays = FormFactorSettings::default();
        let solver = SolverSettings::default();
        let lines = std::sync::Mutex::new(Vec::new());
        let progress = |p: Progress| {
            if let (Some(line), false) = (p.describe(), matches!(p, Progress::Solve { .. })) {
                lines.lock().unwrap().push(line);
            }
        };
        let past_link_budget = PastLinkBudget::Sampled;
        let stats = Hierarchy::build(
            scene,
            &occluders,
            (&settings, past_link_budget),
            rays,
            &solver,
            &progress,
        )
        .expect("gmres needs no entries")
        .hierarchy
        .stats();
        (stats, lines.into_inner().unwrap())
    }

    /// The progress lines that coarsen the knob.
    fn coarsenings(lines: &[String]) -> Vec<String> {
        lines
            .iter()
            .filter(|l| l.contains("going on at"))
            .cloned()
            .collect()
    }

    /// What coarsening from `from` to each of `to` in turn says when `limit` forces it.
    fn said_coarsenings(limit: &str, from: f64, to: &[f64]) -> Vec<String> {
        let mut knob = from;
        to.iter()
            .map(|&next| {
                let line =
                    format!("refinement at error {knob} would pass {limit}: going on at {next}");
                knob = next;
                line
            })
            .collect()
    }

    #[test]
    fn the_knob_asked_for_is_used_when_its_leaves_fit() {
        let (stats, lines) = build_with(&closed_cube(), 0.1, 1_000_000);
        assert_eq!(stats.knob_used, 0.1);
        // Refinement says where it is, ending on what it built.
        let last = lines.last().expect("progress lines");
        assert!(
            last.starts_with("refining at error 0.1: round ")
                && last.contains(&format!(" {} links, 0 pairs to decide", stats.links)),
            "{lines:?}"
        );
        assert!(!stats.leaf_budget_reached);
        assert!(
            stats.elements > 6,
            "the cube's edges refine: {}",
            stats.elements
        );
    }

    #[test]
    fn a_budget_of_as_many_leaves_as_faces_splits_none_unless_it_follows_the_faces() {
        let cube = closed_cube();
        let faces = cube.faces.len();
        let asked = HierarchySettings {
            error: 0.1,
            max_leaves: faces,
            leaves_per_face: 0,
            ..HierarchySettings::default()
        };
        assert_eq!(asked.fitted_to(&cube), asked);
        // No room for a split: the knob coarsens until whole faces carry every link.
        let (held, _) = build_within(&cube, asked);
        assert_eq!((held.elements, held.knob_used), (faces, 0.8));
        let following = HierarchySettings {
            leaves_per_face: 4,
            ..asked
        }
        .fitted_to(&cube);
        assert_eq!(following.max_leaves, 4 * faces);
        let (split, _) = build_within(&cube, following);
        assert!(
            split.elements > faces && split.elements <= 4 * faces,
            "{} leaves",
            split.elements
        );
    }

    #[test]
    fn a_tight_leaf_budget_doubles_the_knob_until_the_leaves_fit() {
        // Six faces and room for no split: 0.1 and 0.2 split every face (a wall's factor to
        // its neighbour runs from near 0 at the far edge to 1/2 along the shared one), so
        // doubling did not help and the next step goes to the coarsest knob at once; at 0.8
        // the unsplit faces carry every link within the knob. (Freezing when a split is still
        // asked for is checked on the Cornell box by the `radcast` tests.)
        let (stats, lines) = build_with(&closed_cube(), 0.1, 6);
        assert_eq!(stats.knob_used, 0.8);
        // Each coarsening is said when it happens, not only at the end.
        assert_eq!(
            coarsenings(&lines),
            said_coarsenings("6 leaves (--max-leaves)", 0.1, &[0.2, 0.8])
        );
        assert!(!stats.leaf_budget_reached);
        assert_eq!(stats.elements, 6);
        assert!(stats.links > 0);
    }

    #[test]
    fn a_tight_link_budget_coarsens_the_knob_then_stops_pairs_splitting() {
        let unbounded = build_with(&closed_cube(), 0.1, 1_000_000).0;
        let max_links = unbounded.links / 10;
        let (stats, lines) = build_within(
            &closed_cube(),
            HierarchySettings {
                error: 0.1,
                max_links,
                ..HierarchySettings::default()
            },
        );
        assert_eq!(
            coarsenings(&lines),
            said_coarsenings(
                &format!("{max_links} links (--max-links)"),
                0.1,
                &[0.2, 0.8]
            )
        );
        // A generation that would pass the budget is decided again, coarser: none finishes
        // with more links and pairs still to decide than the budget.
        for line in lines.iter().filter(|l| l.starts_with("refining")) {
            let words: Vec<&str> = line.split(' ').collect();
            let before = |word: &str| -> usize {
                let at = words.iter().position(|w| w.starts_with(word)).expect(word);
                words[at - 1].parse().expect("a count")
            };
            assert!(before("links") + before("pairs") <= max_links, "{line}");
        }
        // What the first generations split at 0.1 stays (nothing starts again); from 0.8 on
        // the rest fits the budget with no pair split past it.
        assert_eq!(stats.knob_used, 0.8);
        assert!(stats.links <= max_links, "{} links", stats.links);
        assert!(!stats.link_budget_reached);
        // From 0.5 on nothing coarser is tried: pairs stop splitting, each kept as it is.
        let room = super::fixtures::room_with_a_box();
        let free = build_with(&room, 0.5, 1_000_000).0;
        let (frozen, _) = build_within(
            &room,
            HierarchySettings {
                error: 0.5,
                max_links: 10,
                ..HierarchySettings::default()
            },
        );
        assert_eq!((frozen.knob_used, frozen.link_budget_reached), (0.5, true));
        assert!(
            frozen.links < free.links && frozen.elements <= free.elements,
            "{frozen:?} against {free:?}"
        );
    }
}
