//! `G` sampled exactly in f64 (MODEL §7): the windowed spectrum of `exp(i·s·h)` from one FFT
//! of the phase field per `(w, λ)`, or from the shared Jacobi–Anger band of Chebyshev-term
//! spectra, with the Gaussian window applied at the lookups by AVX2 kernels where the CPU
//! has them.

use std::sync::Arc;

use rayon::prelude::*;
use rustfft::{Fft, FftPlanner};

use crate::heightfield::HeightField;
use crate::spectrum::num_complex::Complex64;
use crate::{Error, Result};

use super::{Slices, TableSpec};

/// Samples `G(u_i, v_j, w)` for every `w` in `w_nodes` (MODEL §7, exact in f64).
///
/// For each `(w, λ)`: the phase field `exp(i·s·h)` with `s = 2πw/λ` (mean-centred `h`) is
/// transformed with the `+i` convention and `1/(N_x N_y)`, and the Gaussian window (MODEL §3,
/// `σt = N·dH/(2πσs)` texels, summed to 6σt) is applied at the lookups
/// `q = b + (u, v)·N·dH/λ` of the whole grid as two separable passes. `|P̂|²` times the
/// wavelength's XYZ weight is accumulated per slice. `progress` is called once per
/// finished `(w, λ)` pair.
pub fn sample_g(
    hf: &HeightField,
    coherence_um: f64,
    spec: &TableSpec,
    w_nodes: &[f64],
    progress: &(dyn Fn() + Sync),
) -> Result<Slices> {
    sample_g_kept(hf, coherence_um, spec, w_nodes, None, progress)
}

/// [`sample_g`] over only the wavelengths `keep` (indices into the colour table of
/// `spec.step_nm`; `None`: all): the others' weight is left out of `G`
/// ([`crate::leave_out::wavelengths_needed`] bounds it), and their FFTs are not computed.
pub fn sample_g_kept(
    hf: &HeightField,
    coherence_um: f64,
    spec: &TableSpec,
    w_nodes: &[f64],
    keep: Option<&[usize]>,
    progress: &(dyn Fn() + Sync),
) -> Result<Slices> {
    let samples = spec.spectral_samples(keep)?;
    sample_g_lines(hf, coherence_um, spec, w_nodes, &samples, progress)
}

/// [`sample_g`] with the spectral lines given: `Σ_λ |P̂_λ|²·weight_λ` over `lines`
/// (`(λ in nm, XYZ weight)`), with every `(w, λ)` job reading the one shared term band. A
/// weight may carry more than the colour table's (the environment's radiance scale).
pub fn sample_g_lines(
    hf: &HeightField,
    coherence_um: f64,
    spec: &TableSpec,
    w_nodes: &[f64],
    lines: &[(f64, [f64; 3])],
    progress: &(dyn Fn() + Sync),
) -> Result<Slices> {
    let (nu, nv) = spec.validate()?;
    if !(coherence_um.is_finite() && coherence_um > 0.0) {
        return Err(Error::invalid(
            "coherence length",
            format!("{coherence_um} µm; must be positive"),
        ));
    }
    if lines.is_empty() {
        return Err(Error::invalid("table build", "no spectral lines to sum"));
    }
    let samples = lines;
    let (u, v) = spec.node_coords(nu, nv);
    let mut spectrum = PhaseSpectrum::new(hf, coherence_um);
    let (l_min, l_max) = samples.iter().fold((f64::INFINITY, 0.0f64), |(a, b), s| {
        (a.min(s.0), b.max(s.0))
    });
    let s_max = w_nodes.iter().fold(0.0f64, |m, w| m.max(w.abs())) * 2.0 * std::f64::consts::PI
        / (l_min * 1e-3);
    spectrum.share_terms(
        [u[0], u[nu - 1]],
        [v[0], v[nv - 1]],
        [l_min * 1e-3, l_max * 1e-3],
        s_max,
        w_nodes.len() * samples.len(),
    );
    let spectrum = spectrum;
    let data = w_nodes
        .iter()
        .map(|&w| spectrum.slice(&u, &v, w, samples, progress))
        .collect();
    Ok(Slices {
        nu,
        nv,
        w: w_nodes.to_vec(),
        data,
    })
}

