//! Computing the DFT terms (thesis Algorithm 1, MODEL §3–4) with a real-to-complex FFT.
//!
//! Every term is a real field times a constant phase: `(i h')ⁿ = iⁿ h'ⁿ` (Taylor, `h'` mean
//! centred) or `T_n(x)` (Chebyshev). The `+i` transform of a real field is Hermitian, so rows
//! go through a real FFT, only the column frequencies the band needs go through a complex
//! FFT, and the other half-plane follows from `D[−m] = conj(D[m])`.

use std::sync::Arc;

use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use realfft::RealFftPlanner;
use rustfft::num_complex::Complex64;
use rustfft::{Fft, FftPlanner};

use super::{reachable_band, Band, Expansion, Extrema, TermRequest, TermStack};
use crate::heightfield::HeightField;
use crate::Result;

/// Work (samples × terms) above which a progress bar is shown on a terminal.
const PROGRESS_THRESHOLD: usize = 1 << 22;

/// Computes terms `0..=req.max_term` of `hf`, cropped to the reachable band (or the whole
/// spectrum with `req.full_band`), in parallel over terms.
pub fn compute_terms(hf: &HeightField, req: &TermRequest) -> Result<TermStack> {
    req.validate()?;
    let (nx, ny) = (hf.nx(), hf.ny());
    let band = if req.full_band {
        Band {
            x0: 0,
            y0: 0,
            width: nx,
            height: ny,
        }
    } else {
        reachable_band(hf, req.lambda_min_um, req.window_radius)
    };
    let mean = hf.mean();
    let (lo, hi) = hf.range();
    let half_range = 0.5 * (hi - lo);
    let mid = 0.5 * (hi + lo);
    let centred: Vec<f64> = hf.heights_um().iter().map(|h| h - mean).collect();
    // Chebyshev variable x = (h − mid)/A ∈ [−1, 1]; a flat field has A = 0 and x = 0.
    let theta: Vec<f64> = hf
        .heights_um()
        .iter()
        .map(|h| {
            let x = if half_range > 0.0 {
                ((h - mid) / half_range).clamp(-1.0, 1.0)
            } else {
                0.0
            };
            x.acos()
        })
        .collect();

    let plan = Plan::new(nx, ny, band);
    let count = req.max_term + 1;
    let progress = (nx * ny * count > PROGRESS_THRESHOLD).then(|| {
        let bar = ProgressBar::new(count as u64);
        if let Ok(style) = ProgressStyle::with_template("DFT terms {bar:30} {pos}/{len} {elapsed}")
        {
            bar.set_style(style);
        }
        bar
    });
    let scale = 1.0 / (nx * ny) as f64;
    let terms: Vec<Vec<Complex64>> = (0..count)
        .into_par_iter()
        .map(|n| {
            let (field, phase): (Vec<f64>, Complex64) = match req.expansion {
                Expansion::Taylor => (
                    centred.iter().map(|h| h.powi(n as i32)).collect(),
                    // iⁿ
                    [
                        Complex64::new(1.0, 0.0),
                        Complex64::new(0.0, 1.0),
                        Complex64::new(-1.0, 0.0),
                        Complex64::new(0.0, -1.0),
                    ][n % 4],
                ),
                Expansion::Chebyshev => (
                    theta.iter().map(|t| (n as f64 * t).cos()).collect(),
                    Complex64::new(1.0, 0.0),
                ),
            };
            let out = plan.transform(&field, phase * scale);
            if let Some(bar) = &progress {
                bar.inc(1);
            }
            out
        })
        .collect();
    if let Some(bar) = progress {
        bar.finish_and_clear();
    }
    let extrema = terms.iter().map(|t| extrema_of(t)).collect();
    Ok(TermStack {
        expansion: req.expansion,
        nx,
        ny,
        dh_um: hf.dh_um(),
        band,
        terms,
        extrema,
        max_deviation_um: hf.max_deviation(),
        half_range_um: half_range,
    })
}

