//! Messages on the WebSocket, as binary frames. The byte layouts are in docs/PROTOCOL.md.
//!
//! Every message starts with a kind byte and a flags byte; fixed-size headers follow as
//! little-endian fields (bincode 2 with fixed-width integers), then the payload.

use crate::DecodeError;
use bincode::{Decode, Encode};
use std::borrow::Cow;

/// The newest protocol version this crate speaks: 3 adds per-emitter responses and their sums
/// ([`crate::responses`]) to version 2's frames.
pub const PROTOCOL_VERSION: u16 = 3;

/// The oldest version this crate speaks: frames only. A [`Hello`] outside
/// `PLAIN_PROTOCOL_VERSION..=PROTOCOL_VERSION` is refused.
pub const PLAIN_PROTOCOL_VERSION: u16 = 2;

/// The WebSocket subprotocol (`Sec-WebSocket-Protocol`) that asks for protocol `version`:
/// `radcast.3`. A viewer that names none gets version 2.
pub fn subprotocol(version: u16) -> String {
    format!("radcast.{version}")
}

/// The most vertices a frame (or patches a geometry) may claim: bounds what a decoder allocates
/// for hostile input.
pub const MAX_VERTICES: u32 = 1 << 26;

/// Flag: the payload is LZ4-compressed (a u32 uncompressed size, then an LZ4 block).
pub const FLAG_COMPRESSED: u8 = 1;
/// Flag: this frame holds the converged solution for its version.
pub const FLAG_FINAL: u8 = 2;

const KIND_HELLO: u8 = 1;
const KIND_FULL: u8 = 2;
const KIND_DELTA: u8 = 3;
const KIND_GEOMETRY_CHANGED: u8 = 4;
const KIND_RESPONSE: u8 = 5;
const KIND_SUM: u8 = 6;
const KIND_REQUEST_FULL: u8 = 16;

/// Fixed-width little-endian integers: every header has one fixed layout (docs/PROTOCOL.md).
pub(crate) fn config()
-> bincode::config::Configuration<bincode::config::LittleEndian, bincode::config::Fixint> {
    bincode::config::standard()
        .with_fixed_int_encoding()
        .with_little_endian()
}

/// The first message on every connection.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Encode, Decode)]
pub struct Hello {
    /// [`PROTOCOL_VERSION`] of the server.
    pub protocol_version: u16,
    /// Identifies the scene file and solve settings (a hash); stable across restarts.
    pub scene_id: u64,
    /// Bumped whenever the geometry changes: refetch `/api/scene` when it differs.
    pub geometry_version: u64,
    /// Values in every frame: the geometry's vertex count.
    pub vertex_count: u32,
}

/// What every frame says about the solution it carries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameInfo {
    /// Increases with every published state (progressive steps and re-solves alike).
    pub solution_version: u64,
    /// Server clock when the frame was encoded, microseconds since the Unix epoch.
    pub sent_at_unix_micros: u64,
    /// Decoded RGB9E5 values are multiplied by this (a power of two) to give W/m^2; 1 for a
    /// [`SumFrame`], whose values are W/m^2 already.
    pub scale: f32,
    /// Values in the buffer: one per geometry vertex.
    pub vertex_count: u32,
    /// The solver converged for this version.
    pub is_final: bool,
}

/// The whole buffer: one colour per geometry vertex.
#[derive(Clone, Debug, PartialEq)]
pub struct FullFrame {
    /// Version, time, scale, size.
    pub info: FrameInfo,
    /// One RGB9E5 code per vertex, in the order of [`crate::Geometry::positions`].
    pub colours: Vec<u32>,
}

/// Only the vertices whose code changed since `base_version`.
#[derive(Clone, Debug, PartialEq)]
pub struct DeltaFrame {
    /// The version a receiver must hold to apply this.
    pub base_version: u64,
    /// Version, time, scale, size after applying.
    pub info: FrameInfo,
    /// Changed vertex indices, strictly increasing.
    pub indices: Vec<u32>,
    /// New codes, one per index.
    pub colours: Vec<u32>,
}

