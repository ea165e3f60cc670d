//! The trees: a binary cluster tree of median splits over the input faces (Smits, Arvo,
//! Greenberg 1994), and under each face a quadtree of elements on an integer lattice
//! (Hanrahan, Salzman, Aupperle 1991), split only when a link asks for it; a long element
//! splits in two across its length instead of in four.

use crate::geometry::{Polygon, bounds};
use crate::mesh::{Mesh, Patch};
use crate::sampling::{splitmix64, stratified_uv, unit_interval};
use crate::scene::Scene;
use glam::DVec3;
use std::collections::HashMap;
use std::ops::Range;

/// Corners of elements are points of a per-face lattice with this many steps per side, so that
/// elements of one face share corners exactly, whatever their level.
const LATTICE_STEPS: u32 = 1 << 24;
/// Deepest split of an input face (each level halves the lattice step).
pub(super) const MAX_DEPTH: u32 = 20;
/// How many times longer one pair of a quad's sides must be than the other for it to split
/// across them only, into two halves (near square, just past it); less elongated, it splits
/// into four quarters like itself. (`sqrt 2`, past which halves are nearer square than
/// quarters, was measured too: docs/BENCHMARKS.md.)
const ELONGATED_QUAD: f64 = 2.0;
/// How many times its height onto its longest side a triangle must be long to split across
/// its length: past 2 (a right isosceles triangle's) it is a sliver.
const ELONGATED_TRIANGLE: f64 = 2.0;
/// Marks "no parent".
pub(super) const NONE: u32 = u32::MAX;

/// An axis-aligned box as (min corner, max corner).
pub(super) type Bounds = (DVec3, DVec3);

/// A piece of one input face.
#[derive(Clone, Debug)]
pub(super) struct Element {
    /// The piece as a patch (its face, object and materials are the face's).
    pub(super) patch: Patch,
    /// Lattice coordinates of the corners: `(u, v)` on a quad, `(s, t)` on a triangle.
    pub(super) lattice: [[u32; 2]; 4],
    /// Splits from the input face.
    pub(super) depth: u32,
    /// The length the smallest element is relative to ([`smallest_scale`]).
    pub(super) size_scale: f64,
}

/// A node of the hierarchy: an element (of a face) or a cluster (of faces).
#[derive(Clone, Debug)]
pub(super) struct Node {
    /// `None` for a cluster.
    pub(super) element: Option<Element>,
    pub(super) first_child: u32,
    pub(super) child_count: u32,
    /// [`NONE`] for the root.
    pub(super) parent: u32,
    pub(super) area: f64,
    pub(super) centroid: DVec3,
    /// Bounding radius about the centroid.
    pub(super) radius: f64,
    pub(super) bounds: Bounds,
    /// Largest reflectance channel of anything below.
    pub(super) reflectance: f64,
    /// Positions in [`Tree::order`] of the input faces below.
    pub(super) faces: Range<u32>,
}

/// The cluster tree over a scene's faces and the element quadtrees under them: the nodes and
/// what sampling a cluster's surfaces needs.
pub(super) struct Tree {
    pub(super) nodes: Vec<Node>,
    /// Input faces in cluster order: every cluster covers a contiguous run.
    pub(super) order: Vec<u32>,
    /// Prefix sums of face areas in `order` (for area-weighted sampling inside a cluster).
    area_prefix: Vec<f64>,
    /// Each input face's polygon.
    pub(super) faces: Vec<Polygon>,
    /// Each input face's unit normal (cluster samples take it for every point).
    face_normals: Vec<DVec3>,
    /// Each input face's root element.
    pub(super) face_node: Vec<u32>,
    /// The leaves, face by face ([`Tree::collect_leaves`]).
    pub(super) leaves: Vec<u32>,
}

/// A point drawn on a node's surfaces.
pub(super) struct SurfacePoint {
    pub(super) position: DVec3,
    pub(super) normal: DVec3,
    /// The input face it lies on.
    pub(super) face: u32,
}

