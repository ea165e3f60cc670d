//! The radcast wire protocol: what the server sends and viewers receive. No async runtime.
//!
//! - [`rgb9e5`]: each vertex's colour in 4 bytes (shared-exponent HDR).
//! - [`frame`]: hello, full and delta frames, and the viewer's requests.
//! - [`responses`]: protocol 3's per-emitter responses and the sums viewers make of them.
//! - [`geometry`]: the scene as a viewer fetches it once.
//! - [`ColourBuffer`]: a viewer's copy of the colours, kept current by applying frames.
//! - [`summary`]: the JSON of `/api/solution`, typed.
//! - [`display`]: smooth shading and the tone map every consumer shares; [`gltf`]: GLB export.

pub mod display;
pub mod frame;
pub mod geometry;
pub mod gltf;
pub mod responses;
pub mod rgb9e5;
pub mod summary;

pub use frame::{
    ClientMessage, DeltaFrame, FrameInfo, FullFrame, Hello, PLAIN_PROTOCOL_VERSION,
    PROTOCOL_VERSION, ServerMessage, subprotocol,
};
pub use geometry::{Camera, Geometry};
pub use summary::SolutionSummary;

/// Why bytes could not be decoded. Decoders return these; they never panic.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// The message ends early.
    #[error("truncated {what}: need {needed} bytes, have {got}")]
    Truncated {
        /// The part being read.
        what: &'static str,
        /// Bytes needed.
        needed: usize,
        /// Bytes there.
        got: usize,
    },
    /// The kind byte names no message.
    #[error("unknown message kind {0}")]
    UnknownKind(u8),
    /// Flag bits this version does not define.
    #[error("unknown flags {0:#04x}")]
    UnknownFlags(u8),
    /// The peer speaks another protocol version.
    #[error("protocol version {got} is not supported (this side speaks 2 to {supported})")]
    UnsupportedVersion {
        /// The peer's version.
        got: u16,
        /// Our newest.
        supported: u16,
    },
    /// A count or size exceeds what is allowed.
    #[error("{what} {size} exceeds the limit {limit}")]
    TooLarge {
        /// The field.
        what: &'static str,
        /// Its value.
        size: u64,
        /// The limit.
        limit: u64,
    },
    /// A section has the wrong length.
    #[error("{what}: expected {expected} bytes, got {got}")]
    Length {
        /// The section.
        what: &'static str,
        /// Bytes expected.
        expected: usize,
        /// Bytes found.
        got: usize,
    },
    /// A delta names a vertex that does not exist.
    #[error("vertex index {index} out of range (vertex count {vertex_count})")]
    IndexOutOfRange {
        /// The index.
        index: u64,
        /// Vertices in the frame.
        vertex_count: u32,
    },
    /// Bytes after the end of a complete message.
    #[error("{0} trailing bytes after the message")]
    TrailingBytes(usize),
    /// Geometry bytes do not start with [`geometry::MAGIC`].
    #[error("not radcast geometry (bad magic)")]
    BadMagic,
    /// A fixed header could not be read.
    #[error("bad header: {0}")]
    Header(String),
    /// A value is out of its domain.
    #[error("invalid: {0}")]
    Invalid(String),
}

/// Microseconds since the Unix epoch by this machine's clock: what a frame's
/// `sent_at_unix_micros` holds at publish time, and what a viewer compares it with for latency
/// (0 if the clock is before 1970).
pub fn unix_micros_now() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

/// CRC-32 (IEEE, as zlib's `crc32`) of the codes as little-endian bytes: the checksum
/// `/api/solution` reports, so any viewer can check its buffer.
pub fn checksum(colours: &[u32]) -> u32 {
    let mut hasher = crc32fast::Hasher::new();
    for c in colours {
        hasher.update(&c.to_le_bytes());
    }
    hasher.finalize()
}

/// The power-of-two scale that fits `max_value` (W/m^2) under [`rgb9e5::MAX_VALUE`] while using
/// the top of the exponent range, so dim and bright scenes keep the same relative precision.
pub fn scale_for(max_value: f32) -> f32 {
    if !(max_value.is_finite() && max_value > 0.0) {
        return 1.0;
    }
    2f32.powi(
        (max_value / rgb9e5::MAX_VALUE)
            .log2()
            .ceil()
            .clamp(-100.0, 100.0) as i32,
    )
}

