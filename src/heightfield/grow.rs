//! Growing a small measured crop into a coherence-sized height field (`diffract heightfield
//! --from-sample`). A 100² AFM crop spans 6.9 µm, a tenth of the 65 µm coherence length;
//! tiling it would add the crop's own period (lines every `1/(n·dH)` in the spectrum) and
//! its seams (the edges do not match). Instead the big field is a new random surface with
//! the crop's statistics:
//!
//! 1. **Spectrum.** The mean-free crop is multiplied by a separable Hann taper (so its edges
//!    go to zero: no seam leakage), zero-padded to the big field's `N×N` grid and
//!    transformed. Zero-padding evaluates the crop's tapered Fourier transform on the finer
//!    frequency grid `1/(N·dH)` of the big field: an exact interpolation of the crop's
//!    periodogram, smooth on the scale of a crop bin, with no line at the crop's period.
//! 2. **Random phases.** The amplitudes `|S(k)|` are given the phases of the transform of
//!    seeded white noise (Hermitian, so the result is real).
//! 3. **Histogram.** Heights are replaced rank for rank by the crop's sorted heights
//!    (nearest rank), so the height distribution is the crop's.
//! 4. **Iterate (IAAFT).** Steps 2–3 are repeated with the current phases: re-impose the
//!    amplitudes, re-impose the histogram. The last step is the histogram, so it is exact;
//!    the spectrum is the crop's up to the small change the last ranking makes.
//!
//! What it keeps: the height histogram and the second-order statistics (power spectrum, so
//! the ridge period, orientation and its spread). What it does not: higher-order shape (the
//! measured fingers become random ridges of the same spectrum). Deterministic for a seed.
//! Nothing here reads or writes files.

use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;

use super::generate::Rng;
use super::{HeightField, MAX_SIDE};
use crate::{Error, Result};

/// Amplitude/histogram iterations after the first synthesis (IAAFT). Four already bring
/// the spectrum within a few percent of the target; more change little.
pub const GROW_ITERATIONS: usize = 6;

/// Grows `sample` into an `n × n` field with the same `dH` (module docs). `n` must be at
/// least the sample's larger side (a grown field is never smaller than its sample).
pub fn grow(sample: &HeightField, n: usize, seed: u64) -> Result<HeightField> {
    use rayon::prelude::*;
    let (sx, sy) = (sample.nx(), sample.ny());
    if sx < 4 || sy < 4 {
        return Err(Error::invalid(
            "sample",
            format!("{sx}×{sy} samples; growing needs at least 4×4"),
        ));
    }
    if n < sx.max(sy) || n > MAX_SIDE {
        return Err(Error::invalid(
            "grown size",
            format!(
                "{n} samples; must be between the sample's side ({}) and {MAX_SIDE}",
                sx.max(sy)
            ),
        ));
    }
    let mean = sample.mean();
    let hann = |i: usize, len: usize| {
        0.5 - 0.5 * (std::f64::consts::TAU * (i as f64 + 0.5) / len as f64).cos()
    };
    let mut field = vec![Complex64::new(0.0, 0.0); n * n];
    for r in 0..sy {
        for c in 0..sx {
            let h = sample.heights_um()[r * sx + c] - mean;
            field[r * n + c] = Complex64::new(h * hann(c, sx) * hann(r, sy), 0.0);
        }
    }
    let mut fft = Fft2::new(n);
    fft.forward(&mut field);
    let mut amplitude: Vec<f64> = field.iter().map(|z| z.norm()).collect();
    amplitude[0] = 0.0;

    let mut sorted = sample.heights_um().to_vec();
    sorted.sort_unstable_by(f64::total_cmp);

    // Phases of seeded white noise.
    let mut rng = Rng::new(seed);
    let mut current: Vec<Complex64> = (0..n * n)
        .map(|_| Complex64::new(rng.unit() - 0.5, 0.0))
        .collect();
    fft.forward(&mut current);
    let mut heights = vec![0.0; n * n];
    for _ in 0..=GROW_ITERATIONS {
        current.par_iter_mut().zip(&amplitude).for_each(|(z, &a)| {
            let m = z.norm();
            *z = if m > 0.0 {
                *z * (a / m)
            } else {
                Complex64::new(a, 0.0)
            };
        });
        fft.inverse(&mut current);
        for (h, z) in heights.iter_mut().zip(&current) {
            *h = z.re;
        }
        match_histogram(&mut heights, &sorted);
        for (z, &h) in current.iter_mut().zip(&heights) {
            *z = Complex64::new(h, 0.0);
        }
        fft.forward(&mut current);
    }
    HeightField::new(n, n, sample.dh_um(), heights)
}

/// Replaces every value by the sorted target value of the same rank (nearest rank): the
/// result's histogram is `target`'s, resampled to `values.len()` samples.
fn match_histogram(values: &mut [f64], sorted_target: &[f64]) {
    let order = rank_order(values);
    let len = values.len();
    let m = sorted_target.len();
    for (rank, &i) in order.iter().enumerate() {
        // Rank centre (rank + ½)/len → target index; floor keeps it in 0..m.
        let k = ((2 * rank + 1) * m) / (2 * len);
        values[i as usize] = sorted_target[k.min(m - 1)];
    }
}