/// The most terms a sum frame may carry: bounds what a decoder allocates and what a viewer
/// computes per edit (terms x vertices).
pub const MAX_TERMS: u32 = 64;

/// The largest weight a term may carry: the emission rule (W/m^2, what frames hold after
/// reflections).
pub const MAX_WEIGHT: f32 = 1e24;

/// One emitter's response: the colour of every vertex per W/m^2 of its emission, channel by
/// channel, quantised like a full frame (its own scale; values below zero are sent as zero).
#[derive(Clone, Debug, PartialEq)]
pub struct Response {
    /// Names it in sum frames; unique for the server's run (never reused, not even after a
    /// move).
    pub response_id: u32,
    /// Decoded RGB9E5 values are multiplied by this (a power of two).
    pub scale: f32,
    /// One RGB9E5 code per geometry vertex.
    pub codes: Vec<u32>,
}

impl Response {
    /// The response `response_id` with these values (W/m^2 per W/m^2 of emission), at the
    /// scale that fits its brightest channel.
    pub fn quantise(response_id: u32, values: &[[f32; 3]]) -> Response {
        let brightest = values
            .iter()
            .flatten()
            .copied()
            .filter(|c| c.is_finite())
            .fold(0.0, f32::max);
        let scale = crate::scale_for(brightest);
        Response {
            response_id,
            scale,
            codes: values
                .iter()
                .map(|v| crate::encode_colour(*v, scale))
                .collect(),
        }
    }

    /// Its values as a viewer holds them, W/m^2 per W/m^2: `decode_colour` of each code.
    pub fn values(&self) -> Vec<[f32; 3]> {
        self.codes
            .iter()
            .map(|c| crate::decode_colour(*c, self.scale))
            .collect()
    }
}

/// One term of a sum: a response and the emission it is weighted by.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Term {
    /// A response the viewer was sent.
    pub response_id: u32,
    /// W/m^2 per channel: finite, at least 0 and at most [`MAX_WEIGHT`].
    pub weight: [f32; 3],
}

/// A solution version as a weighted sum of responses the viewer holds.
#[derive(Clone, Debug, PartialEq)]
pub struct SumFrame {
    /// Version, time, size and final flag; the scale is 1 (the values are W/m^2 already).
    pub info: FrameInfo,
    /// The terms, in the order they are added.
    pub terms: Vec<Term>,
}

/// A message from the server.
#[derive(Clone, Debug, PartialEq)]
pub enum ServerMessage {
    /// Sent once, first.
    Hello(Hello),
    /// A whole buffer.
    Full(FullFrame),
    /// Changes against an earlier version.
    Delta(DeltaFrame),
    /// The geometry changed (an object moved): fetch `/api/scene` again. On a uniform mesh the
    /// vertices stay the same; a hierarchy's leaves change, and the next full frame carries
    /// their new vertex count.
    GeometryChanged {
        /// The new geometry version.
        geometry_version: u64,
    },
    /// Protocol 3: one emitter's response, to keep for sums until the geometry changes.
    Response(Response),
    /// Protocol 3: a version as a weighted sum of responses sent before.
    Sum(SumFrame),
}

/// A message from a viewer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClientMessage {
    /// "Send me a full frame": after a delta whose base the viewer does not hold.
    RequestFull,
}

#[derive(Encode, Decode)]
struct FullHeader {
    solution_version: u64,
    sent_at_unix_micros: u64,
    scale: f32,
    vertex_count: u32,
}

#[derive(Encode, Decode)]
struct ResponseHeader {
    response_id: u32,
    scale: f32,
    vertex_count: u32,
}

#[derive(Encode, Decode)]
struct SumHeader {
    solution_version: u64,
    sent_at_unix_micros: u64,
    vertex_count: u32,
    term_count: u32,
}

/// Bytes of one sum term: the response id and three f32 weights.
const TERM_BYTES: usize = 16;

#[derive(Encode, Decode)]
struct DeltaHeader {
    base_version: u64,
    solution_version: u64,
    sent_at_unix_micros: u64,
    scale: f32,
    vertex_count: u32,
    change_count: u32,
}

fn flags_for(info: &FrameInfo) -> u8 {
    if info.is_final { FLAG_FINAL } else { 0 }
}

