//! The NMM variant's physics (thesis §1.5.2; MODEL §7 "NMM done right"), in f64: the
//! grating period estimated from the height field's spectrum, the wavelengths a pixel can
//! see (`λ = d·|t|/ν` near integer orders `ν = n`, `t = u` or `v`), and the spectral integral
//! over just those, with the Jacobian `|dλ/dν| = λ²/(|t|·d)` that the thesis dropped (its
//! renders turned purple). The GPU shader (glsl/nmm.frag) follows [`plan`] sample for sample.

use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;

use super::{integrated, model, Shading};
use crate::colour::{cmf_1nm, d65_1nm, ColourTable, LAMBDA_MAX_NM, LAMBDA_MIN_NM};
use crate::heightfield::HeightField;
use crate::spectrum::{TermStack, Window};
use crate::{Error, Result};

/// Share of the non-DC spectral power that the strongest peak (with its neighbours and its
/// mirror image) must hold for the field to count as a grating. A sinusoid holds ~100 %,
/// the shipped synthetic gratings 40–90 %; an irregular surface spreads its power thinly.
pub const MIN_PEAK_SHARE: f64 = 0.25;

/// Half-width of a line in Gaussian-window stds `σν = σt·d/L`: each order is integrated
/// over `ν ∈ n ± LINE_SIGMAS·σν`. `|P̂|²` falls like `exp(−(ν−n)²/σν²)` around an order, so
/// the cut leaves out `erfc(2.5) ≈ 4e-4` of a line's light.
pub const LINE_SIGMAS: f64 = 2.5;

/// Samples per order on each side of `ν = n`, `0.625·σν` apart (a trapezoid rule; 9 per
/// order). `|P̂|²` is a sum of Gaussians of std `σν/√2` (products of the window's taps),
/// which this step alone would integrate to `2·exp(−2π²·0.64)` ≈ 6e-6 relative; what is
/// left comes from the CIE·D65 density, which has structure at the 1 nm of its table where
/// high orders make lines a few nm wide. Measured on a 1D 2 µm grating against the 1 nm
/// reference (tests/nmm_accuracy.rs): 7.5e-4 rel L2, where 13 samples over `±4σν` gave
/// 1.3e-3; on the Elaphe field 2.95e-2 against 2.90e-2 (the narrower line leaves out a
/// little more of the light between orders, which NMM does not model).
pub const HALF_SAMPLES: i32 = 4;

/// The estimated grating.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grating {
    /// Period along x and y (µm); `None` where the grating vector has no component.
    pub period_um: [Option<f64>; 2],
    /// Share of the non-DC power in the peak (see [`MIN_PEAK_SHARE`]).
    pub peak_share: f64,
    /// Frequency of the peak in cycles per patch (sub-bin refined).
    pub peak_cycles: [f64; 2],
}