impl Node {
    pub(super) fn children(&self) -> Range<u32> {
        self.first_child..self.first_child + self.child_count
    }
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

/// How an element splits. An elongated element splits across its length only, so that its
/// pieces come nearer square: a quad into two halves across its long sides, a triangle into a
/// triangle and a quad by the cut through its long sides' midpoints, parallel to its shortest
/// side. Else a quad splits into four quarters, a triangle into four similar ones.
/// Split into four like itself, a sliver's pieces are slivers: a strip 18 m x 24 cm atop a
/// real model's wall became leaves 2.3 m x 3 cm, the light along them (where a column passes
/// through the strip) read from corners metres apart; the monastery read 5.98% smooth RMS with
/// 435k leaves, split across, 5.59% with 310k (docs/BENCHMARKS.md).
#[derive(Clone, Copy)]
enum SplitShape {
    /// Two halves, cutting the sides from corner 0 to 1 and from 3 to 2.
    QuadHalvesAcrossFirstSides,
    /// Two halves, cutting the sides from corner 1 to 2 and from 3 to 0.
    QuadHalvesAcrossSecondSides,
    QuadQuarters,
    /// A tip triangle at corner `apex` and the trapezoid left.
    TriangleCutBelow {
        apex: usize,
    },
    TriangleQuarters,
}

impl SplitShape {
    fn of(polygon: &Polygon) -> SplitShape {
        let c = polygon.corners();
        if c.len() == 4 {
            let along_first = c[0].distance(c[1]) + c[3].distance(c[2]);
            let along_second = c[0].distance(c[3]) + c[1].distance(c[2]);
            return if along_first > ELONGATED_QUAD * along_second {
                SplitShape::QuadHalvesAcrossFirstSides
            } else if along_second > ELONGATED_QUAD * along_first {
                SplitShape::QuadHalvesAcrossSecondSides
            } else {
                SplitShape::QuadQuarters
            };
        }
        let sides = [0, 1, 2].map(|k| c[k].distance(c[(k + 1) % 3]));
        let longest = sides.iter().copied().fold(0.0, f64::max);
        // The height onto the longest side is twice the area over it; the margin keeps a right
        // isosceles triangle's round-off from cutting it one way and its like the other.
        if longest * longest > ELONGATED_TRIANGLE * 2.0 * polygon.area() * (1.0 + 1e-9) {
            let shortest = (0..3)
                .min_by(|&a, &b| sides[a].total_cmp(&sides[b]))
                .unwrap_or(0);
            SplitShape::TriangleCutBelow {
                apex: (shortest + 2) % 3,
            }
        } else {
            SplitShape::TriangleQuarters
        }
    }

    fn child_count(self) -> usize {
        match self {
            SplitShape::QuadQuarters | SplitShape::TriangleQuarters => 4,
            _ => 2,
        }
    }

