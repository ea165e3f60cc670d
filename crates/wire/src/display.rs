//! How vertex radiosity becomes displayable colour, shared by every consumer (the software
//! renderer, the glTF export) so they agree.
//!
//! Smooth shading: frames carry one radiosity per geometry vertex, interpolated linearly over
//! each patch's fan triangles (`corners[0], corners[k], corners[k + 1]`). Vertices are shared
//! within one input face only, so colours never blend across a crease.
//!
//! Tone map: exposure `k = 0.18 / Lavg`, `Lavg` the area-weighted geometric mean of the
//! vertices' Rec. 709 luminance (each patch's area shared among its corners) (Reinhard et al. 2002, "Photographic Tone Reproduction", eq. 1-2); each
//! channel becomes `x / (1 + x)` with `x = k * radiosity`. [`srgb_byte`] then applies the sRGB
//! transfer function (IEC 61966-2-1) for 8-bit images.

use crate::Geometry;
use crate::geometry::NO_CORNER;

type Rgb = [f32; 3];

/// `a - b` in f64: exact for f32 inputs, and no overflow at the far end of f32's range.
fn sub(a: [f32; 3], b: [f32; 3]) -> [f64; 3] {
    [0, 1, 2].map(|k| a[k] as f64 - b[k] as f64)
}

fn cross_length(a: [f64; 3], b: [f64; 3]) -> f64 {
    let c = [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ];
    (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
}

/// The used corners of a patch: three or four.
pub fn corners(patch: &[u32; 4]) -> &[u32] {
    if patch[3] == NO_CORNER {
        &patch[..3]
    } else {
        &patch[..]
    }
}

/// Area of patch `i` of `geometry`, scene units squared, in f64 (f32 positions near 1e38
/// give areas past f32's range).
pub fn patch_area(geometry: &Geometry, patch: &[u32; 4]) -> f64 {
    let p = |i: usize| geometry.positions[patch[i] as usize];
    if patch[3] == NO_CORNER {
        0.5 * cross_length(sub(p(1), p(0)), sub(p(2), p(0)))
    } else {
        0.5 * cross_length(sub(p(2), p(0)), sub(p(3), p(1)))
    }
}

/// Rec. 709 luminance.
fn luminance(rgb: &Rgb) -> f32 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}

/// The exposure `0.18 / Lavg` of the module docs (1 for a black scene).
pub fn exposure(geometry: &Geometry, vertex_radiosity: &[Rgb]) -> f32 {
    let brightest = vertex_radiosity.iter().map(luminance).fold(0.0, f32::max);
    if brightest <= 0.0 {
        return 1.0;
    }
    // Black vertices would send the log-average to zero; floor them far below the brightest.
    let floor = 1e-4 * brightest;
    let (mut log_sum, mut area_sum) = (0.0f64, 0.0f64);
    for patch in &geometry.patches {
        let used = corners(patch);
        let share = patch_area(geometry, patch) / used.len() as f64;
        for &c in used {
            let rgb = vertex_radiosity.get(c as usize).unwrap_or(&[0.0; 3]);
            log_sum += share * (luminance(rgb).max(floor) as f64).ln();
            area_sum += share;
        }
    }
    (0.18 / (log_sum / area_sum.max(f64::MIN_POSITIVE)).exp()) as f32
}

/// Tone-maps linear radiosity to linear display values in [0, 1).
pub fn tone_map(rgb: Rgb, exposure: f32) -> Rgb {
    rgb.map(|c| {
        let x = (c * exposure).max(0.0);
        x / (1.0 + x)
    })
}

/// Encodes a linear display value in [0, 1] as an 8-bit sRGB byte.
pub fn srgb_byte(linear: f32) -> u8 {
    let c = linear.clamp(0.0, 1.0);
    let encoded = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (encoded * 255.0 + 0.5) as u8
}
