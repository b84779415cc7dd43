//! `G` sampled exactly (MODEL §7): the windowed spectrum of `exp(i·s·h)` from one FFT of
//! the phase field per `(w, λ)`, or from the shared Jacobi–Anger band of Chebyshev-term
//! spectra, with the Gaussian window applied at the lookups by the kernels of [`kernels`]
//! (AVX-512 or AVX2 where the CPU has them). The reference build runs in f64 throughout;
//! the fast build ([`sample_g_kept_in`] with [`Precision::F32`]) sums the band and the
//! window in f32 from f64 transforms, within [`FAST_BUILD_TOLERANCE`] of the reference,
//! and measures its own difference on a probe of nodes.

use std::sync::Arc;

use rayon::prelude::*;
use rustfft::{Fft, FftPlanner};

use crate::brdf::truncation::Precision;
use crate::heightfield::HeightField;
use crate::spectrum::num_complex::{Complex, Complex32, Complex64};
use crate::{Error, Result};

use super::{Slices, TableSpec};

mod kernels;

use kernels::Real;

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
    sample_g_lines_in(
        hf,
        coherence_um,
        spec,
        w_nodes,
        lines,
        Precision::F64,
        progress,
    )
    .map(|s| s.slices)
}

/// A table's samples and the arithmetic that made them.
#[derive(Debug, Clone)]
pub struct Sampled {
    pub slices: Slices,
    /// The arithmetic of the sums: f32 only where asked for and where the shared term band
    /// is used (the per-job transforms are f64 either way).
    pub precision: Precision,
    /// For an f32 build: its largest difference from the f64 build over a probe of nodes
    /// (rows around the brightest row of the middle `w` node), relative to the probe's peak.
    pub probe: Option<f64>,
}

/// The most an f32 build may differ from the f64 build anywhere, relative to the slice
/// peak: a fiftieth of the stored table's float16 rounding (4.9e-4). Measured: 1e-7 on the
/// default table (tests/fast_table_build.rs checks three fields against it).
pub const FAST_BUILD_TOLERANCE: f64 = 1e-5;

/// Rows of nodes an f32 build is probed on against f64 ([`Sampled::probe`]).
const PROBE_ROWS: usize = 8;

/// [`sample_g_kept`] with the sums in `precision`. The transforms of the terms are f64
/// either way; in f32 the Jacobi–Anger sums and the Gaussian window run in float32 (twice
/// the lanes, half the memory traffic), a few parts in 1e7 of the peak, far below the
/// stored table's float16 rounding (4.9e-4). The result says what it measured against f64.
pub fn sample_g_kept_in(
    hf: &HeightField,
    coherence_um: f64,
    spec: &TableSpec,
    w_nodes: &[f64],
    keep: Option<&[usize]>,
    precision: Precision,
    progress: &(dyn Fn() + Sync),
) -> Result<Sampled> {
    let samples = spec.spectral_samples(keep)?;
    sample_g_lines_in(
        hf,
        coherence_um,
        spec,
        w_nodes,
        &samples,
        precision,
        progress,
    )
}

