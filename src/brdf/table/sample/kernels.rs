//! The inner loops of the exact sampler: the Gaussian window at one wavelength's lookups
//! and the Jacobi–Anger sum of one band row. Both are generic over the arithmetic of the
//! sums ([`Real`]: f64 for the reference build, f32 for the fast one) and compiled three
//! times: for AVX-512 and for AVX2 where the CPU has them, and portable. The three run the
//! same operations in the same order (Rust never fuses a multiply and an add), so they give
//! the same numbers and the choice is speed only.

use std::ops::{Add, AddAssign, Mul, Range, Sub};

use crate::spectrum::num_complex::Complex;

use super::{Lookups, PhaseSpectrum, TermBand};

/// The arithmetic of a build's sums.
pub(super) trait Real:
    Copy
    + Default
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + AddAssign
{
    /// `x` rounded to this type.
    fn of(x: f64) -> Self;
    /// This value as f64 (exact).
    fn wide(self) -> f64;
}

impl Real for f64 {
    fn of(x: f64) -> Self {
        x
    }
    fn wide(self) -> f64 {
        self
    }
}

impl Real for f32 {
    fn of(x: f64) -> Self {
        x as f32
    }
    fn wide(self) -> f64 {
        f64::from(self)
    }
}

/// Wavelengths whose windows one pass over the accumulators takes: each node column of the
/// accumulators is read and written once per block, not once per wavelength.
pub(super) const WINDOW_BLOCK: usize = 8;

/// One wavelength of a [`PhaseSpectrum::window`] block: its lookups, its windowed-spectrum
/// input over the lookups' texels (row-major) and its XYZ weight.
pub(super) type WindowJob<'a, T> = (&'a Lookups, &'a [Complex<T>], [f64; 3]);

