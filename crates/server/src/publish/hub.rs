//! The current solution, encoded once per version and shared by every viewer.
//!
//! A `watch` channel holds only the newest [`Published`] state: a viewer that falls behind
//! skips straight to it, so a slow viewer never queues frames or slows the others.

use bytes::Bytes;
use std::sync::Arc;
use tokio::sync::watch;
use wire::responses::{Response, SumFrame, Term};
use wire::{
    DeltaFrame, FrameInfo, FullFrame, Geometry, Hello, PLAIN_PROTOCOL_VERSION, PROTOCOL_VERSION,
    ServerMessage,
};

/// One version of the solution, with its frames already encoded.
#[derive(Debug)]
pub struct Published {
    /// Solution version (starts at 1, one per publish).
    pub version: u64,
    /// Whether the solver had converged.
    pub is_final: bool,
    /// The RGB9E5 codes.
    pub colours: Arc<Vec<u32>>,
    /// The frame scale (W/m^2 per decoded unit).
    pub scale: f32,
    /// The encoded full frame.
    pub full: Bytes,
    /// The encoded delta from the previous version, when the scale stayed the same.
    pub delta: Option<(u64, Bytes)>,
    /// [`wire::checksum`] of `colours`.
    pub checksum: u32,
    /// The geometry version these colours belong to.
    pub geometry_version: u64,
    /// The same version as a sum of responses, for protocol-3 viewers, when the server has one
    /// within the stated bound.
    pub sum: Option<Arc<SumForm>>,
}

/// A version as a sum of the hub's responses: what protocol-3 viewers are sent instead of its
/// frames.
#[derive(Debug)]
pub struct SumForm {
    /// The responses it names, each sent to a viewer once.
    pub response_ids: Vec<u32>,
    /// The encoded [`SumFrame`].
    pub frame: Bytes,
    /// [`wire::responses::sum_checksum`] of the values it gives.
    pub checksum: u32,
}

impl Published {
    /// The state `info` and `colours` describe, with its full frame encoded here (the same
    /// bytes wherever it is encoded: an edge rebuilds what the origin sent) and `delta`, the
    /// encoded delta from its base version, as it was received or made.
    pub fn new(
        info: FrameInfo,
        colours: Vec<u32>,
        delta: Option<(u64, Bytes)>,
        geometry_version: u64,
    ) -> Published {
        let full = Bytes::from(
            ServerMessage::Full(FullFrame {
                info,
                colours: colours.clone(),
            })
            .encode(),
        );
        Published {
            version: info.solution_version,
            is_final: info.is_final,
            checksum: wire::checksum(&colours),
            colours: Arc::new(colours),
            scale: info.scale,
            full,
            delta,
            geometry_version,
            sum: None,
        }
    }

    /// The same version with `sum` (a response set it can now be made from).
    pub fn with_sum(&self, sum: Arc<SumForm>) -> Published {
        Published {
            colours: self.colours.clone(),
            full: self.full.clone(),
            delta: self.delta.clone(),
            sum: Some(sum),
            ..*self
        }
    }
}

/// The geometry as served, replaced whole when an object moves.
#[derive(Debug)]
pub struct GeometryState {
    /// Starts at 1; bumped by every move.
    pub version: u64,
    /// The scene id the hello carries.
    pub scene_id: u64,
    /// The encoded hello every viewer gets first: protocol 2's and 3's.
    hellos: [Bytes; 2],
    /// The encoded geometry served at `/api/scene`.
    pub encoded: Bytes,
    /// The same geometry, for exports.
    pub model: Arc<Geometry>,
    /// The PNG of each texture the geometry's texture section names, served at
    /// `/api/textures/{index}`; the same for every geometry version of a run.
    pub textures: Arc<[Bytes]>,
}

impl GeometryState {
    /// The state served for version `version` of `geometry` of scene `scene_id`, with its
    /// textures' PNGs.
    pub fn new(
        scene_id: u64,
        version: u64,
        geometry: Geometry,
        textures: Arc<[Bytes]>,
    ) -> GeometryState {
        let hello = |protocol_version| {
            let hello = Hello {
                protocol_version,
                scene_id,
                geometry_version: version,
                vertex_count: geometry.positions.len() as u32,
            };
            Bytes::from(ServerMessage::Hello(hello).encode())
        };
        GeometryState {
            version,
            scene_id,
            hellos: [hello(PLAIN_PROTOCOL_VERSION), hello(PROTOCOL_VERSION)],
            encoded: geometry.encode().into(),
            model: Arc::new(geometry),
            textures,
        }
    }
}

