//! Colour spaces: sRGB <-> linear RGB <-> CIE XYZ <-> CIE Lab (D65 white), and CIE76 ΔE.
//!
//! Formulas follow IEC 61966-2-1 (sRGB) and CIE 15 (Lab). Linear RGB uses the sRGB primaries,
//! so `linear_to_xyz` is the standard sRGB matrix. XYZ is scaled so that white has Y = 1.

/// D65 reference white in XYZ (Y = 1), as used by sRGB.
pub const D65_WHITE: [f32; 3] = [0.950_47, 1.0, 1.088_83];

/// sRGB transfer function decoded: an sRGB-encoded value in [0, 1] to linear light.
///
/// Values outside [0, 1] are extended symmetrically (odd function), never NaN for finite input.
pub fn srgb_to_linear(encoded: f32) -> f32 {
    let a = encoded.abs();
    let lin = if a <= 0.040_45 {
        a / 12.92
    } else {
        ((a + 0.055) / 1.055).powf(2.4)
    };
    lin.copysign(encoded)
}

/// sRGB transfer function encoded: linear light to an sRGB-encoded value (inverse of
/// [`srgb_to_linear`]).
pub fn linear_to_srgb(linear: f32) -> f32 {
    let a = linear.abs();
    let enc = if a <= 0.003_130_8 {
        a * 12.92
    } else {
        1.055 * a.powf(1.0 / 2.4) - 0.055
    };
    enc.copysign(linear)
}

/// Lookup table from an 8-bit sRGB code to linear light: `table[code]`.
pub fn srgb8_to_linear_table() -> [f32; 256] {
    std::array::from_fn(|code| srgb_to_linear(code as f32 / 255.0))
}

/// Quantises linear light to the nearest 8-bit sRGB code, exactly as rounding
/// `linear_to_srgb(v) * 255` would, but with a binary search over precomputed thresholds.
#[derive(Debug, Clone)]
pub struct Srgb8Encoder {
    /// `thresholds[k]` is the linear value where the rounded code changes from k to k + 1.
    thresholds: [f32; 255],
}

impl Default for Srgb8Encoder {
    fn default() -> Self {
        Self::new()
    }
}

impl Srgb8Encoder {
    /// Builds the 255 decision thresholds (once; reuse the encoder for many pixels).
    pub fn new() -> Self {
        Self {
            thresholds: std::array::from_fn(|k| srgb_to_linear((k as f32 + 0.5) / 255.0)),
        }
    }

    /// The 8-bit sRGB code of a linear value; clamps to [0, 255], NaN gives 0.
    pub fn encode(&self, linear: f32) -> u8 {
        // partition_point counts thresholds strictly below the value: that count is the code.
        // NaN compares false everywhere, so it lands on 0.
        self.thresholds.partition_point(|&t| t < linear) as u8
    }
}

/// Linear RGB (sRGB primaries) to CIE XYZ (D65, Y of white = 1).
pub fn linear_to_xyz([r, g, b]: [f32; 3]) -> [f32; 3] {
    [
        0.412_456_4 * r + 0.357_576_1 * g + 0.180_437_5 * b,
        0.212_672_9 * r + 0.715_152_2 * g + 0.072_175 * b,
        0.019_333_9 * r + 0.119_192 * g + 0.950_304_1 * b,
    ]
}

/// CIE XYZ (D65) to linear RGB with sRGB primaries (inverse of [`linear_to_xyz`]).
pub fn xyz_to_linear([x, y, z]: [f32; 3]) -> [f32; 3] {
    [
        3.240_454_2 * x - 1.537_138_5 * y - 0.498_531_4 * z,
        -0.969_266 * x + 1.876_010_8 * y + 0.041_556 * z,
        0.055_643_4 * x - 0.204_025_9 * y + 1.057_225_2 * z,
    ]
}

const LAB_EPSILON: f32 = 216.0 / 24389.0; // (6/29)^3
const LAB_KAPPA: f32 = 24389.0 / 27.0; // (29/3)^3