/// Appends `payload` raw, or LZ4-compressed when that is smaller, and returns the flag to set.
fn push_payload(out: &mut Vec<u8>, payload: &[u8]) -> u8 {
    let compressed = lz4_flex::block::compress(payload);
    if compressed.len() + 4 < payload.len() {
        out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        out.extend_from_slice(&compressed);
        FLAG_COMPRESSED
    } else {
        out.extend_from_slice(payload);
        0
    }
}

/// A full frame's or a response's bytes: the header, then one code a vertex (LZ4 when smaller).
fn encode_codes(kind: u8, flags: u8, header: impl Encode, codes: &[u32]) -> Vec<u8> {
    let mut out = encode_header(kind, flags, header);
    let payload: Vec<u8> = codes.iter().flat_map(|c| c.to_le_bytes()).collect();
    out[1] |= push_payload(&mut out, &payload);
    out
}

fn encode_header(kind: u8, flags: u8, header: impl Encode) -> Vec<u8> {
    let mut out = vec![kind, flags];
    bincode::encode_into_std_write(header, &mut out, config())
        .expect("writing to a Vec cannot fail");
    out
}

impl ServerMessage {
    /// The message's bytes, ready to send as one binary WebSocket message.
    pub fn encode(&self) -> Vec<u8> {
        match self {
            ServerMessage::Hello(hello) => encode_header(KIND_HELLO, 0, hello),
            ServerMessage::GeometryChanged { geometry_version } => {
                encode_header(KIND_GEOMETRY_CHANGED, 0, geometry_version)
            }
            ServerMessage::Full(frame) => {
                let info = &frame.info;
                let header = FullHeader {
                    solution_version: info.solution_version,
                    sent_at_unix_micros: info.sent_at_unix_micros,
                    scale: info.scale,
                    vertex_count: frame.colours.len() as u32,
                };
                encode_codes(KIND_FULL, flags_for(info), header, &frame.colours)
            }
            ServerMessage::Delta(frame) => {
                let info = &frame.info;
                let header = DeltaHeader {
                    base_version: frame.base_version,
                    solution_version: info.solution_version,
                    sent_at_unix_micros: info.sent_at_unix_micros,
                    scale: info.scale,
                    vertex_count: info.vertex_count,
                    change_count: frame.indices.len() as u32,
                };
                let mut out = encode_header(KIND_DELTA, flags_for(info), header);
                let mut payload = Vec::with_capacity(frame.indices.len() * 6);
                let mut next = 0u32;
                for &index in &frame.indices {
                    // Gaps between strictly increasing indices, as LEB128 varints.
                    write_varint(&mut payload, index - next);
                    next = index + 1;
                }
                payload.extend(frame.colours.iter().flat_map(|c| c.to_le_bytes()));
                out[1] |= push_payload(&mut out, &payload);
                out
            }
            ServerMessage::Response(response) => {
                let header = ResponseHeader {
                    response_id: response.response_id,
                    scale: response.scale,
                    vertex_count: response.codes.len() as u32,
                };
                encode_codes(KIND_RESPONSE, 0, header, &response.codes)
            }
            ServerMessage::Sum(sum) => {
                let info = &sum.info;
                let header = SumHeader {
                    solution_version: info.solution_version,
                    sent_at_unix_micros: info.sent_at_unix_micros,
                    vertex_count: info.vertex_count,
                    term_count: sum.terms.len() as u32,
                };
                let mut out = encode_header(KIND_SUM, flags_for(info), header);
                for term in &sum.terms {
                    out.extend(term.response_id.to_le_bytes());
                    out.extend(term.weight.iter().flat_map(|w| w.to_le_bytes()));
                }
                out
            }
        }
    }