impl GeometryState {
    /// The hello for a viewer speaking `protocol` (2 or 3).
    pub fn hello(&self, protocol: u16) -> Bytes {
        self.hellos[usize::from(protocol >= PROTOCOL_VERSION)].clone()
    }
}

/// A response as the hub holds it: its values as viewers decode them, and its message.
#[derive(Debug)]
pub struct HeldResponse {
    /// What a viewer holds once it has the message.
    pub response: Response,
    /// The encoded [`ServerMessage::Response`].
    pub message: Bytes,
}

/// Publishes solution versions and hands them to viewers.
pub struct Hub {
    sender: watch::Sender<Arc<Published>>,
    geometry: std::sync::RwLock<Arc<GeometryState>>,
    /// The responses sums are made of, for the current geometry, by id.
    responses: std::sync::RwLock<std::collections::BTreeMap<u32, Arc<HeldResponse>>>,
    /// Identifies scene content and solve settings.
    pub scene_id: u64,
}

/// Headroom a frame may leave unused before the scale is lowered: 2^8. Keeping the previous
/// scale while the brightest value moves within that band lets changing lights travel as
/// deltas instead of full frames; it costs precision only on patches 2^23 below the brightest.
const SCALE_HEADROOM: f32 = 256.0;

fn encode(radiosity: &[[f32; 3]], previous_scale: Option<f32>) -> (f32, Vec<u32>) {
    let brightest = radiosity
        .iter()
        .flatten()
        .copied()
        .filter(|c| c.is_finite())
        .fold(0.0, f32::max);
    let fits = |scale: f32| {
        brightest <= wire::rgb9e5::MAX_VALUE * scale
            && brightest * SCALE_HEADROOM >= wire::rgb9e5::MAX_VALUE * scale
    };
    let scale = previous_scale
        .filter(|s| fits(*s))
        .unwrap_or_else(|| wire::scale_for(brightest));
    (
        scale,
        radiosity
            .iter()
            .map(|rgb| wire::encode_colour(*rgb, scale))
            .collect(),
    )
}

impl Hub {
    /// A hub for `geometry` (with `textures`, the PNGs its texture section names), publishing
    /// `initial` (non-final) as version 1.
    pub fn new(
        scene_id: u64,
        geometry: &Geometry,
        textures: Arc<[Bytes]>,
        initial: &[[f32; 3]],
    ) -> Hub {
        let (scale, colours) = encode(initial, None);
        let first = Self::frames(1, false, scale, colours, None, 1);
        Hub {
            sender: watch::Sender::new(Arc::new(first)),
            geometry: std::sync::RwLock::new(Arc::new(GeometryState::new(
                scene_id,
                1,
                geometry.clone(),
                textures,
            ))),
            responses: Default::default(),
            scene_id,
        }
    }

    /// The geometry as served now.
    pub fn geometry(&self) -> Arc<GeometryState> {
        self.geometry.read().expect("geometry lock").clone()
    }

    /// Replaces the geometry (the patches moved, or new leaves of a hierarchy) and returns its
    /// new version; frames published from now on carry it, and viewers are told before their
    /// next frame.
    pub fn replace_geometry(&self, geometry: Geometry) -> u64 {
        let mut current = self.geometry.write().expect("geometry lock");
        let version = current.version + 1;
        let textures = current.textures.clone();
        *current = Arc::new(GeometryState::new(
            self.scene_id,
            version,
            geometry,
            textures,
        ));
        version
    }

    fn frames(
        version: u64,
        is_final: bool,
        scale: f32,
        colours: Vec<u32>,
        previous: Option<&Published>,
        geometry_version: u64,
    ) -> Published {
        let info = FrameInfo {
            solution_version: version,
            sent_at_unix_micros: wire::unix_micros_now(),
            scale,
            vertex_count: colours.len() as u32,
            is_final,
        };
        // A delta needs the same scale and the same vertices (a hierarchy's leaves change on a move).
        let delta = previous
            .filter(|p| p.scale == scale && p.colours.len() == colours.len())
            .map(|p| {
                let (indices, changed) = wire::changes(&p.colours, &colours);
                let frame = DeltaFrame {
                    base_version: p.version,
                    info,
                    indices,
                    colours: changed,
                };
                (p.version, Bytes::from(ServerMessage::Delta(frame).encode()))
            });
        Published::new(info, colours, delta, geometry_version)
    }