    /// The children's lattices for an element with corner lattice points `l`; the first
    /// [`SplitShape::child_count`] are the children.
    fn child_lattices(self, l: [[u32; 2]; 4]) -> [[[u32; 2]; 4]; 4] {
        let mid = midpoint;
        match self {
            SplitShape::QuadHalvesAcrossFirstSides => {
                let (m01, m23) = (mid(l[0], l[1]), mid(l[2], l[3]));
                let first = [l[0], m01, m23, l[3]];
                [first, [m01, l[1], l[2], m23], first, first]
            }
            SplitShape::QuadHalvesAcrossSecondSides => {
                let (m12, m30) = (mid(l[1], l[2]), mid(l[3], l[0]));
                let first = [l[0], l[1], m12, m30];
                [first, [m30, m12, l[2], l[3]], first, first]
            }
            SplitShape::QuadQuarters => {
                let (m01, m12, m23, m30) = (
                    mid(l[0], l[1]),
                    mid(l[1], l[2]),
                    mid(l[2], l[3]),
                    mid(l[3], l[0]),
                );
                // The lattice centre: a quad cut from a triangle is a trapezoid, whose
                // diagonals' midpoints differ.
                let centre = mid(m01, m23);
                [
                    [l[0], m01, centre, m30],
                    [m01, l[1], m12, centre],
                    [centre, m12, l[2], m23],
                    [m30, centre, m23, l[3]],
                ]
            }
            SplitShape::TriangleCutBelow { apex } => {
                let (a, b, d) = (l[apex], l[(apex + 1) % 3], l[(apex + 2) % 3]);
                let (ab, ad) = (mid(a, b), mid(a, d));
                let tip = [a, ab, ad, ad];
                [tip, [ab, b, d, ad], tip, tip]
            }
            SplitShape::TriangleQuarters => {
                let (ab, bc, ca) = (mid(l[0], l[1]), mid(l[1], l[2]), mid(l[2], l[0]));
                [
                    [l[0], ab, ca, ca],
                    [ab, l[1], bc, bc],
                    [ca, bc, l[2], l[2]],
                    [ab, bc, ca, ca],
                ]
            }
        }
    }
}

/// Face `face` of `scene` as one unsplit element, its size scale capped at `typical_radius`.
fn face_element(scene: &Scene, face: u32, typical_radius: f64) -> Element {
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
    Element {
        patch,
        lattice,
        depth: 0,
        size_scale: f.polygon.radius().min(typical_radius),
    }
}

/// Each cluster's area, centroid, bounds, radius and reflectance from its children's,
/// bottom-up (children follow their parent in `nodes`).
fn summarise_clusters(nodes: &mut [Node]) {
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
}

pub(super) fn union(a: Bounds, b: Bounds) -> Bounds {
    (a.0.min(b.0), a.1.max(b.1))
}

impl Tree {
    /// The cluster tree over `scene`'s faces, each face one unsplit element.
    pub(super) fn over(scene: &Scene) -> Tree {
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
                let element = face_element(scene, face, typical_radius);
                nodes[index as usize] = element_node(element, parent, faces);
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
        summarise_clusters(&mut nodes);
        let mut area_prefix = vec![0.0];
        area_prefix.extend(order.iter().scan(0.0, |sum, &f| {
            *sum += scene.faces[f as usize].polygon.area();
            Some(*sum)
        }));
        Tree {
            nodes,
            order,
            area_prefix,
            faces: scene.faces.iter().map(|f| f.polygon).collect(),
            face_normals: scene.faces.iter().map(|f| f.polygon.normal()).collect(),
            face_node,
            leaves: Vec::new(),
        }
    }

    /// The patch of node `n`, which must be an element (a leaf, a face or a piece of one).
    pub(super) fn element_patch(&self, n: u32) -> &Patch {
        &self.element(n).patch
    }

    /// The element of node `n`.
    fn element(&self, n: u32) -> &Element {
        (self.nodes[n as usize].element.as_ref()).expect("an element, not a cluster")
    }

    /// Whether node `n` is an element not split yet: splitting it adds
    /// [`Tree::children_if_split`] less one leaves.
    pub(super) fn is_unsplit_element(&self, n: u32) -> bool {
        let node = &self.nodes[n as usize];
        node.element.is_some() && node.child_count == 0
    }

    /// How many children element `n` splits into ([`SplitShape`]).
    pub(super) fn children_if_split(&self, n: u32) -> usize {
        SplitShape::of(&self.element_patch(n).polygon).child_count()
    }

