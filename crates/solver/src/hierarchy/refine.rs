//! Refinement: each candidate link is kept, dropped, or split at the end whose splitting
//! reduces its error most (BF refinement with visibility), until every kept link carries at
//! most the tolerance; and the leaf budget that bounds how far it may go.

use super::factor::{
    CLUSTER_SAMPLING, Estimate, KEPT_PAST_BUDGET, LinkFactors, Rays, kernel_centre,
    tangent_coordinates,
};
use super::shaft::Visibility;
use super::tree::{MAX_DEPTH, Node};
use super::{Hierarchy, Link, Pair, PastLinkBudget};
use crate::pair::FormFactorSettings;
use crate::sampling::pair_seed;
use crate::scene::Rgb;
use crate::visibility::Occluders;
use crate::{Limit, Progress};
use rayon::prelude::*;

/// What refinement decided for one link. A split carries how many times the tolerance the
/// link's error is (infinite where the split is forced whatever the knob), so that a
/// generation that would pass a budget can tell which splits a coarser knob would keep.
#[derive(Clone)]
enum Decision {
    Drop,
    Keep(Link),
    /// Split one end: the link's error over the tolerance (`excess`); whether the pair's
    /// shaft was clear, which its children's pairs inherit.
    Split {
        end: End,
        excess: f32,
        clear: bool,
    },
    /// A cluster's self-link: every pair of its children.
    SplitBoth,
}

/// One end of a link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum End {
    Receiver,
    Source,
}

impl Pair {
    /// The node at `end`.
    fn at(self, end: End) -> u32 {
        match end {
            End::Receiver => self.receiver,
            End::Source => self.source,
        }
    }

    /// This pair with `node` at `end` instead.
    fn with(self, end: End, node: u32) -> Pair {
        match end {
            End::Receiver => Pair {
                receiver: node,
                ..self
            },
            End::Source => Pair {
                source: node,
                ..self
            },
        }
    }
}

/// Per node, what it sends as refinement sees it: the largest channel of its mean radiosity
/// and the spread of that over its leaves, W/m^2.
#[derive(Default)]
pub(super) struct NodeRadiosity {
    mean: Vec<f64>,
    spread: Vec<f64>,
}

impl NodeRadiosity {
    /// Node `n`'s (mean, spread).
    fn at(&self, n: u32) -> (f64, f64) {
        (self.mean[n as usize], self.spread[n as usize])
    }
}

/// How fine refinement goes.
#[derive(Clone, Copy)]
pub(super) struct Fineness {
    /// Largest radiosity error a link may carry, W/m^2.
    pub(super) tolerance: f64,
    /// Smallest element radius, as a fraction of its size scale.
    pub(super) smallest: f64,
    /// Smallest element radius, scene units, whatever the size scale ([`finest_radius`]).
    pub(super) finest_radius: f64,
}

impl Fineness {
    /// Whether node `n` may split: a cluster always, an element above the smallest size.
    fn can_split(&self, n: &Node) -> bool {
        n.element.as_ref().is_none_or(|e| {
            element_size(n) > (self.smallest * e.size_scale).max(self.finest_radius)
                && e.depth < MAX_DEPTH
        })
    }

    /// The same, with no element split once the leaf budget is `frozen`.
    fn frozen_if(self, frozen: bool) -> Fineness {
        Fineness {
            smallest: if frozen { f64::INFINITY } else { self.smallest },
            ..self
        }
    }
}

/// An element's size as refinement measures it: its bounding radius, or that of the equilateral
/// triangle of its area where that is smaller, `sqrt(4 A / (3 sqrt 3))`. The same for squares
/// and well-shaped triangles; a sliver counts as small as its area. By its length alone a
/// 4 m x 15 cm strip of a real model split into 1,024 leaves of 4 cm when elements split into
/// four like themselves, and such faces made most of its 490k leaves; split across their
/// length (`tree::SplitShape`), slivers still stop by their area: by length, the monastery
/// made 429k leaves instead of 310k and read 5.83% smooth RMS instead of 5.59%.
fn element_size(n: &Node) -> f64 {
    n.radius.min((4.0 * n.area / (3.0 * 3.0f64.sqrt())).sqrt())
}

/// Whether element `n` is above `finest_radius` ([`finest_radius`]) and may still split.
pub(super) fn can_split_to(n: &Node, finest_radius: f64) -> bool {
    n.element
        .as_ref()
        .is_some_and(|e| element_size(n) > finest_radius && e.depth < MAX_DEPTH)
}

/// The smallest element radius a leaf budget affords everywhere: that of a disc of the
/// receiving area's share per leaf, `sqrt(A / (pi max_leaves))`. Finer elements can only be
/// afforded in a small part of the scene, and on models of many small faces the size scale
/// (the median face) is centimetres under a ground of hundreds of metres: refined to it, the
/// shadow of a building on the ground alone passed the leaf budget at every knob.
pub(super) fn finest_radius(receiving_area: f64, max_leaves: usize) -> f64 {
    (receiving_area / (std::f64::consts::PI * max_leaves.max(1) as f64)).sqrt()
}