    /// Publishes a new state (radiosity in W/m^2) unless it encodes to what viewers already
    /// have; returns the version viewers will hold.
    pub fn publish(&self, radiosity: &[[f32; 3]], is_final: bool) -> u64 {
        self.publish_with_sum(radiosity, is_final, None)
    }

    /// Like [`Hub::publish`], and for protocol-3 viewers the same state as the sum of
    /// `terms` (responses given to [`Hub::add_response`]) when that sum is within the bound
    /// [`sum_within_bound`] states of `radiosity`.
    pub fn publish_with_sum(
        &self,
        radiosity: &[[f32; 3]],
        is_final: bool,
        terms: Option<Vec<Term>>,
    ) -> u64 {
        let previous = self.current();
        let geometry_version = self.geometry().version;
        let (scale, colours) = encode(radiosity, Some(previous.scale));
        if previous.scale == scale
            && *previous.colours == colours
            && previous.is_final == is_final
            && previous.geometry_version == geometry_version
        {
            if let Some(terms) = terms {
                self.attach_sum(radiosity, terms);
            }
            return previous.version;
        }
        let version = previous.version + 1;
        let mut next = Self::frames(
            version,
            is_final,
            scale,
            colours,
            Some(&previous),
            geometry_version,
        );
        next.sum = terms.and_then(|terms| self.sum_form(version, is_final, radiosity, terms));
        self.sender.send_replace(Arc::new(next));
        version
    }

    /// Gives the version viewers hold, whose values are `radiosity` (to the solver's
    /// tolerance: the same solution, summed from its lights' responses), the sum of `terms`
    /// as well, unless it has one: protocol-3 viewers then fetch the responses before the next
    /// edit, and the version stays the same for everyone.
    pub fn attach_sum(&self, radiosity: &[[f32; 3]], terms: Vec<Term>) {
        let current = self.current();
        if current.sum.is_some() || current.colours.len() != radiosity.len() {
            return;
        }
        if let Some(sum) = self.sum_form(current.version, current.is_final, radiosity, terms) {
            self.sender.send_replace(Arc::new(current.with_sum(sum)));
        }
    }

    /// Version `version` as the sum of `terms`, if the hub holds their responses and the sum
    /// gives every vertex of `radiosity` within the bound.
    fn sum_form(
        &self,
        version: u64,
        is_final: bool,
        radiosity: &[[f32; 3]],
        terms: Vec<Term>,
    ) -> Option<Arc<SumForm>> {
        let frame = SumFrame {
            info: FrameInfo {
                solution_version: version,
                sent_at_unix_micros: wire::unix_micros_now(),
                scale: 1.0,
                vertex_count: radiosity.len() as u32,
                is_final,
            },
            terms,
        };
        let viewers = self.responses_of(&frame.terms)?;
        let shown = viewers.evaluate(&frame).ok()?;
        let bound = viewers
            .quantisation_bound(&frame.terms, frame.info.vertex_count)
            .ok()?;
        if !sum_within_bound(radiosity, &shown, &bound) {
            tracing::info!(
                version,
                "the sum of responses is past its bound: frames only"
            );
            return None;
        }
        Some(Arc::new(SumForm {
            response_ids: frame.terms.iter().map(|t| t.response_id).collect(),
            checksum: wire::responses::sum_checksum(&shown),
            frame: Bytes::from(ServerMessage::Sum(frame).encode()),
        }))
    }

    /// The held responses `terms` name, as a viewer holds them; `None` when one is missing.
    fn responses_of(&self, terms: &[Term]) -> Option<wire::responses::Responses> {
        let held = self.responses.read().expect("responses lock");
        let mut viewers = wire::responses::Responses::default();
        for term in terms {
            viewers.insert(&held.get(&term.response_id)?.response);
        }
        Some(viewers)
    }