fn extrema_of(t: &[Complex64]) -> Extrema {
    t.iter().fold(
        Extrema {
            re_min: f64::INFINITY,
            re_max: f64::NEG_INFINITY,
            im_min: f64::INFINITY,
            im_max: f64::NEG_INFINITY,
        },
        |e, z| Extrema {
            re_min: e.re_min.min(z.re),
            re_max: e.re_max.max(z.re),
            im_min: e.im_min.min(z.im),
            im_max: e.im_max.max(z.im),
        },
    )
}

/// FFT plans and the frequency bookkeeping of one band, shared by all terms.
struct Plan {
    nx: usize,
    ny: usize,
    band: Band,
    row: Arc<dyn realfft::RealToComplex<f64>>,
    col: Arc<dyn Fft<f64>>,
    /// Non-negative column frequencies `m_x ∈ [0, N_x/2]` that the band needs.
    needed: Vec<usize>,
}

impl Plan {
    fn new(nx: usize, ny: usize, band: Band) -> Self {
        let row = RealFftPlanner::<f64>::new().plan_fft_forward(nx);
        let col = FftPlanner::<f64>::new().plan_fft_inverse(ny);
        let bx = nx / 2;
        let mut needed: Vec<usize> = (band.x0..band.x0 + band.width)
            .map(|tx| (tx as i64 - bx as i64).unsigned_abs() as usize)
            .collect();
        needed.sort_unstable();
        needed.dedup();
        Self {
            nx,
            ny,
            band,
            row,
            col,
            needed,
        }
    }