/// The most leaves and links refinement may make.
#[derive(Clone, Copy, Debug)]
pub(super) struct Budget {
    pub(super) max_leaves: usize,
    pub(super) max_links: usize,
}

/// One refinement pass: its budget, the knob it refines at (coarsened when a generation would
/// pass the budget), and where its progress goes after each generation of link decisions
/// ([`Progress::Refining`], tagged with the knob and round).
pub(super) struct Pass<'a> {
    pub(super) budget: Budget,
    pub(super) knob: f64,
    pub(super) round: usize,
    /// Leaves so far: the tree's, and those the generations decided since add.
    pub(super) leaves: usize,
    /// How far over the leaf budget this generation would have gone when it was last decided
    /// again (the ratio of what it would make to what is allowed), if it was.
    pub(super) last_overshoot: Option<f64>,
    pub(super) progress: &'a (dyn Fn(Progress) + Sync),
}

impl Pass<'_> {
    /// Whether a budget can still be met by coarsening: below a knob of 0.5 it doubles; from
    /// there elements and then pairs stop splitting instead.
    fn can_coarsen(&self) -> bool {
        2.0 * self.knob < 1.0
    }

    /// Coarsens the knob, and `target` with it, saying why: by the factor a link-budget
    /// `jump` names, or for the leaf budget by doubling, to the coarsest knob at once when the
    /// last doubling of the same generation cut its excess over the budget (the overshoot,
    /// what it would make over what is allowed, less one) by less than a quarter: what passes
    /// the budget then hardly depends on the knob, and each doubling would decide the
    /// generation again for little.
    fn coarsen(&mut self, target: &mut Fineness, limit: Limit, jump: Jump) {
        let factor = match jump {
            Jump::By(factor) => factor,
            Jump::Overshoot(overshoot) => {
                // Excess over the budget, before and after the last doubling of this generation.
                let futile = self
                    .last_overshoot
                    .is_some_and(|last| overshoot - 1.0 > 0.75 * (last - 1.0));
                self.last_overshoot = Some(overshoot);
                let mut factor = 2.0;
                while futile && 2.0 * factor * self.knob < 1.0 {
                    factor *= 2.0;
                }
                factor
            }
        };
        (self.progress)(Progress::Coarsening {
            knob: self.knob,
            next_knob: factor * self.knob,
            limit,
        });
        self.knob *= factor;
        target.tolerance *= factor;
        target.smallest *= factor;
    }
}

/// How far to coarsen the knob when a generation would pass a budget.
pub(super) enum Jump {
    /// The leaf budget, passed by this ratio (what the generation would make over what is
    /// allowed): doubling, unless the last doubling hardly helped.
    Overshoot(f64),
    /// The link budget: by this factor, from the errors of the pairs decided so far
    /// ([`Hierarchy::coarsening_to_fit`]): deciding the generation again at each doubling had
    /// cost the 125k-triangle monastery most of a minute.
    By(f64),
}

/// Read-only state for deciding links in parallel.
struct Decider<'a> {
    factors: LinkFactors<'a>,
    sources: &'a NodeRadiosity,
    /// How fine to refine (no element splits once the leaf budget froze them).
    target: Fineness,
}

impl Decision {
    /// Whether this split would be kept as one link at a knob `factor` times coarser: its
    /// error is within that many tolerances (never, for a forced split).
    fn kept_when_coarser_by(&self, factor: f64) -> bool {
        match *self {
            Decision::Split { excess, .. } => excess.is_finite() && excess as f64 <= factor,
            Decision::Keep(_) | Decision::Drop | Decision::SplitBoth => false,
        }
    }

    /// Whether this decision at one knob is the decision at any coarser one: a kept link
    /// carries no more error there, a dropped pair exchanges no light at any knob, and a
    /// forced split (of a cluster) is forced at every knob.
    fn stands_when_coarser(&self) -> bool {
        !self.kept_when_coarser_by(f64::INFINITY)
    }
}