    /// Parses one message; never panics, whatever the bytes.
    pub fn decode(bytes: &[u8]) -> Result<ServerMessage, DecodeError> {
        let (kind, flags, rest) = split_kind(bytes)?;
        match kind {
            KIND_HELLO => decode_hello(flags, rest),
            KIND_FULL => decode_full(flags, rest),
            KIND_DELTA => decode_delta(flags, rest),
            KIND_GEOMETRY_CHANGED => {
                check_flags(flags, 0)?;
                let (geometry_version, used): (u64, usize) = decode_header(rest)?;
                expect_end(&rest[used..])?;
                Ok(ServerMessage::GeometryChanged { geometry_version })
            }
            KIND_RESPONSE => decode_response(flags, rest),
            KIND_SUM => decode_sum(flags, rest),
            other => Err(DecodeError::UnknownKind(other)),
        }
    }
}

/// A hello of a version this crate speaks.
fn decode_hello(flags: u8, rest: &[u8]) -> Result<ServerMessage, DecodeError> {
    check_flags(flags, 0)?;
    let (hello, used): (Hello, usize) = decode_header(rest)?;
    expect_end(&rest[used..])?;
    if !(PLAIN_PROTOCOL_VERSION..=PROTOCOL_VERSION).contains(&hello.protocol_version) {
        return Err(DecodeError::UnsupportedVersion {
            got: hello.protocol_version,
            supported: PROTOCOL_VERSION,
        });
    }
    Ok(ServerMessage::Hello(hello))
}

/// A full frame: every vertex's code.
fn decode_full(flags: u8, rest: &[u8]) -> Result<ServerMessage, DecodeError> {
    check_flags(flags, FLAG_COMPRESSED | FLAG_FINAL)?;
    let (header, used): (FullHeader, usize) = decode_header(rest)?;
    check_vertex_count(header.vertex_count)?;
    let colours = one_code_a_vertex(
        &rest[used..],
        flags,
        header.vertex_count,
        "full frame colours",
    )?;
    let info = frame_info(
        header.solution_version,
        header.sent_at_unix_micros,
        header.scale,
        header.vertex_count,
        flags,
    )?;
    Ok(ServerMessage::Full(FullFrame { info, colours }))
}

/// A delta frame: gap-encoded indices, then their codes.
fn decode_delta(flags: u8, rest: &[u8]) -> Result<ServerMessage, DecodeError> {
    check_flags(flags, FLAG_COMPRESSED | FLAG_FINAL)?;
    let (header, used): (DeltaHeader, usize) = decode_header(rest)?;
    check_vertex_count(header.vertex_count)?;
    if header.change_count > header.vertex_count {
        return Err(DecodeError::TooLarge {
            what: "delta change count",
            size: header.change_count as u64,
            limit: header.vertex_count as u64,
        });
    }
    // Each change takes at most 5 varint bytes and 4 colour bytes.
    let payload = take_payload(&rest[used..], flags, header.change_count as usize * 9)?;
    let (indices, colour_bytes) = read_indices(&payload, header.change_count, header.vertex_count)?;
    let expected = header.change_count as usize * 4;
    if colour_bytes.len() != expected {
        return Err(DecodeError::Length {
            what: "delta colours",
            expected,
            got: colour_bytes.len(),
        });
    }
    let info = frame_info(
        header.solution_version,
        header.sent_at_unix_micros,
        header.scale,
        header.vertex_count,
        flags,
    )?;
    Ok(ServerMessage::Delta(DeltaFrame {
        base_version: header.base_version,
        info,
        indices,
        colours: read_codes(colour_bytes),
    }))
}

/// Protocol 3: one emitter's response, codes like a full frame's.
fn decode_response(flags: u8, rest: &[u8]) -> Result<ServerMessage, DecodeError> {
    check_flags(flags, FLAG_COMPRESSED)?;
    let (header, used): (ResponseHeader, usize) = decode_header(rest)?;
    check_vertex_count(header.vertex_count)?;
    check_scale(header.scale)?;
    let codes = one_code_a_vertex(&rest[used..], flags, header.vertex_count, "response codes")?;
    Ok(ServerMessage::Response(Response {
        response_id: header.response_id,
        scale: header.scale,
        codes,
    }))
}

