//! Hierarchical radiosity with clustering: light moves along links between elements at the
//! level where the transfer is accurate enough, instead of through n^2 form factors on a
//! uniform mesh. The leaves of the element trees are the patches the server streams.
//!
//! - **Elements** (Hanrahan, Salzman, Aupperle 1991, "A Rapid Hierarchical Radiosity
//!   Algorithm"): each input face roots a quadtree (a quad into four quads, a triangle into four
//!   similar triangles), split only when a link asks for it.
//! - **Clusters** (Smits, Arvo, Greenberg 1994; Sillion 1995): a binary tree of median splits
//!   over the input faces sits above them, so refinement starts from one self-link of the root,
//!   not from faces^2 links: a face gathers from whole clusters while they are far enough. A
//!   cluster link carries the sampled area-average kernel. Clusters only send: a receiving
//!   cluster would hand its irradiance to faces that cannot see the source.
//! - **Refinement** (BF with visibility): a link is kept when the radiosity error it can carry,
//!   `rho_R (B_S dF + F dB_S)`, is within the tolerance. `dF` is the spread of the factor over
//!   the receiver, kernel and visibility both (a bound, for a cluster), so partial occlusion
//!   refines while full visibility and full occlusion do not. Between elements the receiver
//!   splits for `dF` and the source for `dB_S`; with a cluster, the larger end splits.
//!   Refinement runs again on each new solution until no link changes.
//! - **Visibility**: a shaft between the two elements (Haines, Wallace 1994, "Shaft Culling for
//!   Efficient Ray-Cast Radiosity") collects the faces that can block. None: clear, no rays. One
//!   face that separates the two and covers every segment between them: hidden, no rays. Else
//!   shadow rays.
//! - **Solving**: pull (area-weighted means up the trees), gather along links, push (sums down
//!   to the leaves) is a linear operator on the leaves, so it is a [`Transport`] and the same
//!   GMRES and Jacobi solve it. No dense matrix anywhere: memory is O(elements + links).

use crate::Progress;
use crate::form_factors::{
    FormFactorSettings, Transport, mutually_facing, near_pair_level, pair_seed, rays_for_pair,
    sees_closed_view, splitmix64, stratified_uv, unoccluded_form_factor,
};
use crate::geometry::{Polygon, bounds, cosine_direction, point_to_polygon_form_factor};
use crate::mesh::{Mesh, Patch};
use crate::scene::{Rgb, Scene};
use crate::solve::{NeedsEntries, SolveOutcome, SolverSettings, System, solve};
use crate::visibility::Occluders;
use glam::DVec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::f64::consts::PI;
use std::ops::Range;
use std::sync::atomic::{AtomicU64, Ordering};

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
    /// Leaves at most. A refinement that would pass it starts again at twice the knob (reported
    /// as [`HierarchyStats::knob_used`]); past a knob of 0.5, elements stop splitting instead
    /// ([`HierarchyStats::leaf_budget_reached`]). Memory runs about 2.3 KB per leaf (links and
    /// the solver's vectors included), so the default stays near 1.2 GB.
    pub max_leaves: usize,
}

impl Default for HierarchySettings {
    fn default() -> Self {
        HierarchySettings {
            error: 0.03,
            max_rounds: 4,
            max_leaves: 500_000,
        }
    }
}

/// Smallest element radius, as a fraction of `error` times its input face's radius capped at
/// the median face radius ([`smallest_scale`]; relative to geometry, so that a lamp far above
/// a floor does not coarsen the floor's shadows). Chosen by measurement on the Cornell box and
/// the shadow slab before the cap (docs/BENCHMARKS.md): 0.5 spent most leaves on contact lines
/// for little RMS; 2 left contact lines and shadow edges too coarse.
pub const MIN_RADIUS_PER_ERROR: f64 = 1.0;

/// Corners of elements are points of a per-face lattice with this many steps per side, so that
/// elements of one face share corners exactly, whatever their level.
const LATTICE_STEPS: u32 = 1 << 24;
/// Deepest split of an input face (each level halves the lattice step).
const MAX_DEPTH: u32 = 20;
/// Point pairs sampled for the factor of a link that involves a cluster.
const CLUSTER_SAMPLES: u32 = 16;
/// Faces in a shaft tested as a single blocker before rays decide.
const MAX_BLOCKER_CANDIDATES: usize = 4;
/// Source points per receiver point for the transfer centre of a clear link ([`kernel_centre`]).
const CENTROID_SAMPLES: u32 = 8;
/// Cosine-distributed rays per point for the buried test ([`is_buried`]).
const BURIED_RAYS: u32 = 8;
/// Marks "no parent".
const NONE: u32 = u32::MAX;

type Bounds = (DVec3, DVec3);

/// A piece of one input face.
#[derive(Clone, Debug)]
struct Element {
    patch: Patch,
    /// Lattice coordinates of the corners: `(u, v)` on a quad, `(s, t)` on a triangle.
    lattice: [[u32; 2]; 4],
    depth: u32,
    /// The length the smallest element is relative to ([`smallest_scale`]).
    size_scale: f64,
}

/// A node of the hierarchy: an element (of a face) or a cluster (of faces).
#[derive(Clone, Debug)]
struct Node {
    element: Option<Element>,
    first_child: u32,
    child_count: u32,
    parent: u32,
    area: f64,
    centroid: DVec3,
    radius: f64,
    bounds: Bounds,
    /// Largest reflectance channel of anything below.
    reflectance: f64,
    /// Positions in [`Hierarchy::order`] of the input faces below.
    faces: Range<u32>,
}

impl Node {
    fn children(&self) -> Range<u32> {
        self.first_child..self.first_child + self.child_count
    }
}

/// A node's linear radiosity model about its children's reached-area centre, as weights on
/// their means (zero: flat).
#[derive(Clone, Copy, Debug, Default)]
struct Slope {
    /// Per child, its weight in the slope along (tangent, bitangent).
    child_weights: [[f64; 2]; 4],
    /// The node's centroid from the centre, in the tangent frame.
    shift: [f64; 2],
    /// How far from the centre the model is read, per axis: half the children's reach. On a
    /// quad of four equal children that keeps every reading a convex mix of their
    /// (non-negative) means, so no link carries negative light.
    reach: [f64; 2],
}

/// A kept link: `receiver` gathers `factor * B(source)`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Link {
    receiver: u32,
    source: u32,
    factor: f32,
    /// The factor's possible spread over the receiver (see the module notes), kept so that a
    /// new solution can re-check the link without integrating it again.
    spread: f32,
    /// Where on the source the transfer is centred: the kernel-weighted mean of the source
    /// points the receiver sees, from the source's centroid, in the source's tangent frame. The
    /// link gathers the source's linear radiosity model there, not its mean.
    offset: [f32; 2],
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
    /// Links whose visibility the shaft decided without rays (clear or hidden).
    pub shaft_decided: u64,
    /// Shadow rays cast.
    #[serde(skip)]
    pub rays: u64,
    /// Solver iterations spent in the rounds before the final solve.
    pub refinement_iterations: usize,
    /// The error knob the hierarchy was refined to: the one asked for, or a coarser one when
    /// that would have passed [`HierarchySettings::max_leaves`].
    pub knob_used: f64,
    /// Whether elements stopped splitting at [`HierarchySettings::max_leaves`] even at the
    /// coarsest knob tried, leaving some links coarser than it asks.
    pub leaf_budget_reached: bool,
}

impl HierarchyStats {
    /// What a user who asked for `asked` should be told about the leaf budget: that the knob was
    /// coarsened to fit it, or that refinement stopped at it (flag names as the `radcast`
    /// command and the server spell them).
    pub fn budget_warnings(&self, asked: &HierarchySettings) -> Vec<String> {
        let mut warnings = Vec::new();
        if self.knob_used > asked.error {
            warnings.push(format!("--error {} needs more than --max-leaves {} leaves here; refined at --error {} instead", asked.error, asked.max_leaves, self.knob_used));
        }
        if self.leaf_budget_reached {
            warnings.push(format!("refinement stopped at --max-leaves {} even at --error {}; some links carry more than that", asked.max_leaves, self.knob_used));
        }
        warnings
    }
}

/// The element and cluster trees of a scene, their links, and the link operator on the leaves.
pub struct Hierarchy {
    nodes: Vec<Node>,
    /// Input faces in cluster order: every cluster covers a contiguous run.
    order: Vec<u32>,
    /// Prefix sums of face areas in `order` (for area-weighted sampling inside a cluster).
    area_prefix: Vec<f64>,
    /// Each input face's polygon.
    faces: Vec<Polygon>,
    /// Each input face's root element.
    face_node: Vec<u32>,
    /// Whether each input face's view is closed (its leaves' rows are normalised to one).
    face_closed: Vec<bool>,
    links: Vec<Link>,
    /// The leaves, face by face.
    leaves: Vec<u32>,
    /// Links by receiver: `incoming[offsets[n]..offsets[n + 1]]` are node `n`'s (source, factor,
    /// reading point).
    offsets: Vec<u32>,
    incoming: Vec<(u32, f32, [f32; 2])>,
    /// Per leaf, the factor its gathered irradiance is multiplied by (1, or 1/row sum).
    row_scale: Vec<f64>,
    /// Per node ever a leaf, the share of its area not buried ([`is_buried`]); NaN until measured.
    seen_share: Vec<f64>,
    /// Per node, the area of its leaves that light can reach: what a source's mean is taken over.
    seen_area: Vec<f64>,
    /// Per element node, its linear radiosity model's weights ([`Hierarchy::slopes_of`]).
    slopes: Vec<Slope>,
    stats: HierarchyStats,
}

