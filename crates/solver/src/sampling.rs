//! Deterministic sample patterns: hashes that seed them per pair, a low-discrepancy sequence
//! on the unit square, and cosine-distributed directions. Every ray the solver casts comes from
//! here, so results are the same on any thread count.

use glam::DVec3;
use std::f64::consts::PI;

/// SplitMix64 (Steele, Lea, Flood 2014): a well-mixed hash of the pair, so the sample pattern
/// is deterministic yet decorrelated between pairs.
pub fn splitmix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// A seed for the sample pattern of the ordered pair `(a, b)`: the same every time, different
/// between pairs.
pub fn pair_seed(a: usize, b: usize) -> u64 {
    splitmix64(((a as u64) << 32) | b as u64)
}

/// The top 53 bits of `bits` as a number uniform in [0, 1): every `f64` step there is equally
/// likely.
pub fn unit_interval(bits: u64) -> f64 {
    (bits >> 11) as f64 / (1u64 << 53) as f64
}

/// The k-th point of Roberts' R2 sequence, rotated by `offset` (Cranley-Patterson), kept off the
/// patch border so that a ray never starts on a shared edge.
pub fn stratified_uv(k: u32, offset: u64) -> (f64, f64) {
    // Roberts 2018, "The Unreasonable Effectiveness of Quasirandom Sequences": 1/phi_2, 1/phi_2^2.
    const A1: f64 = 0.754_877_666_246_692_7;
    const A2: f64 = 0.569_840_290_998_053_2;
    let (u0, v0) = (
        unit_interval(offset),
        (offset & 0xFFFF_FFFF) as f64 / 4_294_967_296.0,
    );
    // x >= 0, so its fraction is x less its integer part, the same bits as `fract` without the
    // libm `trunc` call it becomes on baseline x86-64 (3.5% of a large town's solve).
    let inset = |x: f64| 1e-3 + (1.0 - 2e-3) * (x - x as u64 as f64);
    (inset(u0 + k as f64 * A1), inset(v0 + k as f64 * A2))
}

/// A unit direction about the unit `normal` with density `cos / pi`, from two uniform numbers
/// in [0, 1) (Malley's method: uniform on the disc, lifted to the hemisphere; pbrt 4e, 13.6).
pub fn cosine_direction(normal: DVec3, u: f64, v: f64) -> DVec3 {
    let (radius, angle) = (u.sqrt(), 2.0 * PI * v);
    let (tangent, bitangent) = normal.any_orthonormal_pair();
    (tangent * (radius * angle.cos())
        + bitangent * (radius * angle.sin())
        + normal * (1.0 - u).max(0.0).sqrt())
    .normalize()
}

#[cfg(test)]
mod tests {
    use super::{splitmix64, stratified_uv};

    #[test]
    fn stratified_points_are_roberts_sequence_kept_off_the_border() {
        for seed in 0..200u64 {
            let offset = splitmix64(seed);
            for k in [0, 1, 2, 15, 16, 63, 1000, u32::MAX] {
                let (u, v) = stratified_uv(k, offset);
                let u0 = (offset >> 11) as f64 / (1u64 << 53) as f64;
                let v0 = (offset & 0xFFFF_FFFF) as f64 / 4_294_967_296.0;
                let expected = |x: f64| 1e-3 + (1.0 - 2e-3) * x.fract();
                assert_eq!(u, expected(u0 + k as f64 * 0.754_877_666_246_692_7));
                assert_eq!(v, expected(v0 + k as f64 * 0.569_840_290_998_053_2));
                assert!((1e-3..=1.0 - 1e-3).contains(&u) && (1e-3..=1.0 - 1e-3).contains(&v));
            }
        }
    }
}
