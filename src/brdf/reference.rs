//! The CPU reference (MODEL §6.1): the coherence-windowed transform of the periodically
//! tiled height field as a direct sum in f64 — no Taylor series, no DFT, no frequency-domain
//! window truncation. Slow by design (`N²` complex exponentials per wavelength); used on
//! sparse directions to measure every other evaluator.

use rayon::prelude::*;

use crate::colour::ColourTable;
use crate::heightfield::HeightField;
use crate::spectrum::num_complex::Complex64;

use super::{integrated, spectral, Shading};

/// Half-width of the spatial window sum in units of `σs`.
///
/// MODEL §3 sums to `4σs`. The DFT route implies the untruncated Gaussian, and cutting it at
/// `4σs` drops a weight fraction of `erfc(2√2) ≈ 6e-5` per axis: a floor of ~5e-5 relative
/// error that hid the model's convergence in `R`. At `6σs` the dropped weight is ~2e-9.
pub const WINDOW_HALF_WIDTH_SIGMAS: f64 = 6.0;

/// Per-axis window weights folded onto the period: `G(c) = Σ_{i ≡ c (mod N), |i| ≤ K}
/// g(i·dH)·e^{+iα·i·dH}` with `g(x) = exp(−x²/(2σs²))` and
/// `K = ⌊WINDOW_HALF_WIDTH_SIGMAS·σs/dH⌋`, plus the plain weight sum `Σ g`.
fn folded_axis(n: usize, dh_um: f64, sigma_um: f64, alpha: f64) -> (Vec<Complex64>, f64) {
    let k_max = (WINDOW_HALF_WIDTH_SIGMAS * sigma_um / dh_um).floor() as i64;
    let mut g = vec![Complex64::new(0.0, 0.0); n];
    let mut total = 0.0;
    for i in -k_max..=k_max {
        let x = i as f64 * dh_um;
        let wgt = (-x * x / (2.0 * sigma_um * sigma_um)).exp();
        total += wgt;
        g[i.rem_euclid(n as i64) as usize] += Complex64::from_polar(wgt, alpha * x);
    }
    (g, total)
}

/// Reference `P̂_ref(ku, kv)` of MODEL §3 at wavelength `lambda_um`, window centred on
/// sample (0, 0). `heights` must be the mean-centred samples of `hf` (row-major).
fn p_hat_ref(
    hf: &HeightField,
    heights: &[f64],
    sigma_um: f64,
    d: [f64; 3],
    lambda_um: f64,
) -> Complex64 {
    let k = 2.0 * std::f64::consts::PI / lambda_um;
    let (gx, sx) = folded_axis(hf.nx(), hf.dh_um(), sigma_um, k * d[0]);
    let (gy, sy) = folded_axis(hf.ny(), hf.dh_um(), sigma_um, k * d[1]);
    let kw = k * d[2];
    let mut acc = Complex64::new(0.0, 0.0);
    for (r, row) in heights.chunks_exact(hf.nx()).enumerate() {
        if gy[r].norm_sqr() == 0.0 {
            continue;
        }
        let mut row_acc = Complex64::new(0.0, 0.0);
        for (c, h) in row.iter().enumerate() {
            let (s, co) = (kw * h).sin_cos();
            row_acc += gx[c] * Complex64::new(co, s);
        }
        acc += gy[r] * row_acc;
    }
    acc / (sx * sy)
}

/// Mean-centred heights (MODEL §2: a unit phase that leaves `|P̂|²` unchanged, but halves
/// the phase range the exponentials see).
fn centred(hf: &HeightField) -> Vec<f64> {
    let m = hf.mean();
    hf.heights_um().iter().map(|h| h - m).collect()
}

/// Spectral relative reflectance `ρ_λ` by direct summation.
pub fn rho(
    hf: &HeightField,
    coherence_um: f64,
    shading: &Shading,
    wi: [f64; 3],
    wr: [f64; 3],
    lambda_nm: f64,
) -> f64 {
    spectral(wi, wr, shading, |d| {
        p_hat_ref(hf, &centred(hf), coherence_um / 4.0, d, lambda_nm * 1e-3).norm_sqr()
    })
}

