//! RGB9E5: three 9-bit mantissas sharing a 5-bit exponent in one little-endian `u32`
//! (OpenGL EXT_texture_shared_exponent, section "Encoding").
//!
//! Bits 0-8 red, 9-17 green, 18-26 blue, 27-31 exponent. The largest encodable channel is
//! [`MAX_VALUE`] = 65408; the stream divides radiosity by a power-of-two `scale` first (see
//! [`crate::frame`]), so brighter scenes fit too.
//!
//! Error bound: for inputs in `[0, MAX_VALUE]`, every decoded channel is within
//! `2^-9 * max(r, g, b)` of the input (half a unit in the last place of the shared mantissa),
//! as long as `max(r, g, b) >= 2^-15`; below that the bound is `2^-24` absolute.

/// Mantissa bits per channel.
const MANTISSA_BITS: i32 = 9;
/// Exponent bias.
const EXPONENT_BIAS: i32 = 15;
/// Largest biased exponent.
const MAX_EXPONENT: i32 = 31;

/// The largest value a channel can hold: `(2^9 - 1) / 2^9 * 2^16`.
pub const MAX_VALUE: f32 = 65408.0;

/// The relative error bound against the brightest channel (see the module docs).
pub const RELATIVE_ERROR_BOUND: f32 = 1.0 / 512.0;

/// Encodes a colour. Negative and NaN channels become 0; channels above [`MAX_VALUE`] (and
/// +infinity) clamp to it.
pub fn encode(rgb: [f32; 3]) -> u32 {
    // NaN fails both comparisons inside `clamp`'s max/min pair, so filter it first.
    let clamp = |c: f32| {
        if c.is_nan() {
            0.0
        } else {
            c.clamp(0.0, MAX_VALUE)
        }
    };
    let [r, g, b] = rgb.map(clamp);
    let max = r.max(g).max(b);
    // floor(log2(max)), clamped below so that tiny values share the smallest exponent.
    let floor_log2 = if max > 0.0 {
        max.log2().floor() as i32
    } else {
        -EXPONENT_BIAS - 1
    };
    let mut exponent = floor_log2.max(-EXPONENT_BIAS - 1) + 1 + EXPONENT_BIAS;
    let mut unit = 2f32.powi(exponent - EXPONENT_BIAS - MANTISSA_BITS);
    // Rounding the maximum may carry into the next exponent.
    if (max / unit + 0.5).floor() as i32 == 1 << MANTISSA_BITS {
        exponent += 1;
        unit *= 2.0;
    }
    let exponent = exponent.min(MAX_EXPONENT);
    let mantissa = |c: f32| ((c / unit + 0.5).floor() as u32).min((1 << MANTISSA_BITS) - 1);
    mantissa(r) | mantissa(g) << 9 | mantissa(b) << 18 | (exponent as u32) << 27
}

/// Decodes a colour; every `u32` is a valid code.
pub fn decode(code: u32) -> [f32; 3] {
    let exponent = (code >> 27) as i32;
    let unit = 2f32.powi(exponent - EXPONENT_BIAS - MANTISSA_BITS);
    [code & 0x1FF, (code >> 9) & 0x1FF, (code >> 18) & 0x1FF].map(|m| m as f32 * unit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn within_bound(input: [f32; 3], output: [f32; 3]) -> bool {
        let max = input.iter().cloned().fold(0.0, f32::max);
        let bound = (RELATIVE_ERROR_BOUND * max).max(2f32.powi(-24));
        input
            .iter()
            .zip(output)
            .all(|(i, o)| (i - o).abs() <= bound * 1.0001)
    }

    #[test]
    fn zero_tiny_huge_and_invalid_values() {
        assert_eq!(decode(encode([0.0; 3])), [0.0; 3]);
        assert_eq!(decode(encode([1.0, 0.5, 0.25])), [1.0, 0.5, 0.25]);
        assert_eq!(decode(encode([MAX_VALUE; 3])), [MAX_VALUE; 3]);
        assert_eq!(
            decode(encode([1e9, f32::INFINITY, 0.0])),
            [MAX_VALUE, MAX_VALUE, 0.0]
        );
        assert_eq!(
            decode(encode([f32::NAN, -1.0, f32::NEG_INFINITY])),
            [0.0; 3]
        );
        let tiny = [1e-6, 2e-6, 0.0];
        assert!(within_bound(tiny, decode(encode(tiny))));
        // Below the smallest unit, values round to zero or one unit; never negative or NaN.
        assert!(
            decode(encode([1e-30; 3]))
                .iter()
                .all(|c| *c >= 0.0 && *c <= 2f32.powi(-24))
        );
    }

    #[test]
    fn rounding_carry_moves_to_the_next_exponent() {
        // 511.9 rounds to 512 mantissa units: the code must use the next exponent.
        let value = 511.9 * 2f32.powi(-9);
        let decoded = decode(encode([value, 0.0, 0.0]));
        assert!((decoded[0] - value).abs() <= RELATIVE_ERROR_BOUND * value);
    }

    proptest! {
        #[test]
        fn round_trip_stays_within_the_documented_bound(
            exponent in -15i32..16,
            fractions in prop::array::uniform3(0.0f32..1.0),
        ) {
            let scale = 2f32.powi(exponent);
            let input = fractions.map(|f| (f * scale).min(MAX_VALUE));
            let output = decode(encode(input));
            prop_assert!(within_bound(input, output), "{input:?} -> {output:?}");
            prop_assert!(output.iter().all(|c| c.is_finite() && *c >= 0.0));
        }

        #[test]
        fn any_code_decodes_to_finite_non_negative_values(code in any::<u32>()) {
            prop_assert!(decode(code).iter().all(|c| c.is_finite() && *c >= 0.0));
        }
    }
}