/// Estimates the period from the strongest non-DC peak of the power spectrum of the
/// mean-centred heights, refined to a fraction of a bin by a parabola through the log power
/// of its neighbours; refuses a field without a dominant peak.
pub fn estimate_grating(hf: &HeightField) -> Result<Grating> {
    let (nx, ny) = (hf.nx(), hf.ny());
    let mean = hf.mean();
    let mut data: Vec<Complex64> = hf
        .heights_um()
        .iter()
        .map(|h| Complex64::new(h - mean, 0.0))
        .collect();
    let mut planner = FftPlanner::new();
    let (row, col) = (planner.plan_fft_forward(nx), planner.plan_fft_forward(ny));
    for r in data.chunks_exact_mut(nx) {
        row.process(r);
    }
    let mut column = vec![Complex64::new(0.0, 0.0); ny];
    for c in 0..nx {
        for (r, z) in column.iter_mut().enumerate() {
            *z = data[r * nx + c];
        }
        col.process(&mut column);
        for (r, z) in column.iter().enumerate() {
            data[r * nx + c] = *z;
        }
    }
    let power = |mx: i64, my: i64| {
        data[my.rem_euclid(ny as i64) as usize * nx + mx.rem_euclid(nx as i64) as usize].norm_sqr()
    };
    let signed = |i: usize, n: usize| {
        if i > n / 2 {
            i as i64 - n as i64
        } else {
            i as i64
        }
    };
    let total: f64 = data.iter().map(|z| z.norm_sqr()).sum::<f64>() - data[0].norm_sqr();
    if total <= 0.0 {
        return Err(Error::invalid(
            "nmm",
            "the height field is flat: no grating period to find",
        ));
    }
    let (mut best, mut at) = (0.0, (0i64, 0i64));
    for (k, z) in data.iter().enumerate().skip(1) {
        if z.norm_sqr() > best {
            best = z.norm_sqr();
            at = (signed(k % nx, nx), signed(k / nx, ny));
        }
    }
    let near = |(mx, my): (i64, i64)| -> f64 {
        let mut s = 0.0;
        for dy in -1..=1 {
            for dx in -1..=1 {
                if (mx + dx, my + dy) != (0, 0) {
                    s += power(mx + dx, my + dy);
                }
            }
        }
        s
    };
    // A real field's spectrum is Hermitian: the mirror peak carries the same power.
    let share = (near(at) + near((-at.0, -at.1))) / total;
    if share < MIN_PEAK_SHARE {
        return Err(Error::invalid(
            "nmm",
            format!(
                "no dominant grating period: the strongest spectral peak ({} , {} cycles per patch) holds {:.0}% of the non-DC power, NMM needs ≥ {:.0}%; use another variant",
                at.0,
                at.1,
                100.0 * share,
                100.0 * MIN_PEAK_SHARE
            ),
        ));
    }
    let refine = |m: i64, lo: f64, mid: f64, hi: f64| -> f64 {
        if m == 0 || lo <= 0.0 || hi <= 0.0 {
            return m as f64;
        }
        let (a, b, c) = (lo.ln(), mid.ln(), hi.ln());
        let den = a - 2.0 * b + c;
        m as f64
            + if den < 0.0 {
                (0.5 * (a - c) / den).clamp(-0.5, 0.5)
            } else {
                0.0
            }
    };
    let p0 = power(at.0, at.1);
    let fx = refine(at.0, power(at.0 - 1, at.1), p0, power(at.0 + 1, at.1));
    let fy = refine(at.1, power(at.0, at.1 - 1), p0, power(at.0, at.1 + 1));
    let (lx, ly) = hf.extent_um();
    let period = |f: f64, l: f64| (f != 0.0).then(|| l / f.abs());
    Ok(Grating {
        period_um: [period(fx, lx), period(fy, ly)],
        peak_share: share,
        peak_cycles: [fx, fy],
    })
}

/// One wavelength sample of the NMM integral: `λ` and its weight `Δν·λ²/(|t|·d)` (in nm of
/// wavelength, so `Σ ρ(λ)·density(λ)·weight` is the spectral integral).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub lambda_nm: f64,
    pub weight_nm: f64,
}

/// The line half-width in `ν` along an axis: [`LINE_SIGMAS`] Gaussian-window stds,
/// `σν = σt·d/L`.
fn half_width(d_um: f64, sigma_texels: f64, extent_um: f64) -> f64 {
    LINE_SIGMAS * sigma_texels * d_um / extent_um
}

/// The wavelengths NMM samples for the pixel with `(u, v)`, or `None` near specular, where
/// the zeroth order covers every wavelength and the full spectrum is integrated instead.
/// `jacobian = false` reproduces the thesis (no `λ²/(|t|d)`; weights then need the per-pixel
/// normalisation the thesis applied), for the test that shows why it is wrong.
pub fn plan(
    grating: &Grating,
    window: &Window,
    extent_um: [f64; 2],
    uv: [f64; 2],
    jacobian: bool,
) -> Option<Vec<Sample>> {
    let (lmin, lmax) = (LAMBDA_MIN_NM as f64, LAMBDA_MAX_NM as f64);
    // Zeroth order: within four window stds of DC at the longest wavelength.
    let dc =
        (0..2).all(|a| uv[a].abs() * extent_um[a] / (lmax * 1e-3) <= 4.0 * window.sigma_texels[a]);
    if dc {
        return None;
    }
    let mut out = Vec::new();
    for axis in 0..2 {
        let Some(d) = grating.period_um[axis] else {
            continue;
        };
        let t = uv[axis].abs();
        let delta = half_width(d, window.sigma_texels[axis], extent_um[axis]);
        let dnu = delta / HALF_SAMPLES as f64;
        // Orders whose line reaches the visible range: d·t/λmax − δ ≤ n ≤ d·t/λmin + δ.
        let first = ((d * t * 1e3 / lmax - delta).ceil() as i64).max(1);
        let last = (d * t * 1e3 / lmin + delta).floor() as i64;
        for n in first..=last {
            for j in -HALF_SAMPLES..=HALF_SAMPLES {
                let nu = n as f64 + j as f64 * dnu;
                let lambda = d * t * 1e3 / nu;
                if !(lmin..=lmax).contains(&lambda) {
                    continue;
                }
                if axis == 1 && counted_along_u(grating, window, extent_um, uv, lambda) {
                    continue;
                }
                let trapezoid = if j.abs() == HALF_SAMPLES { 0.5 } else { 1.0 };
                let jac = if jacobian {
                    lambda * lambda / (t * d * 1e3)
                } else {
                    1.0
                };
                out.push(Sample {
                    lambda_nm: lambda,
                    weight_nm: trapezoid * dnu * jac,
                });
            }
        }
    }
    Some(out)
}

