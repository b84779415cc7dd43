//! Colour science of MODEL §5: CIE 1931 2° colour-matching functions, the D65 illuminant,
//! spectral → XYZ weights (trapezoid rule, normalised so a perfect mirror has `Y = 1`),
//! XYZ → linear sRGB and the sRGB transfer curve. Tables are embedded from `assets/`.
//! No rendering here: this module only turns spectra into colours.

use crate::{Error, Result};

/// Shortest wavelength of the integrated spectrum (nm).
pub const LAMBDA_MIN_NM: u32 = 380;
/// Longest wavelength of the integrated spectrum (nm).
pub const LAMBDA_MAX_NM: u32 = 780;

const CMF_CSV: &str = include_str!("../assets/cie1931_2deg_cmf_1nm.csv");
const D65_CSV: &str = include_str!("../assets/cie_d65_spd_1nm.csv");

/// IEC 61966-2-1 XYZ → linear sRGB matrix (rows).
pub const XYZ_TO_SRGB: [[f64; 3]; 3] = [
    [3.2406, -1.5372, -0.4986],
    [-0.9689, 1.8758, 0.0415],
    [0.0557, -0.2040, 1.0570],
];

/// Parses `lambda,v1,v2,..` rows (comments start with `#`) into a 1 nm table over
/// [`LAMBDA_MIN_NM`, `LAMBDA_MAX_NM`].
fn parse_table<const C: usize>(csv: &str, name: &str) -> Vec<[f64; C]> {
    let mut out = vec![[f64::NAN; C]; (LAMBDA_MAX_NM - LAMBDA_MIN_NM + 1) as usize];
    for line in csv.lines() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut it = line.split(',').map(|s| s.trim().parse::<f64>());
        let lambda = match it.next() {
            Some(Ok(l)) => l.round() as i64,
            _ => continue,
        };
        if lambda < LAMBDA_MIN_NM as i64 || lambda > LAMBDA_MAX_NM as i64 {
            continue;
        }
        let mut row = [0.0; C];
        for v in row.iter_mut() {
            *v = it.next().and_then(|r| r.ok()).unwrap_or(f64::NAN);
        }
        out[(lambda - LAMBDA_MIN_NM as i64) as usize] = row;
    }
    // The embedded tables are part of the build; a gap is a packaging bug, caught by tests.
    debug_assert!(
        out.iter().flatten().all(|v| v.is_finite()),
        "embedded table {name} has gaps"
    );
    out
}

/// CIE 1931 2° `(x̄, ȳ, z̄)` at 1 nm steps from 380 to 780 nm.
pub fn cmf_1nm() -> Vec<[f64; 3]> {
    parse_table::<3>(CMF_CSV, "cmf")
}

/// CIE D65 relative spectral power at 1 nm steps from 380 to 780 nm.
pub fn d65_1nm() -> Vec<f64> {
    parse_table::<1>(D65_CSV, "d65")
        .into_iter()
        .map(|r| r[0])
        .collect()
}

/// Spectral sampling and the per-sample XYZ weights of MODEL §5.
///
/// `XYZ = Σ_j ρ(λ_j) · weights[j]`, where `weights[j] = S_D65 · (x̄,ȳ,z̄) · Δλ_j / Σ S_D65 ȳ Δλ`
/// with trapezoid `Δλ_j` (half at both ends). A spectrum of ones gives `Y = 1` exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct ColourTable {
    /// Step between samples in nm; divides 400.
    pub step_nm: u32,
    /// Sample wavelengths in nm, from 380 to 780 inclusive.
    pub lambdas_nm: Vec<f64>,
    /// XYZ weight of each sample.
    pub weights: Vec<[f64; 3]>,
}

impl ColourTable {
    /// Builds the table for a step of `step_nm` nanometres (must divide 400: 1, 2, 4, 5, 8, 10, ...).
    pub fn new(step_nm: u32) -> Result<Self> {
        let span = LAMBDA_MAX_NM - LAMBDA_MIN_NM;
        if step_nm == 0 || !span.is_multiple_of(step_nm) {
            return Err(Error::invalid(
                "wavelength step",
                format!("{step_nm} nm; it must be a positive divisor of 400 nm (1, 2, 4, 5, 8, 10, 16, 20, 25, 40, 50, ...)"),
            ));
        }
        let cmf = cmf_1nm();
        let d65 = d65_1nm();
        let count = (span / step_nm + 1) as usize;
        let mut lambdas_nm = Vec::with_capacity(count);
        let mut weights = Vec::with_capacity(count);
        let mut norm = 0.0;
        for j in 0..count {
            let i = j * step_nm as usize;
            let trap = if j == 0 || j == count - 1 { 0.5 } else { 1.0 } * step_nm as f64;
            let s = d65[i] * trap;
            lambdas_nm.push((LAMBDA_MIN_NM as usize + i) as f64);
            weights.push([s * cmf[i][0], s * cmf[i][1], s * cmf[i][2]]);
            norm += s * cmf[i][1];
        }
        for w in &mut weights {
            for c in w.iter_mut() {
                *c /= norm;
            }
        }
        Ok(Self {
            step_nm,
            lambdas_nm,
            weights,
        })
    }