    /// `state`'s sum from `encoded` (an origin's [`ServerMessage::Sum`], served as it came)
    /// when it is of that version and the hub holds every response it names; says why not
    /// otherwise. Responses older than those it names are forgotten: ids only grow within a
    /// run, so no later sum names them.
    pub fn sum_for(&self, state: &Published, encoded: Bytes) -> Result<Arc<SumForm>, String> {
        let Ok(ServerMessage::Sum(frame)) = ServerMessage::decode(&encoded) else {
            return Err("not a sum frame".into());
        };
        if frame.info.solution_version != state.version
            || frame.info.vertex_count as usize != state.colours.len()
        {
            return Err(format!(
                "the sum is of version {} ({} vertices), not of version {} ({} vertices)",
                frame.info.solution_version,
                frame.info.vertex_count,
                state.version,
                state.colours.len()
            ));
        }
        let viewers = self
            .responses_of(&frame.terms)
            .ok_or("it names a response this hub does not hold")?;
        if let Some(oldest) = frame.terms.iter().map(|t| t.response_id).min() {
            self.responses
                .write()
                .expect("responses lock")
                .retain(|id, _| *id >= oldest);
        }
        let shown = viewers.evaluate(&frame).map_err(|e| e.to_string())?;
        Ok(Arc::new(SumForm {
            response_ids: frame.terms.iter().map(|t| t.response_id).collect(),
            checksum: wire::responses::sum_checksum(&shown),
            frame: encoded,
        }))
    }

    /// Holds `response` for sums from now on (its id new to this hub).
    pub fn add_response(&self, response: Response) {
        let message = Bytes::from(ServerMessage::Response(response.clone()).encode());
        self.hold_response(HeldResponse { response, message });
    }

    /// Holds `held` (an origin's response as it was sent) for sums from now on.
    pub fn hold_response(&self, held: HeldResponse) {
        let held = Arc::new(held);
        self.responses
            .write()
            .expect("responses lock")
            .insert(held.response.response_id, held);
    }

    /// Forgets every response (they belong to a geometry or a gather that is gone).
    pub fn clear_responses(&self) {
        self.responses.write().expect("responses lock").clear();
    }

    /// Response `id`, if the hub holds it.
    pub fn response(&self, id: u32) -> Option<Arc<HeldResponse>> {
        self.responses
            .read()
            .expect("responses lock")
            .get(&id)
            .cloned()
    }

    /// A hub that serves what another hub published (an edge's copy of an origin's): the
    /// geometry and the state as they are, with nothing encoded anew but the hello.
    pub fn restore(geometry: GeometryState, state: Published) -> Hub {
        Hub {
            scene_id: geometry.scene_id,
            sender: watch::Sender::new(Arc::new(state)),
            geometry: std::sync::RwLock::new(Arc::new(geometry)),
            responses: Default::default(),
        }
    }

    /// Serves `state` from now on, whatever its version (an edge following an origin).
    pub fn install(&self, state: Published) {
        self.sender.send_replace(Arc::new(state));
    }

    /// Serves `geometry` from now on; frames installed after it should carry its version.
    pub fn install_geometry(&self, geometry: GeometryState) {
        *self.geometry.write().expect("geometry lock") = Arc::new(geometry);
    }

    /// The newest state.
    pub fn current(&self) -> Arc<Published> {
        self.sender.borrow().clone()
    }

    /// A receiver that wakes on every publish (skipping to the newest).
    pub fn subscribe(&self) -> watch::Receiver<Arc<Published>> {
        self.sender.subscribe()
    }
}