/// The most wavelength samples [`plan`] takes for one pixel whose `|u|`, `|v|` reach at
/// most `t_max`, with wavelengths in `lambda_nm` (the kept range): per axis with a period,
/// the orders whose line reaches the range at the largest `|t|` (their count grows with
/// `|t|`), `2·HALF_SAMPLES + 1` samples each. What the fetch counts multiply.
pub fn max_samples(
    grating: &Grating,
    window: &Window,
    extent_um: [f64; 2],
    t_max: [f64; 2],
    lambda_nm: (f64, f64),
) -> usize {
    let per_order = (2 * HALF_SAMPLES + 1) as usize;
    (0..2)
        .filter_map(|a| {
            let d = grating.period_um[a]?;
            let t = t_max[a].abs().min(2.0);
            let delta = half_width(d, window.sigma_texels[a], extent_um[a]);
            let first = ((d * t * 1e3 / lambda_nm.1 - delta).ceil() as i64).max(1);
            let last = (d * t * 1e3 / lambda_nm.0 + delta).floor() as i64;
            Some((last - first + 1).max(0) as usize * per_order)
        })
        .sum()
}

/// Whether wavelength `λ` already lies on a line of an order along u that [`plan`] samples
/// (so a v-order sample at the same `λ` would count the same light twice).
fn counted_along_u(
    grating: &Grating,
    window: &Window,
    extent: [f64; 2],
    uv: [f64; 2],
    lambda_nm: f64,
) -> bool {
    let Some(d) = grating.period_um[0] else {
        return false;
    };
    let nu = d * uv[0].abs() * 1e3 / lambda_nm;
    let n = nu.round();
    n >= 1.0 && (nu - n).abs() <= half_width(d, window.sigma_texels[0], extent[0])
}

/// CIE·D65 density per nm at `λ` (linear between the 1 nm samples), normalised like
/// [`ColourTable`] so a unit spectrum gives `Y = 1`.
pub struct Density {
    table: Vec<[f64; 3]>,
}

impl Density {
    pub fn new() -> Self {
        let (cmf, d65) = (cmf_1nm(), d65_1nm());
        let last = cmf.len() - 1;
        let norm: f64 = (0..=last)
            .map(|i| d65[i] * cmf[i][1] * if i == 0 || i == last { 0.5 } else { 1.0 })
            .sum();
        Self {
            table: (0..=last)
                .map(|i| [0, 1, 2].map(|c| d65[i] * cmf[i][c] / norm))
                .collect(),
        }
    }

    /// The 1 nm table (for upload).
    pub fn table(&self) -> &[[f64; 3]] {
        &self.table
    }

    pub fn at(&self, lambda_nm: f64) -> [f64; 3] {
        let x = lambda_nm - LAMBDA_MIN_NM as f64;
        if !(0.0..=(self.table.len() - 1) as f64).contains(&x) {
            return [0.0; 3];
        }
        let i = (x.floor() as usize).min(self.table.len() - 2);
        let f = x - i as f64;
        [0, 1, 2].map(|c| self.table[i][c] + f * (self.table[i + 1][c] - self.table[i][c]))
    }
}