    /// Number of spectral samples.
    pub fn len(&self) -> usize {
        self.lambdas_nm.len()
    }

    /// Always false: a table has at least the two end samples.
    pub fn is_empty(&self) -> bool {
        self.lambdas_nm.is_empty()
    }

    /// Integrates a spectrum given as a function of wavelength in nm.
    pub fn integrate(&self, mut rho: impl FnMut(f64) -> f64) -> [f64; 3] {
        let mut xyz = [0.0; 3];
        for (l, w) in self.lambdas_nm.iter().zip(&self.weights) {
            let r = rho(*l);
            for c in 0..3 {
                xyz[c] += r * w[c];
            }
        }
        xyz
    }
}

/// XYZ density (per nm) of a monochromatic line of relative reflectance 1 at `lambda_nm`
/// under D65, on the same normalisation as [`ColourTable`] (a flat unit spectrum integrates
/// to `Y = 1`). Linear interpolation between the 1 nm samples; zero outside 380–780 nm.
pub fn monochromatic_xyz(lambda_nm: f64) -> [f64; 3] {
    if !(lambda_nm >= LAMBDA_MIN_NM as f64 && lambda_nm <= LAMBDA_MAX_NM as f64) {
        return [0.0; 3];
    }
    let cmf = cmf_1nm();
    let d65 = d65_1nm();
    let last = cmf.len() - 1;
    let norm: f64 = (0..=last)
        .map(|i| d65[i] * cmf[i][1] * if i == 0 || i == last { 0.5 } else { 1.0 })
        .sum();
    let x = lambda_nm - LAMBDA_MIN_NM as f64;
    let i = (x.floor() as usize).min(last - 1);
    let f = x - i as f64;
    [0, 1, 2].map(|c| {
        let a = d65[i] * cmf[i][c];
        let b = d65[i + 1] * cmf[i + 1][c];
        (a + f * (b - a)) / norm
    })
}

/// XYZ → linear sRGB (D65 white), no clamping.
pub fn xyz_to_linear_srgb(xyz: [f64; 3]) -> [f64; 3] {
    let m = &XYZ_TO_SRGB;
    [0, 1, 2].map(|r| m[r][0] * xyz[0] + m[r][1] * xyz[1] + m[r][2] * xyz[2])
}

/// Linear sRGB → XYZ (D65 white), no clamping: the exact inverse of [`XYZ_TO_SRGB`], so
/// linear white `(1, 1, 1)` lands on `Y = 1`.
pub fn linear_srgb_to_xyz(rgb: [f64; 3]) -> [f64; 3] {
    static INVERSE: std::sync::OnceLock<glam::DMat3> = std::sync::OnceLock::new();
    let m = INVERSE.get_or_init(|| {
        glam::DMat3::from_cols_array_2d(&XYZ_TO_SRGB)
            .transpose()
            .inverse()
    });
    (*m * glam::DVec3::from(rgb)).to_array()
}

/// The linear values of the 256 8-bit sRGB codes (IEC 61966-2-1's inverse curve).
pub fn srgb8_decode_table() -> [f32; 256] {
    std::array::from_fn(|c| {
        let x = c as f64 / 255.0;
        let l = if x <= 0.04045 {
            x / 12.92
        } else {
            ((x + 0.055) / 1.055).powf(2.4)
        };
        l as f32
    })
}