/// [`sample_g_lines`] with the sums in `precision` ([`sample_g_kept_in`]).
pub fn sample_g_lines_in(
    hf: &HeightField,
    coherence_um: f64,
    spec: &TableSpec,
    w_nodes: &[f64],
    lines: &[(f64, [f64; 3])],
    precision: Precision,
    progress: &(dyn Fn() + Sync),
) -> Result<Sampled> {
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
        precision,
    );
    let spectrum = spectrum;
    let used = match &spectrum.terms {
        Some(band) if band.fast.is_some() => Precision::F32,
        _ => Precision::F64,
    };
    // The lookups and their window taps depend on the wavelength, not on `w`.
    let looks = spectrum.all_lookups(&u, &v, samples);
    // The w nodes' slices run side by side, so that while one slice's thread prepares its
    // next group of wavelengths the other threads work on another's. The term inputs'
    // buffers go back to a pool after each slice, for the next one.
    let pool = std::sync::Mutex::new(Vec::<Inputs>::new());
    let data: Vec<Vec<[f64; 3]>> = w_nodes
        .par_iter()
        .with_max_len(1)
        .map(|&w| {
            let mut inputs = pool
                .lock()
                .ok()
                .and_then(|mut p| p.pop())
                .unwrap_or_default();
            let at = SliceAt {
                looks: &looks,
                samples,
                w,
            };
            let slice = spectrum.slice(at, used, progress, &mut inputs);
            if let Ok(mut p) = pool.lock() {
                p.push(inputs);
            }
            slice
        })
        .collect();
    let mut inputs = pool
        .into_inner()
        .ok()
        .and_then(|mut p| p.pop())
        .unwrap_or_default();
    let probe = (used == Precision::F32 && !w_nodes.is_empty()).then(|| {
        let k = w_nodes.len() / 2;
        let brightest = (0..nv)
            .max_by(|&a, &b| {
                let row = |j: usize| {
                    data[k][j * nu..(j + 1) * nu]
                        .iter()
                        .fold(0.0f64, |m, g| m.max(g[1]))
                };
                row(a).total_cmp(&row(b))
            })
            .unwrap_or(0);
        let j0 = brightest
            .saturating_sub(PROBE_ROWS / 2)
            .min(nv.saturating_sub(PROBE_ROWS));
        let j1 = (j0 + PROBE_ROWS).min(nv);
        let rows = spectrum.all_lookups(&u, &v[j0..j1], samples);
        let at = SliceAt {
            looks: &rows,
            samples,
            w: w_nodes[k],
        };
        let exact = spectrum.slice(at, Precision::F64, &|| {}, &mut inputs);
        let fast = &data[k][j0 * nu..j1 * nu];
        let peak = exact.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        let diff = exact
            .iter()
            .flatten()
            .zip(fast.iter().flatten())
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        if peak > 0.0 {
            diff / peak
        } else {
            diff
        }
    });
    Ok(Sampled {
        slices: Slices {
            nu,
            nv,
            w: w_nodes.to_vec(),
            data,
        },
        precision: used,
        probe,
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
    /// The same rounded to float32, for a build whose sums run in f32.
    fast: Option<Vec<Vec<Complex32>>>,
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
        precision: Precision,
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
        // `count` full transforms once and a `count`-term sum over the band per job, a
        // vectorised multiply-add per sample: measured on the 2-core EPYC (704² field, 25
        // terms, a 345×344 band), a sample of it costs an eighth of a direct sample in f64
        // and a sixteenth in f32.
        let per_job_direct = self.nx * self.ny + cols * self.ny;
        let per_job_shared = count * rows * cols
            / match precision {
                Precision::F64 => 8,
                Precision::F32 => 16,
            };
        let once = count * (self.nx * self.ny + self.nx * self.ny);
        if count * rows * cols > MAX_TERM_BAND
            || (jobs != usize::MAX
                && jobs.saturating_mul(per_job_shared).saturating_add(once)
                    >= jobs.saturating_mul(per_job_direct))
        {
            return;
        }
        let mid = lo + half_range;
        let xs: Vec<f64> = self
            .heights
            .iter()
            .map(|h| {
                if half_range > 0.0 {
                    ((h - mid) / half_range).clamp(-1.0, 1.0)
                } else {
                    0.0
                }
            })
            .collect();
        let spectra = self.term_spectra(&xs, count, [x0, y0], [cols, rows]);
        let fast = (precision == Precision::F32).then(|| {
            spectra
                .iter()
                .map(|t| {
                    t.iter()
                        .map(|z| Complex32::new(z.re as f32, z.im as f32))
                        .collect()
                })
                .collect()
        });
        self.terms = Some(TermBand {
            t0: [x0, y0],
            cols,
            rows,
            half_range,
            spectra,
            fast,
        });
    }

    /// `DFT[T_n(x)]/(N_x N_y)` for `n < count` over the band of shifted texels from `t0`,
    /// `size = [cols, rows]` (row-major), where `xs` holds `x ∈ [−1, 1]` per texel.
    ///
    /// Two real terms share one complex transform: `z = T_a + i·T_b` gives
    /// `A(k) = (Z(k) + conj Z(−k))/2` and `B(k) = (Z(k) − conj Z(−k))/(2i)`, so the rows are
    /// transformed once per pair and the columns once per band column and its mirror. The
    /// terms come from the recurrence `T_{n+1} = 2x·T_n − T_{n−1}` (its error grows like
    /// `n²·ε`, 1e-13 at the largest `n` kept), started from `cos(n·acos x)` once per task.
    fn term_spectra(
        &self,
        xs: &[f64],
        count: usize,
        [x0, y0]: [i64; 2],
        [cols, rows]: [usize; 2],
    ) -> Vec<Vec<Complex64>> {
        let (nx, ny) = (self.nx, self.ny);
        let bin = |t: i64, n: usize| (t - (n / 2) as i64).rem_euclid(n as i64) as usize;
        let norm = 1.0 / (nx * ny) as f64;
        // The columns to transform (the band's and their mirrors), each once.
        let band_cols: Vec<usize> = (0..cols).map(|c| bin(x0 + c as i64, nx)).collect();
        let mut slot = vec![usize::MAX; nx];
        let mut needed = Vec::new();
        for &fx in &band_cols {
            for f in [fx, (nx - fx) % nx] {
                if slot[f] == usize::MAX {
                    slot[f] = needed.len();
                    needed.push(f);
                }
            }
        }
        let band_rows: Vec<usize> = (0..rows).map(|r| bin(y0 + r as i64, ny)).collect();
        // Pairs of terms, in as many runs as there are threads (each run keeps its own
        // recurrence).
        let pairs = count.div_ceil(2);
        let runs = rayon::current_num_threads().clamp(1, pairs.max(1));
        let per_run = pairs.div_ceil(runs);
        let zero = Complex64::new(0.0, 0.0);
        let out: Vec<Vec<Vec<Complex64>>> = (0..runs)
            .into_par_iter()
            .map(|run| {
                let first = 2 * run * per_run;
                let last = (2 * (run + 1) * per_run).min(count);
                let mut out = Vec::new();
                if first >= last {
                    return out;
                }
                // T_{n−1} and T_n at the run's first n.
                let start = |n: usize| -> Vec<f64> {
                    xs.iter().map(|&x| (n as f64 * x.acos()).cos()).collect()
                };
                let mut prev = if first == 0 {
                    vec![0.0; xs.len()]
                } else {
                    start(first - 1)
                };
                let mut cur = start(first);
                let step = |prev: &mut Vec<f64>, cur: &mut Vec<f64>, n: usize| {
                    // Advances (T_{n−1}, T_n) to (T_n, T_{n+1}); T_1 = x.
                    for ((p, c), &x) in prev.iter_mut().zip(cur.iter_mut()).zip(xs) {
                        let next = if n == 0 { x } else { 2.0 * x * *c - *p };
                        *p = *c;
                        *c = next;
                    }
                };
                let mut field = vec![zero; xs.len()];
                let mut columns = vec![zero; needed.len() * ny];
                let mut scratch = self.fft_scratch();
                let mut n = first;
                while n < last {
                    let pair = n + 1 < last;
                    for (z, &a) in field.iter_mut().zip(&cur) {
                        *z = Complex64::new(a, 0.0);
                    }
                    step(&mut prev, &mut cur, n);
                    if pair {
                        for (z, &b) in field.iter_mut().zip(&cur) {
                            z.im = b;
                        }
                        step(&mut prev, &mut cur, n + 1);
                    }
                    self.row_fft.process_with_scratch(&mut field, &mut scratch);
                    gather_columns(&field, nx, &needed, &mut columns);
                    self.col_fft
                        .process_with_scratch(&mut columns, &mut scratch);
                    let mut a = vec![zero; rows * cols];
                    let mut b = vec![zero; if pair { rows * cols } else { 0 }];
                    for (c, &fx) in band_cols.iter().enumerate() {
                        let here = &columns[slot[fx] * ny..(slot[fx] + 1) * ny];
                        let mirror = slot[(nx - fx) % nx];
                        let there = &columns[mirror * ny..(mirror + 1) * ny];
                        for (r, &fy) in band_rows.iter().enumerate() {
                            let z = here[fy];
                            if !pair {
                                a[r * cols + c] = z * norm;
                                continue;
                            }
                            let m = there[(ny - fy) % ny].conj();
                            let (s, d) = (z + m, z - m);
                            a[r * cols + c] = s * (0.5 * norm);
                            b[r * cols + c] = Complex64::new(d.im, -d.re) * (0.5 * norm);
                        }
                    }
                    out.push(a);
                    if pair {
                        out.push(b);
                    }
                    n += if pair { 2 } else { 1 };
                }
                out
            })
            .collect();
        out.into_iter().flatten().collect()
    }

    /// A scratch buffer both transforms (rows and columns) can run in place with.
    fn fft_scratch(&self) -> Vec<Complex64> {
        let len = self
            .row_fft
            .get_inplace_scratch_len()
            .max(self.col_fft.get_inplace_scratch_len());
        vec![Complex64::new(0.0, 0.0); len]
    }

    /// The lookups of every wavelength of `samples` (nm) over the node grid `u × v`.
    fn all_lookups(&self, u: &[f64], v: &[f64], samples: &[(f64, [f64; 3])]) -> Vec<Lookups> {
        samples
            .par_iter()
            .map(|&(l, _)| self.lookups(u, v, l * 1e-3))
            .collect()
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
        // Each lookup's window: its first texel (from the reach's first) and its weights.
        let taps = |q: &[f64], r: i64, c0: i64, sigma: f64| {
            let mut first = Vec::with_capacity(q.len());
            let mut weights = Vec::with_capacity(q.len() * (2 * r + 1) as usize);
            for &q in q {
                let a = q.floor() as i64;
                first.push((a - r - c0) as usize);
                for t in a - r..=a + r {
                    let d = t as f64 - q;
                    weights.push((-d * d / (2.0 * sigma * sigma)).exp());
                }
            }
            Taps { first, weights }
        };
        Lookups {
            lambda_um,
            x: taps(&qx, rx, cx0, self.sigma[0]),
            y: taps(&qy, ry, cy0, self.sigma[1]),
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
        at: SliceAt<'_>,
        precision: Precision,
        progress: &(dyn Fn() + Sync),
        inputs: &mut Inputs,
    ) -> Vec<[f64; 3]> {
        let SliceAt { looks, samples, w } = at;
        // Accumulators are bands of `band_rows` node rows, each planar (X, then Y, then Z)
        // and column-major over its nodes (`i·h + j`, `h` the band's rows); the slice is
        // row-major (`j·nu + i`).
        let (nu, nv) = looks.first().map_or((0, 0), Lookups::nodes);
        let n = nu * nv;
        let zero = || vec![0.0f64; 3 * n];
        let interleave = |acc: Vec<f64>, band_rows: usize| -> Vec<[f64; 3]> {
            (0..n)
                .into_par_iter()
                .map(|p| {
                    let (i, j) = (p % nu, p / nu);
                    let j0 = j / band_rows * band_rows;
                    let h = band_rows.min(nv - j0);
                    let at = 3 * nu * j0 + i * h + (j - j0);
                    let plane = nu * h;
                    [acc[at], acc[plane + at], acc[2 * plane + at]]
                })
                .collect()
        };
        let s_of = |lambda_um: f64| phase_scale(w, lambda_um);
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
                        self.window::<f64>(&[(g, &spectrum, weight)], 0..nv, &mut acc);
                        progress();
                        acc
                    })
                    .reduce(zero, add_planes),
                nv,
            );
        };
        let acc = match (&band.fast, precision) {
            (Some(fast), Precision::F32) => {
                self.band_slice(band, fast, at, progress, &mut inputs.f32)
            }
            _ => self.band_slice(band, &band.spectra, at, progress, &mut inputs.f64),
        };
        interleave(acc, WINDOW_ROWS)
    }

    /// The accumulators of [`Self::slice`] (in bands of [`WINDOW_ROWS`] node rows) from the
    /// shared band, its terms and sums in `T`. Wavelengths go in groups whose inputs
    /// together stay within [`TERM_GROUP_SAMPLES`]; within a group the inputs are summed
    /// band row by band row ([`TermBand::sum`]), then windowed band of node rows by band of
    /// node rows in parallel: each thread writes its own rows, for every wavelength of the
    /// group, so nothing is reduced and the threads stay busy to the group's end.
    fn band_slice<T: Real>(
        &self,
        band: &TermBand,
        terms: &[Vec<Complex<T>>],
        at: SliceAt<'_>,
        progress: &(dyn Fn() + Sync),
        inputs: &mut Vec<Vec<Complex<T>>>,
    ) -> Vec<f64> {
        let SliceAt { looks, samples, w } = at;
        let (nu, nv) = looks.first().map_or((0, 0), Lookups::nodes);
        let mut acc = vec![0.0f64; 3 * nu * nv];
        let mut first = 0;
        while first < looks.len() {
            let mut last = first + 1;
            let mut held = looks[first].len();
            while last < looks.len() && held + looks[last].len() <= TERM_GROUP_SAMPLES {
                held += looks[last].len();
                last += 1;
            }
            let group = &looks[first..last];
            let s: Vec<f64> = group.iter().map(|g| phase_scale(w, g.lambda_um)).collect();
            band.sum(terms, &s, group, inputs);
            let jobs: Vec<kernels::WindowJob<'_, T>> = group
                .iter()
                .zip(inputs.iter())
                .zip(&samples[first..last])
                .map(|((g, spectrum), &(_, weight))| (g, spectrum.as_slice(), weight))
                .collect();
            acc.par_chunks_mut(3 * nu * WINDOW_ROWS)
                .enumerate()
                .for_each(|(b, out)| {
                    let j0 = b * WINDOW_ROWS;
                    let rows = j0..(j0 + WINDOW_ROWS).min(nv);
                    for block in jobs.chunks(kernels::WINDOW_BLOCK) {
                        self.window(block, rows.clone(), out);
                    }
                });
            group.iter().for_each(|_| progress());
            first = last;
        }
        acc
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
        let zero = Complex64::new(0.0, 0.0);
        let mut scratch = self.fft_scratch();
        self.row_fft.process_with_scratch(&mut field, &mut scratch);
        // Columns: only the frequencies the lookups reach. Shifted texel t holds frequency
        // t − b, i.e. FFT bin (t − b) mod N; the spectrum is periodic, so t wraps too.
        let bin = |t: i64, n: usize| (t - (n / 2) as i64).rem_euclid(n as i64) as usize;
        let norm = 1.0 / (nx * ny) as f64;
        let which: Vec<usize> = (0..cols).map(|c| bin(cx0 + c as i64, nx)).collect();
        let mut columns = vec![zero; cols * ny];
        gather_columns(&field, nx, &which, &mut columns);
        self.col_fft
            .process_with_scratch(&mut columns, &mut scratch);
        for (c, column) in columns.chunks_exact(ny).enumerate() {
            for r in 0..rows {
                spectrum[r * cols + c] = column[bin(cy0 + r as i64, ny)] * norm;
            }
        }
    }
}