impl Default for Density {
    fn default() -> Self {
        Self::new()
    }
}

/// The NMM colour in f64 (what glsl/nmm.frag computes): `C·Σ_samples |P̂(λ)|²·density(λ)·w`
/// with FLSS's `P̂` (same terms and taps), or the full spectrum of `table` near specular.
#[allow(clippy::too_many_arguments)]
pub fn xyz(
    stack: &TermStack,
    terms: usize,
    window: &Window,
    shading: &Shading,
    table: &ColourTable,
    grating: &Grating,
    density: &Density,
    wi: [f64; 3],
    wr: [f64; 3],
    jacobian: bool,
) -> [f64; 3] {
    let extent = [stack.nx as f64 * stack.dh_um, stack.ny as f64 * stack.dh_um];
    integrated(wi, wr, shading, |d| {
        let power = |l_nm: f64| model::p_hat(stack, terms, window, d, l_nm * 1e-3).norm_sqr();
        match plan(grating, window, extent, [d[0], d[1]], jacobian) {
            None => table.integrate(power),
            Some(samples) => {
                let mut acc = [0.0; 3];
                let mut norm = 0.0;
                for s in &samples {
                    let r = power(s.lambda_nm);
                    let c = density.at(s.lambda_nm);
                    for (a, x) in acc.iter_mut().zip(c) {
                        *a += r * x * s.weight_nm;
                    }
                    norm += c[1] * s.weight_nm;
                }
                if !jacobian && norm > 0.0 {
                    // The thesis normalised by the weights it summed, per pixel.
                    acc = acc.map(|a| a / norm);
                }
                acc
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grating_field(nx: usize, period_samples: f64, along_x: bool) -> HeightField {
        let tau = 2.0 * std::f64::consts::PI;
        let h = (0..nx * nx)
            .map(|i| {
                let (c, r) = ((i % nx) as f64, (i / nx) as f64);
                let p = if along_x { c } else { r };
                0.1 * (1.0 + (tau * p / period_samples).sin())
            })
            .collect();
        HeightField::new(nx, nx, 0.1, h).unwrap()
    }

    #[test]
    fn period_is_found_along_either_axis_and_noise_is_refused() {
        let g = estimate_grating(&grating_field(200, 12.5, true)).unwrap();
        let d = g.period_um[0].unwrap();
        assert!((d - 1.25).abs() / 1.25 < 5e-3, "{d}");
        assert!(g.period_um[1].is_none() && g.peak_share > 0.9);
        let g = estimate_grating(&grating_field(200, 16.0, false)).unwrap();
        assert!(g.period_um[0].is_none());
        assert!((g.period_um[1].unwrap() - 1.6).abs() / 1.6 < 5e-3);
        // White noise: no dominant peak.
        let mut s = 0x1234_5678_u64;
        let h = (0..128 * 128)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 40) as f64 / (1u64 << 24) as f64
            })
            .collect();
        let err = estimate_grating(&HeightField::new(128, 128, 0.1, h).unwrap()).unwrap_err();
        assert!(
            err.to_string().contains("no dominant grating period"),
            "{err}"
        );
    }

    #[test]
    fn plan_weights_integrate_the_wavelength_axis() {
        // Σ weight over the samples of one order ≈ the λ-span of the line: with the
        // Jacobian the weights are wavelength intervals, so they sum to the span.
        let g = Grating {
            period_um: [Some(1.5), None],
            peak_share: 1.0,
            peak_cycles: [40.0, 0.0],
        };
        let w = Window::new(400, 400, 0.15, 65.0, 2).unwrap();
        let ext = [60.0, 60.0];
        let u = 0.35;
        let samples = plan(&g, &w, ext, [u, 0.0], true).unwrap();
        assert!(!samples.is_empty());
        let delta = half_width(1.5, w.sigma_texels[0], 60.0);
        let span = 1.5 * u * 1e3 * (1.0 / (1.0 - delta) - 1.0 / (1.0 + delta));
        let sum: f64 = samples.iter().map(|s| s.weight_nm).sum();
        assert!((sum - span).abs() / span < 2e-3, "{sum} vs {span}");
        assert!(plan(&g, &w, ext, [0.0, 0.0], true).is_none());
    }
}