/// Encodes one radiosity (W/m^2) with a frame's scale.
pub fn encode_colour(rgb: [f32; 3], scale: f32) -> u32 {
    rgb9e5::encode(rgb.map(|c| c / scale))
}

/// Decodes one code with a frame's scale, to W/m^2.
pub fn decode_colour(code: u32, scale: f32) -> [f32; 3] {
    rgb9e5::decode(code).map(|c| c * scale)
}

/// Why a frame could not be applied to a buffer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ApplyError {
    /// A delta against a version this buffer does not hold as codes: ask for a full frame.
    #[error("delta from version {base} but the buffer holds {held:?}")]
    BaseMismatch {
        /// The delta's base.
        base: u64,
        /// What the buffer holds.
        held: Option<u64>,
    },
    /// A sum the responses held cannot make (protocol 3).
    #[error(transparent)]
    Sum(#[from] responses::SumError),
}

/// A viewer's copy of the vertex colours: codes from full and delta frames, or (protocol 3)
/// the values of a sum of the responses it holds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ColourBuffer {
    /// The frame info of the state held, none before the first full frame.
    pub info: Option<FrameInfo>,
    /// One code per geometry vertex, from the last full or delta frame.
    pub colours: Vec<u32>,
    /// The responses sums are made of.
    pub responses: responses::Responses,
    /// The values of the last sum frame, W/m^2, while it is the state held (a full frame
    /// replaces it).
    pub sum: Option<Vec<[f32; 3]>>,
    /// That sum frame's terms.
    pub sum_terms: Vec<responses::Term>,
}

impl ColourBuffer {
    /// Applies a message; a hello changes nothing, a geometry change forgets the responses.
    pub fn apply(&mut self, message: &ServerMessage) -> Result<(), ApplyError> {
        match message {
            ServerMessage::Hello(_) => {}
            ServerMessage::GeometryChanged { .. } => self.responses.clear(),
            ServerMessage::Full(frame) => {
                self.colours.clone_from(&frame.colours);
                self.info = Some(frame.info);
                self.sum = None;
            }
            ServerMessage::Delta(delta) => {
                let held = self
                    .info
                    .filter(|_| self.sum.is_none())
                    .map(|i| i.solution_version);
                if held != Some(delta.base_version)
                    || self.colours.len() != delta.info.vertex_count as usize
                {
                    return Err(ApplyError::BaseMismatch {
                        base: delta.base_version,
                        held,
                    });
                }
                for (&index, &colour) in delta.indices.iter().zip(&delta.colours) {
                    self.colours[index as usize] = colour;
                }
                self.info = Some(delta.info);
            }
            ServerMessage::Response(response) => self.responses.insert(response),
            ServerMessage::Sum(sum) => {
                self.sum = Some(self.responses.evaluate(sum)?);
                self.sum_terms.clone_from(&sum.terms);
                self.info = Some(sum.info);
            }
        }
        Ok(())
    }

    /// Radiosity at every geometry vertex, W/m^2.
    pub fn radiosity(&self) -> Vec<[f32; 3]> {
        if let Some(values) = &self.sum {
            return values.clone();
        }
        let scale = self.info.map_or(1.0, |info| info.scale);
        self.colours
            .iter()
            .map(|&c| decode_colour(c, scale))
            .collect()
    }

    /// Whether the state held is what `/api/solution` describes: its `checksum` of the codes,
    /// or for a sum its `sum_checksum` of the values.
    pub fn matches(&self, solution: &SolutionSummary) -> bool {
        let version = self.info.map(|i| i.solution_version);
        version == Some(solution.solution_version)
            && match &self.sum {
                Some(values) => solution.sum_checksum == Some(responses::sum_checksum(values)),
                None => solution.checksum == checksum(&self.colours),
            }
    }
}

/// The delta from `old` to `new` (same length): the indices whose code changed.
pub fn changes(old: &[u32], new: &[u32]) -> (Vec<u32>, Vec<u32>) {
    old.iter()
        .zip(new)
        .enumerate()
        .filter(|(_, (a, b))| a != b)
        .map(|(i, (_, b))| (i as u32, *b))
        .unzip()
}