/// The indices of `values` in increasing order (`f64::total_cmp`), ties by index: each value's
/// order-preserving bit pattern and its index packed into one 128-bit key (so every key is
/// distinct and the order total), sorted in parallel (a comparison sort of `(value, index)`
/// pairs on one core dominated growing).
fn rank_order(values: &[f64]) -> Vec<u32> {
    use rayon::prelude::*;
    // total_cmp's order as unsigned integers: negatives flipped whole, positives' sign set.
    let key = |x: f64| {
        let b = x.to_bits();
        if b >> 63 == 1 {
            !b
        } else {
            b | 1 << 63
        }
    };
    let mut keys: Vec<u128> = values
        .par_iter()
        .zip(0..values.len() as u32)
        .map(|(&x, i)| (u128::from(key(x)) << 32) | u128::from(i))
        .collect();
    keys.par_sort_unstable();
    keys.into_par_iter().map(|k| k as u32).collect()
}

/// A square 2D complex FFT (rows, then columns through a transpose). `forward` is the `−i`
/// transform, `inverse` the `+i` transform divided by `N²`, so `inverse(forward(x)) = x`.
struct Fft2 {
    n: usize,
    fwd: std::sync::Arc<dyn rustfft::Fft<f64>>,
    inv: std::sync::Arc<dyn rustfft::Fft<f64>>,
    /// Scratch length each row transform needs.
    scratch: usize,
    tmp: Vec<Complex64>,
}

impl Fft2 {
    fn new(n: usize) -> Self {
        let mut planner = FftPlanner::new();
        let fwd = planner.plan_fft_forward(n);
        let inv = planner.plan_fft_inverse(n);
        let len = fwd
            .get_inplace_scratch_len()
            .max(inv.get_inplace_scratch_len());
        Self {
            n,
            fwd,
            inv,
            scratch: len,
            tmp: vec![Complex64::new(0.0, 0.0); n * n],
        }
    }

    /// Rows transformed in parallel, then a tiled transpose; twice.
    fn run(&mut self, data: &mut [Complex64], forward: bool) {
        use rayon::prelude::*;
        let plan = if forward { &self.fwd } else { &self.inv };
        let n = self.n;
        let scratch = self.scratch;
        const TILE: usize = 16;
        for _ in 0..2 {
            data.par_chunks_mut(n * TILE).for_each_init(
                || vec![Complex64::new(0.0, 0.0); scratch],
                |scratch, rows| plan.process_with_scratch(rows, scratch),
            );
            let src: &[Complex64] = data;
            // tmp row c (of TILE rows per task) = data column c.
            self.tmp
                .par_chunks_mut(n * TILE)
                .enumerate()
                .for_each(|(block, out)| {
                    let c0 = block * TILE;
                    let width = out.len() / n;
                    for r in 0..n {
                        let line = &src[r * n + c0..r * n + c0 + width];
                        for (k, &z) in line.iter().enumerate() {
                            out[k * n + r] = z;
                        }
                    }
                });
            data.copy_from_slice(&self.tmp);
        }
    }

    fn forward(&mut self, data: &mut [Complex64]) {
        self.run(data, true);
    }

    fn inverse(&mut self, data: &mut [Complex64]) {
        self.run(data, false);
        let s = 1.0 / (self.n * self.n) as f64;
        for z in data.iter_mut() {
            *z *= s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fft2_round_trips_and_puts_a_wave_in_its_bin() {
        let n = 12;
        let mut fft = Fft2::new(n);
        let wave: Vec<Complex64> = (0..n * n)
            .map(|i| {
                let (c, r) = ((i % n) as f64, (i / n) as f64);
                let ph = std::f64::consts::TAU * (2.0 * c + 3.0 * r) / n as f64;
                Complex64::new(ph.cos(), 0.0)
            })
            .collect();
        let mut spec = wave.clone();
        fft.forward(&mut spec);
        let peak = (0..n * n)
            .max_by(|&a, &b| spec[a].norm().total_cmp(&spec[b].norm()))
            .unwrap();
        // cos splits into (2, 3) and (−2, −3); either is the maximum.
        assert!(peak == 3 * n + 2 || peak == (n - 3) * n + (n - 2), "{peak}");
        fft.inverse(&mut spec);
        for (a, b) in spec.iter().zip(&wave) {
            assert!((a - b).norm() < 1e-12);
        }
    }

    #[test]
    fn rank_order_is_the_total_order_with_ties_by_index() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut values: Vec<f64> = (0..5000)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                // Few distinct values (ties), both signs, both zeros, large and tiny.
                match x % 7 {
                    0 => -0.0,
                    1 => 0.0,
                    2 => ((x >> 8) % 5) as f64 - 2.0,
                    3 => (x >> 11) as f64 * 1e-300,
                    4 => -((x >> 11) as f64) * 1e200,
                    _ => ((x >> 11) as f64 / (1u64 << 53) as f64) - 0.5,
                }
            })
            .collect();
        values.push(f64::INFINITY);
        values.push(f64::NEG_INFINITY);
        let mut want: Vec<u32> = (0..values.len() as u32).collect();
        want.sort_by(|&a, &b| {
            values[a as usize]
                .total_cmp(&values[b as usize])
                .then(a.cmp(&b))
        });
        assert_eq!(rank_order(&values), want);
    }

    #[test]
    fn histogram_matching_takes_the_target_values_in_rank_order() {
        let mut v = vec![3.0, -1.0, 10.0, 0.5];
        match_histogram(&mut v, &[1.0, 2.0]);
        assert_eq!(v, vec![2.0, 1.0, 2.0, 1.0]);
    }
}