impl Decider<'_> {
    /// The shadow rays a partly hidden pair needs, from its unoccluded `estimate`, or the
    /// split it gets whatever they would show. Occlusion only widens the factor's spread over
    /// the receiver (by the unoccluded factor times the spread of the visible share, at most
    /// one) and only lowers the factor: a receiver error the kernel alone puts over the
    /// tolerance splits the receiver with no rays, and a pair whose error stays within it
    /// even at the widest spread is kept, so a few rays for its factor do. Rays spent on pairs
    /// that went on to split, and on the spread of pairs kept anyway, were most of the cost on
    /// a real model (62% of the time in ray traversal, 69 rays a link).
    fn rays_for(
        &self,
        r: &Node,
        s: &Node,
        source: u32,
        estimate: &Estimate,
    ) -> Result<Rays, Decision> {
        let (factor, tolerance) = (estimate.factor, self.target.tolerance);
        let unoccluded = LinkErrors::new(r, self.sources.at(source), factor, estimate.spread);
        if unoccluded.receiver > tolerance
            && unoccluded.end_to_split(r, s, &self.target) == Some(End::Receiver)
        {
            let excess = (unoccluded.receiver + unoccluded.source) / tolerance;
            return Err(Decision::Split {
                end: End::Receiver,
                excess: excess as f32,
                clear: false,
            });
        }
        let widest = LinkErrors::new(r, self.sources.at(source), factor, estimate.spread + factor);
        if widest.receiver + widest.source > tolerance {
            return Ok(Rays::ForSpread);
        }
        Ok(Rays::ForFactor)
    }

    /// Keep, drop or split the link from `pair.source` to `pair.receiver`.
    fn decide(&self, pair: Pair) -> Decision {
        let (receiver, source) = (pair.receiver, pair.source);
        let (r, s) = (self.factors.node(receiver), self.factors.node(source));
        if receiver == source {
            return if r.element.is_none() {
                Decision::SplitBoth
            } else {
                Decision::Drop
            };
        }
        // An end light reaches nowhere: a face inside a solid it runs into, the floor under a box.
        if !self.factors.hierarchy.reach.reaches_both(receiver, source) {
            return Decision::Drop;
        }
        // Clusters gather nothing themselves: one that received would hand the same irradiance
        // to every face below it, including faces that cannot see the source (light leaked
        // through a wall whose two sides share a cluster). Links end at elements, and clusters
        // only send.
        if r.element.is_none() {
            return Decision::Split {
                end: End::Receiver,
                excess: f32::INFINITY,
                clear: false,
            };
        }
        let Some(mut estimate) = self.factors.estimate(pair) else {
            return Decision::Drop;
        };
        match estimate.visibility {
            Visibility::Hidden => return Decision::Drop,
            Visibility::Partial => match self.rays_for(r, s, source, &estimate) {
                Ok(rays) => {
                    estimate = self
                        .factors
                        .measure_visibility(receiver, source, estimate, rays)
                }
                Err(split) => return split,
            },
            Visibility::Clear | Visibility::Sampled => {}
        }
        let errors = LinkErrors::new(r, self.sources.at(source), estimate.factor, estimate.spread);
        let excess = ((errors.receiver + errors.source) / self.target.tolerance) as f32;
        if let Some(end) = errors.end_to_split(r, s, &self.target) {
            let clear = estimate.visibility == Visibility::Clear;
            return Decision::Split { end, excess, clear };
        }
        // A quarter of the link's error budget for its factor's quadrature: `rho_R B_S dF`.
        let (radiosity, _) = self.sources.at(source);
        let allowed = QUADRATURE_SHARE * self.target.tolerance / (r.reflectance * radiosity);
        // Past the link budget a pair is only kept or dropped: its factor sampled coarsely.
        let sampling = match self.target.tolerance.is_finite() {
            true => CLUSTER_SAMPLING,
            false => KEPT_PAST_BUDGET,
        };
        let factor = (self.factors).factor(receiver, source, &estimate, (allowed, sampling));
        if factor <= 0.0 {
            return Decision::Drop;
        }
        let offset = match (&s.element, estimate.visibility) {
            (Some(e), Visibility::Partial | Visibility::Clear) => {
                let centroid = estimate.centroid.unwrap_or_else(|| {
                    kernel_centre(
                        self.factors.hierarchy.tree.element_patch(receiver),
                        &e.patch,
                        pair_seed(receiver as usize, source as usize),
                    )
                });
                tangent_coordinates(&e.patch, centroid)
            }
            _ => [0.0; 2],
        };
        Decision::Keep(Link {
            receiver,
            source,
            factor: factor as f32,
            spread: estimate.spread as f32,
            offset,
        })
    }
}

/// The share of a link's error budget (the tolerance) its factor's quadrature may use.
const QUADRATURE_SHARE: f64 = 0.25;

/// Slices a generation of pairs is decided in while the link budget can abandon it.
const GENERATION_SLICES: usize = 16;
/// The fewest pairs in a slice: enough to keep every thread busy.
const MIN_SLICE: usize = 1 << 14;

impl Hierarchy {
    /// Links from `pending` pairs, refined until every kept one is accurate enough; the rays
    /// and shaft decisions are added to the stats. A generation of decisions that would pass
    /// the budget is decided again at a coarser knob (`run.knob`, `target`; [`Jump`]): what is
    /// already refined stays, finer than the new knob asks, and nothing starts again. Where the knob
    /// can no longer coarsen, elements stop splitting at the leaf budget and pairs at the link
    /// budget (marked in the stats).
    pub(super) fn refine(
        &mut self,
        mut sources: NodeRadiosity,
        target: &mut Fineness,
        occluders: &Occluders,
        rays: FormFactorSettings,
        mut pending: Vec<Pair>,
        run: &mut Pass,
    ) {
        while !pending.is_empty() {
            // Links now plus pairs still to decide: what the links would be with no more splits.
            if self.links.len() + pending.len() > run.budget.max_links {
                self.stats.link_budget_reached = true;
                if self.past_link_budget == PastLinkBudget::Deferred {
                    self.stats.deferred_pairs = pending.len();
                    pending.shrink_to_fit();
                    self.deferred = pending;
                    return;
                }
            }
            let mut earlier = Vec::new();
            let decisions = loop {
                let generation = (&pending[..], &mut earlier);
                match self.decide_generation(generation, &sources, target, occluders, rays, run) {
                    Ok((decisions, new_leaves)) => {
                        run.leaves += new_leaves;
                        run.last_overshoot = None;
                        break decisions;
                    }
                    Err((limit, jump)) => run.coarsen(target, limit, jump),
                }
            };
            pending = self.next_generation(pending, decisions, &mut sources);
            (run.progress)(Progress::Refining {
                knob: run.knob,
                round: run.round,
                leaves: run.leaves,
                links: self.links.len(),
                undecided: pending.len(),
            });
        }
    }