/// Copies the columns `which` of the row-major `field` (rows of `nx`) into `columns`, one
/// after another, a band of rows at a time (so the reads stay in cache).
fn gather_columns(field: &[Complex64], nx: usize, which: &[usize], columns: &mut [Complex64]) {
    const BAND: usize = 16;
    let ny = field.len() / nx;
    for r0 in (0..ny).step_by(BAND) {
        let r1 = (r0 + BAND).min(ny);
        for (k, &fx) in which.iter().enumerate() {
            for r in r0..r1 {
                columns[k * ny + r] = field[r * nx + fx];
            }
        }
    }
}

/// The phase field's scale `s = 2πw/λ` (µm⁻¹) of one `(w, λ)` job.
fn phase_scale(w: f64, lambda_um: f64) -> f64 {
    2.0 * std::f64::consts::PI * w / lambda_um
}

/// `a + b`, element by element (planar accumulators).
fn add_planes(mut a: Vec<f64>, b: Vec<f64>) -> Vec<f64> {
    for (x, y) in a.iter_mut().zip(&b) {
        *x += y;
    }
    a
}

/// The lookups of one wavelength over a node grid, and the texels their windows read.
struct Lookups {
    lambda_um: f64,
    /// First shifted texel (x, y) of the windows' reach, and its width and height.
    t0: [i64; 2],
    size: [usize; 2],
    /// The Gaussian window's taps of each lookup along x (one per `u` node) and along y
    /// (one per `v` node).
    x: Taps,
    y: Taps,
}

