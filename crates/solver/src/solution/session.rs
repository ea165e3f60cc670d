//! A solved scene kept live for edits: emission changes by superposition, moves by updating
//! only the form factors they can change (or rebuilding a hierarchy).

use super::display::{Displayed, split_where_direct_light_curves};
use super::report::{ObjectRadiosity, SolveReport, StageSeconds};
use super::request::{SolveError, SolveRequest, check_dense_size};
use super::vertices::{
    CornerIndirect, CornerLight, MAX_GATHERED_EMITTERS, MAX_GATHERED_EMITTING_FACES,
    clamp_below_zero, gathers_direct_light, reached_corners,
};
use crate::check::{CheckSettings, Estimate};
use crate::form_factors::{DenseFormFactors, UpdateStats};
use crate::hierarchy::{
    BuiltHierarchy, Hierarchy, HierarchySettings, HierarchyStats, PastLinkBudget,
};
use crate::mesh::Mesh;
use crate::scene::motion::{Motion, reach_after};
use crate::scene::{MAX_COORDINATE, Rgb, Scene, check_emission};
use crate::solve::{NeedsEntries, SolveOutcome, System, solve};
use crate::transport::Transport;
use crate::visibility::Occluders;
use crate::{Progress, no_progress};
use glam::DVec3;
use std::collections::{BTreeMap, BTreeSet};
use std::time::Instant;

/// How a session moves light between patches.
enum Factors {
    Dense(DenseFormFactors),
    Hierarchy(Box<Hierarchy>),
}

impl Factors {
    fn transport(&self) -> &dyn Transport {
        match self {
            Factors::Dense(factors) => factors,
            Factors::Hierarchy(hierarchy) => hierarchy.as_ref(),
        }
    }
}

/// A solved scene kept live for emission changes. Radiosity is linear in emission,
/// `B = (I - rho F)^-1 E`, so the session keeps, per edited object `k`, its response `G_k` to
/// unit emission on its patches and `R_k` to its original emission; after edits,
/// `B = B_base + sum_k (e_k * G_k - R_k)`: an O(n) sum per edit instead of a solve, exact to
/// the solver tolerance; the vertex values viewers are sent sum the same way from each
/// response's own. Each object costs one or two solves and their vertex values, once.
pub struct Session {
    scene: Scene,
    mesh: Mesh,
    factors: Factors,
    /// Direct light at the mesh corners, for the values viewers are sent.
    corner_light: CornerLight,
    /// The objects whose direct light `corner_light` gathers: those that emitted when the
    /// session began or have been set to emit since (off now or not).
    lights: BTreeSet<u32>,
    /// The solution for the scene's own emission.
    base: Vec<Rgb>,
    /// Its relative residual (infinite before the first solve).
    base_residual: f64,
    /// Its vertex values before the clamp at zero, once solved: edits add their responses'
    /// vertex values to these instead of rebuilding every vertex from the transport.
    base_vertices: Option<Vec<Rgb>>,
    /// Per edited object, its responses.
    responses: BTreeMap<u32, Response>,
    /// Bumped whenever a response's vertex values may have changed (a move, a new light's
    /// gather), so that whoever holds copies of them ([`Session::vertex_terms`]) knows.
    terms_epoch: u64,
    /// Current emission of every edited object.
    edited: BTreeMap<u32, Rgb>,
    objects: Vec<String>,
    patch_objects: Vec<u32>,
    reflectance: Vec<Rgb>,
    emission: Vec<Rgb>,
    area: Vec<f64>,
    request: SolveRequest,
    seconds: StageSeconds,
    triangles: usize,
    skipped_faces: usize,
    radiosity: Vec<Rgb>,
}

/// What one object's emission does to every patch and vertex, W/m^2.
struct Response {
    /// `G_k`: the radiosity its patches emitting one W/m^2 (each channel) give.
    unit: Vec<Rgb>,
    /// `R_k`: the radiosity its emission as loaded gives.
    original: Vec<Rgb>,
    /// The larger relative residual of the solves that made them.
    residual: f64,
    /// The vertex values of `unit` (its object emitting one W/m^2), before the clamp at zero.
    unit_vertices: Vec<Rgb>,
    /// The vertex values of `original`, likewise.
    original_vertices: Vec<Rgb>,
    /// The object's emission as loaded when every patch of it has the same (then `original`
    /// is `unit` times it).
    uniform: Option<Rgb>,
}

/// Which of an object's responses a [`VertexTerm`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum TermKey {
    /// The object emitting 1 W/m^2 in every channel.
    Unit(u32),
    /// The object emitting as loaded (patches that differ, which an edit would make uniform).
    AsLoaded(u32),
}

/// One term of the session's vertex values as a weighted sum of responses.
#[derive(Clone, Copy, Debug)]
pub struct VertexTerm<'a> {
    /// Whose response, and which.
    pub key: TermKey,
    /// The response's vertex values before the clamp at zero, per W/m^2 of `weight`.
    pub values: &'a [Rgb],
    /// W/m^2 per channel: the object's current emission (1 for [`TermKey::AsLoaded`]).
    pub weight: Rgb,
}

/// An emission change that cannot be applied.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EditError {
    /// No object has that name.
    #[error("no object named '{0}'")]
    UnknownObject(String),
    /// An emission out of range ([`crate::scene::check_emission`]).
    #[error("emission {0}")]
    InvalidEmission(String),
    /// A move out of range ([`Motion::check`]), or one that would take the object past
    /// [`crate::scene::MAX_COORDINATE`].
    #[error("{0}")]
    InvalidMove(String),
    /// A light that would stop the corners gathering ([`MAX_GATHERED_EMITTERS`] emitters of
    /// [`MAX_GATHERED_EMITTING_FACES`] faces at most) on a hierarchy whose pairs past its link
    /// budget were left to them.
    #[error(
        "lighting '{object}' would bring the emitters past the {MAX_GATHERED_EMITTERS} (of \
         {MAX_GATHERED_EMITTING_FACES} faces) the vertices gather, and this hierarchy left \
         {pairs} pairs at its link budget to their gathers: solve the scene with that light \
         on, or with a larger --max-links"
    )]
    PastGatheredEmitters {
        /// The object the edit would light.
        object: String,
        /// The pairs the hierarchy left undecided.
        pairs: usize,
    },
}