    /// Decides one generation of `pending` pairs; returns the decisions and the leaves their
    /// element splits add, or, while the knob can still coarsen, the budget they would pass
    /// and how far to coarsen, leaving what it decided in `earlier` (the decisions a finer
    /// knob made for the first pairs, which the next call at a coarser knob starts from).
    fn decide_generation(
        &mut self,
        (pending, earlier): (&[Pair], &mut Vec<Decision>),
        sources: &NodeRadiosity,
        target: &Fineness,
        occluders: &Occluders,
        rays: FormFactorSettings,
        run: &Pass,
    ) -> Result<(Vec<Decision>, usize), (Limit, Jump)> {
        let budget = run.budget;
        // Past the link budget no pair splits: each is kept as it is (or dropped unseen).
        let tolerance = match self.stats.link_budget_reached {
            true => f64::INFINITY,
            false => target.tolerance,
        };
        let decide = |this: &mut Hierarchy, pairs: &[Pair], frozen: bool| {
            let refiner = Decider {
                factors: LinkFactors::new(this, occluders, rays),
                sources,
                target: Fineness {
                    tolerance,
                    ..target.frozen_if(frozen)
                },
            };
            let decisions: Vec<Decision> =
                pairs.par_iter().map(|&pair| refiner.decide(pair)).collect();
            let (cast, decided) = refiner.factors.into_counts();
            this.stats.rays += cast;
            this.stats.shaft_decided += decided;
            decisions
        };
        let frozen = self.stats.leaf_budget_reached;
        // Decided a slice at a time while the knob can coarsen, so that a generation that will
        // be decided again stops as soon as the links kept plus the pairs made so far pass the
        // budget (both only grow), instead of being decided to its end first.
        let watch_links = run.can_coarsen() && !self.stats.link_budget_reached;
        let slice = if watch_links {
            (pending.len() / GENERATION_SLICES).max(MIN_SLICE)
        } else {
            pending.len().max(1)
        };
        let mut decisions = Vec::with_capacity(pending.len());
        let (mut made, mut fewest) = (self.links.len(), 0);
        // What a finer knob decided for the first pairs: a link kept or a pair dropped stands
        // at any coarser knob, so only its splits are decided again.
        let mut reading = std::mem::take(earlier).into_iter();
        for pairs in pending.chunks(slice) {
            let decided =
                decide_unless_known(pairs, &mut reading, |open| decide(self, open, frozen));
            for (&pair, decision) in pairs.iter().zip(&decided) {
                let (now, coarser) = self.pairs_made(pair, decision);
                (made, fewest) = (made + now, fewest + coarser);
            }
            decisions.extend(decided);
            // Where even the coarsest knob would make too many over the whole generation
            // (clusters receive through their faces: on a 125k-triangle model, 7M pairs at
            // every knob), coarsening cannot help: the generation is decided to its end, and
            // the next one stops pairs splitting at the link budget.
            let in_all = |n: usize| n as f64 * pending.len() as f64 / decisions.len() as f64;
            if watch_links
                && made > budget.max_links
                && self.links.len() as f64 + in_all(fewest) <= budget.max_links as f64
            {
                let factor =
                    self.coarsening_to_fit(pending, &decisions, budget.max_links, run.knob);
                *earlier = decisions;
                return Err((Limit::Links(budget.max_links), Jump::By(factor)));
            }
        }
        if frozen {
            return Ok((decisions, 0));
        }
        let (splits, new_leaves) = self.element_splits(pending, &decisions);
        if run.leaves + new_leaves <= budget.max_leaves {
            return Ok((decisions, new_leaves));
        }
        if run.can_coarsen() {
            let overshoot = (run.leaves + new_leaves) as f64 / budget.max_leaves as f64;
            *earlier = decisions;
            return Err((Limit::Leaves(budget.max_leaves), Jump::Overshoot(overshoot)));
        }
        // Over budget: the pairs that asked for element splits decide again without them.
        let pairs: Vec<Pair> = splits.iter().map(|&i| pending[i]).collect();
        let again = decide(self, &pairs, true);
        splits
            .iter()
            .zip(again)
            .for_each(|(&i, decision)| decisions[i] = decision);
        self.stats.leaf_budget_reached = true;
        Ok((decisions, 0))
    }

