//! Protocol 3: light as a sum of per-emitter responses (docs/PROTOCOL.md, "Responses and
//! sums").
//!
//! Radiosity is linear in emission, so the server can send each emitter's *response* (the
//! colours its object gives every vertex emitting 1 W/m^2 per channel) once, 4 bytes a vertex
//! as in a full frame, and afterwards only the emitters' current emissions: a [`SumFrame`]. A
//! viewer shows `sum_k weight_k * response_k`, evaluated exactly as [`Responses::evaluate`]
//! does so that every implementation computes the same f32 values and [`sum_checksum`] of
//! them.

pub use crate::frame::{MAX_TERMS, MAX_WEIGHT, Response, SumFrame, Term};
use crate::rgb9e5;
use std::collections::BTreeMap;

/// What can be wrong with a sum frame against the responses a viewer holds.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SumError {
    /// A term names a response the viewer was not sent (or dropped at a geometry change).
    #[error("the sum names response {0}, which this viewer does not hold")]
    MissingResponse(u32),
    /// A response of another vertex count.
    #[error("response {response_id} has {got} vertices, the sum {expected}")]
    VertexCount {
        /// The response.
        response_id: u32,
        /// The sum's count.
        expected: u32,
        /// The response's count.
        got: u32,
    },
}

/// The responses a viewer holds, by id: each one's scale and decoded values.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Responses {
    held: BTreeMap<u32, (f32, Vec<[f32; 3]>)>,
}

/// A term as a sum adds it up: its weight, its response's scale and decoded values.
type HeldTerm<'a> = ([f32; 3], f32, &'a [[f32; 3]]);

impl Responses {
    /// Keeps `response` (replacing one of the same id).
    pub fn insert(&mut self, response: &Response) {
        self.held
            .insert(response.response_id, (response.scale, response.values()));
    }

    /// Forgets every response: the geometry changed, and they belong to the old one.
    pub fn clear(&mut self) {
        self.held.clear();
    }

    /// Whether response `id` is held.
    pub fn holds(&self, id: u32) -> bool {
        self.held.contains_key(&id)
    }

    /// The values `sum` stands for, W/m^2: per vertex and channel, starting from 0 in f64, add
    /// `f64(weight) * f64(value)` term by term in the frame's order (each product is exact: two
    /// f32 mantissas fit in f64's), then round to the nearest f32. Every viewer that follows
    /// this gets the same bits.
    pub fn evaluate(&self, sum: &SumFrame) -> Result<Vec<[f32; 3]>, SumError> {
        let terms = self.terms_of(&sum.terms, sum.info.vertex_count)?;
        Ok((0..sum.info.vertex_count as usize)
            .map(|v| {
                let mut total = [0.0f64; 3];
                for (weight, _, values) in &terms {
                    for c in 0..3 {
                        total[c] += f64::from(weight[c]) * f64::from(values[v][c]);
                    }
                }
                total.map(|t| t as f32)
            })
            .collect())
    }

    /// Per vertex, how far each channel of the sum of `terms` may be from the same sum of the
    /// responses before they were quantised, W/m^2: each response's codes are within
    /// [`rgb9e5::RELATIVE_ERROR_BOUND`] of its brightest channel at that vertex, or `2^-24`
    /// of its scale (RGB9E5's bounds), so the sum is within
    /// `sum_k max(weight_k) * (2^-9 * max(response_k) + 2^-24 * scale_k)`. With white lights
    /// that is at most three times a full frame's bound on the vertex's brightest channel (a
    /// response's brightest channel is at most the sum of its three); under a coloured light a
    /// dim channel's error follows the light's brightest channel.
    pub fn quantisation_bound(
        &self,
        terms: &[Term],
        vertex_count: u32,
    ) -> Result<Vec<f64>, SumError> {
        let terms = self.terms_of(terms, vertex_count)?;
        let unit = f64::from(rgb9e5::RELATIVE_ERROR_BOUND);
        Ok((0..vertex_count as usize)
            .map(|v| {
                terms
                    .iter()
                    .map(|(weight, scale, values)| {
                        let strongest = weight.iter().copied().fold(0.0f32, f32::max);
                        let largest = values[v].iter().copied().fold(0.0f32, f32::max);
                        f64::from(strongest)
                            * (unit * f64::from(largest) + 2f64.powi(-24) * f64::from(*scale))
                    })
                    .sum()
            })
            .collect())
    }