/// Whether `shown`, the sum of responses as viewers evaluate it, is within the bound
/// docs/PROTOCOL.md states of the served `radiosity` at every vertex: the responses'
/// `quantisation` ([`wire::responses::Responses::quantisation_bound`]) plus one full frame's
/// bound, which covers the f32 rounding of both and a version whose codes came from the base
/// solve (the same solution to the solver's tolerance).
fn sum_within_bound(radiosity: &[[f32; 3]], shown: &[[f32; 3]], quantisation: &[f64]) -> bool {
    radiosity
        .iter()
        .zip(shown)
        .enumerate()
        .all(|(v, (exact, sum))| {
            let brightest = exact.iter().copied().fold(0.0f32, f32::max) as f64;
            let bound = quantisation[v] + wire::rgb9e5::RELATIVE_ERROR_BOUND as f64 * brightest;
            exact
                .iter()
                .zip(sum)
                .all(|(e, s)| (*e as f64 - *s as f64).abs() <= bound)
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn geometry(vertices: usize) -> Geometry {
        Geometry {
            positions: vec![[0.0; 3]; vertices],
            patches: vec![[0, 0, 0, wire::geometry::NO_CORNER]],
            patch_objects: vec![0],
            objects: vec!["thing".into()],
            camera: None,
            textures: None,
        }
    }

    #[test]
    fn a_new_scale_is_the_smallest_power_of_two_that_fits_the_brightest_value() {
        let (scale, _) = encode(&[[1000.0, 0.0, 3.0]], None);
        assert_eq!(scale, wire::scale_for(1000.0));
        assert_eq!(scale.log2().fract(), 0.0, "a power of two");
        assert!(1000.0 <= wire::rgb9e5::MAX_VALUE * scale);
        assert!(
            1000.0 > wire::rgb9e5::MAX_VALUE * scale / 2.0,
            "the smallest that fits"
        );
    }

    #[test]
    fn the_scale_is_kept_while_the_brightest_stays_within_the_headroom() {
        let hub = Hub::new(1, &geometry(2), Arc::from([]), &[[100.0; 3], [1.0; 3]]);
        let first = hub.current();
        // Dimmer by 16: within the 256x headroom, so the scale stays and a delta can carry it.
        hub.publish(&[[100.0 / 16.0; 3], [1.0; 3]], false);
        let dimmer = hub.current();
        assert_eq!(dimmer.scale, first.scale);
        assert!(
            dimmer
                .delta
                .as_ref()
                .is_some_and(|(base, _)| *base == first.version)
        );
        // Dimmer by 1024 in all: past the headroom, a finer scale and a full frame only.
        hub.publish(&[[100.0 / 1024.0; 3], [1.0 / 1024.0; 3]], false);
        let dim = hub.current();
        assert!(dim.scale < first.scale);
        assert!(dim.delta.is_none());
        // Brighter than the scale holds: a coarser one, never clipping.
        hub.publish(&[[1e6; 3], [1.0; 3]], true);
        let bright = hub.current();
        assert!(1e6 <= wire::rgb9e5::MAX_VALUE * bright.scale);
        // Within RGB9E5's 9-bit mantissa (EXT_texture_shared_exponent).
        let decoded = wire::decode_colour(bright.colours[0], bright.scale)[0];
        assert!((decoded / 1e6 - 1.0).abs() <= 2f32.powi(-9), "{decoded}");
    }

    #[test]
    fn an_edge_takes_an_origins_sum_only_of_its_version_and_with_every_response() {
        let values = [[2.0, 1.0, 0.5], [0.25; 3]];
        let origin = Hub::new(1, &geometry(2), Arc::from([]), &values);
        let edge = Hub::new(1, &geometry(2), Arc::from([]), &values);
        let older = Response::quantise(3, &[[9.0; 3]; 2]);
        let response = Response::quantise(7, &values);
        origin.add_response(response.clone());
        let terms = vec![Term {
            response_id: 7,
            weight: [1.0; 3],
        }];
        origin.publish_with_sum(&values, true, Some(terms));
        let published = origin.current();
        let sum = published.sum.clone().expect("the sum is within its bound");
        let state = Published::new(
            FrameInfo {
                solution_version: published.version,
                sent_at_unix_micros: 0,
                scale: published.scale,
                vertex_count: 2,
                is_final: true,
            },
            published.colours.to_vec(),
            None,
            1,
        );
        edge.add_response(older);
        assert_eq!(
            edge.sum_for(&state, sum.frame.clone()).unwrap_err(),
            "it names a response this hub does not hold"
        );
        edge.add_response(response);
        let taken = edge.sum_for(&state, sum.frame.clone()).unwrap();
        assert_eq!(
            (&taken.response_ids, taken.checksum, &taken.frame),
            (&sum.response_ids, sum.checksum, &sum.frame),
            "the origin's sum, as the origin evaluates it"
        );
        assert!(edge.response(3).is_none(), "older than any sum to come");
        let first = edge.current();
        assert!(
            edge.sum_for(&first, sum.frame.clone()).is_err(),
            "another version"
        );
        assert!(
            edge.sum_for(&state, published.full.clone()).is_err(),
            "not a sum"
        );
    }

    #[test]
    fn publishing_what_viewers_hold_makes_no_version_and_a_new_geometry_does() {
        let hub = Hub::new(1, &geometry(1), Arc::from([]), &[[1.0; 3]]);
        assert_eq!(hub.publish(&[[1.0; 3]], false), 1);
        assert_eq!(hub.publish(&[[1.0; 3]], true), 2, "final is news");
        assert_eq!(hub.replace_geometry(geometry(3)), 2);
        // Three vertices now: a full frame of the new count on the new geometry, no delta.
        assert_eq!(hub.publish(&[[1.0; 3]; 3], true), 3);
        let current = hub.current();
        assert_eq!((current.colours.len(), current.geometry_version), (3, 2));
        assert!(current.delta.is_none());
    }
}