    /// Applies a generation's `decisions` on its `pending` pairs: links kept, elements split
    /// (`sources` follows the new children); returns the pairs the next generation decides.
    fn next_generation(
        &mut self,
        pending: Vec<Pair>,
        decisions: Vec<Decision>,
        sources: &mut NodeRadiosity,
    ) -> Vec<Pair> {
        let mut next = Vec::new();
        for (pair, decision) in pending.into_iter().zip(decisions) {
            match decision {
                Decision::Drop => {}
                Decision::Keep(link) => self.links.push(link),
                Decision::Split { end, clear, .. } => {
                    let n = pair.at(end);
                    self.split_for(n, sources);
                    let children = self.tree.nodes[n as usize].children();
                    next.extend(children.map(|c| Pair {
                        clear,
                        ..pair.with(end, c)
                    }));
                }
                Decision::SplitBoth => {
                    let children = self.tree.nodes[pair.receiver as usize].children();
                    next.extend(
                        children
                            .clone()
                            .flat_map(|a| children.clone().map(move |b| Pair::new(a, b))),
                    );
                }
            }
        }
        next
    }

    /// Takes out of the kept links those that the new solution `sources` shows too coarse and
    /// returns their pairs for refinement; only links that can still be split count.
    pub(super) fn take_links_to_redo(
        &mut self,
        sources: &NodeRadiosity,
        target: &Fineness,
    ) -> Vec<Pair> {
        let node = |n: u32| &self.tree.nodes[n as usize];
        let target = target.frozen_if(self.stats.leaf_budget_reached);
        let (redo, keep): (Vec<Link>, Vec<Link>) = self.links.par_iter().partition(|l| {
            let (r, s) = (node(l.receiver), node(l.source));
            LinkErrors::new(r, sources.at(l.source), l.factor as f64, l.spread as f64)
                .end_to_split(r, s, &target)
                .is_some()
        });
        if !redo.is_empty() {
            self.links = keep;
        }
        redo.iter()
            .map(|l| Pair::new(l.receiver, l.source))
            .collect()
    }

    /// The links or pairs `decision` on pair `(r, s)` makes: one kept link, or the pairs of
    /// the split end's children; and the fewest it would make at any coarser knob (one link,
    /// unless the split is forced, as a cluster that receives always splits).
    fn pairs_made(&self, pair: Pair, decision: &Decision) -> (usize, usize) {
        let children = |n: u32| match self.tree.is_unsplit_element(n) {
            true => self.tree.children_if_split(n),
            false => self.tree.nodes[n as usize].child_count as usize,
        };
        let now = match decision {
            Decision::Drop => 0,
            Decision::Keep(_) => 1,
            Decision::Split { end, .. } => children(pair.at(*end)),
            Decision::SplitBoth => children(pair.receiver) * children(pair.receiver),
        };
        match decision.kept_when_coarser_by(f64::INFINITY) {
            true => (now, 1),
            false => (now, now),
        }
    }

    /// The least power of two to coarsen the knob by (from `knob`, at most to the coarsest)
    /// at which the `decisions` so far on `pending`, projected to the whole generation, fit
    /// `max_links`: each split whose error is within that many tolerances kept as one link.
    fn coarsening_to_fit(
        &self,
        pending: &[Pair],
        decisions: &[Decision],
        max_links: usize,
        knob: f64,
    ) -> f64 {
        let scale = pending.len() as f64 / decisions.len() as f64;
        let made_at = |factor: f64| -> usize {
            pending
                .iter()
                .zip(decisions)
                .map(
                    |(&pair, decision)| match decision.kept_when_coarser_by(factor) {
                        true => 1,
                        false => self.pairs_made(pair, decision).0,
                    },
                )
                .sum()
        };
        let mut factor = 2.0;
        while 2.0 * factor * knob < 1.0
            && self.links.len() as f64 + made_at(factor) as f64 * scale > max_links as f64
        {
            factor *= 2.0;
        }
        factor
    }

    /// Which of `decisions` (for `pending`) split a leaf element, and how many leaves those
    /// splits add.
    fn element_splits(&self, pending: &[Pair], decisions: &[Decision]) -> (Vec<usize>, usize) {
        let mut marked = vec![false; self.tree.nodes.len()];
        let (mut indices, mut added) = (Vec::new(), 0);
        for (i, (pair, decision)) in pending.iter().zip(decisions).enumerate() {
            let Decision::Split { end, .. } = *decision else {
                continue;
            };
            let n = pair.at(end);
            if self.tree.is_unsplit_element(n) {
                indices.push(i);
                if !std::mem::replace(&mut marked[n as usize], true) {
                    // The element stops being a leaf; its children are.
                    added += self.tree.children_if_split(n) - 1;
                }
            }
        }
        (indices, added)
    }

    /// Subdivides `n` if it is an element, giving new children their parent's radiosity.
    fn split_for(&mut self, n: u32, sources: &mut NodeRadiosity) {
        if self.tree.is_unsplit_element(n) {
            self.tree.subdivide(n);
            let (mean, spread) = sources.at(n);
            sources.mean.resize(self.tree.nodes.len(), mean);
            // A new child inherits its parent's mean; its spread is unknown but at most the
            // parent's.
            sources.spread.resize(self.tree.nodes.len(), spread);
        }
    }