    /// Each term's weight, scale and values, if every response is held at `vertex_count`.
    fn terms_of(&self, terms: &[Term], vertex_count: u32) -> Result<Vec<HeldTerm<'_>>, SumError> {
        terms
            .iter()
            .map(|term| {
                let (scale, values) = self
                    .held
                    .get(&term.response_id)
                    .ok_or(SumError::MissingResponse(term.response_id))?;
                if values.len() != vertex_count as usize {
                    return Err(SumError::VertexCount {
                        response_id: term.response_id,
                        expected: vertex_count,
                        got: values.len() as u32,
                    });
                }
                Ok((term.weight, *scale, values.as_slice()))
            })
            .collect()
    }
}

/// CRC-32 (IEEE, as zlib's `crc32`) of the values a sum gives, each vertex's red, green and
/// blue as little-endian f32: what `/api/solution` reports as `sum_checksum`, so a viewer can
/// check what it shows.
pub fn sum_checksum(values: &[[f32; 3]]) -> u32 {
    let mut hasher = crc32fast::Hasher::new();
    for value in values.iter().flatten() {
        hasher.update(&value.to_le_bytes());
    }
    hasher.finalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::FrameInfo;

    fn info(vertex_count: u32) -> FrameInfo {
        FrameInfo {
            solution_version: 3,
            sent_at_unix_micros: 0,
            scale: 1.0,
            vertex_count,
            is_final: true,
        }
    }

    #[test]
    fn a_sum_of_one_response_at_one_watt_is_the_response_as_decoded() {
        let values = [[0.5, 0.25, 3.0], [1e-6, 0.0, 2.0]];
        let response = Response::quantise(7, &values);
        let mut held = Responses::default();
        held.insert(&response);
        let sum = SumFrame {
            info: info(2),
            terms: vec![Term {
                response_id: 7,
                weight: [1.0; 3],
            }],
        };
        assert_eq!(held.evaluate(&sum), Ok(response.values()));
        // Exact binary fractions survive the quantisation.
        assert_eq!(response.values()[0], [0.5, 0.25, 3.0]);
    }

    #[test]
    fn two_emitters_sum_channel_by_channel_within_the_stated_bound() {
        let red: Vec<[f32; 3]> = (0..50).map(|i| [i as f32 * 0.37, 0.01, 0.0]).collect();
        let blue: Vec<[f32; 3]> = (0..50)
            .map(|i| [0.2, 0.0, 1.0 / (1.0 + i as f32)])
            .collect();
        let (a, b) = (Response::quantise(1, &red), Response::quantise(2, &blue));
        let mut held = Responses::default();
        held.insert(&a);
        held.insert(&b);
        let weights = [[3.0, 1.0, 0.5], [0.0, 2.0, 40.0]];
        let sum = SumFrame {
            info: info(50),
            terms: vec![
                Term {
                    response_id: 1,
                    weight: weights[0],
                },
                Term {
                    response_id: 2,
                    weight: weights[1],
                },
            ],
        };
        let shown = held.evaluate(&sum).unwrap();
        let bounds = held.quantisation_bound(&sum.terms, 50).unwrap();
        for v in 0..50 {
            let bound = bounds[v];
            for c in 0..3 {
                let exact = weights[0][c] as f64 * red[v][c] as f64
                    + weights[1][c] as f64 * blue[v][c] as f64;
                let error = (shown[v][c] as f64 - exact).abs();
                // The f32 rounding of the result adds at most half an ulp.
                assert!(
                    error <= bound + exact * 2f64.powi(-24),
                    "{v} {c}: {error} > {bound}"
                );
            }
        }
    }

    #[test]
    fn a_sum_names_only_responses_of_its_vertex_count_that_the_viewer_holds() {
        let mut held = Responses::default();
        held.insert(&Response::quantise(1, &[[1.0; 3]; 3]));
        let term = |id| Term {
            response_id: id,
            weight: [1.0; 3],
        };
        let sum = |terms| SumFrame {
            info: info(3),
            terms,
        };
        assert_eq!(
            held.evaluate(&sum(vec![term(1), term(2)])),
            Err(SumError::MissingResponse(2))
        );
        held.insert(&Response::quantise(2, &[[1.0; 3]; 4]));
        assert_eq!(
            held.evaluate(&sum(vec![term(2)])),
            Err(SumError::VertexCount {
                response_id: 2,
                expected: 3,
                got: 4
            })
        );
        held.clear();
        assert!(!held.holds(1));
    }

    #[test]
    fn the_sum_checksum_is_zlibs_crc32_of_the_values_as_little_endian_f32() {
        // Python: hex(zlib.crc32(struct.pack('<3f', 1, 1, 1))): one vertex of 1.0 in every channel.
        assert_eq!(sum_checksum(&[[1.0; 3]]), 0xdc7c_4e94);
        assert_ne!(sum_checksum(&[[1.0; 3]]), sum_checksum(&[[1.0, 1.0, -1.0]]));
    }
}