/// The windowed spectrum of `exp(i·s·h)` of one height field, evaluated on grids.
struct PhaseSpectrum {
    nx: usize,
    ny: usize,
    dh_um: f64,
    /// Mean-centred heights, row-major.
    heights: Vec<f64>,
    /// Gaussian window std in texels along x and y.
    sigma: [f64; 2],
    row_fft: Arc<dyn Fft<f64>>,
    col_fft: Arc<dyn Fft<f64>>,
    /// The spectra of `T_n(x)` over the band every job reads, when shared.
    terms: Option<TermBand>,
}

/// The Jacobi–Anger expansion of the phase field shared by every `(w, λ)` job (MODEL §4):
/// with `x = (h − mid)/A ∈ [−1, 1]`, `exp(i·s·h) = e^{i·s·mid} Σ_n ε_n iⁿ J_n(s·A) T_n(x)`,
/// so the transform of the phase field is `Σ_n ε_n iⁿ J_n(s·A)·DFT[T_n(x)]`: the transforms
/// of the Chebyshev polynomials of the heights are computed once, over the band of shifted
/// texels the lookups of every job reach, and each job only sums them with its Bessel
/// weights. `|J_n| ≤ 1` and `|T_n| ≤ 1`: no cancellation; the series is cut where
/// `J_n(s_max·A)` drops below 1e-16. (The unit phase `e^{i·s·mid}` leaves `|P̂|²` alone.)
struct TermBand {
    /// Shifted texel of the band's first column and row.
    t0: [i64; 2],
    cols: usize,
    rows: usize,
    /// Half the height range `A` (µm).
    half_range: f64,
    /// `spectra[n][r·cols + c]` = DFT[T_n(x)] / (N_x N_y) at shifted texel `t0 + (c, r)`.
    spectra: Vec<Vec<Complex64>>,
}

/// Largest shared term band (complex samples over all terms): beyond it each job transforms
/// its own phase field.
const MAX_TERM_BAND: usize = 16_000_000;

impl PhaseSpectrum {
    fn new(hf: &HeightField, coherence_um: f64) -> Self {
        let mean = hf.mean();
        let sigma_s = coherence_um / 4.0;
        let s = |n: usize| n as f64 * hf.dh_um() / (2.0 * std::f64::consts::PI * sigma_s);
        let mut planner = FftPlanner::new();
        Self {
            nx: hf.nx(),
            ny: hf.ny(),
            dh_um: hf.dh_um(),
            heights: hf.heights_um().iter().map(|h| h - mean).collect(),
            sigma: [s(hf.nx()), s(hf.ny())],
            row_fft: planner.plan_fft_inverse(hf.nx()),
            col_fft: planner.plan_fft_inverse(hf.ny()),
            terms: None,
        }
    }

    /// Texels the Gaussian window reaches on each side of a lookup along `axis`: 6σt, up.
    fn reach(&self, axis: usize) -> i64 {
        (6.0 * self.sigma[axis]).ceil() as i64
    }

    /// Shifted texels `[lo, hi]` the window of lookups over `t ∈ [t0, t1]` (u or v) reads
    /// along `axis`, for every wavelength in `lambda_um`.
    fn texel_span(&self, axis: usize, t: [f64; 2], lambda_um: [f64; 2]) -> [i64; 2] {
        let n = [self.nx, self.ny][axis];
        let r = self.reach(axis);
        let q = |t: f64, l: f64| ((n / 2) as f64 + t * n as f64 * self.dh_um / l).floor() as i64;
        let all = [
            q(t[0], lambda_um[0]),
            q(t[0], lambda_um[1]),
            q(t[1], lambda_um[0]),
            q(t[1], lambda_um[1]),
        ];
        [
            all.iter().copied().min().unwrap_or(0) - r,
            all.iter().copied().max().unwrap_or(0) + r,
        ]
    }