    /// Per node, the largest channel of its area-mean radiosity and the spread of that over
    /// its leaves, from per-leaf radiosity.
    pub(super) fn node_radiosity(&self, leaf_radiosity: &[Rgb]) -> NodeRadiosity {
        let mean = self.pull(leaf_radiosity);
        let mut low = vec![f64::INFINITY; self.tree.nodes.len()];
        let mut high = vec![0.0f64; self.tree.nodes.len()];
        // A buried leaf sends nothing anyone gathers: its value is no spread of the source.
        for (i, &leaf) in self
            .tree
            .leaves
            .iter()
            .enumerate()
            .filter(|(_, leaf)| self.reach.seen_area[**leaf as usize] > 0.0)
        {
            let b = leaf_radiosity[i].max_element();
            (low[leaf as usize], high[leaf as usize]) = (b, b);
        }
        for n in (0..self.tree.nodes.len()).rev() {
            for c in self.tree.nodes[n].children() {
                low[n] = low[n].min(low[c as usize]);
                high[n] = high[n].max(high[c as usize]);
            }
        }
        let spread = high
            .iter()
            .zip(&low)
            .map(|(h, l)| (h - l).max(0.0))
            .collect();
        NodeRadiosity {
            mean: mean.iter().map(|b| b.max_element()).collect(),
            spread,
        }
    }
}

/// Decisions on `pairs`: those of `earlier` (read in order, made at a finer knob) that stand
/// at a coarser one, the rest from `decide`. The buffer of `earlier` is freed once read.
fn decide_unless_known(
    pairs: &[Pair],
    earlier: &mut std::vec::IntoIter<Decision>,
    decide: impl FnOnce(&[Pair]) -> Vec<Decision>,
) -> Vec<Decision> {
    if earlier.len() == 0 {
        *earlier = Vec::new().into_iter();
        return decide(pairs);
    }
    let known: Vec<Option<Decision>> = pairs
        .iter()
        .map(|_| earlier.next().filter(Decision::stands_when_coarser))
        .collect();
    let open: Vec<Pair> = (pairs.iter().zip(&known))
        .filter(|(_, known)| known.is_none())
        .map(|(&pair, _)| pair)
        .collect();
    let mut fresh = decide(&open).into_iter();
    (known.into_iter())
        .map(|known| known.or_else(|| fresh.next()).expect("one decision a pair"))
        .collect()
}

/// The radiosity errors a link can carry, W/m^2.
struct LinkErrors {
    /// `rho_R B_S dF`, from the factor's spread over the receiver: only splitting the receiver
    /// reduces it.
    receiver: f64,
    /// `rho_R F dB_S`, from the source's own spread: only splitting the source reduces it.
    source: f64,
}

impl LinkErrors {
    /// The errors of a link into `receiver` with `factor` and its `spread`, from its source's
    /// (mean, spread) of radiosity.
    fn new(
        receiver: &Node,
        (radiosity, radiosity_spread): (f64, f64),
        factor: f64,
        spread: f64,
    ) -> Self {
        LinkErrors {
            receiver: receiver.reflectance * radiosity * spread,
            source: receiver.reflectance * factor * radiosity_spread,
        }
    }