/// The taps of a window along one axis, for each lookup: the first texel it reads (from
/// the lookups' first, `t0`) and its `2·reach + 1` weights, lookup after lookup.
struct Taps {
    first: Vec<usize>,
    weights: Vec<f64>,
}

impl Lookups {
    /// The node grid's size: the lookups along x (`u` nodes) and along y (`v` nodes).
    fn nodes(&self) -> (usize, usize) {
        (self.x.first.len(), self.y.first.len())
    }

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

/// One `w` node's slice to sample: the lookups of its wavelengths, the wavelengths (nm) with
/// their XYZ weights, and `w`.
#[derive(Clone, Copy)]
struct SliceAt<'a> {
    looks: &'a [Lookups],
    samples: &'a [(f64, [f64; 3])],
    w: f64,
}

/// The windowed-spectrum inputs of a group of wavelengths, kept from group to group and
/// from `w` node to `w` node (tens of megabytes: allocated and zeroed once).
#[derive(Default)]
struct Inputs {
    f32: Vec<Vec<Complex<f32>>>,
    f64: Vec<Vec<Complex<f64>>>,
}

/// Node rows one task windows for every wavelength of a group: a multiple of the kernel's
/// register block of rows, small enough that a task's accumulators and transposed rows
/// stay in a core's cache.
const WINDOW_ROWS: usize = 64;