/// The point of `face` at lattice coordinates `at`.
fn lattice_point(face: &Polygon, at: [u32; 2]) -> DVec3 {
    let (u, v) = (
        at[0] as f64 / LATTICE_STEPS as f64,
        at[1] as f64 / LATTICE_STEPS as f64,
    );
    let c = face.corners();
    if face.is_quad() {
        face.point_at(u, v)
    } else {
        c[0] + (c[1] - c[0]) * u + (c[2] - c[0]) * v
    }
}

fn midpoint(a: [u32; 2], b: [u32; 2]) -> [u32; 2] {
    [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2]
}

fn union(a: Bounds, b: Bounds) -> Bounds {
    (a.0.min(b.0), a.1.max(b.1))
}

/// The convex hull of two boxes as their union box cut by up to 12 planes through matching
/// edges (Haines, Wallace 1994): a point is outside when `normal . p > offset` for a plane.
struct Shaft {
    union: Bounds,
    planes: [(DVec3, f64); 12],
    count: usize,
    /// Margin that keeps the test conservative against round-off.
    margin: f64,
}

impl Shaft {
    fn new(a: Bounds, b: Bounds) -> Shaft {
        let union = union(a, b);
        // Which box alone sets the union's face on `axis` (`high`: its max side): Some(true) a,
        // Some(false) b, None both.
        let side = |bounds: Bounds, axis: usize, high: bool| {
            if high { bounds.1[axis] } else { bounds.0[axis] }
        };
        let owner = |axis: usize, high: bool| {
            let (va, vb) = (side(a, axis, high), side(b, axis, high));
            if va == vb {
                None
            } else {
                Some((va > vb) == high)
            }
        };
        let mut shaft = Shaft {
            union,
            planes: [(DVec3::ZERO, 0.0); 12],
            count: 0,
            margin: 1e-9 * (union.1 - union.0).length(),
        };
        for i in 0..3 {
            for j in i + 1..3 {
                for high_i in [false, true] {
                    for high_j in [false, true] {
                        let (Some(oi), Some(oj)) = (owner(i, high_i), owner(j, high_j)) else {
                            continue;
                        };
                        if oi == oj {
                            continue;
                        }
                        // The plane through the (i, j) edge of a and the same edge of b, facing
                        // the union's corner they cut off.
                        let (pa, pb) = (
                            (side(a, i, high_i), side(a, j, high_j)),
                            (side(b, i, high_i), side(b, j, high_j)),
                        );
                        let mut normal = DVec3::ZERO;
                        normal[i] = pb.1 - pa.1;
                        normal[j] = pa.0 - pb.0;
                        let towards_corner = normal[i] * if high_i { 1.0 } else { -1.0 }
                            + normal[j] * if high_j { 1.0 } else { -1.0 };
                        if towards_corner < 0.0 {
                            normal = -normal;
                        }
                        shaft.planes[shaft.count] = (normal, normal[i] * pa.0 + normal[j] * pa.1);
                        shaft.count += 1;
                    }
                }
            }
        }
        shaft
    }

    /// False only when `bounds` lies wholly outside the shaft.
    fn may_meet_box(&self, (lo, hi): Bounds) -> bool {
        let m = self.margin;
        if lo.cmpgt(self.union.1 + m).any() || hi.cmplt(self.union.0 - m).any() {
            return false;
        }
        self.planes[..self.count].iter().all(|(normal, offset)| {
            let nearest = DVec3::select(normal.cmpgt(DVec3::ZERO), lo, hi);
            normal.dot(nearest) <= offset + m * normal.length()
        })
    }

    /// False only when every point lies outside one and the same bounding plane of the shaft.
    fn may_meet_points(&self, points: &[DVec3]) -> bool {
        let m = self.margin;
        for axis in 0..3 {
            if points.iter().all(|p| p[axis] > self.union.1[axis] + m)
                || points.iter().all(|p| p[axis] < self.union.0[axis] - m)
            {
                return false;
            }
        }
        self.planes[..self.count].iter().all(|(normal, offset)| {
            points
                .iter()
                .any(|p| normal.dot(*p) <= offset + m * normal.length())
        })
    }
}

/// Whether face `blocker` lies strictly between the point sets `a` and `b` (convex polygons'
/// corners) and covers every segment from one to the other: all such segments cross its plane
/// inside the convex hull of the corner-to-corner crossings, so those crossings decide.
fn blocks_every_segment(blocker: &Polygon, normal: DVec3, a: &[DVec3], b: &[DVec3]) -> bool {
    let c = blocker.corners();
    let tolerance = 1e-9 * blocker.radius();
    let height = |p: &DVec3| (*p - c[0]).dot(normal);
    let (above_a, below_a) = (
        a.iter().all(|p| height(p) > tolerance),
        a.iter().all(|p| height(p) < -tolerance),
    );
    let (above_b, below_b) = (
        b.iter().all(|p| height(p) > tolerance),
        b.iter().all(|p| height(p) < -tolerance),
    );
    if !((above_a && below_b) || (below_a && above_b)) {
        return false;
    }
    a.iter().all(|p| {
        b.iter().all(|q| {
            let (hp, hq) = (height(p), height(q));
            let x = *p + (*q - *p) * (hp / (hp - hq));
            // Strictly inside every edge (CCW about `normal`), by a relative margin.
            (0..c.len()).all(|k| {
                let edge = c[(k + 1) % c.len()] - c[k];
                edge.cross(x - c[k]).dot(normal) > 1e-9 * edge.length_squared()
            })
        })
    })
}

/// What refinement decided for one link.
enum Decision {
    Drop,
    Keep(Link),
    SplitReceiver,
    SplitSource,
    /// A cluster's self-link: every pair of its children.
    SplitBoth,
}

/// How the shaft saw a pair of elements.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Visibility {
    Clear,
    Hidden,
    Partial,
    /// A cluster takes part: the factor is sampled with rays.
    Sampled,
}

/// A link's factor before refinement decides.
struct Estimate {
    /// The factor between elements (unoccluded, or with visibility when partly hidden), or an
    /// upper bound with a cluster.
    factor: f64,
    /// Its spread over the receiver, visibility included.
    spread: f64,
    visibility: Visibility,
    /// The kernel-weighted mean of the visible source points, when rays measured it.
    centroid: Option<DVec3>,
}

/// Read-only state for deciding links in parallel.
struct Refiner<'a> {
    hierarchy: &'a Hierarchy,
    occluders: &'a Occluders,
    rays: FormFactorSettings,
    /// Per node: the largest channel of its mean radiosity, and the spread of that over its leaves.
    radiosity: &'a [f64],
    spread: &'a [f64],
    /// Largest radiosity error a link may carry, W/m^2.
    tolerance: f64,
    /// Smallest element radius as a fraction of its face's.
    smallest: f64,
    rays_cast: AtomicU64,
    shaft_decided: AtomicU64,
}