/// Protocol 3: a sum frame, its terms checked.
fn decode_sum(flags: u8, rest: &[u8]) -> Result<ServerMessage, DecodeError> {
    check_flags(flags, FLAG_FINAL)?;
    let (header, used): (SumHeader, usize) = decode_header(rest)?;
    check_term_count(header.term_count, header.vertex_count)?;
    let body = &rest[used..];
    let expected = header.term_count as usize * TERM_BYTES;
    if body.len() != expected {
        return Err(DecodeError::Length {
            what: "sum terms",
            expected,
            got: body.len(),
        });
    }
    let terms = body
        .chunks_exact(TERM_BYTES)
        .map(|t| {
            let word = |k: usize| [t[4 * k], t[4 * k + 1], t[4 * k + 2], t[4 * k + 3]];
            let weight = [1, 2, 3].map(|k| f32::from_le_bytes(word(k)));
            Ok(Term {
                response_id: u32::from_le_bytes(word(0)),
                weight: check_weight(weight)?,
            })
        })
        .collect::<Result<_, DecodeError>>()?;
    let info = frame_info(
        header.solution_version,
        header.sent_at_unix_micros,
        1.0,
        header.vertex_count,
        flags,
    )?;
    Ok(ServerMessage::Sum(SumFrame { info, terms }))
}

impl ClientMessage {
    /// The message's bytes.
    pub fn encode(&self) -> Vec<u8> {
        match self {
            ClientMessage::RequestFull => vec![KIND_REQUEST_FULL, 0],
        }
    }

    /// Parses one message; never panics, whatever the bytes.
    pub fn decode(bytes: &[u8]) -> Result<ClientMessage, DecodeError> {
        let (kind, flags, rest) = split_kind(bytes)?;
        match kind {
            KIND_REQUEST_FULL => {
                check_flags(flags, 0)?;
                expect_end(rest)?;
                Ok(ClientMessage::RequestFull)
            }
            other => Err(DecodeError::UnknownKind(other)),
        }
    }
}

fn split_kind(bytes: &[u8]) -> Result<(u8, u8, &[u8]), DecodeError> {
    match bytes {
        [kind, flags, rest @ ..] => Ok((*kind, *flags, rest)),
        _ => Err(DecodeError::Truncated {
            what: "message kind and flags",
            needed: 2,
            got: bytes.len(),
        }),
    }
}

/// The checks a decoded term must pass.
fn check_weight(weight: [f32; 3]) -> Result<[f32; 3], DecodeError> {
    if weight
        .iter()
        .all(|w| w.is_finite() && (0.0..=MAX_WEIGHT).contains(w))
    {
        Ok(weight)
    } else {
        Err(DecodeError::Invalid(format!(
            "sum weight {weight:?} must be finite, at least 0 and at most {MAX_WEIGHT:e}"
        )))
    }
}

/// The checks a decoded term count must pass.
fn check_term_count(count: u32, vertex_count: u32) -> Result<(), DecodeError> {
    check_vertex_count(vertex_count)?;
    if count > MAX_TERMS {
        return Err(DecodeError::TooLarge {
            what: "sum term count",
            size: count as u64,
            limit: MAX_TERMS as u64,
        });
    }
    Ok(())
}

fn check_flags(flags: u8, allowed: u8) -> Result<(), DecodeError> {
    if flags & !allowed != 0 {
        Err(DecodeError::UnknownFlags(flags))
    } else {
        Ok(())
    }
}

fn check_vertex_count(count: u32) -> Result<(), DecodeError> {
    if count > MAX_VERTICES {
        Err(DecodeError::TooLarge {
            what: "vertex count",
            size: count as u64,
            limit: MAX_VERTICES as u64,
        })
    } else {
        Ok(())
    }
}

/// The frame info shared by full and delta frames, with the scale checked.
fn frame_info(
    solution_version: u64,
    sent_at_unix_micros: u64,
    scale: f32,
    vertex_count: u32,
    flags: u8,
) -> Result<FrameInfo, DecodeError> {
    check_scale(scale)?;
    Ok(FrameInfo {
        solution_version,
        sent_at_unix_micros,
        scale,
        vertex_count,
        is_final: flags & FLAG_FINAL != 0,
    })
}