/// The sRGB transfer curve (IEC 61966-2-1) of a linear value, clamped to [0, 1] first.
/// NaN maps to 0 so it can never reach an output.
pub fn srgb_encode(linear: f64) -> f64 {
    let x = if linear.is_nan() {
        0.0
    } else {
        linear.clamp(0.0, 1.0)
    };
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear sRGB → 8-bit sRGB after multiplying by `exposure`.
pub fn linear_to_srgb8(rgb: [f64; 3], exposure: f64) -> [u8; 3] {
    let codes = Srgb8::get();
    rgb.map(|c| codes.code(c * exposure))
}

/// The 8-bit sRGB code of a linear value by the formula: `⌊255·encode(x) + ½⌋`.
fn srgb8_by_formula(x: f64) -> u8 {
    (srgb_encode(x) * 255.0 + 0.5).floor() as u8
}

/// [`srgb8_by_formula`] without a power per value: the code of the cell of a fine grid the
/// value falls in, then up past the code edges below it. Exact: the edges are found once by
/// bisection on the formula itself, and the formula never decreases.
struct Srgb8 {
    /// `edges[b]`: the least linear value whose code is `b + 1` or more.
    edges: [f64; 255],
    /// `start[i]`: the code of `i / CELLS`, a lower bound for the cell's values.
    start: [u8; Srgb8::CELLS + 1],
}

impl Srgb8 {
    const CELLS: usize = 4096;

    fn get() -> &'static Srgb8 {
        static CODES: std::sync::OnceLock<Srgb8> = std::sync::OnceLock::new();
        CODES.get_or_init(|| Srgb8 {
            edges: std::array::from_fn(|k| {
                let code = k as u8 + 1;
                // Non-negative doubles order as their bits: bisect on the bits of [0, 1].
                let (mut lo, mut hi) = (0u64, 1f64.to_bits());
                while lo < hi {
                    let mid = lo + (hi - lo) / 2;
                    if srgb8_by_formula(f64::from_bits(mid)) >= code {
                        hi = mid;
                    } else {
                        lo = mid + 1;
                    }
                }
                f64::from_bits(lo)
            }),
            start: std::array::from_fn(|i| srgb8_by_formula(i as f64 / Self::CELLS as f64)),
        })
    }

    fn code(&self, x: f64) -> u8 {
        if x.is_nan() || x <= 0.0 {
            return 0;
        }
        if x >= 1.0 {
            return 255;
        }
        let mut c = self.start[(x * Self::CELLS as f64) as usize];
        while c < 255 && x >= self.edges[usize::from(c)] {
            c += 1;
        }
        c
    }
}