impl Refiner<'_> {
    fn node(&self, n: u32) -> &Node {
        &self.hierarchy.nodes[n as usize]
    }

    fn decide(&self, receiver: u32, source: u32) -> Decision {
        let (r, s) = (self.node(receiver), self.node(source));
        if receiver == source {
            return if r.element.is_none() {
                Decision::SplitBoth
            } else {
                Decision::Drop
            };
        }
        // Clusters gather nothing themselves: one that received would hand the same irradiance
        // to every face below it, including faces that cannot see the source (light leaked
        // through a wall whose two sides share a cluster). Links end at elements, and clusters
        // only send.
        if r.element.is_none() {
            return Decision::SplitReceiver;
        }
        let Some(estimate) = self.estimate(receiver, source) else {
            return Decision::Drop;
        };
        if estimate.visibility == Visibility::Hidden {
            return Decision::Drop;
        }
        let errors = link_errors(
            r,
            (
                self.radiosity[source as usize],
                self.spread[source as usize],
            ),
            estimate.factor,
            estimate.spread,
        );
        match split_side(r, s, errors, self.tolerance, self.smallest) {
            Some(true) => return Decision::SplitReceiver,
            Some(false) => return Decision::SplitSource,
            None => {}
        }
        let factor = self.factor(receiver, source, &estimate);
        if factor <= 0.0 {
            return Decision::Drop;
        }
        let offset = match (&s.element, estimate.visibility) {
            (Some(e), Visibility::Partial | Visibility::Clear) => {
                let centroid = estimate.centroid.unwrap_or_else(|| {
                    kernel_centre(
                        self.hierarchy.element_patch(receiver),
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

    fn estimate(&self, receiver: u32, source: u32) -> Option<Estimate> {
        let (r, s) = (self.node(receiver), self.node(source));
        if let (Some(er), Some(es)) = (&r.element, &s.element) {
            let (p, q) = (&er.patch, &es.patch);
            if p.face == q.face || !mutually_facing(p, q) {
                return None;
            }
            // The mean from the analytic factor at the receiver's Gauss points; the spread from
            // those, its corners and its centroid, where a smooth kernel's extremes lie (Gauss
            // points alone are symmetric and miss a source straight above the centre).
            let at = |x: DVec3| point_to_polygon_form_factor(x, p.normal, &q.polygon, q.normal);
            let (mut factor, mut low, mut high) = (0.0, f64::INFINITY, 0.0f64);
            let mut extend = |f: f64| {
                low = low.min(f);
                high = high.max(f);
            };
            p.polygon.for_each_quadrature_point(1, |x, weight| {
                let f = at(x);
                factor += weight * f;
                extend(f);
            });
            p.polygon.corners().iter().for_each(|c| extend(at(*c)));
            extend(at(p.centroid));
            let visibility = self.shaft_visibility(p, q);
            if visibility != Visibility::Partial {
                return Some(Estimate {
                    factor,
                    spread: high - low,
                    visibility,
                    centroid: None,
                });
            }
            // Partly hidden: what counts is how much visibility varies over the receiver, not
            // the whole factor (a source hidden alike from every receiver point needs no split).
            let rays_per_point = rays_for_pair(p, q, &self.rays).max(4);
            let (occluded, least, most, centroid) = self.partly_hidden_factor(
                receiver,
                source,
                integration_level(p, q, factor, high - low).min(2),
                rays_per_point,
            );
            return Some(Estimate {
                factor: occluded,
                spread: high - low + factor * (most - least),
                visibility,
                centroid: Some(centroid),
            });
        }
        // A cluster takes part: cull by facing, then bound the factor by the source's area seen
        // from the nearest the two bounding spheres come.
        let in_front = |bounds: Bounds, e: &Element| {
            let (lo, hi) = bounds;
            (0..8).any(|k| {
                let corner = DVec3::new(
                    if k & 1 == 0 { lo.x } else { hi.x },
                    if k & 2 == 0 { lo.y } else { hi.y },
                    if k & 4 == 0 { lo.z } else { hi.z },
                );
                (corner - e.patch.centroid).dot(e.patch.normal) > 0.0
            })
        };
        if r.element.as_ref().is_some_and(|e| !in_front(s.bounds, e))
            || s.element.as_ref().is_some_and(|e| !in_front(r.bounds, e))
        {
            return None;
        }
        let gap = (r.centroid.distance(s.centroid) - r.radius - s.radius).max(0.0);
        let bound = (s.area / (PI * gap * gap)).min(1.0);
        Some(Estimate {
            factor: bound,
            spread: bound,
            visibility: Visibility::Sampled,
            centroid: None,
        })
    }

    /// Clear, hidden or partial, from the faces in the shaft between `p` and `q`.
    fn shaft_visibility(&self, p: &Patch, q: &Patch) -> Visibility {
        let hierarchy = self.hierarchy;
        let (cp, cq) = (p.polygon.corners(), q.polygon.corners());
        let shaft = Shaft::new(bounds(cp.iter().copied()), bounds(cq.iter().copied()));
        let mut candidates = 0;
        let mut stack = vec![0u32];
        while let Some(n) = stack.pop() {
            let node = self.node(n);
            if !shaft.may_meet_box(node.bounds) {
                continue;
            }
            let Some(element) = &node.element else {
                stack.extend(node.children());
                continue;
            };
            // An input face (the search never goes below them).
            let face = element.patch.face;
            if face == p.face
                || face == q.face
                || !shaft.may_meet_points(hierarchy.faces[face as usize].corners())
            {
                continue;
            }
            if blocks_every_segment(
                &hierarchy.faces[face as usize],
                element.patch.normal,
                cp,
                cq,
            ) {
                self.shaft_decided.fetch_add(1, Ordering::Relaxed);
                return Visibility::Hidden;
            }
            // Rays decide from here; looking further for a single face that hides everything
            // costs a walk over every face in a shaft across a furnished room.
            candidates += 1;
            if candidates == MAX_BLOCKER_CANDIDATES {
                return Visibility::Partial;
            }
        }
        if candidates == 0 {
            self.shaft_decided.fetch_add(1, Ordering::Relaxed);
            return Visibility::Clear;
        }
        Visibility::Partial
    }

    /// The factor a kept link carries, visibility included.
    fn factor(&self, receiver: u32, source: u32, estimate: &Estimate) -> f64 {
        let (r, s) = (self.node(receiver), self.node(source));
        let (Some(er), Some(es)) = (&r.element, &s.element) else {
            return self.sampled_factor(receiver, source);
        };
        let (p, q) = (&er.patch, &es.patch);
        if estimate.visibility == Visibility::Partial {
            return estimate.factor;
        }
        match integration_level(p, q, estimate.factor, estimate.spread) {
            1 => estimate.factor,
            level => unoccluded_form_factor(p, q, level),
        }
    }

    /// The factor of a partly hidden pair, the least and most visibility over the receiver's
    /// points, and the kernel-weighted mean of the visible source points: at each receiver
    /// quadrature point, the analytic factor times the kernel-weighted share of clear rays to
    /// stratified source points. The weights matter: where a receiver meets a wall the kernel
    /// peaks just where nothing blocks, and `unoccluded factor x clear share` ran 16-30% low
    /// there (measured on the Cornell box, docs/ACCURACY.md).
    fn partly_hidden_factor(
        &self,
        receiver: u32,
        source: u32,
        level: u32,
        rays_per_point: u32,
    ) -> (f64, f64, f64, DVec3) {
        let (p, q) = (
            self.hierarchy.element_patch(receiver),
            self.hierarchy.element_patch(source),
        );
        let seed = pair_seed(receiver as usize, source as usize);
        let (mut factor, mut point, mut cast, mut least, mut most) =
            (0.0, 0u32, 0u64, 1.0f64, 0.0f64);
        let (mut centroid_sum, mut centroid_weight) = (DVec3::ZERO, 0.0);
        p.polygon.for_each_quadrature_point(level, |x, weight| {
            point += 1;
            let unoccluded = point_to_polygon_form_factor(x, p.normal, &q.polygon, q.normal);
            if unoccluded == 0.0 {
                return;
            }
            let (mut clear, mut total, mut clear_points) = (0.0, 0.0, DVec3::ZERO);
            for k in 0..rays_per_point {
                let (s, t) = stratified_uv(k, splitmix64(seed ^ point as u64));
                let y = q.polygon.point_at(s, t);
                let d = y - x;
                let kernel = facing_kernel(p.normal, q.normal, d);
                if kernel == 0.0 {
                    continue;
                }
                total += kernel;
                cast += 1;
                if self.occluders.segment_is_clear(x, y, [p.face, q.face]) {
                    clear += kernel;
                    clear_points += y * kernel;
                }
            }
            if total > 0.0 {
                let visible = clear / total;
                factor += weight * unoccluded * visible;
                (least, most) = (least.min(visible), most.max(visible));
                // This point's share of the transfer, spread over the source points it sees.
                centroid_sum += clear_points * (weight * unoccluded / total);
                centroid_weight += weight * unoccluded * visible;
            }
        });
        self.rays_cast.fetch_add(cast, Ordering::Relaxed);
        let centroid = if centroid_weight > 0.0 {
            centroid_sum / centroid_weight
        } else {
            q.centroid
        };
        (factor, least.min(most), most, centroid)
    }

    /// The area-average kernel `A_S E[cos cos V / (pi d^2)]` over point pairs spread by area on
    /// both ends: an unbiased estimate of the factor between any two sets of surfaces.
    fn sampled_factor(&self, receiver: u32, source: u32) -> f64 {
        let seed = pair_seed(receiver as usize, source as usize);
        let mut sum = 0.0;
        for k in 0..CLUSTER_SAMPLES {
            let (x, nx, fx) = self.hierarchy.sample(receiver, k, seed);
            let (y, ny, fy) = self.hierarchy.sample(source, k, splitmix64(seed));
            let d = y - x;
            if d == DVec3::ZERO {
                continue;
            }
            let kernel = facing_kernel(nx, ny, d);
            if kernel == 0.0 {
                continue;
            }
            self.rays_cast.fetch_add(1, Ordering::Relaxed);
            if self.occluders.segment_is_clear(x, y, [fx, fy]) {
                sum += kernel / PI;
            }
        }
        (self.node(source).area * sum / CLUSTER_SAMPLES as f64).min(1.0)
    }
}

impl Hierarchy {
    /// The cluster tree over `scene`'s faces, each face one unsplit element.
    fn new(scene: &Scene) -> Hierarchy {
        let face_count = scene.faces.len();
        let mut order: Vec<u32> = (0..face_count as u32).collect();
        let centroids: Vec<DVec3> = scene.faces.iter().map(|f| f.polygon.centroid()).collect();
        let mut nodes: Vec<Node> = Vec::new();
        let mut face_node = vec![NONE; face_count];
        let placeholder = Node {
            element: None,
            first_child: 0,
            child_count: 0,
            parent: NONE,
            area: 0.0,
            centroid: DVec3::ZERO,
            radius: 0.0,
            bounds: (DVec3::ZERO, DVec3::ZERO),
            reflectance: 0.0,
            faces: 0..0,
        };
        if face_count > 0 {
            nodes.push(placeholder.clone());
        }
        let typical_radius = smallest_scale(scene);
        // Top-down, children after their parent, so that index order is a valid pull (reverse)
        // and push (forward) order.
        let mut stack = vec![(0u32, 0..face_count, NONE)];
        while let Some((index, range, parent)) = stack.pop().filter(|_| face_count > 0) {
            let faces = range.start as u32..range.end as u32;
            if range.len() == 1 {
                let face = order[range.start];
                let f = &scene.faces[face as usize];
                let patch = Patch {
                    polygon: f.polygon,
                    corners: [0; 4],
                    face,
                    object: f.object,
                    area: 0.0,
                    centroid: DVec3::ZERO,
                    normal: f.polygon.normal(),
                    radius: 0.0,
                    reflectance: f.reflectance,
                    emission: f.emission,
                };
                let s = LATTICE_STEPS;
                let lattice = if f.polygon.is_quad() {
                    [[0, 0], [s, 0], [s, s], [0, s]]
                } else {
                    [[0, 0], [s, 0], [0, s], [0, s]]
                };
                nodes[index as usize] = element_node(
                    Element {
                        patch,
                        lattice,
                        depth: 0,
                        size_scale: f.polygon.radius().min(typical_radius),
                    },
                    parent,
                    faces,
                );
                face_node[face as usize] = index;
                continue;
            }
            let (lo, hi) = bounds(order[range.clone()].iter().map(|&f| centroids[f as usize]));
            let extent = hi - lo;
            let axis = if extent.x >= extent.y && extent.x >= extent.z {
                0
            } else if extent.y >= extent.z {
                1
            } else {
                2
            };
            let half = range.len() / 2;
            order[range.clone()].select_nth_unstable_by(half, |a, b| {
                centroids[*a as usize][axis].total_cmp(&centroids[*b as usize][axis])
            });
            let first = nodes.len() as u32;
            nodes.push(placeholder.clone());
            nodes.push(placeholder.clone());
            nodes[index as usize] = Node {
                first_child: first,
                child_count: 2,
                parent,
                faces,
                ..placeholder.clone()
            };
            stack.push((first, range.start..range.start + half, index));
            stack.push((first + 1, range.start + half..range.end, index));
        }
        // Clusters from their children, bottom-up.
        for i in (0..nodes.len()).rev() {
            if nodes[i].element.is_some() {
                continue;
            }
            let children: Vec<Node> = nodes[i]
                .children()
                .map(|c| nodes[c as usize].clone())
                .collect();
            let area: f64 = children.iter().map(|c| c.area).sum();
            let centroid = children.iter().map(|c| c.centroid * c.area).sum::<DVec3>() / area;
            let node = &mut nodes[i];
            node.area = area;
            node.centroid = centroid;
            node.bounds = children
                .iter()
                .map(|c| c.bounds)
                .reduce(union)
                .expect("a cluster has children");
            node.radius = children
                .iter()
                .map(|c| c.centroid.distance(centroid) + c.radius)
                .fold(0.0, f64::max);
            node.reflectance = children.iter().map(|c| c.reflectance).fold(0.0, f64::max);
        }
        let mut area_prefix = vec![0.0];
        for &f in &order {
            area_prefix.push(
                area_prefix.last().copied().unwrap_or(0.0) + scene.faces[f as usize].polygon.area(),
            );
        }
        let clusters = nodes.iter().filter(|n| n.element.is_none()).count();
        Hierarchy {
            nodes,
            order,
            area_prefix,
            faces: scene.faces.iter().map(|f| f.polygon).collect(),
            face_node,
            face_closed: vec![false; face_count],
            links: Vec::new(),
            leaves: Vec::new(),
            offsets: Vec::new(),
            incoming: Vec::new(),
            row_scale: Vec::new(),
            seen_share: Vec::new(),
            seen_area: Vec::new(),
            slopes: Vec::new(),
            stats: HierarchyStats {
                clusters,
                ..HierarchyStats::default()
            },
        }
    }

    /// What refinement and solving cost so far.
    pub fn stats(&self) -> HierarchyStats {
        self.stats
    }

    /// The patch of node `n`, which must be an element (a leaf, a face or a piece of one).
    fn element_patch(&self, n: u32) -> &Patch {
        &self.nodes[n as usize]
            .element
            .as_ref()
            .expect("an element, not a cluster")
            .patch
    }

    /// Whether node `n` is an element not split yet: splitting it adds three leaves.
    fn is_unsplit_element(&self, n: u32) -> bool {
        let node = &self.nodes[n as usize];
        node.element.is_some() && node.child_count == 0
    }

    /// Splits element `n` into four (once).
    fn subdivide(&mut self, n: u32) {
        let node = &self.nodes[n as usize];
        if node.child_count > 0 {
            return;
        }
        let element = node.element.clone().expect("only elements are subdivided");
        let faces = node.faces.clone();
        let face = &self.faces[element.patch.face as usize];
        let l = element.lattice;
        let children: [[[u32; 2]; 4]; 4] = if face.is_quad() {
            let centre = midpoint(l[0], l[2]);
            let (m01, m12, m23, m30) = (
                midpoint(l[0], l[1]),
                midpoint(l[1], l[2]),
                midpoint(l[2], l[3]),
                midpoint(l[3], l[0]),
            );
            [
                [l[0], m01, centre, m30],
                [m01, l[1], m12, centre],
                [centre, m12, l[2], m23],
                [m30, centre, m23, l[3]],
            ]
        } else {
            let (ab, bc, ca) = (
                midpoint(l[0], l[1]),
                midpoint(l[1], l[2]),
                midpoint(l[2], l[0]),
            );
            [
                [l[0], ab, ca, ca],
                [ab, l[1], bc, bc],
                [ca, bc, l[2], l[2]],
                [ab, bc, ca, ca],
            ]
        };
        let first = self.nodes.len() as u32;
        for lattice in children {
            let p = lattice.map(|at| lattice_point(face, at));
            let polygon = if face.is_quad() {
                Polygon::quad(p[0], p[1], p[2], p[3])
            } else {
                Polygon::triangle(p[0], p[1], p[2])
            };
            let patch = Patch {
                polygon,
                ..element.patch
            };
            self.nodes.push(element_node(
                Element {
                    patch,
                    lattice,
                    depth: element.depth + 1,
                    size_scale: element.size_scale,
                },
                n,
                faces.clone(),
            ));
        }
        let node = &mut self.nodes[n as usize];
        node.first_child = first;
        node.child_count = 4;
    }

    /// A point of node `n` for the `k`-th sample of a stream: its position, normal and face.
    /// Points spread by area over the faces below a cluster.
    fn sample(&self, n: u32, k: u32, seed: u64) -> (DVec3, DVec3, u32) {
        let node = &self.nodes[n as usize];
        let (u, v) = stratified_uv(k, seed);
        if let Some(e) = &node.element {
            return (e.patch.polygon.point_at(u, v), e.patch.normal, e.patch.face);
        }
        let pick = (splitmix64(seed ^ k as u64) >> 11) as f64 / (1u64 << 53) as f64;
        let (start, end) = (node.faces.start as usize, node.faces.end as usize);
        let target =
            self.area_prefix[start] + pick * (self.area_prefix[end] - self.area_prefix[start]);
        let position = (start + self.area_prefix[start + 1..=end].partition_point(|&c| c < target))
            .min(end - 1);
        let face = self.order[position];
        let polygon = &self.faces[face as usize];
        (polygon.uniform_point(u, v, pick), polygon.normal(), face)
    }

    /// Links from `pending` pairs, refined until every kept one is accurate enough. Past
    /// `max_leaves` it marks the budget reached and then stops at once if `abandon`, else goes on
    /// without element splits.
    fn refine(
        &mut self,
        refiner_state: (Vec<f64>, Vec<f64>, f64, f64),
        occluders: &Occluders,
        rays: FormFactorSettings,
        mut pending: Vec<(u32, u32)>,
        (max_leaves, abandon): (usize, bool),
    ) -> (u64, u64) {
        let (mut radiosity, mut spread, tolerance, smallest) = refiner_state;
        let (mut rays_cast, mut shaft_decided) = (0, 0);
        let mut leaves = self.leaves.len();
        while !pending.is_empty() {
            let mut decide = |pairs: &[(u32, u32)], frozen: bool| {
                let refiner = Refiner {
                    hierarchy: self,
                    occluders,
                    rays,
                    radiosity: &radiosity,
                    spread: &spread,
                    tolerance,
                    smallest: smallest_while(frozen, smallest),
                    rays_cast: AtomicU64::new(0),
                    shaft_decided: AtomicU64::new(0),
                };
                let decisions: Vec<Decision> = pairs
                    .par_iter()
                    .map(|&(r, s)| refiner.decide(r, s))
                    .collect();
                rays_cast += refiner.rays_cast.into_inner();
                shaft_decided += refiner.shaft_decided.into_inner();
                decisions
            };
            let frozen = self.stats.leaf_budget_reached;
            let mut decisions = decide(&pending, frozen);
            if !frozen {
                let (splits, new_leaves) = self.element_splits(&pending, &decisions);
                if leaves + new_leaves <= max_leaves {
                    leaves += new_leaves;
                } else if abandon {
                    self.stats.leaf_budget_reached = true;
                    return (rays_cast, shaft_decided);
                } else {
                    // Over budget: the pairs that asked for element splits decide again without them.
                    let pairs: Vec<(u32, u32)> = splits.iter().map(|&i| pending[i]).collect();
                    splits
                        .iter()
                        .zip(decide(&pairs, true))
                        .for_each(|(&i, decision)| decisions[i] = decision);
                    self.stats.leaf_budget_reached = true;
                }
            }
            let mut next = Vec::new();
            for ((r, s), decision) in pending.into_iter().zip(decisions) {
                match decision {
                    Decision::Drop => {}
                    Decision::Keep(link) => self.links.push(link),
                    Decision::SplitReceiver => {
                        self.split_for(r, &mut radiosity, &mut spread);
                        next.extend(self.nodes[r as usize].children().map(|c| (c, s)));
                    }
                    Decision::SplitSource => {
                        self.split_for(s, &mut radiosity, &mut spread);
                        next.extend(self.nodes[s as usize].children().map(|c| (r, c)));
                    }
                    Decision::SplitBoth => {
                        let children = self.nodes[r as usize].children();
                        next.extend(
                            children
                                .clone()
                                .flat_map(|a| children.clone().map(move |b| (a, b))),
                        );
                    }
                }
            }
            pending = next;
        }
        (rays_cast, shaft_decided)
    }

    /// Which of `decisions` (for `pending`) split a leaf element, and how many leaves those
    /// splits add.
    fn element_splits(
        &self,
        pending: &[(u32, u32)],
        decisions: &[Decision],
    ) -> (Vec<usize>, usize) {
        let mut marked = vec![false; self.nodes.len()];
        let (mut indices, mut added) = (Vec::new(), 0);
        for (i, (&(r, s), decision)) in pending.iter().zip(decisions).enumerate() {
            let n = match decision {
                Decision::SplitReceiver => r,
                Decision::SplitSource => s,
                _ => continue,
            };
            if self.is_unsplit_element(n) {
                indices.push(i);
                if !std::mem::replace(&mut marked[n as usize], true) {
                    added += 3;
                }
            }
        }
        (indices, added)
    }

    /// Subdivides `n` if it is an element, giving new children their parent's radiosity.
    fn split_for(&mut self, n: u32, radiosity: &mut Vec<f64>, spread: &mut Vec<f64>) {
        if self.is_unsplit_element(n) {
            self.subdivide(n);
            let (b, d) = (radiosity[n as usize], spread[n as usize]);
            radiosity.resize(self.nodes.len(), b);
            // A new child inherits its parent's mean; its spread is unknown but at most the parent's.
            spread.resize(self.nodes.len(), d);
        }
    }

    /// Per node, the largest channel of its area-mean radiosity and the spread of that over
    /// its leaves, from per-leaf radiosity.
    fn node_radiosity(&self, leaf_radiosity: &[Rgb]) -> (Vec<f64>, Vec<f64>) {
        let mean = self.pull(leaf_radiosity);
        let mut low = vec![f64::INFINITY; self.nodes.len()];
        let mut high = vec![0.0f64; self.nodes.len()];
        // A buried leaf sends nothing anyone gathers: its value is no spread of the source.
        for (i, &leaf) in self
            .leaves
            .iter()
            .enumerate()
            .filter(|(_, leaf)| self.seen_area[**leaf as usize] > 0.0)
        {
            let b = leaf_radiosity[i].max_element();
            (low[leaf as usize], high[leaf as usize]) = (b, b);
        }
        for n in (0..self.nodes.len()).rev() {
            for c in self.nodes[n].children() {
                low[n] = low[n].min(low[c as usize]);
                high[n] = high[n].max(high[c as usize]);
            }
        }
        let spread = high
            .iter()
            .zip(&low)
            .map(|(h, l)| (h - l).max(0.0))
            .collect();
        (mean.iter().map(|b| b.max_element()).collect(), spread)
    }

    /// The radiosity every node sends: the mean of its leaves' over the area light reaches.
    /// Buried area (under a box on the floor) is seen by nothing, and its link factors carry no
    /// share of it; counting its darkness in the mean ran every link from such a source low
    /// (the Cornell floor sent 4-9% too little, measured against dense factors on the same leaves).
    /// A node with no reached area sends nothing.
    fn pull(&self, leaf_radiosity: &[Rgb]) -> Vec<Rgb> {
        let mut node_radiosity = vec![Rgb::ZERO; self.nodes.len()];
        for (i, &leaf) in self.leaves.iter().enumerate() {
            node_radiosity[leaf as usize] = leaf_radiosity[i];
        }
        for n in (0..self.nodes.len()).rev() {
            let node = &self.nodes[n];
            if node.child_count > 0 && self.seen_area[n] > 0.0 {
                let sum = node.children().fold(Rgb::ZERO, |sum, c| {
                    sum + node_radiosity[c as usize] * self.seen_area[c as usize]
                });
                node_radiosity[n] = sum / self.seen_area[n];
            }
        }
        node_radiosity
    }

    /// Per node, its sent radiosity's slope along its tangent frame (see [`Slope`]). A link
    /// centred off the centre then gathers what that part of the source sends, not the mean:
    /// where a source is bright just where the receiver sees it best, the mean ran links low
    /// (the Cornell floor under its lamp; energy -2.3% at knob 0.02, -0.9% with slopes read
    /// within their reach).
    fn slopes_of(&self, means: &[Rgb]) -> Vec<[Rgb; 2]> {
        (0..self.nodes.len())
            .into_par_iter()
            .map(|n| {
                let mut gradient = [Rgb::ZERO; 2];
                for (c, weights) in self.nodes[n].children().zip(&self.slopes[n].child_weights) {
                    gradient[0] += means[c as usize] * weights[0];
                    gradient[1] += means[c as usize] * weights[1];
                }
                gradient
            })
            .collect()
    }

    /// Where link `offset` reads its source's model: from the centre, within the reach.
    fn reading_point(&self, source: u32, offset: [f32; 2]) -> [f32; 2] {
        let slope = &self.slopes[source as usize];
        [0, 1].map(|k| {
            (offset[k] as f64 + slope.shift[k]).clamp(-slope.reach[k], slope.reach[k]) as f32
        })
    }

    /// The weighted least-squares slope of each element node's children's means (weights: their
    /// reached area), as weights on those means; zero for leaves, clusters and degenerate fits.
    fn fit_slopes(&mut self) {
        self.slopes = (0..self.nodes.len())
            .into_par_iter()
            .map(|n| {
                let node = &self.nodes[n];
                let (Some(element), true) = (&node.element, self.seen_area[n] > 0.0) else {
                    return Slope::default();
                };
                let (tangent, bitangent) = element.patch.normal.any_orthonormal_pair();
                let frame = |p: DVec3| [p.dot(tangent), p.dot(bitangent)];
                let children: Vec<(f64, DVec3)> = node
                    .children()
                    .map(|c| (self.seen_area[c as usize], self.nodes[c as usize].centroid))
                    .collect();
                let mean_centre =
                    children.iter().map(|(w, c)| *c * *w).sum::<DVec3>() / self.seen_area[n];
                let offsets: Vec<[f64; 2]> = children
                    .iter()
                    .map(|(_, c)| frame(*c - mean_centre))
                    .collect();
                let (mut m00, mut m01, mut m11) = (0.0, 0.0, 0.0);
                for ((w, _), d) in children.iter().zip(&offsets) {
                    (m00, m01, m11) = (
                        m00 + w * d[0] * d[0],
                        m01 + w * d[0] * d[1],
                        m11 + w * d[1] * d[1],
                    );
                }
                let determinant = m00 * m11 - m01 * m01;
                if determinant <= 1e-9 * (m00 + m11) * (m00 + m11) {
                    return Slope::default();
                }
                let reach =
                    [0, 1].map(|k| 0.5 * offsets.iter().map(|d| d[k].abs()).fold(0.0, f64::max));
                let mut slope = Slope {
                    shift: frame(node.centroid - mean_centre),
                    reach,
                    ..Slope::default()
                };
                for (k, ((w, _), d)) in children.iter().zip(&offsets).enumerate() {
                    // (M^-1 w d): the slope is linear in the children's means.
                    slope.child_weights[k] = [
                        w * (m11 * d[0] - m01 * d[1]) / determinant,
                        w * (m00 * d[1] - m01 * d[0]) / determinant,
                    ];
                }
                slope
            })
            .collect();
    }

    /// Measures the leaves not measured yet and sums the reached area up the trees.
    fn measure_seen_area(&mut self, occluders: &Occluders) {
        self.seen_share.resize(self.nodes.len(), f64::NAN);
        let unmeasured: Vec<u32> = self
            .leaves
            .iter()
            .copied()
            .filter(|&n| self.seen_share[n as usize].is_nan())
            .collect();
        let shares: Vec<f64> = unmeasured
            .par_iter()
            .map(|&n| {
                let patch = self.element_patch(n);
                let mut share = 0.0;
                let mut point = 0;
                patch.polygon.for_each_quadrature_point(1, |x, weight| {
                    point += 1;
                    if !is_buried(x, patch, occluders, pair_seed(n as usize, point)) {
                        share += weight;
                    }
                });
                share
            })
            .collect();
        for (n, share) in unmeasured.into_iter().zip(shares) {
            self.seen_share[n as usize] = share;
        }
        self.seen_area = vec![0.0; self.nodes.len()];
        for &leaf in &self.leaves {
            self.seen_area[leaf as usize] =
                self.nodes[leaf as usize].area * self.seen_share[leaf as usize];
        }
        for n in (0..self.nodes.len()).rev() {
            let reached: f64 = self.nodes[n]
                .children()
                .map(|c| self.seen_area[c as usize])
                .sum();
            self.seen_area[n] += reached;
        }
    }

    /// Rebuilds the leaf list, the reached areas and the link operator after refinement.
    fn index(&mut self, occluders: &Occluders) {
        self.leaves.clear();
        for &root in &self.face_node {
            let mut stack = vec![root];
            while let Some(n) = stack.pop() {
                let node = &self.nodes[n as usize];
                if node.child_count == 0 {
                    self.leaves.push(n);
                } else {
                    // Reversed, so that children come out in their own order.
                    stack.extend(node.children().rev());
                }
            }
        }
        self.measure_seen_area(occluders);
        self.fit_slopes();
        // Links grouped by receiver (a counting sort).
        let mut offsets = vec![0u32; self.nodes.len() + 1];
        for link in &self.links {
            offsets[link.receiver as usize + 1] += 1;
        }
        for n in 0..self.nodes.len() {
            offsets[n + 1] += offsets[n];
        }
        let mut cursor = offsets.clone();
        let mut incoming = vec![(0u32, 0f32, [0f32; 2]); self.links.len()];
        for link in &self.links {
            let slot = &mut cursor[link.receiver as usize];
            incoming[*slot as usize] = (
                link.source,
                link.factor,
                self.reading_point(link.source, link.offset),
            );
            *slot += 1;
        }
        self.offsets = offsets;
        self.incoming = incoming;
        // Row sums: what each leaf gathers when every radiosity is one. A leaf of a face whose
        // view is closed sends all its light to surfaces, so its row must sum to one.
        self.row_scale = vec![1.0; self.leaves.len()];
        let mut sums = vec![Rgb::ZERO; self.leaves.len()];
        self.gather(&vec![Rgb::ONE; self.leaves.len()], &mut sums);
        for (i, &leaf) in self.leaves.iter().enumerate() {
            let face = self.element_patch(leaf).face;
            if self.face_closed[face as usize] && sums[i].x > 0.0 {
                self.row_scale[i] = 1.0 / sums[i].x;
            }
        }
        self.stats.elements = self.leaves.len();
        self.stats.links = self.links.len();
    }

    fn leaf_patch(&self, i: usize) -> &Patch {
        self.element_patch(self.leaves[i])
    }

    /// The leaves as a mesh: face by face, corners shared between the leaves of a face.
    pub fn leaf_mesh(&self) -> Mesh {
        let mut mesh = Mesh::default();
        let mut corner_ids: HashMap<(u32, [u32; 2]), u32> = HashMap::new();
        for &leaf in &self.leaves {
            let element = self.nodes[leaf as usize]
                .element
                .as_ref()
                .expect("leaves are elements");
            let face = element.patch.face;
            let count = element.patch.polygon.corners().len();
            let mut corners = [0u32; 4];
            for (k, &at) in element.lattice[..count].iter().enumerate() {
                corners[k] = *corner_ids.entry((face, at)).or_insert_with(|| {
                    mesh.positions.push(element.patch.polygon.corners()[k]);
                    mesh.positions.len() as u32 - 1
                });
            }
            if count == 3 {
                corners[3] = corners[2];
            }
            mesh.patches.push(Patch {
                corners,
                ..element.patch
            });
        }
        mesh
    }

    /// Solves for the leaves' `emission` (one per leaf) from `initial`.
    pub fn solve(
        &self,
        emission: &[Rgb],
        initial: Option<&[Rgb]>,
        settings: &SolverSettings,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<SolveOutcome, NeedsEntries> {
        let reflectance: Vec<Rgb> = (0..self.leaves.len())
            .map(|i| self.leaf_patch(i).reflectance)
            .collect();
        let area: Vec<f64> = (0..self.leaves.len())
            .map(|i| self.leaf_patch(i).area)
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
        (0..self.leaves.len())
            .map(|i| self.leaf_patch(i).emission)
            .collect()
    }

    /// Builds the hierarchy of `scene`: refines on an estimate, then, up to
    /// `settings.max_rounds` times, solves and refines the links the solution shows too coarse.
    /// Returns it with the last solution carried to its leaves, to start the final solve from.
    pub fn build(
        scene: &Scene,
        occluders: &Occluders,
        settings: &HierarchySettings,
        rays: FormFactorSettings,
        solver: &SolverSettings,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<(Hierarchy, Vec<Rgb>), NeedsEntries> {
        // Over the leaf budget, the whole refinement again at twice the knob: stopping one
        // part-way leaves whichever elements came first fine and the rest coarse (the furnished
        // room at knob 0.03 stopped so ran 17% RMS; refined at 0.2 it runs 9%). Past 0.5 there
        // is nothing coarser to try, and elements stop splitting instead.
        let abandon = 2.0 * settings.error < 1.0;
        let mut hierarchy = Hierarchy::new(scene);
        hierarchy.face_closed = hierarchy
            .face_node
            .par_iter()
            .enumerate()
            .map(|(face, &n)| sees_closed_view(hierarchy.element_patch(n), face, occluders))
            .collect();
        hierarchy.index(occluders);
        let smallest = MIN_RADIUS_PER_ERROR * settings.error;
        // First estimate: emission plus an ambient term (Cohen et al. 1988): the emitted power
        // spread over all area, reflected by the mean reflectance.
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
        let ambient =
            power / (total_area * (Rgb::ONE - reflected / total_area).max(Rgb::splat(1e-3)));
        let mut radiosity: Vec<Rgb> = (0..hierarchy.leaves.len())
            .map(|i| {
                hierarchy.leaf_patch(i).emission + hierarchy.leaf_patch(i).reflectance * ambient
            })
            .collect();
        let mut pending = if hierarchy.nodes.is_empty() {
            Vec::new()
        } else {
            vec![(0, 0)]
        };
        for round in 0..settings.max_rounds.max(1) {
            if round > 0 {
                let solved = hierarchy.solve(
                    &hierarchy.leaf_emission(),
                    Some(&radiosity),
                    solver,
                    progress,
                )?;
                hierarchy.stats.refinement_iterations += solved.iterations;
                radiosity = solved.radiosity;
            }
            let (node_radiosity, node_spread) = hierarchy.node_radiosity(&radiosity);
            let tolerance = settings.error * mean_reflected(&hierarchy, &radiosity);
            if round > 0 {
                // Links that the new solution shows too coarse go back to refinement; only
                // those that can still be split count as changes.
                let node = |n: u32| &hierarchy.nodes[n as usize];
                let smallest = smallest_while(hierarchy.stats.leaf_budget_reached, smallest);
                let (redo, keep): (Vec<Link>, Vec<Link>) =
                    hierarchy.links.par_iter().partition(|l| {
                        let source = (
                            node_radiosity[l.source as usize],
                            node_spread[l.source as usize],
                        );
                        split_side(
                            node(l.receiver),
                            node(l.source),
                            link_errors(node(l.receiver), source, l.factor as f64, l.spread as f64),
                            tolerance,
                            smallest,
                        )
                        .is_some()
                    });
                if redo.is_empty() {
                    break;
                }
                hierarchy.links = keep;
                pending = redo.iter().map(|l| (l.receiver, l.source)).collect();
            }
            let (before, mut inherited) = (hierarchy.nodes.len(), hierarchy.pull(&radiosity));
            let (rays_cast, shaft_decided) = hierarchy.refine(
                (node_radiosity, node_spread, tolerance, smallest),
                occluders,
                rays,
                std::mem::take(&mut pending),
                (settings.max_leaves, abandon),
            );
            hierarchy.stats.rays += rays_cast;
            hierarchy.stats.shaft_decided += shaft_decided;
            hierarchy.stats.rounds = round + 1;
            if abandon && hierarchy.stats.leaf_budget_reached {
                return Hierarchy::build(
                    scene,
                    occluders,
                    &HierarchySettings {
                        error: 2.0 * settings.error,
                        ..*settings
                    },
                    rays,
                    solver,
                    progress,
                );
            }
            // New leaves start from their parent's value.
            inherited.resize(hierarchy.nodes.len(), Rgb::ZERO);
            for n in before..hierarchy.nodes.len() {
                inherited[n] = inherited[hierarchy.nodes[n].parent as usize];
            }
            hierarchy.index(occluders);
            radiosity = hierarchy
                .leaves
                .iter()
                .map(|&n| inherited[n as usize])
                .collect();
        }
        hierarchy.stats.knob_used = settings.error;
        Ok((hierarchy, radiosity))
    }
}

/// Mean over the reached area of the leaves of the largest channel of reflected radiosity
/// (`B - E`): the scale errors are measured against, which a small bright lamp does not inflate.
fn mean_reflected(hierarchy: &Hierarchy, radiosity: &[Rgb]) -> f64 {
    let (sum, area) = radiosity
        .iter()
        .enumerate()
        .fold((0.0, 0.0), |(sum, area), (i, b)| {
            let (patch, reached) = (
                hierarchy.leaf_patch(i),
                hierarchy.seen_area[hierarchy.leaves[i] as usize],
            );
            (
                sum + (*b - patch.emission).max(Rgb::ZERO).max_element() * reached,
                area + reached,
            )
        });
    if area > 0.0 { sum / area } else { 0.0 }
}

/// The radiosity errors a link into `receiver` can carry, from its source's (mean, spread) of
/// radiosity: `rho_R B_S dF` from the factor's spread over the receiver (only splitting the
/// receiver reduces it) and `rho_R F dB_S` from the source's own spread (only splitting the
/// source does).
fn link_errors(
    receiver: &Node,
    (radiosity, radiosity_spread): (f64, f64),
    factor: f64,
    spread: f64,
) -> (f64, f64) {
    (
        receiver.reflectance * radiosity * spread,
        receiver.reflectance * factor * radiosity_spread,
    )
}

/// Which end of a link to split: `Some(true)` the receiver, `Some(false)` the source, `None`
/// when no end that would help can be split. Between elements the factor is integrated at the
/// receiver's points for any source size, so the receiver helps against `receiver_error` (the
/// factor's spread) and the source against `source_error` (its radiosity's spread): the end
/// with the larger error splits, or the other if that one is at the smallest size and its own
/// error still exceeds the `tolerance`. With a cluster at either end, whose factor is only a
/// bound or a sample, the larger end is split.
fn split_side(
    r: &Node,
    s: &Node,
    (receiver_error, source_error): (f64, f64),
    tolerance: f64,
    smallest: f64,
) -> Option<bool> {
    let can_split = |n: &Node| {
        n.element
            .as_ref()
            .is_none_or(|e| n.radius > smallest * e.size_scale && e.depth < MAX_DEPTH)
    };
    if receiver_error + source_error <= tolerance {
        return None;
    }
    if r.element.is_some() && s.element.is_some() {
        let receiver_first = receiver_error >= source_error;
        let (first, second, second_error) = if receiver_first {
            (r, s, source_error)
        } else {
            (s, r, receiver_error)
        };
        return if can_split(first) {
            Some(receiver_first)
        } else {
            (second_error > tolerance && can_split(second)).then_some(!receiver_first)
        };
    }
    match (can_split(r), can_split(s)) {
        (true, true) => Some(r.radius >= s.radius),
        (true, false) => Some(true),
        (false, true) => Some(false),
        (false, false) => None,
    }
}

/// `cos_p cos_q / d^2` between points with normals `np` and `nq` and `d` from the first to the
/// second (the form factor kernel without its 1/pi), from unnormalised dot products; zero when
/// either faces away.
fn facing_kernel(np: DVec3, nq: DVec3, d: DVec3) -> f64 {
    np.dot(d).max(0.0) * (-nq.dot(d)).max(0.0) / d.length_squared().powi(2)
}

/// The kernel-weighted mean of `q`'s points seen from `p` with nothing between: the receiver's
/// quadrature points against [`CENTROID_SAMPLES`] stratified source points each.
fn kernel_centre(p: &Patch, q: &Patch, seed: u64) -> DVec3 {
    let (mut sum, mut total, mut point) = (DVec3::ZERO, 0.0, 0u64);
    p.polygon.for_each_quadrature_point(1, |x, weight| {
        point += 1;
        for k in 0..CENTROID_SAMPLES {
            let (s, t) = stratified_uv(k, splitmix64(seed ^ point));
            let y = q.polygon.point_at(s, t);
            let d = y - x;
            let kernel = weight * facing_kernel(p.normal, q.normal, d);
            (sum, total) = (sum + y * kernel, total + kernel);
        }
    });
    if total > 0.0 { sum / total } else { q.centroid }
}

/// `point` relative to `patch`'s centroid in the patch's tangent frame.
fn tangent_coordinates(patch: &Patch, point: DVec3) -> [f32; 2] {
    let (tangent, bitangent) = patch.normal.any_orthonormal_pair();
    let d = point - patch.centroid;
    [d.dot(tangent) as f32, d.dot(bitangent) as f32]
}

/// Whether point `x` of `patch` is buried: every one of [`BURIED_RAYS`] cosine-distributed rays
/// from it meets the back of a face, as under a box standing on the floor or inside a wall that
/// cuts through it. Visibility is symmetric, so nothing sees a buried point. One ray that
/// escapes or meets a front face shows the point reachable, so a one-sided face seen from
/// behind buries only the points it covers in every direction.
fn is_buried(x: DVec3, patch: &Patch, occluders: &Occluders, seed: u64) -> bool {
    (0..BURIED_RAYS).all(|k| {
        let (u, v) = stratified_uv(k, seed);
        occluders
            .closest_hit(x, cosine_direction(patch.normal, u, v), patch.face)
            .is_some_and(|hit| !hit.front)
    })
}

/// The receiver quadrature level for the factor between elements `p` and `q`: the dense
/// path's near-field rule, and at least 3 when the factor varies over the receiver more than its
/// four-point mean (a source seen from only part of the receiver, which those points can miss).
fn integration_level(p: &Patch, q: &Patch, mean: f64, spread: f64) -> u32 {
    let near = near_pair_level(p, q).unwrap_or(1);
    if spread > mean { near.max(3) } else { near }
}

/// The smallest element radius (per error and face scale) to refine with: none can split once
/// the leaf budget is `frozen`.
fn smallest_while(frozen: bool, smallest: f64) -> f64 {
    if frozen { f64::INFINITY } else { smallest }
}

/// The median bounding radius of the scene's faces. An element's smallest size is relative to
/// its face's radius, capped at this: the shadows and contact lines a large face must resolve
/// are cast by the scene's typical faces, not sized like the face itself. Relative to the face
/// alone, the 17 m floor of the furnished room stopped at 2.4 m elements at knob 0.2 and its
/// probes ran 37% RMS off (dense at 10,000 patches: 21%); capped, 17% (docs/BENCHMARKS.md).
fn smallest_scale(scene: &Scene) -> f64 {
    let mut radii: Vec<f64> = scene.faces.iter().map(|f| f.polygon.radius()).collect();
    if radii.is_empty() {
        return 0.0;
    }
    let middle = radii.len() / 2;
    *radii.select_nth_unstable_by(middle, f64::total_cmp).1
}

/// A node for element `e` under `parent`.
fn element_node(mut e: Element, parent: u32, faces: Range<u32>) -> Node {
    let polygon = e.patch.polygon;
    (e.patch.area, e.patch.centroid, e.patch.radius) =
        (polygon.area(), polygon.centroid(), polygon.radius());
    Node {
        first_child: 0,
        child_count: 0,
        parent,
        area: e.patch.area,
        centroid: e.patch.centroid,
        radius: e.patch.radius,
        bounds: bounds(polygon.corners().iter().copied()),
        reflectance: e.patch.reflectance.max_element(),
        faces,
        element: Some(e),
    }
}

impl Transport for Hierarchy {
    fn patch_count(&self) -> usize {
        self.leaves.len()
    }

    fn gather(&self, radiosity: &[Rgb], out: &mut [Rgb]) {
        let means = self.pull(radiosity);
        let slopes = self.slopes_of(&means);
        let mut down: Vec<Rgb> = (0..self.nodes.len())
            .into_par_iter()
            .map(|n| {
                let links = &self.incoming[self.offsets[n] as usize..self.offsets[n + 1] as usize];
                links
                    .iter()
                    .map(|&(s, f, o)| {
                        let [du, dv] = slopes[s as usize];
                        (means[s as usize] + du * o[0] as f64 + dv * o[1] as f64) * f as f64
                    })
                    .sum()
            })
            .collect();
        // Push: parents come before children, so one forward pass sums each leaf's ancestors.
        for n in 0..self.nodes.len() {
            let parent = self.nodes[n].parent;
            if parent != NONE {
                down[n] = down[n] + down[parent as usize];
            }
        }
        for (i, o) in out.iter_mut().enumerate() {
            *o = down[self.leaves[i] as usize] * self.row_scale[i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Material;
    use glam::dvec3;

    fn closed_cube() -> Scene {
        let mut scene = Scene::default();
        let material = Material {
            reflectance: Rgb::splat(0.5),
            emission: Rgb::ONE,
        };
        let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
        for (origin, u, v) in [
            (DVec3::ZERO, z, x),
            (y, x, z),
            (DVec3::ZERO, y, z),
            (x, z, y),
            (DVec3::ZERO, x, y),
            (z, y, x),
        ] {
            let object = scene.add_object("wall");
            scene.add_polygon(
                object,
                &[origin, origin + u, origin + u + v, origin + v],
                material,
            );
        }
        scene
    }

    fn build(scene: &Scene, error: f64) -> Hierarchy {
        let occluders = Occluders::new(scene);
        let settings = HierarchySettings {
            error,
            ..HierarchySettings::default()
        };
        Hierarchy::build(
            scene,
            &occluders,
            &settings,
            FormFactorSettings::default(),
            &SolverSettings::default(),
            &crate::no_progress,
        )
        .expect("gmres needs no entries")
        .0
    }

    #[test]
    fn rows_of_a_closed_box_sum_to_one_before_normalisation() {
        let scene = closed_cube();
        for error in [0.1, 0.03] {
            let hierarchy = build(&scene, error);
            assert!(hierarchy.face_closed.iter().all(|c| *c));
            let mut sums = vec![Rgb::ZERO; hierarchy.leaves.len()];
            hierarchy.gather(&vec![Rgb::ONE; hierarchy.leaves.len()], &mut sums);
            let worst = sums
                .iter()
                .zip(&hierarchy.row_scale)
                .map(|(s, k)| (s.x / k - 1.0).abs())
                .fold(0.0, f64::max);
            println!(
                "error {error}: {} leaves, {} links, worst raw row sum off by {worst:.4}",
                hierarchy.leaves.len(),
                hierarchy.links.len()
            );
            assert!(
                worst < 2.0 * error,
                "error {error}: worst row sum off by {worst}"
            );
        }
    }

    /// A 4 x 4 room (faces inwards) lit by its ceiling, with a closed box of five faces standing
    /// on the floor over [1, 2] x [1, 2]: lattice lines of the floor at depth 2.
    fn room_with_a_box() -> Scene {
        let mut scene = Scene::default();
        let grey = Material {
            reflectance: Rgb::splat(0.5),
            emission: Rgb::ZERO,
        };
        let lamp = Material {
            reflectance: Rgb::splat(0.5),
            emission: Rgb::ONE,
        };
        let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
        let mut add = |name: &str, origin: DVec3, u: DVec3, v: DVec3, material: Material| {
            let object = scene.add_object(name);
            scene.add_polygon(
                object,
                &[origin, origin + u, origin + u + v, origin + v],
                material,
            );
        };
        let s = 4.0;
        add("floor", DVec3::ZERO, z * s, x * s, grey);
        add("ceiling", y * s, x * s, z * s, lamp);
        for (origin, u, v) in [
            (DVec3::ZERO, y * s, z * s),
            (x * s, z * s, y * s),
            (DVec3::ZERO, x * s, y * s),
            (z * s, y * s, x * s),
        ] {
            add("wall", origin, u, v, grey);
        }
        let o = dvec3(1.0, 0.0, 1.0);
        for (origin, u, v) in [
            (o + y, z, x),
            (o, z, y),
            (o + x, y, z),
            (o, y, x),
            (o + z, x, y),
        ] {
            add("box", origin, u, v, grey);
        }
        scene
    }

    #[test]
    fn a_box_on_the_floor_buries_its_footprint_and_nothing_else() {
        let scene = room_with_a_box();
        let hierarchy = build(&scene, 0.1);
        let floor = hierarchy.face_node[0] as usize;
        let floor_area = hierarchy.nodes[floor].area;
        println!(
            "floor reached area {} of {floor_area}",
            hierarchy.seen_area[floor]
        );
        assert!(
            (hierarchy.seen_area[floor] - (floor_area - 1.0)).abs() < 1e-9,
            "{}",
            hierarchy.seen_area[floor]
        );
        for (face, &n) in hierarchy.face_node.iter().enumerate().skip(1) {
            let node = n as usize;
            assert!(
                (hierarchy.seen_area[node] - hierarchy.nodes[node].area).abs() < 1e-9,
                "face {face}: {}",
                hierarchy.seen_area[node]
            );
        }
    }

    #[test]
    fn a_large_floor_refines_to_the_scale_of_what_stands_on_it() {
        // A 20 m floor, a 1 m box on it and a 1 m lamp above: the median face is the box's.
        let mut scene = Scene::default();
        let grey = Material {
            reflectance: Rgb::splat(0.5),
            emission: Rgb::ZERO,
        };
        let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
        let mut add = |origin: DVec3, u: DVec3, v: DVec3, material: Material| {
            let object = scene.add_object("part");
            scene.add_polygon(
                object,
                &[origin, origin + u, origin + u + v, origin + v],
                material,
            );
        };
        add(DVec3::ZERO, z * 20.0, x * 20.0, grey);
        let o = dvec3(9.5, 0.0, 9.5);
        for (origin, u, v) in [
            (o + y, z, x),
            (o, z, y),
            (o + x, y, z),
            (o, y, x),
            (o + z, x, y),
        ] {
            add(origin, u, v, grey);
        }
        add(
            dvec3(11.0, 3.0, 9.5),
            x,
            z,
            Material {
                reflectance: Rgb::ZERO,
                emission: Rgb::splat(10.0),
            },
        );
        let error = 0.1;
        let hierarchy = build(&scene, error);
        let floor_leaves = hierarchy
            .leaves
            .iter()
            .map(|&n| &hierarchy.nodes[n as usize])
            .filter(|n| n.element.as_ref().is_some_and(|e| e.patch.face == 0));
        let finest = floor_leaves.map(|n| n.radius).fold(f64::INFINITY, f64::min);
        let (floor_radius, box_radius) = (
            scene.faces[0].polygon.radius(),
            scene.faces[1].polygon.radius(),
        );
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

    #[test]
    fn a_linear_radiosity_is_read_exactly_and_one_bright_quarter_never_below_zero() {
        let scene = room_with_a_box();
        let mut hierarchy = Hierarchy::new(&scene);
        let wall = hierarchy.face_node[2];
        hierarchy.subdivide(wall);
        for child in hierarchy.nodes[wall as usize].children() {
            hierarchy.subdivide(child);
        }
        hierarchy.index(&Occluders::new(&scene));
        let (tangent, bitangent) = hierarchy.element_patch(wall).normal.any_orthonormal_pair();
        let centroid = hierarchy.nodes[wall as usize].centroid;
        let linear = |p: DVec3| {
            3.0 + 0.5 * (p - centroid).dot(tangent) - 0.25 * (p - centroid).dot(bitangent)
        };
        let radiosity: Vec<Rgb> = hierarchy
            .leaves
            .iter()
            .map(|&n| Rgb::splat(linear(hierarchy.nodes[n as usize].centroid)))
            .collect();
        let means = hierarchy.pull(&radiosity);
        let slopes = hierarchy.slopes_of(&means);
        for offset in [[0.0, 0.0], [0.3, -0.7], [-0.9, 0.4]] {
            let [u, v] = hierarchy.reading_point(wall, offset);
            let read = means[wall as usize]
                + slopes[wall as usize][0] * u as f64
                + slopes[wall as usize][1] * v as f64;
            let expected = linear(centroid + tangent * u as f64 + bitangent * v as f64);
            assert!(
                (read.x - expected).abs() < 1e-6,
                "at {offset:?}: {} vs {expected}",
                read.x
            );
        }
        // One bright grandchild quarter: every reading stays a mix of non-negative means.
        let bright = hierarchy.nodes[wall as usize].first_child;
        let radiosity: Vec<Rgb> = hierarchy
            .leaves
            .iter()
            .map(|&n| {
                if hierarchy.nodes[n as usize].parent == bright {
                    Rgb::ONE
                } else {
                    Rgb::ZERO
                }
            })
            .collect();
        let means = hierarchy.pull(&radiosity);
        let slopes = hierarchy.slopes_of(&means);
        for offset in [[-5.0, -5.0], [5.0, -5.0], [-5.0, 5.0], [5.0, 5.0]] {
            let [u, v] = hierarchy.reading_point(wall, offset);
            let read = means[wall as usize]
                + slopes[wall as usize][0] * u as f64
                + slopes[wall as usize][1] * v as f64;
            assert!(read.x >= -1e-12, "at {offset:?}: {}", read.x);
        }
    }

    #[test]
    fn leaves_tile_every_face_and_share_corners() {
        let scene = closed_cube();
        let hierarchy = build(&scene, 0.1);
        let mesh = hierarchy.leaf_mesh();
        for (f, face) in scene.faces.iter().enumerate() {
            let leaves: Vec<usize> = (0..mesh.patches.len())
                .filter(|&i| mesh.patches[i].face == f as u32)
                .collect();
            // Face by face, as the accuracy harness and the viewers' smoothing expect.
            assert_eq!(
                leaves.last().expect("a face has leaves") - leaves[0] + 1,
                leaves.len()
            );
            let area: f64 = leaves.iter().map(|&i| mesh.patches[i].area).sum();
            assert!(
                (area / face.polygon.area() - 1.0).abs() < 1e-12,
                "face {f}: {area}"
            );
        }
        for patch in &mesh.patches {
            for (corner, &id) in patch.polygon.corners().iter().zip(&patch.corners) {
                assert_eq!(*corner, mesh.positions[id as usize]);
            }
        }
        // Shared corners: far fewer positions than corners of leaves.
        assert!(mesh.positions.len() * 2 < mesh.patches.len() * 4);
    }

    #[test]
    fn a_shaft_holds_every_segment_between_its_boxes_and_nothing_beside_them() {
        let a = (dvec3(0.0, 0.0, 0.0), dvec3(1.0, 1.0, 1.0));
        let b = (dvec3(4.0, 3.0, -1.0), dvec3(5.0, 5.0, 0.5));
        let shaft = Shaft::new(a, b);
        assert!(shaft.count > 0);
        let mut seed = 7u64;
        let mut unit = || {
            seed = splitmix64(seed);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..1000 {
            let p = a.0 + (a.1 - a.0) * DVec3::new(unit(), unit(), unit());
            let q = b.0 + (b.1 - b.0) * DVec3::new(unit(), unit(), unit());
            let x = p.lerp(q, unit());
            assert!(
                shaft.may_meet_box((x, x)),
                "{x} lies on a segment between the boxes"
            );
        }
        // Inside the union box but off the hull: the corner regions the planes cut away.
        assert!(!shaft.may_meet_box((dvec3(0.0, 4.5, 0.0), dvec3(0.5, 5.0, 0.2))));
        assert!(!shaft.may_meet_box((dvec3(4.5, 0.0, 0.0), dvec3(5.0, 0.5, 0.2))));
        assert!(!shaft.may_meet_points(&[dvec3(6.0, 0.0, 0.0), dvec3(7.0, 1.0, 0.0)]));
    }

    #[test]
    fn one_face_hides_a_pair_only_when_it_covers_every_segment() {
        let square = |z: f64, half: f64| {
            [
                dvec3(-half, -half, z),
                dvec3(half, -half, z),
                dvec3(half, half, z),
                dvec3(-half, half, z),
            ]
        };
        let (below, above) = (square(0.0, 0.5), square(2.0, 0.5));
        let [a, b, c, d] = square(1.0, 2.0);
        let big = Polygon::quad(a, b, c, d);
        assert!(blocks_every_segment(&big, big.normal(), &below, &above));
        let [a, b, c, d] = square(1.0, 0.4);
        let small = Polygon::quad(a, b, c, d);
        assert!(
            !blocks_every_segment(&small, small.normal(), &below, &above),
            "segments pass around a smaller square"
        );
        let [a, b, c, d] = square(0.0, 2.0);
        let level = Polygon::quad(a, b, c, d);
        assert!(
            !blocks_every_segment(&level, level.normal(), &below, &above),
            "a face in the plane of one end separates nothing"
        );
    }
}
