//! How vertex radiosity becomes displayable colour, shared by every consumer (the software
//! renderer, the glTF export) so they agree.
//!
//! Smooth shading: frames carry one radiosity per geometry vertex, interpolated linearly over
//! each patch's fan triangles (`corners[0], corners[k], corners[k + 1]`). Vertices are shared
//! within one input face only, so colours never blend across a crease.
//!
//! Tone map: exposure `k = 0.18 / Lavg`, `Lavg` the area-weighted geometric mean of the
//! vertices' Rec. 709 luminance (each patch's area shared among its corners) (Reinhard et al. 2002, "Photographic Tone Reproduction", eq. 1-2)
//! over the patches of objects that do not emit (all patches when every object emits or none
//! is known to): the key is that of the lit scene, so a large emitter (a sky) does not darken
//! everything it lights; each
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

/// The exposure `0.18 / Lavg` of the module docs (1 for a black scene); `emitting[o]` says
/// whether object `o` emits (as `/api/objects` reports it; missing entries do not).
pub fn exposure(geometry: &Geometry, vertex_radiosity: &[Rgb], emitting: &[bool]) -> f32 {
    let brightest = vertex_radiosity.iter().map(luminance).fold(0.0, f32::max);
    if brightest <= 0.0 {
        return 1.0;
    }
    // Black vertices would send the log-average to zero; floor them far below the brightest.
    let floor = 1e-4 * brightest;
    let emits = |p: usize| {
        let object = geometry.patch_objects.get(p).copied().unwrap_or(u32::MAX);
        emitting.get(object as usize).copied().unwrap_or(false)
    };
    let lit_only = (0..geometry.patches.len()).any(|p| !emits(p));
    let (mut log_sum, mut area_sum) = (0.0f64, 0.0f64);
    for (p, patch) in geometry.patches.iter().enumerate() {
        if lit_only && emits(p) {
            continue;
        }
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

/// Decodes an 8-bit sRGB byte (a texel) to a linear value in [0, 1] (IEC 61966-2-1).
pub fn srgb_to_linear(byte: u8) -> f32 {
    let c = f32::from(byte) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Two unit squares: object 0 lit at luminance 1, object 1 an emitter at 1000.
    #[test]
    fn the_exposure_is_the_lit_surfaces_key() {
        let geometry = Geometry {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
                [2.0, 0.0, 0.0],
                [3.0, 0.0, 0.0],
                [3.0, 1.0, 0.0],
                [2.0, 1.0, 0.0],
            ],
            patches: vec![[0, 1, 2, 3], [4, 5, 6, 7]],
            patch_objects: vec![0, 1],
            objects: vec!["wall".into(), "sky".into()],
            camera: None,
            textures: None,
        };
        let mut radiosity = vec![[1.0f32; 3]; 4];
        radiosity.extend([[1000.0; 3]; 4]);
        let close = |a: f32, b: f64| (f64::from(a) - b).abs() < 1e-6 * b;
        assert!(close(exposure(&geometry, &radiosity, &[false, true]), 0.18));
        // Not known to emit, or everything emits: the log-average of 1 and 1000.
        let both = 0.18 / 1000f64.sqrt();
        assert!(close(exposure(&geometry, &radiosity, &[]), both));
        assert!(close(exposure(&geometry, &radiosity, &[true, true]), both));
    }
}