    /// Prepares the [`TermBand`] for `jobs` lookups over `u`, `v` (ranges), wavelengths in
    /// `lambda_um` and `|s| ≤ s_max`, when that is cheaper than one transform per job and
    /// fits [`MAX_TERM_BAND`]; otherwise leaves each job to transform its own phase field.
    /// `jobs = usize::MAX` shares whenever the band fits (the tests' way to compare paths).
    fn share_terms(
        &mut self,
        u: [f64; 2],
        v: [f64; 2],
        lambda_um: [f64; 2],
        s_max: f64,
        jobs: usize,
    ) {
        let (lo, hi) = self
            .heights
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
                (a.min(h), b.max(h))
            });
        let half_range = 0.5 * (hi - lo);
        if !(half_range.is_finite() && s_max.is_finite()) {
            return;
        }
        let a = s_max * half_range;
        let nmax = (a + 60.0).ceil() as usize;
        let j = crate::brdf::bessel::jn_all(a, nmax);
        let count = (0..=nmax)
            .rev()
            .find(|&n| j[n].abs() > 1e-16)
            .map_or(1, |n| n + 1);
        let [x0, x1] = self.texel_span(0, u, lambda_um);
        let [y0, y1] = self.texel_span(1, v, lambda_um);
        let (cols, rows) = ((x1 - x0 + 1) as usize, (y1 - y0 + 1) as usize);
        // One job transforms the whole field (rows, then the band's columns); the terms cost
        // `count` full transforms once and a `count`-term sum over the band per job.
        let per_job_direct = self.nx * self.ny + cols * self.ny;
        let per_job_shared = count * rows * cols / 4;
        let once = count * (self.nx * self.ny + self.nx * self.ny);
        if count * rows * cols > MAX_TERM_BAND
            || (jobs != usize::MAX
                && jobs.saturating_mul(per_job_shared).saturating_add(once)
                    >= jobs.saturating_mul(per_job_direct))
        {
            return;
        }
        let mid = lo + half_range;
        let (nx, ny) = (self.nx, self.ny);
        let bin = |t: i64, n: usize| (t - (n / 2) as i64).rem_euclid(n as i64) as usize;
        let norm = 1.0 / (nx * ny) as f64;
        // T_n(x) = cos(n·θ) with θ = acos x, taken once per texel.
        let thetas: Vec<f64> = self
            .heights
            .iter()
            .map(|h| {
                if half_range > 0.0 {
                    ((h - mid) / half_range).clamp(-1.0, 1.0)
                } else {
                    0.0
                }
                .acos()
            })
            .collect();
        let spectra = (0..count)
            .into_par_iter()
            .map(|n| {
                let mut field: Vec<Complex64> = thetas
                    .iter()
                    .map(|&t| Complex64::new((n as f64 * t).cos(), 0.0))
                    .collect();
                for row in field.chunks_exact_mut(nx) {
                    self.row_fft.process(row);
                }
                let mut band = vec![Complex64::new(0.0, 0.0); rows * cols];
                let mut column = vec![Complex64::new(0.0, 0.0); ny];
                for c in 0..cols {
                    let fx = bin(x0 + c as i64, nx);
                    for (r, z) in column.iter_mut().enumerate() {
                        *z = field[r * nx + fx];
                    }
                    self.col_fft.process(&mut column);
                    for r in 0..rows {
                        band[r * cols + c] = column[bin(y0 + r as i64, ny)] * norm;
                    }
                }
                band
            })
            .collect();
        self.terms = Some(TermBand {
            t0: [x0, y0],
            cols,
            rows,
            half_range,
            spectra,
        });
    }

    /// The lookups of one wavelength over the node grid `u × v`.
    fn lookups(&self, u: &[f64], v: &[f64], lambda_um: f64) -> Lookups {
        let (nx, ny) = (self.nx, self.ny);
        // Lookup positions (thesis eq. 1.8), increasing with u and v.
        let qx: Vec<f64> = u
            .iter()
            .map(|u| (nx / 2) as f64 + u * nx as f64 * self.dh_um / lambda_um)
            .collect();
        let qy: Vec<f64> = v
            .iter()
            .map(|v| (ny / 2) as f64 + v * ny as f64 * self.dh_um / lambda_um)
            .collect();
        let (rx, ry) = (self.reach(0), self.reach(1));
        let cx0 = qx[0].floor() as i64 - rx;
        let cx1 = qx[qx.len() - 1].floor() as i64 + rx;
        let cy0 = qy[0].floor() as i64 - ry;
        let cy1 = qy[qy.len() - 1].floor() as i64 + ry;
        Lookups {
            lambda_um,
            qx,
            qy,
            t0: [cx0, cy0],
            size: [(cx1 - cx0 + 1) as usize, (cy1 - cy0 + 1) as usize],
        }
    }

    /// `Σ_λ |P̂_λ(u_i, v_j; w)|² · weight_λ` over the node grid `u × v`, row-major.
    ///
    /// With the shared term band, the windowed-spectrum inputs of a group of wavelengths are
    /// summed together, row by row of the band, so each band row is read from memory once
    /// per group rather than once per wavelength; otherwise each wavelength transforms its
    /// own phase field. The Gaussian window then runs per wavelength, in parallel.
    fn slice(
        &self,
        u: &[f64],
        v: &[f64],
        w: f64,
        samples: &[(f64, [f64; 3])],
        progress: &(dyn Fn() + Sync),
    ) -> Vec<[f64; 3]> {
        // Accumulators are planar (X, then Y, then Z, each row-major over the nodes).
        let n = u.len() * v.len();
        let zero = || vec![0.0f64; 3 * n];
        let add = |mut a: Vec<f64>, b: Vec<f64>| {
            for (x, y) in a.iter_mut().zip(&b) {
                *x += y;
            }
            a
        };
        let interleave = |acc: Vec<f64>| -> Vec<[f64; 3]> {
            (0..n)
                .map(|p| [acc[p], acc[n + p], acc[2 * n + p]])
                .collect()
        };
        let s_of = |lambda_um: f64| 2.0 * std::f64::consts::PI * w / lambda_um;
        let looks: Vec<Lookups> = samples
            .iter()
            .map(|&(l, _)| self.lookups(u, v, l * 1e-3))
            .collect();
        let band = self
            .terms
            .as_ref()
            .filter(|b| looks.iter().all(|g| g.inside(b)));
        let Some(band) = band else {
            return interleave(
                looks
                    .par_iter()
                    .zip(samples)
                    .fold(zero, |mut acc, (g, &(_, weight))| {
                        let mut spectrum = vec![Complex64::new(0.0, 0.0); g.len()];
                        self.transform(s_of(g.lambda_um), g.t0, g.size, &mut spectrum);
                        self.window(g, &spectrum, weight, &mut acc);
                        progress();
                        acc
                    })
                    .reduce(zero, add),
            );
        };
        // Groups of wavelengths whose inputs together stay within TERM_GROUP_SAMPLES.
        let mut acc = zero();
        let mut first = 0;
        while first < looks.len() {
            let mut last = first + 1;
            let mut held = looks[first].len();
            while last < looks.len() && held + looks[last].len() <= TERM_GROUP_SAMPLES {
                held += looks[last].len();
                last += 1;
            }
            let group = &looks[first..last];
            let s: Vec<f64> = group.iter().map(|g| s_of(g.lambda_um)).collect();
            let inputs = band.sum(&s, group);
            // One accumulator per thread's share of the group (not one per split).
            let share = group.len().div_ceil(rayon::current_num_threads().max(1));
            let part = group
                .par_chunks(share)
                .zip(inputs.par_chunks(share))
                .zip(samples[first..last].par_chunks(share))
                .map(|((gs, spectra), weights)| {
                    let mut acc = zero();
                    for ((g, spectrum), &(_, weight)) in gs.iter().zip(spectra).zip(weights) {
                        self.window(g, spectrum, weight, &mut acc);
                        progress();
                    }
                    acc
                })
                .reduce(zero, add);
            acc = add(acc, part);
            first = last;
        }
        interleave(acc)
    }

    /// The windowed-spectrum input of one job by direct transform: `spectrum[r·cols + c]`
    /// = DFT[exp(i·s·h)]/(N_x N_y) at shifted texel `t0 + (c, r)`.
    fn transform(
        &self,
        s: f64,
        t0: [i64; 2],
        [cols, rows]: [usize; 2],
        spectrum: &mut [Complex64],
    ) {
        let (nx, ny) = (self.nx, self.ny);
        let [cx0, cy0] = t0;
        // Rows: the x transform of every row of the phase field.
        let mut field: Vec<Complex64> = self
            .heights
            .iter()
            .map(|h| Complex64::from_polar(1.0, s * h))
            .collect();
        for row in field.chunks_exact_mut(nx) {
            self.row_fft.process(row);
        }
        // Columns: only the frequencies the lookups reach. Shifted texel t holds frequency
        // t − b, i.e. FFT bin (t − b) mod N; the spectrum is periodic, so t wraps too.
        let bin = |t: i64, n: usize| (t - (n / 2) as i64).rem_euclid(n as i64) as usize;
        let norm = 1.0 / (nx * ny) as f64;
        let mut column = vec![Complex64::new(0.0, 0.0); ny];
        for c in 0..cols {
            let fx = bin(cx0 + c as i64, nx);
            for (r, z) in column.iter_mut().enumerate() {
                *z = field[r * nx + fx];
            }
            self.col_fft.process(&mut column);
            for r in 0..rows {
                spectrum[r * cols + c] = column[bin(cy0 + r as i64, ny)] * norm;
            }
        }
    }

    /// The Gaussian window at the lookups of every node, `|P̂|²·weight` added to `acc`
    /// (planar: X, Y, Z planes over the nodes). `spectrum` is the windowed-spectrum input
    /// over `g`'s texels.
    fn window(&self, g: &Lookups, spectrum: &[Complex64], weight: [f64; 3], acc: &mut [f64]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked above).
            return unsafe { self.window_avx2(g, spectrum, weight, acc) };
        }
        self.window_kernel(g, spectrum, weight, acc);
    }

    /// [`Self::window`] compiled for AVX2: the same operations in the same order (no fused
    /// multiply-add), so the same numbers, with twice the lanes.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn window_avx2(
        &self,
        g: &Lookups,
        spectrum: &[Complex64],
        weight: [f64; 3],
        acc: &mut [f64],
    ) {
        self.window_kernel(g, spectrum, weight, acc);
    }

    #[inline(always)]
    fn window_kernel(
        &self,
        g: &Lookups,
        spectrum: &[Complex64],
        weight: [f64; 3],
        acc: &mut [f64],
    ) {
        let [cx0, cy0] = g.t0;
        let [cols, _] = g.size;
        let (rx, ry) = (self.reach(0), self.reach(1));
        let rows = g.size[1];

        // Separable Gaussian window: first along x for every needed row, then along y. The
        // taps of one lookup add as complex numbers (re and im as a pair, each tap's weight
        // stored twice so a pair multiplies at once); |P̂|² comes after.
        let gauss = |d: f64, sigma: f64| (-d * d / (2.0 * sigma * sigma)).exp();
        let nu = g.qx.len();
        let taps = (2 * rx + 1) as usize;
        // Per lookup: the first texel it reads (from cx0) and its taps' weights.
        let mut starts = Vec::with_capacity(nu);
        let mut gx: Vec<[f64; 2]> = Vec::with_capacity(nu * taps);
        for &q in &g.qx {
            let a = q.floor() as i64;
            starts.push((a - rx - cx0) as usize);
            gx.extend((a - rx..=a + rx).map(|t| [gauss(t as f64 - q, self.sigma[0]); 2]));
        }
        let mut xpass = vec![[0.0f64; 2]; rows * nu];
        for (line, out) in spectrum.chunks_exact(cols).zip(xpass.chunks_exact_mut(nu)) {
            for ((o, &start), gw) in out.iter_mut().zip(&starts).zip(gx.chunks_exact(taps)) {
                let mut sum = [0.0f64; 2];
                for (x, gk) in line[start..start + taps].iter().zip(gw) {
                    sum[0] += x.re * gk[0];
                    sum[1] += x.im * gk[1];
                }
                *o = sum;
            }
        }
        // Along y, a block of lookups at a time, their sums held through all taps (re, im
        // interleaved as flat numbers, so a block is whole vector registers).
        let xpass: &[f64] = xpass.as_flattened();
        const BLOCK: usize = 16;
        let mut gy: Vec<f64> = Vec::with_capacity(taps);
        let mut from: Vec<usize> = Vec::with_capacity(taps);
        let mut p = vec![0.0f64; 2 * nu];
        let mut power = vec![0.0f64; nu];
        let plane = nu * g.qy.len();
        for (j, &q) in g.qy.iter().enumerate() {
            let a = q.floor() as i64;
            gy.clear();
            from.clear();
            for t in a - ry..=a + ry {
                gy.push(gauss(t as f64 - q, self.sigma[1]));
                from.push((t - cy0) as usize * 2 * nu);
            }
            let whole = 2 * nu / BLOCK * BLOCK;
            for i0 in (0..whole).step_by(BLOCK) {
                let mut sum = [0.0f64; BLOCK];
                for (&gk, &r) in gy.iter().zip(&from) {
                    let x: &[f64; BLOCK] = xpass[r + i0..r + i0 + BLOCK].try_into().unwrap();
                    for k in 0..BLOCK {
                        sum[k] += x[k] * gk;
                    }
                }
                p[i0..i0 + BLOCK].copy_from_slice(&sum);
            }
            p[whole..].fill(0.0);
            for (&gk, &r) in gy.iter().zip(&from) {
                for (pk, x) in p[whole..].iter_mut().zip(&xpass[r + whole..r + 2 * nu]) {
                    *pk += x * gk;
                }
            }
            for (pw, pi) in power.iter_mut().zip(p.chunks_exact(2)) {
                *pw = pi[0] * pi[0] + pi[1] * pi[1];
            }
            for (c, &wc) in weight.iter().enumerate() {
                let at = c * plane + j * nu;
                for (o, &pw) in acc[at..at + nu].iter_mut().zip(&power) {
                    *o += pw * wc;
                }
            }
        }
    }
}