/// A frame's or a response's scale: the largest code times it must stay a finite f32.
fn check_scale(scale: f32) -> Result<(), DecodeError> {
    let max_scale = f32::MAX / crate::rgb9e5::MAX_VALUE;
    if scale > 0.0 && scale <= max_scale {
        Ok(())
    } else {
        Err(DecodeError::Invalid(format!(
            "scale {scale} must be positive and at most {max_scale:e}"
        )))
    }
}

/// The `vertex_count` codes of a full frame's or a response's payload (decompressed if
/// flagged), refused unless there are exactly that many.
fn one_code_a_vertex(
    payload: &[u8],
    flags: u8,
    vertex_count: u32,
    what: &'static str,
) -> Result<Vec<u32>, DecodeError> {
    let expected = vertex_count as usize * 4;
    let payload = take_payload(payload, flags, expected)?;
    if payload.len() != expected {
        return Err(DecodeError::Length {
            what,
            expected,
            got: payload.len(),
        });
    }
    Ok(read_codes(&payload))
}

/// Little-endian u32 codes (the caller has checked the length is a multiple of 4).
fn read_codes(bytes: &[u8]) -> Vec<u32> {
    bytes
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

fn expect_end(rest: &[u8]) -> Result<(), DecodeError> {
    if rest.is_empty() {
        Ok(())
    } else {
        Err(DecodeError::TrailingBytes(rest.len()))
    }
}

fn decode_header<T: Decode<()>>(bytes: &[u8]) -> Result<(T, usize), DecodeError> {
    bincode::decode_from_slice(bytes, config()).map_err(|e| DecodeError::Header(e.to_string()))
}

/// The payload, decompressed if flagged (borrowed when not); refuses to inflate beyond
/// `limit` bytes.
fn take_payload(bytes: &[u8], flags: u8, limit: usize) -> Result<Cow<'_, [u8]>, DecodeError> {
    if flags & FLAG_COMPRESSED == 0 {
        return Ok(Cow::Borrowed(bytes));
    }
    let [a, b, c, d, block @ ..] = bytes else {
        return Err(DecodeError::Truncated {
            what: "compressed payload size",
            needed: 4,
            got: bytes.len(),
        });
    };
    let size = u32::from_le_bytes([*a, *b, *c, *d]) as usize;
    if size > limit {
        return Err(DecodeError::TooLarge {
            what: "uncompressed payload",
            size: size as u64,
            limit: limit as u64,
        });
    }
    let mut out = vec![0; size];
    let written = lz4_flex::block::decompress_into(block, &mut out)
        .map_err(|e| DecodeError::Invalid(format!("LZ4 payload: {e}")))?;
    if written != size {
        return Err(DecodeError::Length {
            what: "decompressed payload",
            expected: size,
            got: written,
        });
    }
    Ok(Cow::Owned(out))
}

fn write_varint(out: &mut Vec<u8>, mut value: u32) {
    while value >= 0x80 {
        out.push((value as u8) | 0x80);
        value >>= 7;
    }
    out.push(value as u8);
}

/// Reads `count` gap-encoded indices; returns them and the bytes after them.
fn read_indices(
    bytes: &[u8],
    count: u32,
    vertex_count: u32,
) -> Result<(Vec<u32>, &[u8]), DecodeError> {
    let mut indices = Vec::with_capacity(count as usize);
    let (mut position, mut next) = (0usize, 0u64);
    for _ in 0..count {
        let (mut gap, mut shift) = (0u64, 0);
        loop {
            let &byte = bytes.get(position).ok_or(DecodeError::Truncated {
                what: "delta indices",
                needed: position + 1,
                got: bytes.len(),
            })?;
            position += 1;
            gap |= ((byte & 0x7F) as u64) << shift;
            if byte & 0x80 == 0 {
                break;
            }
            shift += 7;
            if shift > 28 {
                return Err(DecodeError::Invalid(
                    "delta index varint longer than 5 bytes".into(),
                ));
            }
        }
        let index = next + gap;
        if index >= vertex_count as u64 {
            return Err(DecodeError::IndexOutOfRange {
                index,
                vertex_count,
            });
        }
        indices.push(index as u32);
        next = index + 1;
    }
    Ok((indices, &bytes[position..]))
}