    /// Which end of the link from `s` to `r` to split, `None` when no end that would help can
    /// be split. Between elements the factor is integrated at the receiver's points for any
    /// source size, so the receiver helps against the receiver error (the factor's spread) and
    /// the source against the source error (its radiosity's spread): the end with the larger
    /// error splits, or the other if that one is at the smallest size and its own error still
    /// exceeds the `tolerance`. With a cluster at either end, whose factor is only a bound or a
    /// sample, the larger end is split.
    fn end_to_split(&self, r: &Node, s: &Node, target: &Fineness) -> Option<End> {
        let (tolerance, can_split) = (target.tolerance, |n: &Node| target.can_split(n));
        if self.receiver + self.source <= tolerance {
            return None;
        }
        if r.element.is_some() && s.element.is_some() {
            let (first, second, second_error) = if self.receiver >= self.source {
                ((End::Receiver, r), (End::Source, s), self.source)
            } else {
                ((End::Source, s), (End::Receiver, r), self.receiver)
            };
            return if can_split(first.1) {
                Some(first.0)
            } else {
                (second_error > tolerance && can_split(second.1)).then_some(second.0)
            };
        }
        match (can_split(r), can_split(s)) {
            (true, true) if r.radius >= s.radius => Some(End::Receiver),
            (true, true) => Some(End::Source),
            (true, false) => Some(End::Receiver),
            (false, true) => Some(End::Source),
            (false, false) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hierarchy::MIN_RADIUS_PER_ERROR;
    use crate::hierarchy::fixtures::{GREY, add_parallelogram, build, screened_lamp, unit_box};
    use crate::input::contact::split_at_contacts;
    use crate::scene::{Material, Scene};
    use glam::{DVec3, dvec3};

    /// The indexed hierarchy of `scene`, its occluders, and what its nodes send when only the
    /// emitters shine.
    fn lit_by_emission(scene: Scene) -> (Hierarchy, Occluders, NodeRadiosity) {
        let mut hierarchy = Hierarchy::cluster_tree(&scene);
        let occluders = Occluders::new(&scene);
        hierarchy.index(&occluders);
        let leaf_radiosity: Vec<Rgb> = (0..hierarchy.tree.leaves.len())
            .map(|i| hierarchy.tree.leaf_patch(i).emission)
            .collect();
        let sources = hierarchy.node_radiosity(&leaf_radiosity);
        (hierarchy, occluders, sources)
    }

    #[test]
    fn a_partly_hidden_pair_gets_rays_only_where_they_can_change_its_decision() {
        let (hierarchy, occluders, sources) = lit_by_emission(screened_lamp(0.01, 0.37));
        let (floor, lamp) = (hierarchy.tree.face_node[0], hierarchy.tree.face_node[1]);
        let decide_at = |tolerance: f64| {
            let decider = Decider {
                factors: LinkFactors::new(&hierarchy, &occluders, FormFactorSettings::default()),
                sources: &sources,
                target: Fineness {
                    tolerance,
                    smallest: 0.0,
                    finest_radius: 0.0,
                },
            };
            let estimate = decider
                .factors
                .estimate(Pair::new(floor, lamp))
                .expect("facing");
            let node = |n: u32| decider.factors.node(n);
            let rays = decider.rays_for(node(floor), node(lamp), lamp, &estimate);
            (rays, estimate, decider.factors.into_counts().0)
        };
        let (_, estimate, _) = decide_at(1.0);
        assert!(estimate.visibility == Visibility::Partial);
        // The floor's reflectance (0.5) times the lamp's radiosity (1) times the spread:
        // the kernel's alone, or that and the whole factor when visibility varies all it can.
        let kernel_error = 0.5 * estimate.spread;
        let widest_error = 0.5 * (estimate.spread + estimate.factor);
        // The kernel alone passes the tolerance: the receiver splits, and no ray is cast.
        let (split, _, cast) = decide_at(0.5 * kernel_error);
        assert!(matches!(
            split,
            Err(Decision::Split {
                end: End::Receiver,
                ..
            })
        ));
        assert_eq!(cast, 0);
        // Visibility could pass it: the spread is measured.
        let (measure, _, _) = decide_at(0.5 * (kernel_error + widest_error));
        assert_eq!(measure.ok(), Some(Rays::ForSpread));
        // Nothing visibility does could pass it: the factor alone is measured.
        let (factor_only, _, _) = decide_at(2.0 * widest_error);
        assert_eq!(factor_only.ok(), Some(Rays::ForFactor));
    }

    #[test]
    fn a_clear_pair_passes_its_shaft_on_to_its_pieces_and_a_blocked_one_does_not() {
        // A screen 1 above the unit floor covers x < 0.37 there: from the floor's quarters at
        // x > 0.5 every segment to the lamp 10 above passes it; from those below, some do not.
        let (mut hierarchy, occluders, sources) = lit_by_emission(screened_lamp(1.0, 0.37));
        let (floor, lamp) = (hierarchy.tree.face_node[0], hierarchy.tree.face_node[1]);
        hierarchy.tree.subdivide(floor);
        let quarters: Vec<u32> = hierarchy.tree.nodes[floor as usize].children().collect();
        quarters.iter().for_each(|&q| hierarchy.tree.subdivide(q));
        let decider = Decider {
            factors: LinkFactors::new(&hierarchy, &occluders, FormFactorSettings::default()),
            sources: &sources,
            target: Fineness {
                tolerance: 1e-9,
                smallest: 0.0,
                finest_radius: 0.0,
            },
        };
        let patch = |n: u32| hierarchy.tree.element_patch(n);
        let mut clear_quarters = 0;
        for &quarter in &quarters {
            let decision = decider.decide(Pair::new(quarter, lamp));
            let passes_clear = matches!(decision, Decision::Split { clear: true, .. });
            assert_eq!(passes_clear, patch(quarter).centroid.x > 0.5);
            if !passes_clear {
                continue;
            }
            clear_quarters += 1;
            for piece in hierarchy.tree.nodes[quarter as usize].children() {
                let inherited = Pair {
                    clear: true,
                    ..Pair::new(piece, lamp)
                };
                let (given, walked) = (
                    decider.factors.estimate(inherited).expect("facing"),
                    decider
                        .factors
                        .estimate(Pair::new(piece, lamp))
                        .expect("facing"),
                );
                assert!(given.visibility == Visibility::Clear);
                assert_eq!((given.factor, given.spread), (walked.factor, walked.spread));
                // What the inherited shaft promises: nothing between any two of their points.
                let (p, q) = (patch(piece), patch(lamp));
                for k in 0..64 {
                    let (u, v) = ((k % 8) as f64 / 7.0, (k / 8) as f64 / 7.0);
                    let from = p.polygon.point_at(u, v);
                    let to = q.polygon.point_at(1.0 - v, u);
                    assert!(occluders.segment_is_clear(from, to, [p.face, q.face]));
                }
            }
        }
        assert_eq!(clear_quarters, 2);
    }

    #[test]
    fn a_sliver_is_as_small_as_its_area_and_a_square_as_its_corners() {
        let mut scene = Scene::default();
        add_parallelogram(
            &mut scene,
            "square",
            (DVec3::ZERO, DVec3::X, DVec3::Z),
            GREY,
        );
        // A triangle 4 m long and 1 cm wide, standing a little away.
        let strip = scene.add_object("strip");
        let at = dvec3(0.0, 0.0, 2.0);
        scene.add_polygon(
            strip,
            &[at, at + DVec3::X * 4.0, at + dvec3(4.0, 0.0, 0.01)],
            GREY,
        );
        let hierarchy = build(&scene, 0.5);
        let size = |face: usize| {
            element_size(&hierarchy.tree.nodes[hierarchy.tree.face_node[face] as usize])
        };
        assert!((size(0) - 0.5f64.sqrt()).abs() < 1e-12, "{}", size(0));
        let area = 0.5 * 4.0 * 0.01;
        let equilateral = (4.0 * area / (3.0 * 3.0f64.sqrt())).sqrt();
        assert!(
            (size(1) - equilateral).abs() < 1e-12,
            "{} vs {equilateral}",
            size(1)
        );
        assert!(hierarchy.tree.nodes[hierarchy.tree.face_node[1] as usize].radius > 1.0);
    }

    #[test]
    fn only_the_splits_a_coarser_knob_may_keep_are_decided_again() {
        let split = |end, excess| Decision::Split {
            end,
            excess,
            clear: false,
        };
        let link = Link {
            receiver: 1,
            source: 2,
            factor: 0.5,
            spread: 0.0,
            offset: [0.0; 2],
        };
        let earlier = vec![
            Decision::Keep(link),
            split(End::Receiver, 2.0),
            Decision::Drop,
            split(End::Source, f32::INFINITY),
        ];
        let pairs: Vec<Pair> = (0..6).map(|i| Pair::new(i, i + 10)).collect();
        let mut reading = earlier.into_iter();
        let mut asked = Vec::new();
        let decided = decide_unless_known(&pairs[..4], &mut reading, |open| {
            asked.extend_from_slice(open);
            open.iter().map(|_| Decision::SplitBoth).collect()
        });
        assert_eq!(asked, [Pair::new(1, 11)]);
        assert!(matches!(
            decided[..],
            [
                Decision::Keep(kept),
                Decision::SplitBoth,
                Decision::Drop,
                Decision::Split {
                    end: End::Source,
                    ..
                }
            ] if kept == link
        ));
        // Past what was decided before, every pair is decided afresh.
        let rest = decide_unless_known(&pairs[4..], &mut reading, |open| {
            assert_eq!(open, &pairs[4..]);
            vec![Decision::Drop; open.len()]
        });
        assert_eq!(rest.len(), 2);
    }

    #[test]
    fn the_finest_radius_is_a_discs_share_of_the_area_per_leaf() {
        assert!((finest_radius(std::f64::consts::PI * 1e6, 1_000_000) - 1.0).abs() < 1e-12);
        assert_eq!(finest_radius(0.0, 0), 0.0);
    }

    #[test]
    fn a_large_floor_refines_to_the_scale_of_what_stands_on_it() {
        // A 20 m floor, a 1 m box on it and a 1 m lamp above: the median face is the box's.
        let mut scene = Scene::default();
        let (x, z) = (DVec3::X, DVec3::Z);
        add_parallelogram(&mut scene, "part", (DVec3::ZERO, z * 20.0, x * 20.0), GREY);
        for sides in unit_box(dvec3(9.5, 0.0, 9.5)) {
            add_parallelogram(&mut scene, "part", sides, GREY);
        }
        add_parallelogram(
            &mut scene,
            "part",
            (dvec3(11.0, 3.0, 9.5), x, z),
            Material {
                reflectance: Rgb::ZERO,
                emission: Rgb::splat(10.0),
            },
        );
        let (floor_radius, box_radius) = (
            scene.faces[0].polygon.radius(),
            scene.faces[1].polygon.radius(),
        );
        // As loaded: the floor cut along the box's footprint (else the leaves over its outline,
        // half buried, split to the finest size the leaf budget allows).
        split_at_contacts(&mut scene);
        let error = 0.1;
        let hierarchy = build(&scene, error);
        let floor_leaves = hierarchy
            .tree
            .leaves
            .iter()
            .map(|&n| &hierarchy.tree.nodes[n as usize])
            .filter(|n| {
                n.element
                    .as_ref()
                    .is_some_and(|e| scene.faces[e.patch.face as usize].source == 0)
            });
        let finest = floor_leaves.map(|n| n.radius).fold(f64::INFINITY, f64::min);
        println!(
            "finest floor leaf radius {finest:.4} (floor radius {floor_radius:.2}, box face {box_radius:.3})"
        );
        // Far below the floor's own scale, and not below the box's: a leaf is at most half its
        // splittable parent.
        assert!(
            finest < MIN_RADIUS_PER_ERROR * error * floor_radius / 4.0,
            "{finest}"
        );
        assert!(
            finest > MIN_RADIUS_PER_ERROR * error * box_radius / 2.0,
            "{finest}"
        );
    }
}