/// What moving an object cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MoveReport {
    /// What was recomputed.
    pub work: MoveWork,
    /// Seconds for the form-factor update or the rebuild.
    pub seconds: f64,
}

/// What a move recomputed, by path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MoveWork {
    /// The dense matrix: only the pairs the move can affect.
    Dense(UpdateStats),
    /// A hierarchy, built again (new leaves and links).
    Rebuilt(HierarchyStats),
}

impl Session {
    /// The session `request` asks for over `mesh` (from [`super::request::starting_mesh`]):
    /// the dense form factors of `mesh`, or the hierarchy refined from `scene`, whose leaves
    /// replace `mesh`. Nothing is solved yet.
    pub fn start(
        scene: &Scene,
        mesh: &Mesh,
        request: &SolveRequest,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<Session, SolveError> {
        match request.hierarchy {
            Some(_) => Session::hierarchical(scene, request, progress),
            None => Session::new(scene, mesh, request, progress),
        }
    }

    /// Computes the form factors of `mesh`; nothing is solved yet.
    pub fn new(
        scene: &Scene,
        mesh: &Mesh,
        request: &SolveRequest,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<Session, SolveError> {
        let n = mesh.patches.len();
        check_dense_size(n, scene.faces.len(), request)?;
        let mut seconds = StageSeconds::default();
        let clock = Instant::now();
        let occluders = Occluders::new(scene);
        seconds.mesh = clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let form_factors =
            DenseFormFactors::compute(mesh, &occluders, &request.form_factors, progress);
        let lights = lit_objects(scene);
        let averaged = CornerIndirect::Averaged;
        let seed = request.seed;
        let reached = (mesh, reached_corners(mesh, &occluders, seed));
        let corner_light = CornerLight::new(
            scene, reached, &occluders, &lights, averaged, seed, progress,
        );
        seconds.form_factors = clock.elapsed().as_secs_f64();
        Ok(Session::assemble(
            scene.clone(),
            mesh.clone(),
            Factors::Dense(form_factors),
            corner_light,
            request,
            seconds,
            vec![Rgb::ZERO; n],
        ))
    }

    /// Builds the element and link hierarchy of `scene` with `request.hierarchy`'s settings (the
    /// defaults if it names none), which also decides the patches: the leaves.
    /// [`Session::solve`] then finishes from the refinement's last solution.
    pub fn hierarchical(
        scene: &Scene,
        request: &SolveRequest,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<Session, SolveError> {
        Session::hierarchical_keeping(scene, request, &BTreeSet::new(), progress)
    }

    /// [`Session::hierarchical`] for a session whose vertices will gather the light of
    /// `lights` too (objects lit once and turned off since keep their place): the pairs past
    /// the link budget are left to the vertices' gathers only where they will gather every
    /// emitter among the scene's and these.
    fn hierarchical_keeping(
        scene: &Scene,
        request: &SolveRequest,
        lights: &BTreeSet<u32>,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<Session, SolveError> {
        let settings = request.hierarchy.unwrap_or_default();
        let request = &SolveRequest {
            hierarchy: Some(settings),
            ..*request
        };
        if request.solver.method.needs_entries() {
            return Err(NeedsEntries(request.solver.method).into());
        }
        let mut seconds = StageSeconds::default();
        let clock = Instant::now();
        let occluders = Occluders::new(scene);
        seconds.mesh = clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        // Corners that gather every bounce read the leaves' system only as their solve's start.
        let gathered: BTreeSet<u32> = lit_objects(scene).union(lights).copied().collect();
        let past_link_budget = match gathers_direct_light(scene, &gathered) {
            true => PastLinkBudget::Deferred,
            false => PastLinkBudget::Sampled,
        };
        let BuiltHierarchy {
            hierarchy,
            radiosity,
        } = Hierarchy::build(
            scene,
            &occluders,
            (&settings, past_link_budget),
            request.form_factors,
            &request.solver,
            progress,
        )?;
        seconds.form_factors = clock.elapsed().as_secs_f64();
        Ok(Session::on_hierarchy(
            scene.clone(),
            hierarchy,
            radiosity,
            &occluders,
            request,
            seconds,
            progress,
        ))
    }

    /// Whether [`Session::refine_further`] can change anything: not for a dense session, one
    /// edited since it was built, or a hierarchy a budget stopped.
    pub fn can_refine_further(&self) -> bool {
        let hierarchy = matches!(&self.factors, Factors::Hierarchy(h) if h.can_refine_further());
        hierarchy && self.edited.is_empty()
    }

    /// The link budget a hierarchical session refines under; `None` for a dense one.
    pub fn link_budget(&self) -> Option<usize> {
        match &self.factors {
            Factors::Hierarchy(_) => Some(self.request.hierarchy.unwrap_or_default().max_links),
            _ => None,
        }
    }

    /// Whether refinement stopped at the link budget (a hierarchy only).
    pub fn stopped_at_link_budget(&self) -> bool {
        matches!(&self.factors, Factors::Hierarchy(h) if h.stats().link_budget_reached)
    }

    /// Raises a hierarchical session's link budget to `max_links`: the next
    /// [`Session::refine_further`] goes on past where the lower one stopped it.
    pub fn raise_link_budget(&mut self, max_links: usize) {
        if let Factors::Hierarchy(h) = &mut self.factors {
            h.raise_link_budget(max_links);
            self.request.hierarchy = Some(HierarchySettings {
                max_links,
                ..self.request.hierarchy.unwrap_or_default()
            });
        }
    }

    /// This hierarchical session refined further at the finer error `knob`, from its current
    /// solution ([`Hierarchy::refine_further`]: nothing is thrown away), with whether anything
    /// changed (see [`Session::can_refine_further`]). The next [`Session::solve`] solves on
    /// the new leaves.
    pub fn refine_further(
        self,
        knob: f64,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<(Session, bool), NeedsEntries> {
        if !self.can_refine_further() {
            return Ok((self, false));
        }
        // Refined on the answer's patch values: a hierarchy's own system lacks the light of
        // the pairs it left undecided at the link budget, and carries its links' errors.
        let radiosity = self.patch_values();
        let Session {
            scene,
            factors,
            request,
            mut seconds,
            ..
        } = self;
        let Factors::Hierarchy(hierarchy) = factors else {
            unreachable!("checked to be a hierarchy above")
        };
        let clock = Instant::now();
        let occluders = Occluders::new(&scene);
        let settings = request.hierarchy.unwrap_or_default();
        let BuiltHierarchy {
            hierarchy,
            radiosity,
        } = hierarchy.refine_further(
            &scene,
            &occluders,
            &settings,
            request.form_factors,
            &request.solver,
            (knob, radiosity),
            progress,
        )?;
        seconds.form_factors += clock.elapsed().as_secs_f64();
        // Refined to `knob` now: a move rebuilds the hierarchy at it.
        let request = SolveRequest {
            hierarchy: Some(HierarchySettings {
                error: knob,
                ..settings
            }),
            ..request
        };
        let session = Session::on_hierarchy(
            scene, hierarchy, radiosity, &occluders, &request, seconds, progress,
        );
        Ok((session, true))
    }

    /// A session on `hierarchy`, built from `scene` and solved as `radiosity` (per leaf), its
    /// leaves split where viewers would miss the direct light's shape across them
    /// ([`display`](super::display)) and its corners' light gathered (reporting `progress`); the time it takes counts
    /// as form factors.
    fn on_hierarchy(
        scene: Scene,
        mut hierarchy: Hierarchy,
        radiosity: Vec<Rgb>,
        occluders: &Occluders,
        request: &SolveRequest,
        mut seconds: StageSeconds,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Session {
        let clock = Instant::now();
        let Displayed {
            mesh,
            radiosity,
            light,
        } = split_where_direct_light_curves(
            &mut hierarchy,
            radiosity,
            &scene,
            occluders,
            (&request.hierarchy.unwrap_or_default(), request.seed),
            &lit_objects(&scene),
            progress,
        );
        seconds.form_factors += clock.elapsed().as_secs_f64();
        let factors = Factors::Hierarchy(Box::new(hierarchy));
        Session::assemble(scene, mesh, factors, light, request, seconds, radiosity)
    }

    fn assemble(
        scene: Scene,
        mesh: Mesh,
        factors: Factors,
        corner_light: CornerLight,
        request: &SolveRequest,
        seconds: StageSeconds,
        radiosity: Vec<Rgb>,
    ) -> Session {
        let column =
            |f: fn(&crate::mesh::Patch) -> Rgb| mesh.patches.iter().map(f).collect::<Vec<_>>();
        let lights = lit_objects(&scene);
        Session {
            objects: scene.objects.iter().map(|o| o.name.clone()).collect(),
            patch_objects: mesh.patches.iter().map(|p| p.object).collect(),
            reflectance: column(|p| p.reflectance),
            emission: column(|p| p.emission),
            area: mesh.patches.iter().map(|p| p.area).collect(),
            request: *request,
            base: radiosity.clone(),
            base_residual: f64::INFINITY,
            base_vertices: None,
            responses: BTreeMap::new(),
            terms_epoch: 0,
            edited: BTreeMap::new(),
            seconds,
            lights,
            triangles: scene.triangle_count(),
            skipped_faces: scene.skipped_degenerate_faces,
            radiosity,
            corner_light,
            scene,
            mesh,
            factors,
        }
    }

    /// Counts `seconds` more for meshing: the time the caller spent building the mesh it gave.
    pub(crate) fn add_mesh_seconds(&mut self, seconds: f64) {
        self.seconds.mesh += seconds;
    }

    /// The patches and their values ([`Session::patch_values`]) with the corners' values
    /// `shown` ([`Session::vertex_radiosity`]), the session given up.
    pub(crate) fn into_solution(self, shown: &[Rgb]) -> (Mesh, Vec<Rgb>) {
        let values = self.patch_values_with(shown);
        (self.mesh, values)
    }

    /// Radiosity per patch as the answer gives it, W/m^2: where the corners gather every
    /// bounce themselves (a hierarchy's), the mean over the patch of what viewers are shown
    /// (the final gather's, Lischinski, Tampieri, Greenberg 1993), else the patches' own
    /// solution ([`Session::radiosity`]). A hierarchy's own leaf values carry its links'
    /// sampled cluster factors and coarse leaves: on the monastery they read 54.6% flat RMS
    /// against its reference, the means of what is shown 5.8%; on the Cornell box at knob
    /// 0.05, 3.2% against 1.5% (docs/BENCHMARKS.md).
    pub fn patch_values(&self) -> Vec<Rgb> {
        self.patch_values_with(&self.vertex_radiosity())
    }

    /// [`Session::patch_values`], with the corners' values `shown` at hand.
    fn patch_values_with(&self, shown: &[Rgb]) -> Vec<Rgb> {
        match self.corner_light.gathers_every_bounce() {
            true => self.mesh.patch_means(shown),
            false => self.radiosity.clone(),
        }
    }

    /// The scene as it is now (after moves).
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The patches as they are now (after moves).
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The self-check of the current answer ([`crate::check`]), traced in the scene as edited.
    pub fn self_check(
        &self,
        settings: &CheckSettings,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> Estimate {
        let lit = self.edited_scene();
        let shown = self.vertex_radiosity();
        crate::check::self_check(
            &lit,
            &Occluders::new(&lit),
            &self.mesh,
            (&self.patch_values_with(&shown), &shown),
            settings,
            progress,
        )
    }

    /// The scene with the emission edits since the last move applied to its faces (a move
    /// folds them into the scene itself).
    fn edited_scene(&self) -> Scene {
        let mut lit = self.scene.clone();
        for face in &mut lit.faces {
            if let Some(emission) = self.edited.get(&face.object) {
                face.emission = *emission;
            }
        }
        lit
    }

    /// The hierarchy's statistics, for a hierarchical session.
    fn hierarchy_stats(&self) -> Option<HierarchyStats> {
        match &self.factors {
            Factors::Dense(_) => None,
            Factors::Hierarchy(hierarchy) => Some(hierarchy.stats()),
        }
    }

    fn object_index(&self, name: &str) -> Result<u32, EditError> {
        self.objects
            .iter()
            .position(|o| o == name)
            .map(|i| i as u32)
            .ok_or_else(|| EditError::UnknownObject(name.into()))
    }

    /// Moves object `name` rigidly (a translation, or a rotation about its centre or a given
    /// pivot, then a translation), recomputing only the form factors the move can affect. The
    /// next [`Session::solve`] solves the moved scene in full (with the current emission).
    pub fn move_object(
        &mut self,
        name: &str,
        motion: impl Into<Motion>,
    ) -> Result<MoveReport, EditError> {
        let object = self.object_index(name)?;
        let motion = motion.into();
        motion.check().map_err(EditError::InvalidMove)?;
        let affine = motion.affine(self.scene.object_centre(object));
        let reach = reach_after(&affine, self.scene.object_corners(object));
        if reach > MAX_COORDINATE {
            return Err(EditError::InvalidMove(format!(
                "{motion} would take '{name}' {reach:e} from the origin, past {MAX_COORDINATE:e}"
            )));
        }
        let clock = Instant::now();
        // The responses were for the old transport: fold the edits into the emission (of the
        // patches, and of the scene, which a hierarchy is rebuilt from) and let the next solve
        // start over from it.
        self.emission = self.current_emission();
        for (object, emission) in std::mem::take(&mut self.edited) {
            self.scene
                .faces
                .iter_mut()
                .filter(|f| f.object == object)
                .for_each(|f| f.emission = emission);
        }
        self.responses.clear();
        self.terms_epoch += 1;
        self.base_vertices = None;
        // Form factors change only where the object was and where it is now.
        let mut swept: Vec<DVec3> = self.scene.object_corners(object).collect();
        self.scene.move_object(object, &affine);
        swept.extend(self.scene.object_corners(object));
        match &mut self.factors {
            Factors::Dense(form_factors) => {
                let occluders = Occluders::new(&self.scene);
                self.mesh.move_object(object, &affine);
                let moved: Vec<bool> = self.patch_objects.iter().map(|o| *o == object).collect();
                let stats = form_factors.update_moved(
                    &self.mesh,
                    &occluders,
                    &moved,
                    crate::geometry::bounds(swept),
                );
                let averaged = CornerIndirect::Averaged;
                let lights = &self.lights;
                let seed = self.request.seed;
                let reached = reached_corners(&self.mesh, &occluders, seed);
                self.corner_light = CornerLight::new(
                    &self.scene,
                    (&self.mesh, reached),
                    &occluders,
                    lights,
                    averaged,
                    seed,
                    &no_progress,
                );
                Ok(MoveReport {
                    work: MoveWork::Dense(stats),
                    seconds: clock.elapsed().as_secs_f64(),
                })
            }
            Factors::Hierarchy(_) => {
                // Refinement depends on where light falls, so the hierarchy is built again: new
                // leaves, which viewers get as a new geometry.
                let (seconds, lights) = (self.seconds, std::mem::take(&mut self.lights));
                let epoch = self.terms_epoch;
                let request = &self.request;
                *self = Session::hierarchical_keeping(&self.scene, request, &lights, &no_progress)
                    .expect("this session's method already ran on a hierarchy");
                (self.seconds, self.terms_epoch) = (seconds, epoch);
                self.keep_lights(lights);
                let stats = self.hierarchy_stats().expect("a hierarchical session");
                Ok(MoveReport {
                    work: MoveWork::Rebuilt(stats),
                    seconds: clock.elapsed().as_secs_f64(),
                })
            }
        }
    }

    /// Radiosity per patch as the patches' own system solved it, W/m^2 (what edits and
    /// warm starts go on from): zero until the first [`Session::solve`]. What the answer
    /// gives per patch is [`Session::patch_values`].
    pub fn radiosity(&self) -> &[Rgb] {
        &self.radiosity
    }

    /// Radiosity at every mesh corner, W/m^2: what viewers are sent and interpolate
    /// (`CornerLight::linear_corner_radiosity`: direct light gathered at the corner, indirect
    /// light from the patches around it). After edits, the base solution's values plus each
    /// edited object's response values: O(vertices × edited objects), no transport product.
    pub fn vertex_radiosity(&self) -> Vec<Rgb> {
        if let Some((_, terms)) = self.vertex_terms() {
            // Each light's share clamped at zero on its own (no light takes any away), which
            // is also exactly what viewers that sum the responses themselves add up.
            let mut values = vec![Rgb::ZERO; self.mesh.positions.len()];
            for term in terms {
                for (value, share) in values.iter_mut().zip(term.values) {
                    *value += share.max(Rgb::ZERO) * term.weight;
                }
            }
            return values;
        }
        let responses: Option<Vec<(&Response, Rgb)>> = self
            .edited
            .iter()
            .map(|(object, emission)| self.responses.get(object).map(|r| (r, *emission)))
            .collect();
        let values = match (&self.base_vertices, responses) {
            (Some(base), Some(responses)) => {
                let mut values = base.clone();
                for (response, emission) in responses {
                    superpose(
                        &mut values,
                        &response.unit_vertices,
                        &response.original_vertices,
                        emission,
                    );
                }
                values
            }
            // Not solved since the last change: the values of what the patches hold now.
            _ => self.linear_vertices(&self.radiosity, &self.current_emission()),
        };
        clamp_below_zero(values)
    }

    /// The vertex values of the patch solution `radiosity` under `emission`, before the clamp
    /// at zero.
    fn linear_vertices(&self, radiosity: &[Rgb], emission: &[Rgb]) -> Vec<Rgb> {
        self.corner_light.linear_corner_radiosity(
            &self.mesh,
            self.factors.transport(),
            radiosity,
            emission,
        )
    }

    /// Each patch's emission with the edits applied, W/m^2.
    fn current_emission(&self) -> Vec<Rgb> {
        self.emission
            .iter()
            .zip(&self.patch_objects)
            .map(|(e, object)| self.edited.get(object).copied().unwrap_or(*e))
            .collect()
    }

    /// Takes `radiosity` as the solution for the scene's own emission (a cached solve), so that
    /// edits can be applied without solving it again.
    pub fn adopt_solution(&mut self, radiosity: Vec<Rgb>) {
        assert_eq!(radiosity.len(), self.base.len(), "one radiosity per patch");
        self.base.clone_from(&radiosity);
        self.base_residual = self.request.solver.tolerance;
        self.base_vertices = Some(self.linear_vertices(&radiosity, &self.emission));
        self.radiosity = radiosity;
    }

    /// Sets the emission of every patch of object `name`; [`Session::solve`] applies it.
    pub fn set_emission(&mut self, name: &str, emission: Rgb) -> Result<(), EditError> {
        let object = self.object_index(name)?;
        check_emission(emission.to_array()).map_err(EditError::InvalidEmission)?;
        let pairs = self.hierarchy_stats().map_or(0, |h| h.deferred_pairs);
        if emission.max_element() > 0.0 && pairs > 0 {
            let lights: BTreeSet<u32> = self.lights.iter().copied().chain([object]).collect();
            // Lights keep their place when turned off: the scene's own emitters and `lights`.
            if !gathers_direct_light(&self.scene, &lights) {
                let object = name.to_string();
                return Err(EditError::PastGatheredEmitters { object, pairs });
            }
        }
        self.edited.insert(object, emission);
        if emission.max_element() > 0.0 {
            self.keep_lights(BTreeSet::from([object]));
        }
        Ok(())
    }

    /// Gathers the direct light of `lights` too from now on (see [`Session::lights`]): when
    /// that adds one, the corners' factors are gathered again, and every vertex value kept
    /// for summing with them.
    fn keep_lights(&mut self, lights: BTreeSet<u32>) {
        if lights.is_subset(&self.lights) {
            return;
        }
        self.lights.extend(lights);
        self.terms_epoch += 1;
        // Gathered at the emissions as edited: each emitter's share of the rays is what a
        // fresh solve of the edited scene gives it.
        let lit = self.edited_scene();
        let occluders = Occluders::new(&lit);
        self.corner_light
            .gather_lights(&lit, &self.mesh, &occluders, &self.lights, &no_progress);
        // The vertex values summed so far, gathered again alike (each light's share of the
        // rays may have changed with the new one).
        if self.base_vertices.is_some() {
            self.base_vertices = Some(self.linear_vertices(&self.base, &self.emission));
        }
        let objects: Vec<u32> = self.responses.keys().copied().collect();
        for object in objects {
            let (unit_emission, original_emission) = self.response_emissions(object);
            let response = &self.responses[&object];
            let unit_vertices = self.linear_vertices(&response.unit, &unit_emission);
            let original_vertices = self.linear_vertices(&response.original, &original_emission);
            let response = self.responses.get_mut(&object).expect("listed above");
            response.unit_vertices = unit_vertices;
            response.original_vertices = original_vertices;
        }
    }

    /// Solves for `emission` from `initial` (or zero).
    fn solve_for(
        &self,
        emission: &[Rgb],
        initial: Option<&[Rgb]>,
        progress: &(dyn Fn(Progress) + Sync),
    ) -> SolveOutcome {
        let system = System {
            reflectance: &self.reflectance,
            emission,
            area: &self.area,
        };
        // Both constructors refuse a method the transport cannot run.
        solve(
            self.factors.transport(),
            &system,
            &self.request.solver,
            initial,
            progress,
        )
        .expect("method checked when the session was made")
    }

    /// The emission of `object`'s two responses, per patch: one W/m^2, and as loaded.
    fn response_emissions(&self, object: u32) -> (Vec<Rgb>, Vec<Rgb>) {
        let mask = |value: &dyn Fn(usize) -> Rgb| -> Vec<Rgb> {
            (0..self.emission.len())
                .map(|i| {
                    if self.patch_objects[i] == object {
                        value(i)
                    } else {
                        Rgb::ZERO
                    }
                })
                .collect()
        };
        (mask(&|_| Rgb::ONE), mask(&|i| self.emission[i]))
    }

    /// Computes the responses of `object` unless known; returns the solver iterations spent.
    fn ensure_response(&mut self, object: u32) -> usize {
        if self.responses.contains_key(&object) {
            return 0;
        }
        let (unit_emission, original_emission) = self.response_emissions(object);
        let unit = self.solve_for(&unit_emission, None, &no_progress);
        let (mut iterations, mut residual) = (unit.iterations, unit.residual);
        // Uniform original emission needs no second solve: its response is e * G.
        let first = original_emission
            .iter()
            .zip(&self.patch_objects)
            .find(|(_, o)| **o == object)
            .map(|(e, _)| *e)
            .unwrap_or(Rgb::ZERO);
        let uniform = original_emission
            .iter()
            .zip(&self.patch_objects)
            .all(|(e, o)| *o != object || *e == first);
        let unit_vertices = self.linear_vertices(&unit.radiosity, &unit_emission);
        let (original, original_vertices) = if uniform {
            (
                unit.radiosity.iter().map(|g| *g * first).collect(),
                unit_vertices.iter().map(|g| *g * first).collect(),
            )
        } else {
            let solved = self.solve_for(&original_emission, None, &no_progress);
            iterations += solved.iterations;
            residual = worse(residual, solved.residual);
            let vertices = self.linear_vertices(&solved.radiosity, &original_emission);
            (solved.radiosity, vertices)
        };
        self.responses.insert(
            object,
            Response {
                unit: unit.radiosity,
                original,
                residual,
                unit_vertices,
                original_vertices,
                uniform: uniform.then_some(first),
            },
        );
        iterations
    }

    /// The vertex values [`Session::vertex_radiosity`] serves, before the clamp at zero, as a
    /// weighted sum of responses: each edited object's unit response at its emission, and each
    /// other object that emits its response as loaded. It equals them to the solver's
    /// tolerance (the base solution is solved on its own). `None` until every object that
    /// emits (or was edited) has its responses ([`Session::prepare_emitters`]). The number
    /// says which responses these are: it changes whenever one of them may have.
    pub fn vertex_terms(&self) -> Option<(u64, Vec<VertexTerm<'_>>)> {
        let mut objects: BTreeSet<u32> = self.edited.keys().copied().collect();
        objects.extend(
            self.emission
                .iter()
                .zip(&self.patch_objects)
                .filter(|(e, _)| e.max_element() > 0.0)
                .map(|(_, object)| *object),
        );
        let mut terms = Vec::with_capacity(objects.len());
        for object in objects {
            let response = self.responses.get(&object)?;
            let term = match (self.edited.get(&object), response.uniform) {
                (Some(emission), _) => (TermKey::Unit(object), &response.unit_vertices, *emission),
                (None, Some(loaded)) => (TermKey::Unit(object), &response.unit_vertices, loaded),
                (None, None) => (
                    TermKey::AsLoaded(object),
                    &response.original_vertices,
                    Rgb::ONE,
                ),
            };
            terms.push(VertexTerm {
                key: term.0,
                values: term.1,
                weight: term.2,
            });
        }
        Some((self.terms_epoch, terms))
    }

    /// Prepares the responses of every object that emits in the scene, so that edits of the
    /// scene's lights apply at once. Returns the solver iterations spent.
    pub fn prepare_emitters(&mut self) -> usize {
        let emitting: std::collections::BTreeSet<u32> = self
            .emission
            .iter()
            .zip(&self.patch_objects)
            .filter(|(e, _)| e.max_element() > 0.0)
            .map(|(_, o)| *o)
            .collect();
        emitting.into_iter().map(|o| self.ensure_response(o)).sum()
    }

    /// Solves: the first time (or with no edits) from zero, afterwards by superposing the
    /// responses of the edited objects on the base solution.
    pub fn solve(&mut self, progress: &(dyn Fn(Progress) + Sync)) -> SolveReport {
        let clock = Instant::now();
        let (iterations, residual, converged) = if self.edited.is_empty() {
            // From the current answer: after a move, most of it still holds.
            let outcome = self.solve_for(&self.emission, Some(&self.radiosity), progress);
            self.base.clone_from(&outcome.radiosity);
            self.base_residual = outcome.residual;
            self.base_vertices = Some(self.linear_vertices(&outcome.radiosity, &self.emission));
            self.radiosity = outcome.radiosity;
            (outcome.iterations, outcome.residual, outcome.converged)
        } else {
            let edited: Vec<(u32, Rgb)> = self.edited.iter().map(|(o, e)| (*o, *e)).collect();
            let iterations = edited.iter().map(|(o, _)| self.ensure_response(*o)).sum();
            let mut radiosity = self.base.clone();
            let mut residual = self.base_residual;
            for (object, emission) in edited {
                let response = &self.responses[&object];
                residual = worse(residual, response.residual);
                superpose(&mut radiosity, &response.unit, &response.original, emission);
            }
            // Clamp round-off below zero, as the solver does.
            radiosity.iter_mut().for_each(|b| *b = b.max(Rgb::ZERO));
            self.radiosity = radiosity;
            // A sum is as good as its worst part: never final while one did not converge.
            (
                iterations,
                residual,
                residual <= self.request.solver.tolerance,
            )
        };
        self.seconds.solve = clock.elapsed().as_secs_f64();
        self.seconds.total = self.seconds.mesh + self.seconds.form_factors + self.seconds.solve;
        let (mut area, mut power) = (
            vec![0.0; self.objects.len()],
            vec![Rgb::ZERO; self.objects.len()],
        );
        // As the answer gives them: a hierarchy's own system may lack light it left undecided.
        let values = self.patch_values();
        for ((o, a), b) in self.patch_objects.iter().zip(&self.area).zip(&values) {
            area[*o as usize] += a;
            power[*o as usize] += *b * *a;
        }
        SolveReport {
            patches: self.radiosity.len(),
            triangles: self.triangles,
            skipped_faces: self.skipped_faces,
            warnings: self.scene.load_warnings.clone(),
            method: if self.request.hierarchy.is_some() {
                "hierarchical".into()
            } else {
                self.request.solver.method.name().into()
            },
            iterations,
            residual,
            converged,
            tolerance: self.request.solver.tolerance,
            ray_backend: crate::visibility::RayBackend::DEFAULT.name(),
            seed: self.request.seed.0,
            rays: match &self.factors {
                Factors::Dense(factors) => factors.rays_cast,
                Factors::Hierarchy(hierarchy) => hierarchy.stats().rays,
            },
            seconds: self.seconds,
            objects: self
                .objects
                .iter()
                .zip(area.iter().zip(&power))
                .map(|(name, (a, p))| ObjectRadiosity {
                    name: name.clone(),
                    area: *a,
                    radiosity: if *a > 0.0 {
                        (*p / *a).to_array()
                    } else {
                        [0.0; 3]
                    },
                })
                .collect(),
            hierarchy: self.hierarchy_stats(),
            estimate: None,
            target: None,
        }
    }
}

/// The objects of `scene` with a face that emits.
fn lit_objects(scene: &Scene) -> BTreeSet<u32> {
    (scene.faces.iter())
        .filter(|f| f.emission.max_element() > 0.0)
        .map(|f| f.object)
        .collect()
}

/// `values += emission * unit - original`: one object's response moved from its original
/// emission to `emission` (per patch or per vertex).
fn superpose(values: &mut [Rgb], unit: &[Rgb], original: &[Rgb], emission: Rgb) {
    for ((v, g), r) in values.iter_mut().zip(unit).zip(original) {
        *v += *g * emission - *r;
    }
}

/// The larger of two residuals, NaN (a solve that broke down) over any number.
fn worse(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::PatchTarget;
    use crate::scene::Material;

    /// 65 x 64 grey tiles (one object, emitting `tiles_emission`) under a lamp: lit, the tiles
    /// are 4,160 emitting faces, past the 4,096 the vertices gather.
    fn tiles_under_a_lamp(tiles_emission: Rgb) -> Scene {
        let mut scene = Scene::default();
        let grey = Material {
            reflectance: Rgb::splat(0.5),
            emission: Rgb::ZERO,
        };
        let tiles = scene.add_object("tiles");
        let tile = Material {
            emission: tiles_emission,
            ..grey
        };
        for (i, j) in (0..65).flat_map(|i| (0..64).map(move |j| (i, j))) {
            let o = DVec3::new(i as f64 * 0.1, 0.0, j as f64 * 0.1);
            let (x, z) = (DVec3::X * 0.1, DVec3::Z * 0.1);
            scene.add_polygon(tiles, &[o, o + z, o + z + x, o + x], tile);
        }
        let lamp = scene.add_object("lamp");
        let (o, x, z) = (DVec3::new(0.5, 1.0, 0.5), DVec3::X, DVec3::Z * 0.5);
        let lit = Material {
            emission: Rgb::ONE,
            ..grey
        };
        scene.add_polygon(lamp, &[o, o + x, o + x + z, o + z], lit);
        scene
    }

    /// A hierarchy at knob 0.3 within `max_links` links.
    fn within_links(max_links: usize) -> SolveRequest {
        SolveRequest {
            hierarchy: Some(HierarchySettings {
                error: 0.3,
                max_links,
                ..HierarchySettings::default()
            }),
            ..SolveRequest::default()
        }
    }

    #[test]
    fn lighting_past_the_gathered_emitters_a_hierarchy_left_pairs_to_is_refused_by_name() {
        // Lit, the tiles would be 4,161 emitting faces, and the pairs the hierarchy left at its
        // link budget would go dark.
        let scene = tiles_under_a_lamp(Rgb::ZERO);
        let mut left = Session::hierarchical(&scene, &within_links(10), &no_progress).unwrap();
        let pairs = left.hierarchy_stats().unwrap().deferred_pairs;
        assert!(pairs > 0);
        let refused = left.set_emission("tiles", Rgb::ONE).unwrap_err();
        assert_eq!(
            refused,
            EditError::PastGatheredEmitters {
                object: "tiles".into(),
                pairs
            }
        );
        assert!(
            refused
                .to_string()
                .starts_with("lighting 'tiles' would bring")
        );
        assert!(left.set_emission("lamp", Rgb::splat(2.0)).is_ok());
        let request = within_links(10_000_000);
        let mut whole = Session::hierarchical(&scene, &request, &no_progress).unwrap();
        assert_eq!(whole.hierarchy_stats().unwrap().deferred_pairs, 0);
        assert!(whole.set_emission("tiles", Rgb::ONE).is_ok());
    }

    #[test]
    fn lights_turned_off_keep_their_place_when_a_move_rebuilds_the_hierarchy() {
        // Lit as loaded, the tiles are past the emitters the vertices gather: the hierarchy
        // samples every pair into a link. Turned off and the lamp moved, the rebuilt hierarchy
        // must still, or the tiles could never be lit again (and their gathers would miss the
        // pairs it left).
        let scene = tiles_under_a_lamp(Rgb::splat(0.5));
        let mut session = Session::hierarchical(&scene, &within_links(10), &no_progress).unwrap();
        assert_eq!(session.hierarchy_stats().unwrap().deferred_pairs, 0);
        session.set_emission("tiles", Rgb::ZERO).unwrap();
        session.solve(&no_progress);
        session.move_object("lamp", DVec3::X * 0.2).unwrap();
        assert_eq!(session.hierarchy_stats().unwrap().deferred_pairs, 0);
        assert_eq!(session.set_emission("tiles", Rgb::splat(0.5)), Ok(()));
        session.solve(&no_progress);
        let tiles = (session.mesh().patches.iter())
            .position(|p| p.object == 0)
            .unwrap();
        assert!(session.radiosity()[tiles].min_element() >= 0.5);
    }

    /// A closed unit cube whose floor and ceiling are separate lamps.
    fn two_lamp_box() -> Scene {
        let mut scene = Scene::default();
        let (x, y, z) = (DVec3::X, DVec3::Y, DVec3::Z);
        for (name, origin, u, v, emission) in [
            ("floor", DVec3::ZERO, z, x, Rgb::new(1.0, 0.5, 0.0)),
            ("ceiling", y, x, z, Rgb::new(0.0, 2.0, 1.0)),
            ("wall", DVec3::ZERO, y, z, Rgb::ZERO),
            ("wall", x, z, y, Rgb::ZERO),
            ("wall", DVec3::ZERO, x, y, Rgb::ZERO),
            ("wall", z, y, x, Rgb::ZERO),
        ] {
            let object = match scene.objects.iter().position(|o| o.name == name) {
                Some(index) => index as u32,
                None => scene.add_object(name),
            };
            let material = Material {
                reflectance: Rgb::splat(0.6),
                emission,
            };
            scene.add_polygon(
                object,
                &[origin, origin + u, origin + u + v, origin + v],
                material,
            );
        }
        scene
    }

    fn session(scene: &Scene) -> Session {
        let request = SolveRequest {
            patches: PatchTarget::Count(96),
            ..SolveRequest::default()
        };
        let mesh = Mesh::build(scene, request.patches);
        Session::new(scene, &mesh, &request, &no_progress).expect("a small dense matrix")
    }

    #[test]
    fn vertex_values_of_an_edit_are_the_sum_of_their_responses_values() {
        let scene = two_lamp_box();
        let mut live = session(&scene);
        live.solve(&no_progress);
        let before = live.vertex_radiosity();
        live.prepare_emitters();
        // Once summed from the lights' responses, the values move by the solver's tolerance.
        let brightest = before.iter().map(|v| v.max_element()).fold(0.0, f64::max);
        let moved = live
            .vertex_radiosity()
            .iter()
            .zip(&before)
            .map(|(a, b)| (*a - *b).abs().max_element())
            .fold(0.0, f64::max);
        assert!(moved <= 1e-5 * brightest, "{moved} of {brightest}");
        // Lights left on in every channel: a light switched off leaves patch values that cancel
        // to round-off, which the patch clamp and the vertex clamp cut differently.
        for (floor, ceiling) in [
            (Rgb::new(3.0, 0.2, 1.0), Rgb::splat(0.1)),
            (Rgb::ONE, Rgb::splat(5.0)),
        ] {
            live.set_emission("floor", floor).unwrap();
            live.set_emission("ceiling", ceiling).unwrap();
            live.solve(&no_progress);
            let summed = live.vertex_radiosity();
            let rebuilt =
                clamp_below_zero(live.linear_vertices(live.radiosity(), &live.current_emission()));
            let scale = rebuilt.iter().map(|v| v.max_element()).fold(0.0, f64::max);
            let worst = summed
                .iter()
                .zip(&rebuilt)
                .map(|(a, b)| (*a - *b).abs().max_element())
                .fold(0.0, f64::max);
            // Summed from responses each solved to the tolerance (1e-6), not rebuilt from one.
            assert!(worst <= 1e-5 * scale, "{worst} of {scale}");
        }
    }

    #[test]
    fn the_vertex_terms_sum_to_the_vertex_values_served() {
        let scene = two_lamp_box();
        let mut live = session(&scene);
        live.solve(&no_progress);
        assert!(live.vertex_terms().is_none(), "no responses yet");
        live.prepare_emitters();
        let (epoch, _) = live.vertex_terms().expect("both lamps have responses");
        // The floor edited, the ceiling as loaded; the walls emit nothing and are no term.
        live.set_emission("floor", Rgb::new(0.0, 3.0, 0.5)).unwrap();
        live.solve(&no_progress);
        let (same_epoch, terms) = live.vertex_terms().expect("still every response");
        assert_eq!(same_epoch, epoch, "no response changed");
        let keys: Vec<TermKey> = terms.iter().map(|t| t.key).collect();
        assert_eq!(keys, [TermKey::Unit(0), TermKey::Unit(1)]);
        assert_eq!(terms[0].weight, Rgb::new(0.0, 3.0, 0.5));
        assert_eq!(terms[1].weight, Rgb::new(0.0, 2.0, 1.0));
        // A move changes every response: the terms say so.
        live.move_object("floor", DVec3::new(0.0, 0.1, 0.0))
            .unwrap();
        live.solve(&no_progress);
        assert!(
            live.vertex_terms().is_none(),
            "responses gone with the move"
        );
        live.prepare_emitters();
        assert!(live.vertex_terms().unwrap().0 > epoch);
    }

    #[test]
    fn the_self_check_of_an_edited_session_traces_the_light_as_edited() {
        // Dimming a lamp scales the answer and the reference alike: the relative error the
        // check estimates stays where it was (it was 100% when the check traced the scene as
        // loaded against the answer as edited).
        let scene = two_lamp_box();
        let mut live = session(&scene);
        live.solve(&no_progress);
        let settings = CheckSettings::after_solve(0.0);
        let before = live.self_check(&settings, &no_progress).smooth.rms;
        live.set_emission("floor", Rgb::new(0.5, 0.25, 0.0))
            .unwrap();
        live.set_emission("ceiling", Rgb::new(0.0, 1.0, 0.5))
            .unwrap();
        live.solve(&no_progress);
        let after = live.self_check(&settings, &no_progress).smooth.rms;
        assert!((after - before).abs() < 0.01, "{before} -> {after}");
    }

    #[test]
    fn an_edit_is_final_only_when_every_solve_it_sums_converged() {
        let scene = two_lamp_box();
        let request = SolveRequest {
            patches: PatchTarget::Count(96),
            ..SolveRequest::default()
        };
        let mesh = Mesh::build(&scene, request.patches);
        let mut live = Session::new(&scene, &mesh, &request, &no_progress).unwrap();
        assert!(live.solve(&no_progress).converged);
        live.set_emission("floor", Rgb::ONE).unwrap();
        let summed = live.solve(&no_progress);
        assert!(summed.converged && summed.residual <= request.solver.tolerance);
        // The same edit on a session whose solver stops after one iteration: the responses
        // it sums did not converge, and the sum must not say it did.
        let mut starved = request;
        starved.solver.max_iterations = 1;
        let mut live = Session::new(&scene, &mesh, &starved, &no_progress).unwrap();
        assert!(!live.solve(&no_progress).converged);
        live.set_emission("floor", Rgb::ONE).unwrap();
        let summed = live.solve(&no_progress);
        assert!(
            !summed.converged && summed.residual > starved.solver.tolerance,
            "{summed:?}"
        );
    }

    #[test]
    fn an_edit_by_superposition_equals_a_solve_of_the_edited_scene() {
        let scene = two_lamp_box();
        let mut live = session(&scene);
        live.solve(&no_progress);
        let (floor, ceiling) = (Rgb::new(3.0, 0.0, 1.0), Rgb::ZERO);
        live.set_emission("floor", floor).unwrap();
        live.set_emission("ceiling", ceiling).unwrap();
        let report = live.solve(&no_progress);
        let mut edited = scene.clone();
        for face in &mut edited.faces {
            match scene.objects[face.object as usize].name.as_str() {
                "floor" => face.emission = floor,
                "ceiling" => face.emission = ceiling,
                _ => {}
            }
        }
        let mut fresh = session(&edited);
        fresh.solve(&no_progress);
        let worst = live
            .radiosity()
            .iter()
            .zip(fresh.radiosity())
            .map(|(a, b)| (*a - *b).abs().max_element())
            .fold(0.0, f64::max);
        // Each response is solved to the tolerance (relative 1e-6); B ~ 10 here.
        assert!(worst < 1e-4, "worst difference {worst}");
        assert!(report.converged);
        // The vertices too: their direct light follows the edited emission (an emitter turned
        // off gathers nothing, as in a scene where it never emitted).
        let worst_vertex = live
            .vertex_radiosity()
            .iter()
            .zip(fresh.vertex_radiosity())
            .map(|(a, b)| (*a - b).abs().max_element())
            .fold(0.0, f64::max);
        assert!(
            worst_vertex < 1e-4,
            "worst vertex difference {worst_vertex}"
        );
        // The floor at (3, 0, 1) and an unlit ceiling: no green left, up to the tolerance of the
        // responses that cancelled it.
        assert!(live.radiosity().iter().all(|b| b.y < 1e-5));
    }

    #[test]
    fn bad_edits_are_refused_and_change_nothing() {
        let scene = two_lamp_box();
        let mut live = session(&scene);
        live.solve(&no_progress);
        let before = live.radiosity().to_vec();
        assert_eq!(
            live.set_emission("lamp", Rgb::ONE),
            Err(EditError::UnknownObject("lamp".into()))
        );
        for bad in [
            Rgb::new(1.0, f64::NAN, 0.0),
            Rgb::splat(-1.0),
            Rgb::splat(f64::INFINITY),
            Rgb::splat(1e308),
            Rgb::new(0.0, 3e38, 0.0),
        ] {
            assert!(matches!(
                live.set_emission("floor", bad),
                Err(EditError::InvalidEmission(_))
            ));
        }
        for bad in [DVec3::new(0.0, f64::NAN, 0.0), DVec3::new(1e39, 0.0, 0.0)] {
            assert!(matches!(
                live.move_object("floor", bad),
                Err(EditError::InvalidMove(_))
            ));
        }

        live.solve(&no_progress);
        assert_eq!(live.radiosity(), &before[..]);
    }

    #[test]
    fn a_move_may_not_carry_an_object_past_what_f32_geometry_holds() {
        let mut live = session(&two_lamp_box());
        let far = DVec3::new(1e30, 0.0, 0.0);
        assert!(live.move_object("floor", far).is_ok(), "up to the bound");
        assert_eq!(
            live.move_object("floor", far),
            Err(EditError::InvalidMove(
                "translate [1e30, 0.0, 0.0] would take 'floor' 2e30 from the origin, past 1e30"
                    .into()
            ))
        );
    }
}