impl PhaseSpectrum {
    /// The Gaussian window at the lookups of the nodes of rows `rows` (`v_j`, every `u_i`)
    /// for each wavelength of `block`, `|P̂|²·weight` added to `acc`: planar (X, Y, Z
    /// planes), each node column-major within the rows (`i·h + (j − rows.start)` for node
    /// `(u_i, v_j)`, `h = rows.len()`), in f64. The window's sums run in `T`. Each node's
    /// sums are the same whatever rows are asked with it, so a slice can be windowed as
    /// bands of rows on separate threads.
    pub(super) fn window<T: Real>(
        &self,
        block: &[WindowJob<'_, T>],
        rows: Range<usize>,
        acc: &mut [f64],
    ) {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512F (checked above).
                return unsafe { self.window_avx512(block, rows, acc) };
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2 (checked above).
                return unsafe { self.window_avx2(block, rows, acc) };
            }
        }
        self.window_kernel(block, rows, acc);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn window_avx512<T: Real>(
        &self,
        block: &[WindowJob<'_, T>],
        rows: Range<usize>,
        acc: &mut [f64],
    ) {
        self.window_kernel(block, rows, acc);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn window_avx2<T: Real>(
        &self,
        block: &[WindowJob<'_, T>],
        rows: Range<usize>,
        acc: &mut [f64],
    ) {
        self.window_kernel(block, rows, acc);
    }

    /// The separable window, `y` first: per wavelength, each node row's sum over the taps
    /// of whole band rows (contiguous, so every lane of a vector register works), stored
    /// transposed; then, node column by node column, the sum over the `x` taps of whole
    /// transposed rows, its `|P̂|²` weighted into the column of `acc`.
    #[inline(always)]
    fn window_kernel<T: Real>(
        &self,
        block: &[WindowJob<'_, T>],
        rows: Range<usize>,
        acc: &mut [f64],
    ) {
        let Some(&(first, _, _)) = block.first() else {
            return;
        };
        let nu = first.nodes().0;
        // The rows' height: the transposed rows and the accumulators hold only these.
        let nv = rows.len();
        let n = nu * nv;
        let taps = (2 * self.reach(0) + 1) as usize;
        let y_taps = (2 * self.reach(1) + 1) as usize;
        struct Pass<'a, T> {
            /// `ycols[c·2nv + j]` and `ycols[c·2nv + nv + j]`: re and im of the y pass at band
            /// column `c`, node row `j`.
            ycols: Vec<T>,
            /// Per node column: the first band column its x taps read, and their weights.
            starts: &'a [usize],
            gx: Vec<T>,
            weight: [f64; 3],
        }
        // Plain loops, not closures: a closure would be compiled without this function's
        // target features.
        let mut passes: Vec<Pass<'_, T>> = Vec::with_capacity(block.len());
        let mut line = Vec::new();
        for &(g, spectrum, weight) in block {
            let cols = g.size[0];
            let mut ycols = vec![T::default(); cols * 2 * nv];
            // A tile of node rows at a time, written transposed a cache line per column.
            const TILE: usize = 16;
            line.clear();
            line.resize(TILE * cols, Complex::new(T::default(), T::default()));
            for j0 in (0..nv).step_by(TILE) {
                let j1 = (j0 + TILE).min(nv);
                for (j, tile_row) in (j0..j1).zip(line.chunks_exact_mut(cols)) {
                    let node = rows.start + j;
                    let gy = &g.y.weights[node * y_taps..(node + 1) * y_taps];
                    tile_row.fill(Complex::new(T::default(), T::default()));
                    for (k, &gk) in gy.iter().enumerate() {
                        let gk = T::of(gk);
                        let r = g.y.first[node] + k;
                        for (l, x) in tile_row.iter_mut().zip(&spectrum[r * cols..(r + 1) * cols]) {
                            l.re += x.re * gk;
                            l.im += x.im * gk;
                        }
                    }
                }
                for c in 0..cols {
                    let at = c * 2 * nv;
                    for (k, j) in (j0..j1).enumerate() {
                        let l = line[k * cols + c];
                        ycols[at + j] = l.re;
                        ycols[at + nv + j] = l.im;
                    }
                }
            }
            passes.push(Pass {
                ycols,
                starts: &g.x.first,
                gx: g.x.weights.iter().map(|&x| T::of(x)).collect(),
                weight,
            });
        }
        // Node rows whose sums stay in registers through all x taps.
        const ROWS: usize = 32;
        let whole = nv / ROWS * ROWS;
        for i in 0..nu {
            for p in &passes {
                let from = p.starts[i] * 2 * nv;
                let gw = &p.gx[i * taps..(i + 1) * taps];
                let mut j0 = 0;
                while j0 < whole {
                    let (mut re, mut im) = ([T::default(); ROWS], [T::default(); ROWS]);
                    for (k, &gk) in gw.iter().enumerate() {
                        let at = from + k * 2 * nv + j0;
                        let xr: &[T; ROWS] = p.ycols[at..at + ROWS].try_into().unwrap();
                        let xi: &[T; ROWS] = p.ycols[at + nv..at + nv + ROWS].try_into().unwrap();
                        for m in 0..ROWS {
                            re[m] += xr[m] * gk;
                            im[m] += xi[m] * gk;
                        }
                    }
                    let mut power = [0.0f64; ROWS];
                    for m in 0..ROWS {
                        power[m] = (re[m] * re[m] + im[m] * im[m]).wide();
                    }
                    for (c, &wc) in p.weight.iter().enumerate() {
                        let at = c * n + i * nv + j0;
                        let out: &mut [f64; ROWS] = (&mut acc[at..at + ROWS]).try_into().unwrap();
                        for m in 0..ROWS {
                            out[m] += power[m] * wc;
                        }
                    }
                    j0 += ROWS;
                }
                for j in whole..nv {
                    let (mut re, mut im) = (T::default(), T::default());
                    for (k, &gk) in gw.iter().enumerate() {
                        let at = from + k * 2 * nv + j;
                        re += p.ycols[at] * gk;
                        im += p.ycols[at + nv] * gk;
                    }
                    let power = (re * re + im * im).wide();
                    for (c, &wc) in p.weight.iter().enumerate() {
                        acc[c * n + i * nv + j] += power * wc;
                    }
                }
            }
        }
    }
}

impl TermBand {
    /// Adds the terms' samples `start..start + even.len()` (one band row), times their
    /// weights, to `even` (even `n`) and `odd` (odd `n`).
    pub(super) fn sum_row<T: Real>(
        terms: &[Vec<Complex<T>>],
        start: usize,
        weight: &[T],
        even: &mut [Complex<T>],
        odd: &mut [Complex<T>],
    ) {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512F (checked above).
                return unsafe { Self::sum_row_avx512(terms, start, weight, even, odd) };
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2 (checked above).
                return unsafe { Self::sum_row_avx2(terms, start, weight, even, odd) };
            }
        }
        Self::sum_row_kernel(terms, start, weight, even, odd);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    unsafe fn sum_row_avx512<T: Real>(
        terms: &[Vec<Complex<T>>],
        start: usize,
        weight: &[T],
        even: &mut [Complex<T>],
        odd: &mut [Complex<T>],
    ) {
        Self::sum_row_kernel(terms, start, weight, even, odd);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn sum_row_avx2<T: Real>(
        terms: &[Vec<Complex<T>>],
        start: usize,
        weight: &[T],
        even: &mut [Complex<T>],
        odd: &mut [Complex<T>],
    ) {
        Self::sum_row_kernel(terms, start, weight, even, odd);
    }

    #[inline(always)]
    fn sum_row_kernel<T: Real>(
        terms: &[Vec<Complex<T>>],
        start: usize,
        weight: &[T],
        even: &mut [Complex<T>],
        odd: &mut [Complex<T>],
    ) {
        let cols = even.len();
        for (n, (term, &wn)) in terms.iter().zip(weight).enumerate() {
            let sum = if n % 2 == 0 { &mut *even } else { &mut *odd };
            for (acc, x) in sum.iter_mut().zip(&term[start..start + cols]) {
                acc.re += x.re * wn;
                acc.im += x.im * wn;
            }
        }
    }
}