/// Band rows one task sums for every wavelength of a group.
const TERM_ROWS_PER_TASK: usize = 4;

impl TermBand {
    /// The windowed-spectrum inputs of `group` (phase scales `s`) into `inputs`: for each
    /// wavelength, `Σ_n ε_n iⁿ J_n(s·A) DFT[T_n]` over its texels, row-major. Band rows are
    /// the unit of work, so a row of every term is read once for the whole group.
    fn sum<T: Real>(
        &self,
        spectra: &[Vec<Complex<T>>],
        s: &[f64],
        group: &[Lookups],
        inputs: &mut Vec<Vec<Complex<T>>>,
    ) {
        let terms = spectra.len();
        // ε_n iⁿ J_n: real weights for the even terms, imaginary for the odd ones.
        let weights: Vec<Vec<T>> = s
            .iter()
            .map(|&s| {
                let j = crate::brdf::bessel::jn_all(s * self.half_range, terms);
                (0..terms)
                    .map(|n| {
                        let sign = if (n / 2) % 2 == 0 { 1.0 } else { -1.0 };
                        T::of(sign * if n == 0 { 1.0 } else { 2.0 } * j[n])
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
        let zero = Complex::new(T::default(), T::default());
        // The buffers of the last group, reused: each task zeroes the rows it sums, so the
        // calling thread neither allocates nor clears tens of megabytes while the others wait.
        inputs.resize_with(group.len(), Vec::new);
        for (buf, g) in inputs.iter_mut().zip(group) {
            if buf.len() < g.len() {
                buf.resize(g.len(), zero);
            }
            buf.truncate(g.len());
        }
        // Every wavelength's rows, handed to the task of the band rows they read.
        let tasks = ((hi - lo).max(0) as usize).div_ceil(TERM_ROWS_PER_TASK);
        // (wavelength, first band sample it reads, its row of the output)
        type Row<'a, T> = (usize, usize, &'a mut [Complex<T>]);
        let mut rows_of: Vec<Vec<Row<'_, T>>> = (0..tasks).map(|_| Vec::new()).collect();
        for (l, (g, out)) in group.iter().zip(inputs.iter_mut()).enumerate() {
            let first = g.t0[1] - self.t0[1];
            let start = (g.t0[0] - self.t0[0]) as usize;
            for (r, row) in out.chunks_exact_mut(g.size[0]).enumerate() {
                let t = (first + r as i64) as usize;
                rows_of[(t - lo as usize) / TERM_ROWS_PER_TASK].push((
                    l,
                    t * self.cols + start,
                    row,
                ));
            }
        }
        rows_of.into_par_iter().for_each(|rows| {
            let mut odd = Vec::new();
            for (l, at, row) in rows {
                row.fill(zero);
                odd.clear();
                odd.resize(row.len(), zero);
                Self::sum_row(spectra, at, &weights[l], row, &mut odd);
                // even + i·odd
                for (e, d) in row.iter_mut().zip(&odd) {
                    *e = Complex::new(e.re - d.im, e.im + d.re);
                }
            }
        });
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
        shared.share_terms(
            [u[0], u[8]],
            [v[0], v[6]],
            [0.45, 0.64],
            s_max,
            usize::MAX,
            Precision::F64,
        );
        assert!(shared.terms.is_some(), "the band must fit");
        let looks = direct.all_lookups(&u, &v, &samples);
        let mut inputs = Inputs::default();
        let at = SliceAt {
            looks: &looks,
            samples: &samples,
            w,
        };
        let a = direct.slice(at, Precision::F64, &|| {}, &mut inputs);
        let b = shared.slice(at, Precision::F64, &|| {}, &mut inputs);
        let peak = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(peak > 0.0);
        for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
            assert!((x - y).abs() <= 1e-12 * peak, "{x} vs {y} (peak {peak})");
        }
    }
}