    /// `fftshift(Σ f·e^{+2πi(m_x c/N_x + m_y r/N_y)})` over the band, times `factor`.
    fn transform(&self, field: &[f64], factor: Complex64) -> Vec<Complex64> {
        let (nx, ny) = (self.nx, self.ny);
        let half = nx / 2 + 1;
        // Rows: forward real FFT gives Σ f e^{−iθ}; its conjugate is the +i transform.
        let mut rows = vec![Complex64::new(0.0, 0.0); half * ny];
        let mut input = self.row.make_input_vec();
        let mut scratch = self.row.make_scratch_vec();
        for (r, out) in rows.chunks_exact_mut(half).enumerate() {
            input.copy_from_slice(&field[r * nx..(r + 1) * nx]);
            // Lengths come from the planner itself, so this cannot fail.
            let _ = self.row.process_with_scratch(&mut input, out, &mut scratch);
        }
        // Columns: inverse (+i) complex FFT of the conjugated row spectra, only where needed.
        let mut cols = vec![Vec::new(); half];
        let mut col_scratch = vec![Complex64::new(0.0, 0.0); self.col.get_inplace_scratch_len()];
        for &mx in &self.needed {
            let mut col: Vec<Complex64> = (0..ny).map(|r| rows[r * half + mx].conj()).collect();
            self.col.process_with_scratch(&mut col, &mut col_scratch);
            cols[mx] = col;
        }
        let (bx, by) = ((nx / 2) as i64, (ny / 2) as i64);
        let mut out = Vec::with_capacity(self.band.width * self.band.height);
        for ty in self.band.y0..self.band.y0 + self.band.height {
            let my = ty as i64 - by;
            for tx in self.band.x0..self.band.x0 + self.band.width {
                let mx = tx as i64 - bx;
                let v = if mx >= 0 {
                    cols[mx as usize][my.rem_euclid(ny as i64) as usize]
                } else {
                    // Hermitian symmetry of the transform of a real field.
                    cols[(-mx) as usize][(-my).rem_euclid(ny as i64) as usize].conj()
                };
                out.push(v * factor);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Direct O(N⁴) transform for checking the FFT path on tiny fields.
    fn direct(field: &[f64], nx: usize, ny: usize, mx: i64, my: i64) -> Complex64 {
        let mut acc = Complex64::new(0.0, 0.0);
        for r in 0..ny {
            for c in 0..nx {
                let ph = 2.0
                    * std::f64::consts::PI
                    * (mx as f64 * c as f64 / nx as f64 + my as f64 * r as f64 / ny as f64);
                acc += Complex64::from_polar(field[r * nx + c], ph);
            }
        }
        acc
    }

    fn test_field(nx: usize, ny: usize) -> HeightField {
        let h = (0..nx * ny)
            .map(|i| {
                let (c, r) = ((i % nx) as f64, (i / nx) as f64);
                0.1 * (0.7 * c + 0.3 * r).sin() + 0.05 * ((c * r) * 0.37).cos() + 0.2
            })
            .collect();
        HeightField::new(nx, ny, 0.05, h).unwrap()
    }

    #[test]
    fn fft_path_matches_direct_sum_for_odd_and_even_sizes() {
        for (nx, ny) in [(8, 6), (7, 9), (5, 4)] {
            let hf = test_field(nx, ny);
            for expansion in [Expansion::Taylor, Expansion::Chebyshev] {
                let req = TermRequest {
                    expansion,
                    max_term: 3,
                    lambda_min_um: 0.38,
                    window_radius: 1,
                    full_band: true,
                };
                let s = compute_terms(&hf, &req).unwrap();
                let mean = hf.mean();
                let (lo, hi) = hf.range();
                for n in 0..=3usize {
                    let f: Vec<Complex64> = hf
                        .heights_um()
                        .iter()
                        .map(|h| match expansion {
                            Expansion::Taylor => Complex64::new(0.0, h - mean).powu(n as u32),
                            Expansion::Chebyshev => {
                                let x = (h - 0.5 * (hi + lo)) / (0.5 * (hi - lo));
                                Complex64::new((n as f64 * x.clamp(-1.0, 1.0).acos()).cos(), 0.0)
                            }
                        })
                        .collect();
                    let re: Vec<f64> = f.iter().map(|z| z.re).collect();
                    let im: Vec<f64> = f.iter().map(|z| z.im).collect();
                    for ty in 0..ny {
                        for tx in 0..nx {
                            let (mx, my) =
                                (tx as i64 - (nx / 2) as i64, ty as i64 - (ny / 2) as i64);
                            let want = (direct(&re, nx, ny, mx, my)
                                + Complex64::new(0.0, 1.0) * direct(&im, nx, ny, mx, my))
                                / (nx * ny) as f64;
                            let got = s.texel(n, tx as i64, ty as i64);
                            assert!(
                                (got - want).norm() < 1e-12,
                                "{nx}x{ny} {expansion} n={n} t=({tx},{ty}): {got} vs {want}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn flat_field_has_unit_dc_and_nothing_else() {
        let hf = HeightField::new(16, 16, 0.05, vec![0.3; 256]).unwrap();
        for expansion in [Expansion::Taylor, Expansion::Chebyshev] {
            let req = TermRequest {
                expansion,
                max_term: 4,
                lambda_min_um: 0.38,
                window_radius: 1,
                full_band: true,
            };
            let s = compute_terms(&hf, &req).unwrap();
            assert!((s.texel(0, 8, 8) - Complex64::new(1.0, 0.0)).norm() < 1e-14);
            let off: f64 = (0..256).map(|i| s.terms[0][i].norm()).sum::<f64>() - 1.0;
            assert!(off.abs() < 1e-12);
        }
    }

    #[test]
    fn cropped_band_equals_the_same_texels_of_the_full_spectrum() {
        let hf = HeightField::new(
            64,
            48,
            0.02,
            (0..64 * 48)
                .map(|i| ((i * 7919) % 101) as f64 * 1e-3)
                .collect(),
        )
        .unwrap();
        let mut req = TermRequest {
            expansion: Expansion::Taylor,
            max_term: 2,
            lambda_min_um: 0.38,
            window_radius: 1,
            full_band: true,
        };
        let full = compute_terms(&hf, &req).unwrap();
        req.full_band = false;
        let crop = compute_terms(&hf, &req).unwrap();
        assert!(
            crop.band.width < 64 && crop.band.height < 48,
            "{:?}",
            crop.band
        );
        for n in 0..=2 {
            for ty in crop.band.y0..crop.band.y0 + crop.band.height {
                for tx in crop.band.x0..crop.band.x0 + crop.band.width {
                    let (a, b) = (
                        crop.texel(n, tx as i64, ty as i64),
                        full.texel(n, tx as i64, ty as i64),
                    );
                    assert!((a - b).norm() < 1e-14);
                }
            }
        }
    }
}