/// The lookups of one wavelength over a node grid, and the texels their windows read.
struct Lookups {
    lambda_um: f64,
    /// Lookup positions along x (one per `u` node) and y (one per `v` node), in texels.
    qx: Vec<f64>,
    qy: Vec<f64>,
    /// First shifted texel (x, y) of the windows' reach, and its width and height.
    t0: [i64; 2],
    size: [usize; 2],
}

impl Lookups {
    /// Complex samples of its windowed-spectrum input.
    fn len(&self) -> usize {
        self.size[0] * self.size[1]
    }

    /// Whether the band holds every texel it reads.
    fn inside(&self, b: &TermBand) -> bool {
        let [cx0, cy0] = self.t0;
        cx0 >= b.t0[0]
            && cy0 >= b.t0[1]
            && cx0 + self.size[0] as i64 <= b.t0[0] + b.cols as i64
            && cy0 + self.size[1] as i64 <= b.t0[1] + b.rows as i64
    }
}

/// Most complex samples of windowed-spectrum inputs a group of wavelengths holds at once.
const TERM_GROUP_SAMPLES: usize = 8_000_000;

/// Band rows one task sums for every wavelength of a group.
const TERM_ROWS_PER_TASK: usize = 4;

impl TermBand {
    /// The windowed-spectrum inputs of `group` (phase scales `s`): for each wavelength,
    /// `Σ_n ε_n iⁿ J_n(s·A) DFT[T_n]` over its texels, row-major. Band rows are the unit of
    /// work, so a row of every term is read once for the whole group.
    fn sum(&self, s: &[f64], group: &[Lookups]) -> Vec<Vec<Complex64>> {
        let terms = self.spectra.len();
        // ε_n iⁿ J_n: real weights for the even terms, imaginary for the odd ones.
        let weights: Vec<Vec<f64>> = s
            .iter()
            .map(|&s| {
                let j = crate::brdf::bessel::jn_all(s * self.half_range, terms);
                (0..terms)
                    .map(|n| {
                        let sign = if (n / 2) % 2 == 0 { 1.0 } else { -1.0 };
                        sign * if n == 0 { 1.0 } else { 2.0 } * j[n]
                    })
                    .collect()
            })
            .collect();
        // Band rows (from the band's first) that some wavelength reads.
        let lo = group.iter().map(|g| g.t0[1]).min().unwrap_or(0) - self.t0[1];
        let hi = group
            .iter()
            .map(|g| g.t0[1] + g.size[1] as i64)
            .max()
            .unwrap_or(0)
            - self.t0[1];
        let starts: Vec<i64> = (lo..hi).step_by(TERM_ROWS_PER_TASK).collect();
        let blocks: Vec<Vec<Vec<Complex64>>> = starts
            .into_par_iter()
            .map(|r0| {
                let r1 = (r0 + TERM_ROWS_PER_TASK as i64).min(hi);
                let mut out: Vec<Vec<Complex64>> = vec![Vec::new(); group.len()];
                let (mut even, mut odd) = (Vec::new(), Vec::new());
                for t in r0..r1 {
                    for ((g, weight), o) in group.iter().zip(&weights).zip(out.iter_mut()) {
                        let r = t + self.t0[1] - g.t0[1];
                        if r < 0 || r >= g.size[1] as i64 {
                            continue;
                        }
                        let cols = g.size[0];
                        even.clear();
                        even.resize(cols, Complex64::new(0.0, 0.0));
                        odd.clear();
                        odd.resize(cols, Complex64::new(0.0, 0.0));
                        let start = t as usize * self.cols + (g.t0[0] - self.t0[0]) as usize;
                        self.sum_row(start, weight, &mut even, &mut odd);
                        o.extend(
                            even.iter()
                                .zip(&odd)
                                .map(|(e, d)| e + Complex64::new(-d.im, d.re)),
                        );
                    }
                }
                out
            })
            .collect();
        let mut inputs: Vec<Vec<Complex64>> =
            group.iter().map(|g| Vec::with_capacity(g.len())).collect();
        for block in blocks {
            for (input, rows) in inputs.iter_mut().zip(block) {
                input.extend(rows);
            }
        }
        inputs
    }