    /// Splits element `n` into its children ([`SplitShape`]), once.
    pub(super) fn subdivide(&mut self, n: u32) {
        let node = &self.nodes[n as usize];
        if node.child_count > 0 {
            return;
        }
        let element = node.element.clone().expect("only elements are subdivided");
        let faces = node.faces.clone();
        let face = &self.faces[element.patch.face as usize];
        let shape = SplitShape::of(&element.patch.polygon);
        let (children, count) = (shape.child_lattices(element.lattice), shape.child_count());
        let first = self.nodes.len() as u32;
        for &lattice in &children[..count] {
            let p = lattice.map(|at| lattice_point(face, at));
            let polygon = if lattice[3] != lattice[2] {
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
        node.child_count = count as u32;
    }

    /// A point of node `n` for the `k`-th sample of a stream. Points spread by area over the
    /// faces below a cluster.
    pub(super) fn sample(&self, n: u32, k: u32, seed: u64) -> SurfacePoint {
        let node = &self.nodes[n as usize];
        let (u, v) = stratified_uv(k, seed);
        if let Some(e) = &node.element {
            return SurfacePoint {
                position: e.patch.polygon.point_at(u, v),
                normal: e.patch.normal,
                face: e.patch.face,
            };
        }
        let pick = unit_interval(splitmix64(seed ^ k as u64));
        let (start, end) = (node.faces.start as usize, node.faces.end as usize);
        let target =
            self.area_prefix[start] + pick * (self.area_prefix[end] - self.area_prefix[start]);
        let position = (start + self.area_prefix[start + 1..=end].partition_point(|&c| c < target))
            .min(end - 1);
        let face = self.order[position];
        let polygon = &self.faces[face as usize];
        // Where the pick fell within the face's share, uniform again: the pick itself, nearly
        // the same for every point of a small face, put them all in one triangle of a quad.
        let (low, high) = (self.area_prefix[position], self.area_prefix[position + 1]);
        let within = if high > low {
            ((target - low) / (high - low)).clamp(0.0, 1.0)
        } else {
            pick
        };
        SurfacePoint {
            position: polygon.uniform_point(u, v, within),
            normal: self.face_normals[face as usize],
            face,
        }
    }

    /// Lists the leaves again after refinement split elements: face by face, each face's in
    /// its quadtree's order.
    pub(super) fn collect_leaves(&mut self) {
        self.leaves.clear();
        let mut stack = Vec::new();
        for &root in &self.face_node {
            stack.push(root);
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
    }

    /// The patch of the `i`-th leaf.
    pub(super) fn leaf_patch(&self, i: usize) -> &Patch {
        self.element_patch(self.leaves[i])
    }

    /// The leaves as a mesh: face by face, corners shared between the leaves of a face on the
    /// same side of where light reaches (`buried` tells whether a leaf's `k`-th corner lies
    /// where no light reaches, for the leaf). Kept apart, a buried leaf's corners carried no
    /// longer the lit side's light into it (under a teddy bear's feet) nor its dark onto the
    /// lit side (a roof where a wall passes through), and a lit leaf's corner inside a post
    /// standing on it no longer took the dark of the leaf beside the post.
    pub fn leaf_mesh(&self, buried: impl Fn(u32, usize) -> bool) -> Mesh {
        // Corners are shared within a face alone, and the leaves are listed face by face
        // ([`Tree::collect_leaves`]): each face's run of leaves looks its corners up in a map
        // of its own, small enough to stay in cache.
        let mut mesh = Mesh {
            positions: Vec::new(),
            patches: Vec::with_capacity(self.leaves.len()),
        };
        let face_of = |leaf: u32| self.element(leaf).patch.face;
        for leaves in self.leaves.chunk_by(|&a, &b| face_of(a) == face_of(b)) {
            let mut corner_ids: HashMap<([u32; 2], bool), u32> = HashMap::new();
            for &leaf in leaves {
                let element = self.element(leaf);
                let count = element.patch.polygon.corners().len();
                let mut corners = [0u32; 4];
                for (k, &at) in element.lattice[..count].iter().enumerate() {
                    let side = buried(leaf, k);
                    corners[k] = *corner_ids.entry((at, side)).or_insert_with(|| {
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
        }
        mesh
    }
}

/// The median bounding radius of the scene's faces. An element's smallest size is relative to
/// its face's radius, capped at this: the shadows and contact lines a large face must resolve
/// are cast by the scene's typical faces, not sized like the face itself. Relative to the face
/// alone, the 17 m floor of the furnished room stopped at 2.4 m elements at knob 0.2 and its
/// probes ran 37% RMS off (dense at 10,000 patches: 21%); capped, 17% (docs/BENCHMARKS.md).
///
/// Faces count as the scene file gave them: the pieces contact lines cut a floor into are one
/// face here, or a furnished room's cut floor would make every face's scale that of its pieces.
fn smallest_scale(scene: &Scene) -> f64 {
    // The pieces of one source face follow each other.
    let mut radii: Vec<f64> = scene
        .faces
        .chunk_by(|a, b| a.source == b.source)
        .map(|pieces| {
            let area: f64 = pieces.iter().map(|f| f.polygon.area()).sum();
            let centre = pieces
                .iter()
                .map(|f| f.polygon.centroid() * f.polygon.area())
                .sum::<DVec3>()
                / area;
            pieces
                .iter()
                .flat_map(|f| f.polygon.corners())
                .map(|c| c.distance(centre))
                .fold(0.0, f64::max)
        })
        .collect();
    if radii.is_empty() {
        return 0.0;
    }
    let middle = radii.len() / 2;
    *radii.select_nth_unstable_by(middle, f64::total_cmp).1
}

/// A node for element `e` under `parent`.
pub(super) fn element_node(mut e: Element, parent: u32, faces: Range<u32>) -> Node {
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

#[cfg(test)]
mod tests {
    use super::Tree;
    use crate::geometry::Polygon;
    use crate::hierarchy::fixtures::{GREY, add_parallelogram, build, closed_cube};
    use crate::sampling::splitmix64;
    use crate::scene::Scene;
    use glam::DVec3;

    #[test]
    fn a_clusters_points_spread_over_its_faces_by_area() {
        // Two unit squares side by side, one quad face each; their cluster's points, four
        // thousand streams of sixteen, have the squares' mean position and spread: x uniform
        // over [0, 2) (mean 1, variance 1/3), z over [0, 1) (mean 1/2, variance 1/12).
        let mut scene = Scene::default();
        for x in [0.0, 1.0] {
            let origin = DVec3::new(x, 0.0, 0.0);
            add_parallelogram(&mut scene, "floor", (origin, DVec3::Z, DVec3::X), GREY);
        }
        let tree = Tree::over(&scene);
        assert!(tree.nodes[0].element.is_none(), "the root is the cluster");
        let points: Vec<DVec3> = (0..4096u64)
            .flat_map(|seed| (0..16).map(move |k| (seed, k)))
            .map(|(seed, k)| tree.sample(0, k, splitmix64(seed)).position)
            .collect();
        let n = points.len() as f64;
        let mean = points.iter().sum::<DVec3>() / n;
        let variance = points
            .iter()
            .map(|p| (*p - mean) * (*p - mean))
            .sum::<DVec3>()
            / n;
        // Within about four standard errors.
        assert!(
            (mean.x - 1.0).abs() < 0.01 && (mean.z - 0.5).abs() < 0.005,
            "{mean}"
        );
        let (vx, vz) = (variance.x - 1.0 / 3.0, variance.z - 1.0 / 12.0);
        assert!(vx.abs() < 0.01 && vz.abs() < 0.003, "{variance}");
        // Each quad's halves (either side of its diagonal from (x, 0) to (x + 1, 1)) alike.
        for square in [0.0, 1.0] {
            let on: Vec<&DVec3> = points.iter().filter(|p| p.x.floor() == square).collect();
            let below = on.iter().filter(|p| p.z < p.x - square).count();
            let share = below as f64 / on.len() as f64;
            assert!(
                (share - 0.5).abs() < 0.015,
                "square {square}: {below} of {}",
                on.len()
            );
        }
    }

    /// The leaves of `tree`'s face `face` once every leaf of it wider than `size` is split.
    fn split_down_to(tree: &mut Tree, face: usize, size: f64) -> Vec<u32> {
        loop {
            tree.collect_leaves();
            let leaves: Vec<u32> = tree
                .leaves
                .clone()
                .into_iter()
                .filter(|&n| tree.element_patch(n).face == face as u32)
                .collect();
            let wide: Vec<u32> = leaves
                .iter()
                .copied()
                .filter(|&n| tree.nodes[n as usize].radius > size)
                .collect();
            if wide.is_empty() {
                return leaves;
            }
            wide.into_iter().for_each(|n| tree.subdivide(n));
        }
    }

    /// The longest side of a polygon over its height onto that side.
    fn elongation(polygon: &Polygon) -> f64 {
        let c = polygon.corners();
        let longest = (0..c.len())
            .map(|k| c[k].distance(c[(k + 1) % c.len()]))
            .fold(0.0, f64::max);
        longest * longest / polygon.area() / if c.len() == 3 { 2.0 } else { 1.0 }
    }

    #[test]
    fn long_elements_split_across_their_length_into_pieces_near_square() {
        // A 16 x 0.25 strip as a quad and as a right triangle (a roof sliver of a real model),
        // a unit square and a unit right triangle, each split until no piece is larger than
        // 0.2 about its centroid. Split into four like themselves, the strips' pieces would be
        // strips 64 times longer than wide, 4,096 of them; across their length, every face's
        // pieces are about as many as its area holds squares of side 0.25 and tile it, and a
        // quad face's pieces are near square (a triangle's near its sharp corner cannot be).
        let mut scene = Scene::default();
        let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
        add_parallelogram(&mut scene, "strip", (DVec3::ZERO, x * 16.0, z * 0.25), GREY);
        add_parallelogram(&mut scene, "square", (y, x, z), GREY);
        let object = scene.add_object("triangles");
        scene.add_polygon(
            object,
            &[y * 2.0, y * 2.0 + x * 16.0, y * 2.0 + z * 0.25],
            GREY,
        );
        scene.add_polygon(object, &[y * 3.0, y * 3.0 + x, y * 3.0 + z], GREY);
        let mut tree = Tree::over(&scene);
        for face in 0..4 {
            let polygon = tree.faces[face];
            let leaves = split_down_to(&mut tree, face, 0.2);
            let area: f64 = leaves.iter().map(|&n| tree.nodes[n as usize].area).sum();
            assert!(
                (area / polygon.area() - 1.0).abs() < 1e-12,
                "face {face}: {area}"
            );
            let squares = polygon.area() / (0.25 * 0.25);
            assert!(
                leaves.len() as f64 <= 2.0 * squares,
                "face {face}: {} pieces",
                leaves.len()
            );
            for &n in &leaves {
                let piece = tree.element_patch(n).polygon;
                assert!(
                    !polygon.is_quad() || elongation(&piece) <= 2.0,
                    "face {face}: {:?}",
                    piece.corners()
                );
            }
        }
    }

    #[test]
    fn a_corner_buried_for_one_leaf_is_that_leafs_own_and_the_rest_stay_shared() {
        // A unit floor split into four leaves, their common corner at the centre buried for
        // the first leaf alone (a post standing there, over that leaf's reading point).
        let mut scene = Scene::default();
        add_parallelogram(&mut scene, "floor", (DVec3::ZERO, DVec3::Z, DVec3::X), GREY);
        let mut tree = Tree::over(&scene);
        tree.collect_leaves();
        tree.subdivide(tree.leaves[0]);
        tree.collect_leaves();
        assert_eq!(tree.leaves.len(), 4);
        let centre = DVec3::new(0.5, 0.0, 0.5);
        let at_centre = |p: DVec3| p.distance(centre) < 1e-12;
        let first = tree.leaves[0];
        let mesh = tree.leaf_mesh(|leaf, k| {
            leaf == first && at_centre(tree.element_patch(leaf).polygon.corners()[k])
        });
        let ids: Vec<u32> = (mesh.patches.iter())
            .flat_map(|p| p.corners[..p.corner_count()].to_vec())
            .filter(|&c| at_centre(mesh.positions[c as usize]))
            .collect();
        assert_eq!(ids.len(), 4, "each leaf has a corner at the centre");
        assert_ne!(ids[0], ids[1], "the first leaf's is its own");
        assert!(ids[1..].iter().all(|&c| c == ids[1]), "{ids:?}");
        // The 3 x 3 lattice points, the centre twice.
        assert_eq!(mesh.positions.len(), 10);
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
}