fn lab_f(t: f32) -> f32 {
    if t > LAB_EPSILON {
        t.cbrt()
    } else {
        (LAB_KAPPA * t + 16.0) / 116.0
    }
}

fn lab_f_inv(f: f32) -> f32 {
    let cube = f * f * f;
    if cube > LAB_EPSILON {
        cube
    } else {
        (116.0 * f - 16.0) / LAB_KAPPA
    }
}

/// CIE L* of a relative luminance `y` (white 1): [0, 100] for [0, 1].
pub fn lightness(y: f32) -> f32 {
    116.0 * lab_f(y / D65_WHITE[1]) - 16.0
}

/// The relative luminance of CIE lightness `l`, the inverse of [`lightness`].
pub fn luminance_of_lightness(l: f32) -> f32 {
    D65_WHITE[1] * lab_f_inv((l + 16.0) / 116.0)
}

/// CIE XYZ (D65) to CIE L*a*b*: L in [0, 100] for [0, white].
pub fn xyz_to_lab([x, y, z]: [f32; 3]) -> [f32; 3] {
    let fx = lab_f(x / D65_WHITE[0]);
    let fy = lab_f(y / D65_WHITE[1]);
    let fz = lab_f(z / D65_WHITE[2]);
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// CIE L*a*b* to CIE XYZ (D65), the inverse of [`xyz_to_lab`].
pub fn lab_to_xyz([l, a, b]: [f32; 3]) -> [f32; 3] {
    let fy = (l + 16.0) / 116.0;
    let fx = fy + a / 500.0;
    let fz = fy - b / 200.0;
    [
        D65_WHITE[0] * lab_f_inv(fx),
        D65_WHITE[1] * lab_f_inv(fy),
        D65_WHITE[2] * lab_f_inv(fz),
    ]
}

/// A linear RGB pixel brought into the display's range [0, 1] keeping its chromaticity:
/// negative channels are raised to 0, and a pixel with a channel above 1 is scaled down as a
/// whole until its largest channel is 1. Clipping each channel on its own instead turns an
/// over-range highlight's hue (a bright yellow pixel loses its yellow): on the built-in sponge
/// the relit highlights clipped that way were false-colour specks, a* kurtosis 40 against the
/// measured 3.1.
pub fn fit_to_gamut(rgb: [f32; 3]) -> [f32; 3] {
    let rgb = rgb.map(|v| v.max(0.0));
    let peak = rgb[0].max(rgb[1]).max(rgb[2]);
    if peak > 1.0 {
        rgb.map(|v| v / peak)
    } else {
        rgb
    }
}

/// Linear RGB to CIE Lab (D65), the colour space of the paper's error figures.
pub fn linear_to_lab(rgb: [f32; 3]) -> [f32; 3] {
    xyz_to_lab(linear_to_xyz(rgb))
}

/// CIE Lab to linear RGB (D65); may leave [0, 1] for colours outside the sRGB gamut.
pub fn lab_to_linear(lab: [f32; 3]) -> [f32; 3] {
    xyz_to_linear(lab_to_xyz(lab))
}

/// [`lab_to_linear`] of the nearest colour with no negative channel at the same L* and hue:
/// a* and b* scaled towards 0 (bisection on the scale) until every channel is at least 0, then
/// what is still negative (L* <= 0) set to 0. A synthesized dark pixel keeps the chroma excursion of
/// a brighter one, which lies outside the gamut and would otherwise come out as a pure
/// primary after clamping.
pub fn lab_to_linear_in_gamut(lab: [f32; 3]) -> [f32; 3] {
    let rgb = lab_to_linear(lab);
    if rgb.iter().all(|&c| c >= 0.0) {
        return rgb;
    }
    let (mut inside, mut outside) = (0.0f32, 1.0f32);
    for _ in 0..12 {
        let t = 0.5 * (inside + outside);
        if lab_to_linear([lab[0], t * lab[1], t * lab[2]])
            .iter()
            .all(|&c| c >= 0.0)
        {
            inside = t;
        } else {
            outside = t;
        }
    }
    lab_to_linear([lab[0], inside * lab[1], inside * lab[2]]).map(|c| c.max(0.0))
}

/// A chroma coordinate (a* or b*) per unit of lightness, `c / (L* + 16)`: a function of the
/// chromaticity alone (for colours above the dark linear segment of L*), so scaling a pixel's
/// linear RGB, as shading does, leaves it as it is. [`chroma_of`] inverts it.
pub fn chroma_per_lightness(c: f64, l: f64) -> f64 {
    c / lightness_offset(l)
}

/// The chroma coordinate of `per_lightness` (see [`chroma_per_lightness`]) at lightness `l`.
pub fn chroma_of(per_lightness: f64, l: f64) -> f64 {
    per_lightness * lightness_offset(l)
}

/// `L* + 16`, at least 1 (L* is not negative for a colour of non-negative luminance).
fn lightness_offset(l: f64) -> f64 {
    (l + 16.0).max(1.0)
}

/// CIE76 colour difference: the Euclidean distance in Lab.
pub fn delta_e76(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    #[test]
    fn fitting_to_the_gamut_keeps_in_range_pixels_and_the_chromaticity_of_highlights() {
        assert_eq!(super::fit_to_gamut([0.2, 0.5, 1.0]), [0.2, 0.5, 1.0]);
        assert_eq!(super::fit_to_gamut([-0.1, 0.5, 0.3]), [0.0, 0.5, 0.3]);
        let bright = [1.6, 1.2, 0.4];
        let fitted = super::fit_to_gamut(bright);
        assert_eq!(fitted[0], 1.0);
        // Chromaticity kept: the same hue in Lab, where clipping each channel turns it.
        let hue = |rgb: [f32; 3]| {
            let lab = super::linear_to_lab(rgb);
            lab[2].atan2(lab[1])
        };
        let scaled = bright.map(|v| v / 2.0);
        assert!((hue(fitted) - hue(scaled)).abs() < 1e-3);
        assert!((hue(bright.map(|v| v.min(1.0))) - hue(scaled)).abs() > 0.05);
    }

    use super::*;

    #[test]
    fn shading_leaves_the_chroma_per_unit_of_lightness() {
        // A colour and the same colour at a tenth of its light, above L*'s dark segment.
        for rgb in [[0.6f32, 0.3, 0.1], [0.2, 0.5, 0.7]] {
            let per = |rgb: [f32; 3]| {
                let [l, a, b] = linear_to_lab(rgb);
                [a, b].map(|c| chroma_per_lightness(f64::from(c), f64::from(l)))
            };
            let (lit, shaded) = (per(rgb), per(rgb.map(|v| 0.1 * v)));
            for (x, y) in lit.iter().zip(&shaded) {
                assert!((x - y).abs() < 1e-4, "{lit:?} {shaded:?}");
            }
            let [l, a, _] = linear_to_lab(rgb);
            let back = chroma_of(
                chroma_per_lightness(f64::from(a), f64::from(l)),
                f64::from(l),
            );
            assert!((back - f64::from(a)).abs() < 1e-9);
        }
    }
    use approx::assert_abs_diff_eq;

    fn srgb8(r: u8, g: u8, b: u8) -> [f32; 3] {
        [r, g, b].map(|c| srgb_to_linear(c as f32 / 255.0))
    }

    #[test]
    fn out_of_gamut_colours_lose_chroma_not_lightness() {
        // In gamut: unchanged.
        let lab = linear_to_lab([0.2, 0.1, 0.05]);
        assert_eq!(lab_to_linear_in_gamut(lab), lab_to_linear(lab));
        // A dark pixel with a strong blue excursion: a negative channel as it stands.
        let dark = [8.0, 20.0, -40.0];
        assert!(lab_to_linear(dark).iter().any(|&c| c < 0.0));
        let fixed = lab_to_linear_in_gamut(dark);
        assert!(fixed.iter().all(|&c| c >= 0.0), "{fixed:?}");
        let back = linear_to_lab(fixed);
        assert_abs_diff_eq!(back[0], 8.0, epsilon = 0.05);
        // Same hue, less chroma, at the gamut's edge (one channel near 0).
        assert!(back[1] > 0.0 && back[2] < 0.0 && back[1].hypot(back[2]) < 44.7);
        assert!((back[2] / back[1] + 2.0).abs() < 0.05, "{back:?}");
        assert!(fixed.iter().any(|&c| c < 2e-4), "{fixed:?}");
        // Below black: black.
        assert_eq!(lab_to_linear_in_gamut([-3.0, 5.0, 5.0]), [0.0; 3]);
    }

    #[test]
    fn transfer_function_round_trips_and_hits_known_points() {
        assert_abs_diff_eq!(srgb_to_linear(0.5), 0.214_041, epsilon = 1e-5);
        assert_abs_diff_eq!(linear_to_srgb(0.18), 0.461_356, epsilon = 1e-5);
        for k in 0..=1000 {
            let v = k as f32 / 1000.0;
            assert_abs_diff_eq!(linear_to_srgb(srgb_to_linear(v)), v, epsilon = 1e-5);
        }
    }

    #[test]
    fn encoder_matches_rounding_of_the_formula() {
        let enc = Srgb8Encoder::new();
        for k in 0..=4000 {
            let lin = k as f32 / 4000.0;
            let expected = (linear_to_srgb(lin) * 255.0).round() as u8;
            let got = enc.encode(lin);
            // At an exact tie the two may differ by one code; nowhere else.
            assert!(
                (got as i32 - expected as i32).abs() <= 1,
                "{lin}: {got} vs {expected}"
            );
        }
        let table = srgb8_to_linear_table();
        for code in 0..=255u8 {
            assert_eq!(enc.encode(table[code as usize]), code);
        }
        assert_eq!(enc.encode(-1.0), 0);
        assert_eq!(enc.encode(7.0), 255);
        assert_eq!(enc.encode(f32::NAN), 0);
    }

    #[test]
    fn known_lab_values() {
        // White, black, and the sRGB primaries (reference values from the sRGB/CIE formulas,
        // as tabulated e.g. by Bruce Lindbloom's calculator).
        let cases: [([u8; 3], [f32; 3]); 5] = [
            ([255, 255, 255], [100.0, 0.0, 0.0]),
            ([0, 0, 0], [0.0, 0.0, 0.0]),
            ([255, 0, 0], [53.2408, 80.0925, 67.2032]),
            ([0, 255, 0], [87.7347, -86.1827, 83.1793]),
            ([0, 0, 255], [32.2970, 79.1875, -107.8602]),
        ];
        for (rgb, lab) in cases {
            let got = linear_to_lab(srgb8(rgb[0], rgb[1], rgb[2]));
            for c in 0..3 {
                assert_abs_diff_eq!(got[c], lab[c], epsilon = 0.02);
            }
        }
        let xyz_red = linear_to_xyz([1.0, 0.0, 0.0]);
        assert_abs_diff_eq!(xyz_red[1], 0.2127, epsilon = 1e-4);
    }

    #[test]
    fn lab_and_xyz_round_trip() {
        for &rgb in &[
            [0.2, 0.5, 0.9],
            [0.001, 0.002, 0.0005],
            [1.0, 1.0, 1.0],
            [0.7, 0.1, 0.3],
        ] {
            let back = lab_to_linear(linear_to_lab(rgb));
            for c in 0..3 {
                assert_abs_diff_eq!(back[c], rgb[c], epsilon = 1e-4);
            }
        }
    }

    #[test]
    fn delta_e_is_a_distance() {
        let a = [50.0, 10.0, -10.0];
        let b = [53.0, 14.0, -10.0];
        assert_abs_diff_eq!(delta_e76(a, b), 5.0, epsilon = 1e-6);
        assert_eq!(delta_e76(a, a), 0.0);
        assert_eq!(delta_e76(a, b), delta_e76(b, a));
    }
}