/// CIE XYZ by direct summation at every wavelength of `table` (use a 1 nm table for the
/// reference of MODEL §6.1). Wavelengths run in parallel.
pub fn xyz(
    hf: &HeightField,
    coherence_um: f64,
    shading: &Shading,
    table: &ColourTable,
    wi: [f64; 3],
    wr: [f64; 3],
) -> [f64; 3] {
    integrated(wi, wr, shading, |d| {
        let h = centred(hf);
        let sigma = coherence_um / 4.0;
        table
            .lambdas_nm
            .par_iter()
            .zip(&table.weights)
            .map(|(l, w)| {
                let r = p_hat_ref(hf, &h, sigma, d, l * 1e-3).norm_sqr();
                [r * w[0], r * w[1], r * w[2]]
            })
            .reduce(|| [0.0; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]])
    })
}

/// The reference XYZ at many view directions under one light, in parallel over directions:
/// the same direct sum as [`xyz`], but when the height field has few distinct heights (8-
/// and 16-bit images have at most 65 536) each wavelength computes `exp(i·s·h)` once per
/// height level instead of once per sample. Same numbers, several times faster; `progress`
/// is called once per finished direction.
pub fn xyz_many(
    hf: &HeightField,
    coherence_um: f64,
    shading: &Shading,
    table: &ColourTable,
    wi: [f64; 3],
    wrs: &[[f64; 3]],
    progress: &(dyn Fn() + Sync),
) -> Vec<[f64; 3]> {
    let h = centred(hf);
    let mut levels = h.clone();
    levels.sort_by(f64::total_cmp);
    levels.dedup();
    let quantised = levels.len() <= h.len() / 4;
    let index: Vec<u32> = if quantised {
        h.iter()
            .map(|x| levels.partition_point(|l| l < x) as u32)
            .collect()
    } else {
        Vec::new()
    };
    let sigma = coherence_um / 4.0;
    wrs.par_iter()
        .map(|&wr| {
            let xyz = integrated(wi, wr, shading, |d| {
                let mut acc = [0.0; 3];
                let mut phase = vec![Complex64::new(0.0, 0.0); levels.len()];
                for (l, w) in table.lambdas_nm.iter().zip(&table.weights) {
                    let lambda_um = l * 1e-3;
                    let r = if quantised {
                        let k = 2.0 * std::f64::consts::PI / lambda_um;
                        for (p, h) in phase.iter_mut().zip(&levels) {
                            let (s, c) = (k * d[2] * h).sin_cos();
                            *p = Complex64::new(c, s);
                        }
                        p_hat_levels(hf, &index, &phase, sigma, d, lambda_um).norm_sqr()
                    } else {
                        p_hat_ref(hf, &h, sigma, d, lambda_um).norm_sqr()
                    };
                    for c in 0..3 {
                        acc[c] += r * w[c];
                    }
                }
                acc
            });
            progress();
            xyz
        })
        .collect()
}

/// [`p_hat_ref`] with `exp(i·k·w·h)` looked up per height level.
fn p_hat_levels(
    hf: &HeightField,
    index: &[u32],
    phase: &[Complex64],
    sigma_um: f64,
    d: [f64; 3],
    lambda_um: f64,
) -> Complex64 {
    let k = 2.0 * std::f64::consts::PI / lambda_um;
    let (gx, sx) = folded_axis(hf.nx(), hf.dh_um(), sigma_um, k * d[0]);
    let (gy, sy) = folded_axis(hf.ny(), hf.dh_um(), sigma_um, k * d[1]);
    let mut acc = Complex64::new(0.0, 0.0);
    for (r, row) in index.chunks_exact(hf.nx()).enumerate() {
        if gy[r].norm_sqr() == 0.0 {
            continue;
        }
        let mut row_acc = Complex64::new(0.0, 0.0);
        for (c, &l) in row.iter().enumerate() {
            row_acc += gx[c] * phase[l as usize];
        }
        acc += gy[r] * row_acc;
    }
    acc / (sx * sy)
}