/// CIELAB of an XYZ colour relative to the D65 white (`Y_n = 1`).
pub fn xyz_to_lab(xyz: [f64; 3]) -> [f64; 3] {
    const WHITE: [f64; 3] = [0.950_47, 1.0, 1.088_83];
    let f = |t: f64| {
        let d: f64 = 6.0 / 29.0;
        if t > d * d * d {
            t.cbrt()
        } else {
            t / (3.0 * d * d) + 4.0 / 29.0
        }
    };
    let fx = f(xyz[0] / WHITE[0]);
    let fy = f(xyz[1] / WHITE[1]);
    let fz = f(xyz[2] / WHITE[2]);
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// CIEDE2000 colour difference between two CIELAB colours (Sharma, Wu, Dalal 2005).
pub fn delta_e2000(lab1: [f64; 3], lab2: [f64; 3]) -> f64 {
    use std::f64::consts::PI;
    let [l1, a1, b1] = lab1;
    let [l2, a2, b2] = lab2;
    let c1 = a1.hypot(b1);
    let c2 = a2.hypot(b2);
    let cbar = 0.5 * (c1 + c2);
    let c7 = cbar.powi(7);
    let g = 0.5 * (1.0 - (c7 / (c7 + 25f64.powi(7))).sqrt());
    let a1p = (1.0 + g) * a1;
    let a2p = (1.0 + g) * a2;
    let c1p = a1p.hypot(b1);
    let c2p = a2p.hypot(b2);
    let hue = |b: f64, a: f64| {
        if a == 0.0 && b == 0.0 {
            0.0
        } else {
            let h = b.atan2(a);
            if h < 0.0 {
                h + 2.0 * PI
            } else {
                h
            }
        }
    };
    let h1p = hue(b1, a1p);
    let h2p = hue(b2, a2p);
    let dlp = l2 - l1;
    let dcp = c2p - c1p;
    let dhp = if c1p * c2p == 0.0 {
        0.0
    } else {
        let d = h2p - h1p;
        if d > PI {
            d - 2.0 * PI
        } else if d < -PI {
            d + 2.0 * PI
        } else {
            d
        }
    };
    let dhp_big = 2.0 * (c1p * c2p).sqrt() * (0.5 * dhp).sin();
    let lbarp = 0.5 * (l1 + l2);
    let cbarp = 0.5 * (c1p + c2p);
    let hbarp = if c1p * c2p == 0.0 {
        h1p + h2p
    } else if (h1p - h2p).abs() <= PI {
        0.5 * (h1p + h2p)
    } else if h1p + h2p < 2.0 * PI {
        0.5 * (h1p + h2p + 2.0 * PI)
    } else {
        0.5 * (h1p + h2p - 2.0 * PI)
    };
    let t = 1.0 - 0.17 * (hbarp - PI / 6.0).cos()
        + 0.24 * (2.0 * hbarp).cos()
        + 0.32 * (3.0 * hbarp + PI / 30.0).cos()
        - 0.20 * (4.0 * hbarp - 63.0 * PI / 180.0).cos();
    let dtheta = (30.0 * PI / 180.0) * (-((hbarp * 180.0 / PI - 275.0) / 25.0).powi(2)).exp();
    let cbarp7 = cbarp.powi(7);
    let rc = 2.0 * (cbarp7 / (cbarp7 + 25f64.powi(7))).sqrt();
    let sl = 1.0 + 0.015 * (lbarp - 50.0).powi(2) / (20.0 + (lbarp - 50.0).powi(2)).sqrt();
    let sc = 1.0 + 0.045 * cbarp;
    let sh = 1.0 + 0.015 * cbarp * t;
    let rt = -(2.0 * dtheta).sin() * rc;
    ((dlp / sl).powi(2)
        + (dcp / sc).powi(2)
        + (dhp_big / sh).powi(2)
        + rt * (dcp / sc) * (dhp_big / sh))
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_searched_srgb_codes_are_the_formula_s() {
        for &e in &Srgb8::get().edges {
            let below = f64::from_bits(e.to_bits() - 1);
            for x in [e, below, f64::from_bits(e.to_bits() + 1)] {
                assert_eq!(
                    linear_to_srgb8([x; 3], 1.0)[0],
                    srgb8_by_formula(x),
                    "{x:e}"
                );
            }
        }
        let mut z = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..200_000 {
            z ^= z << 13;
            z ^= z >> 7;
            z ^= z << 17;
            let x = (z >> 11) as f64 / (1u64 << 53) as f64 * 1.2 - 0.1;
            assert_eq!(
                linear_to_srgb8([x; 3], 1.0)[0],
                srgb8_by_formula(x),
                "{x:e}"
            );
        }
        for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -0.0, 1e-300] {
            assert_eq!(
                linear_to_srgb8([x; 3], 1.0)[0],
                srgb8_by_formula(x),
                "{x:e}"
            );
        }
    }

    #[test]
    fn tables_cover_the_visible_range_without_gaps() {
        let cmf = cmf_1nm();
        let d65 = d65_1nm();
        assert_eq!(cmf.len(), 401);
        assert_eq!(d65.len(), 401);
        assert!(cmf.iter().flatten().chain(&d65).all(|v| v.is_finite()));
        // Peak of ȳ at 555 nm is 1 (CIE).
        assert!((cmf[175][1] - 1.0).abs() < 1e-3);
        // D65 is 100 at 560 nm by definition.
        assert!((d65[180] - 100.0).abs() < 1e-6);
    }

    #[test]
    fn unit_spectrum_is_d65_white_with_y_one() {
        for step in [1, 5, 10] {
            let t = ColourTable::new(step).unwrap();
            let xyz = t.integrate(|_| 1.0);
            assert!((xyz[1] - 1.0).abs() < 1e-12, "step {step}: Y = {}", xyz[1]);
            // D65 white point (x, y) = (0.3127, 0.3290).
            let s = xyz[0] + xyz[1] + xyz[2];
            assert!((xyz[0] / s - 0.3127).abs() < 2e-3, "x = {}", xyz[0] / s);
            assert!((xyz[1] / s - 0.3290).abs() < 2e-3, "y = {}", xyz[1] / s);
            let rgb = xyz_to_linear_srgb(xyz);
            for c in rgb {
                assert!((c - 1.0).abs() < 0.02, "white maps to {rgb:?}");
            }
        }
    }

    #[test]
    fn bad_step_is_rejected() {
        assert!(ColourTable::new(0).is_err());
        assert!(ColourTable::new(3).is_err());
        assert!(ColourTable::new(5).is_ok());
    }

    #[test]
    fn transfer_curve_is_continuous_and_clamped() {
        assert_eq!(srgb_encode(f64::NAN), 0.0);
        assert_eq!(srgb_encode(-1.0), 0.0);
        assert!((srgb_encode(2.0) - 1.0).abs() < 1e-12);
        let a = srgb_encode(0.003_130_8);
        let b = srgb_encode(0.003_130_8 + 1e-9);
        assert!((a - b).abs() < 1e-6);
    }

    #[test]
    fn ciede2000_matches_sharma_reference_pairs() {
        // Pairs 1, 7 and 17 of the Sharma et al. (2005) test data.
        let cases = [
            ([50.0, 2.6772, -79.7751], [50.0, 0.0, -82.7485], 2.0425),
            ([50.0, 0.0, 0.0], [50.0, -1.0, 2.0], 2.3669),
            ([50.0, 2.5, 0.0], [73.0, 25.0, -18.0], 27.1492),
        ];
        for (a, b, de) in cases {
            let got = delta_e2000(a, b);
            assert!((got - de).abs() < 1e-3, "{a:?} {b:?}: {got} vs {de}");
        }
    }
}