    /// Adds the terms' samples `start..start + even.len()` (one band row), times their
    /// weights, to `even` (even `n`) and `odd` (odd `n`).
    fn sum_row(&self, start: usize, weight: &[f64], even: &mut [Complex64], odd: &mut [Complex64]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked above).
            return unsafe { self.sum_row_avx2(start, weight, even, odd) };
        }
        self.sum_row_kernel(start, weight, even, odd);
    }

    /// [`Self::sum_row`] compiled for AVX2 (the same operations in the same order).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn sum_row_avx2(
        &self,
        start: usize,
        weight: &[f64],
        even: &mut [Complex64],
        odd: &mut [Complex64],
    ) {
        self.sum_row_kernel(start, weight, even, odd);
    }

    #[inline(always)]
    fn sum_row_kernel(
        &self,
        start: usize,
        weight: &[f64],
        even: &mut [Complex64],
        odd: &mut [Complex64],
    ) {
        let cols = even.len();
        for (n, (term, &wn)) in self.spectra.iter().zip(weight).enumerate() {
            let sum = if n % 2 == 0 { &mut *even } else { &mut *odd };
            for (acc, x) in sum.iter_mut().zip(&term[start..start + cols]) {
                *acc += x * wn;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::table::uniform_nodes;

    #[test]
    fn shared_terms_give_the_direct_transform_s_slice() {
        // A rough 24×20 field: the Jacobi–Anger band summed for a group of wavelengths must
        // give what each wavelength's own transform of exp(i·s·h) gives.
        let (nx, ny) = (24, 20);
        let heights: Vec<f64> = (0..nx * ny)
            .map(|k| {
                let (x, y) = ((k % nx) as f64, (k / nx) as f64);
                0.2 * (0.7 * x).sin()
                    + 0.15 * (1.3 * y + 0.4 * x).cos()
                    + 0.05 * (2.9 * x * y).sin()
            })
            .collect();
        let hf = HeightField::new(nx, ny, 0.1, heights).unwrap();
        let u = uniform_nodes(-0.6, 0.5, 9);
        let v = uniform_nodes(-0.4, 0.7, 7);
        let samples = [
            (450.0, [1.0, 0.5, 0.2]),
            (520.0, [0.3, 1.0, 0.1]),
            (640.0, [0.7, 0.2, 0.0]),
        ];
        let w: f64 = -1.6;
        let direct = PhaseSpectrum::new(&hf, 2.0);
        let mut shared = PhaseSpectrum::new(&hf, 2.0);
        let s_max = 2.0 * std::f64::consts::PI * w.abs() / 0.45;
        shared.share_terms([u[0], u[8]], [v[0], v[6]], [0.45, 0.64], s_max, usize::MAX);
        assert!(shared.terms.is_some(), "the band must fit");
        let a = direct.slice(&u, &v, w, &samples, &|| {});
        let b = shared.slice(&u, &v, w, &samples, &|| {});
        let peak = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(peak > 0.0);
        for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
            assert!((x - y).abs() <= 1e-12 * peak, "{x} vs {y} (peak {peak})");
        }
    }
}
