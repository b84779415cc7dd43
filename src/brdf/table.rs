//! Pre-integrated tables (MODEL §7). With the height field, the coherence window, D65 and
//! the CIE functions fixed, the colour is `XYZ(ωi, ωr) = C(ωi, ωr) · G(u, v, w)`, where
//!
//! `G(u, v, w) = Σ_λ |P̂_λ(ku, kv; w)|² · weights(λ)`
//!
//! depends on three scalars only. This module computes `G` in f64 on a grid over the region
//! of `(u, v, w)` a scene can reach — exactly, from the windowed spectrum of `exp(i·s·h)` at
//! `s = k·w` (one FFT of the phase field gives the whole `(u, v)` plane of one `s`), with
//! the Gaussian window untruncated (6σ) — so no series and no cancellation reach the GPU.
//! It also holds the f64 CPU models of the three stored representations, which interpolate
//! exactly as the GPU variants do: [`Volume`] (trilinear in `(u, v, w)`), [`ChebyshevW`]
//! (bilinear coefficients of a Chebyshev series in `w`, Clenshaw) and [`Dhillon`]
//! (bilinear coefficients of powers of `w`, Horner). No Vulkan here.

use std::sync::Arc;

use rayon::prelude::*;
use rustfft::{Fft, FftPlanner};

use crate::colour::ColourTable;
use crate::heightfield::HeightField;
use crate::spectrum::num_complex::Complex64;
use crate::{Error, Result};

use super::{integrated, Shading};

/// Largest number of grid nodes along `u` or `v`.
pub const MAX_NODES_UV: usize = 4096;
/// Largest number of `w` nodes (slices or coefficients).
pub const MAX_NODES_W: usize = 64;
/// Largest table, in f64 samples of G (`nu·nv·nw·3`): bounds CPU memory of a build.
pub const MAX_SAMPLES: usize = 120_000_000;

/// An axis-aligned box of `(u, v, w)`: what a scene or a BRDF map can reach.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Region {
    /// Lower corner `(u, v, w)`.
    pub lo: [f64; 3],
    /// Upper corner `(u, v, w)`.
    pub hi: [f64; 3],
}

impl Region {
    /// Everything physically possible: `u, v ∈ [−2, 2]`, `w ∈ [−2, 0]` (MODEL §1).
    pub const ALL: Region = Region {
        lo: [-2.0, -2.0, -2.0],
        hi: [2.0, 2.0, 0.0],
    };

    /// A BRDF map under light `wi`: `ωr` covers the upper hemisphere, so `(u, v)` covers the
    /// unit disk around `−ωi.xy` and `w ∈ [−cosθi − 1, −cosθi]`.
    pub fn brdf_map(wi: [f64; 3]) -> Region {
        Region {
            lo: [-wi[0] - 1.0, -wi[1] - 1.0, -wi[2] - 1.0],
            hi: [-wi[0] + 1.0, -wi[1] + 1.0, -wi[2]],
        }
        .clamped()
    }

    /// The bounding box of `points`, widened by `margin` on every side (fragments
    /// interpolate between vertices and renormalise, so they stray slightly outside).
    /// `None` without points.
    pub fn around(points: impl IntoIterator<Item = [f64; 3]>, margin: f64) -> Option<Region> {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut any = false;
        for p in points {
            if !p.iter().all(|c| c.is_finite()) {
                continue;
            }
            any = true;
            for a in 0..3 {
                lo[a] = lo[a].min(p[a] - margin);
                hi[a] = hi[a].max(p[a] + margin);
            }
        }
        any.then(|| Region { lo, hi }.clamped())
    }

    /// This box widened by `margin` on every side (and clamped to [`Region::ALL`]).
    pub fn widened(&self, margin: f64) -> Region {
        Region {
            lo: self.lo.map(|x| x - margin),
            hi: self.hi.map(|x| x + margin),
        }
        .clamped()
    }

    /// The smallest box holding this one and `other`.
    pub fn union(&self, other: &Region) -> Region {
        Region {
            lo: std::array::from_fn(|a| self.lo[a].min(other.lo[a])),
            hi: std::array::from_fn(|a| self.hi[a].max(other.hi[a])),
        }
    }

    fn clamped(self) -> Region {
        let mut r = self;
        for a in 0..3 {
            r.lo[a] = r.lo[a].clamp(Self::ALL.lo[a], Self::ALL.hi[a]);
            r.hi[a] = r.hi[a].clamp(Self::ALL.lo[a], Self::ALL.hi[a]);
            // A degenerate axis (one reachable value) still needs two nodes to interpolate.
            if r.hi[a] - r.lo[a] < 1e-3 {
                let mid = 0.5 * (r.lo[a] + r.hi[a]);
                r.lo[a] = mid - 5e-4;
                r.hi[a] = mid + 5e-4;
            }
        }
        r
    }

    /// Whether `p` lies inside (inclusive).
    pub fn contains(&self, p: [f64; 3]) -> bool {
        (0..3).all(|a| p[a] >= self.lo[a] && p[a] <= self.hi[a])
    }

    /// Edge lengths.
    pub fn extent(&self) -> [f64; 3] {
        [
            self.hi[0] - self.lo[0],
            self.hi[1] - self.lo[1],
            self.hi[2] - self.lo[2],
        ]
    }
}

/// How to sample `G`: the region, the `(u, v)` node spacing, the number of `w` nodes and the
/// wavelength step of the offline spectral integral.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableSpec {
    pub region: Region,
    /// Node spacing in `u` and `v`.
    pub texel_uv: f64,
    /// Nodes along `w` (slices of a volume, coefficients of a series).
    pub w_nodes: usize,
    /// Wavelength step of the offline integral (nm; divides 400).
    pub step_nm: u32,
}

impl TableSpec {
    /// The wavelengths (nm) of the offline spectral integral with their XYZ weights: every
    /// line of the colour table at `step_nm`, or only those whose indices `keep` lists.
    pub fn spectral_samples(&self, keep: Option<&[usize]>) -> Result<Vec<(f64, [f64; 3])>> {
        let colour = ColourTable::new(self.step_nm)?;
        Ok(match keep {
            Some(k) => k
                .iter()
                .filter_map(|&i| Some((*colour.lambdas_nm.get(i)?, colour.weights[i])))
                .collect(),
            None => colour
                .lambdas_nm
                .iter()
                .copied()
                .zip(colour.weights.iter().copied())
                .collect(),
        })
    }

    /// The `u` and `v` of the `nu × nv` nodes over the region, both ends included.
    pub fn node_coords(&self, nu: usize, nv: usize) -> (Vec<f64>, Vec<f64>) {
        let r = &self.region;
        let axis = |a: usize, n: usize| -> Vec<f64> {
            (0..n)
                .map(|i| r.lo[a] + r.extent()[a] * i as f64 / (n - 1) as f64)
                .collect()
        };
        (axis(0, nu), axis(1, nv))
    }

    /// The default `(u, v)` spacing: half the width of the coherence lobe,
    /// `λ/(2πσs)` at 550 nm (MODEL §7: about 0.005 in `u` for 65 µm).
    pub fn default_texel(coherence_um: f64) -> f64 {
        let sigma_s = coherence_um / 4.0;
        0.5 * 0.55 / (2.0 * std::f64::consts::PI * sigma_s)
    }

    /// Nodes along `u` and `v` (both ends included).
    pub fn uv_nodes(&self) -> Result<(usize, usize)> {
        if !(self.texel_uv.is_finite() && self.texel_uv > 0.0) {
            return Err(Error::invalid(
                "table texel",
                format!("{}; must be a positive spacing in u and v", self.texel_uv),
            ));
        }
        let e = self.region.extent();
        let n = |len: f64| (len / self.texel_uv).ceil() as usize + 1;
        let (nu, nv) = (n(e[0]).max(2), n(e[1]).max(2));
        if nu > MAX_NODES_UV || nv > MAX_NODES_UV {
            return Err(Error::invalid(
                "table texel",
                format!(
                    "{} needs {nu}×{nv} nodes over u ∈ [{:.3}, {:.3}], v ∈ [{:.3}, {:.3}]; at most {MAX_NODES_UV} a side: use a coarser spacing or a smaller region",
                    self.texel_uv, self.region.lo[0], self.region.hi[0], self.region.lo[1], self.region.hi[1]
                ),
            ));
        }
        Ok((nu, nv))
    }

    /// Checks the node counts and the size of the build.
    pub fn validate(&self) -> Result<(usize, usize)> {
        let (nu, nv) = self.uv_nodes()?;
        if !(2..=MAX_NODES_W).contains(&self.w_nodes) {
            return Err(Error::invalid(
                "table w nodes",
                format!("{}; expected 2..={MAX_NODES_W}", self.w_nodes),
            ));
        }
        let samples = nu * nv * self.w_nodes * 3;
        if samples > MAX_SAMPLES {
            return Err(Error::invalid(
                "table size",
                format!(
                    "{nu}×{nv}×{} nodes ({:.0} MB in f64) exceed the {:.0} MB build limit: use a coarser texel, fewer w nodes or a smaller region",
                    self.w_nodes,
                    samples as f64 * 8e-6,
                    MAX_SAMPLES as f64 * 8e-6
                ),
            ));
        }
        ColourTable::new(self.step_nm)?;
        Ok((nu, nv))
    }
}

/// `G` sampled on the `(u, v)` nodes of a spec, one slice per `w` node.
#[derive(Debug, Clone, PartialEq)]
pub struct Slices {
    pub nu: usize,
    pub nv: usize,
    /// The `w` of each slice.
    pub w: Vec<f64>,
    /// `data[k][j·nu + i]` = XYZ of `G(u_i, v_j, w_k)`.
    pub data: Vec<Vec<[f64; 3]>>,
}

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
    let (nu, nv) = spec.validate()?;
    if !(coherence_um.is_finite() && coherence_um > 0.0) {
        return Err(Error::invalid(
            "coherence length",
            format!("{coherence_um} µm; must be positive"),
        ));
    }
    let samples = spec.spectral_samples(keep)?;
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
        .map(|&w| spectrum.slice(&u, &v, w, &samples, progress))
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
        let j = super::bessel::jn_all(a, nmax);
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
                let j = super::bessel::jn_all(s * self.half_range, terms);
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

/// The sun's disc as a footprint in `(u, v)`: the directions over a disc of angular radius
/// `α` around the light's centre `ωi` move `(u, v) = −(ωi + ωr).xy` by the tangent-plane
/// projection of their offsets, an ellipse with semi-axes `α` (across the plane of incidence)
/// and `α·cosθi` (along it). `axes` maps the unit disc onto it: offset `= axes·p`, `|p| ≤ 1`.
/// A table convolved with it ([`prefilter_disc`]) holds the disc's sum of `G`, so a shader
/// evaluates it once, at the centre direction, instead of once per direction of the disc.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiscKernel {
    /// Columns: the images of the unit disc's x and y axes (u, v).
    pub axes: [[f64; 2]; 2],
}

impl DiscKernel {
    /// A circle of radius `radius` in `(u, v)` (the footprint at normal incidence).
    pub fn isotropic(radius: f64) -> Self {
        Self {
            axes: [[radius, 0.0], [0.0, radius]],
        }
    }

    /// The exact footprint of a disc of angular radius `radius` (rad) around `wi` (tangent
    /// frame, unit; small-angle: offsets are tangent to the sphere).
    pub fn footprint(wi: [f64; 3], radius: f64) -> Self {
        let h = (wi[0] * wi[0] + wi[1] * wi[1]).sqrt();
        // a ⊥ ωi and ⊥ N (unit in the plane); b = ωi × a, whose projection is cosθi long.
        let a = if h > 1e-12 {
            [-wi[1] / h, wi[0] / h, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let b = [
            wi[1] * a[2] - wi[2] * a[1],
            wi[2] * a[0] - wi[0] * a[2],
            wi[0] * a[1] - wi[1] * a[0],
        ];
        Self {
            axes: [
                [radius * a[0], radius * b[0]],
                [radius * a[1], radius * b[1]],
            ],
        }
    }

    /// Covariance of the uniform ellipse: `axes·axesᵀ/4`.
    pub fn covariance(&self) -> [[f64; 2]; 2] {
        let m = &self.axes;
        let c = |i: usize, j: usize| 0.25 * (m[i][0] * m[j][0] + m[i][1] * m[j][1]);
        [[c(0, 0), c(0, 1)], [c(1, 0), c(1, 1)]]
    }

    /// The uniform ellipse of covariance `cov` (symmetric, positive semi-definite): axes
    /// `2·√cov` (the symmetric square root).
    pub fn with_covariance(cov: [[f64; 2]; 2]) -> Self {
        let (a, b, d) = (cov[0][0], 0.5 * (cov[0][1] + cov[1][0]), cov[1][1]);
        // √ of a 2×2 SPD matrix: (M + √det·I)/√(tr + 2√det).
        let det = (a * d - b * b).max(0.0).sqrt();
        let t = (a + d + 2.0 * det).max(0.0).sqrt();
        if t <= 0.0 {
            return Self::isotropic(0.0);
        }
        let s = |x: f64| 2.0 * x / t;
        Self {
            axes: [[s(a + det), s(b)], [s(b), s(d + det)]],
        }
    }

    /// The covariance-mean of footprints: one ellipse for many directions of the light.
    pub fn mean(kernels: &[DiscKernel]) -> Option<Self> {
        if kernels.is_empty() {
            return None;
        }
        let mut c = [[0.0; 2]; 2];
        for k in kernels {
            let kc = k.covariance();
            for i in 0..2 {
                for j in 0..2 {
                    c[i][j] += kc[i][j] / kernels.len() as f64;
                }
            }
        }
        Some(Self::with_covariance(c))
    }

    /// The largest offset (the semi-major axis).
    pub fn reach(&self) -> f64 {
        let c = self.covariance();
        let (a, b, d) = (c[0][0], c[0][1], c[1][1]);
        let l = 0.5 * (a + d) + (0.25 * (a - d) * (a - d) + b * b).sqrt();
        2.0 * l.max(0.0).sqrt()
    }

    /// Weights `K(m)` of node offsets `m = (mu, mv)` on a grid of spacing `(du, dv)`:
    /// the disc's mean of the tensor cubic B-spline, `K(m) = E_p[β₃(mu − x_p)·β₃(mv − y_p)]`
    /// with `(x_p, y_p)` = `axes·p / (du, dv)`, `p` uniform on the unit disc. Convolving
    /// the spline coefficients of a plane with it gives the exact disc average of the
    /// spline interpolant at every node. Sums to 1 (partition of unity).
    pub fn taps(&self, du: f64, dv: f64) -> Vec<(i64, i64, f64)> {
        // Uniform points on the unit disc: rings of equal width, points in proportion to
        // each ring's area.
        const RINGS: usize = 24;
        let mut pts = Vec::new();
        for r in 0..RINGS {
            let rho = (r as f64 + 0.5) / RINGS as f64;
            let n = 6 * (2 * r + 1);
            for k in 0..n {
                let phi = 2.0 * std::f64::consts::PI * (k as f64 + 0.5 * (r % 2) as f64) / n as f64;
                let (s, c) = phi.sin_cos();
                let (x, y) = (rho * c, rho * s);
                let m = &self.axes;
                pts.push((
                    (m[0][0] * x + m[0][1] * y) / du,
                    (m[1][0] * x + m[1][1] * y) / dv,
                ));
            }
        }
        let reach_u = (self.axes[0][0].hypot(self.axes[0][1]) / du).ceil() as i64 + 2;
        let reach_v = (self.axes[1][0].hypot(self.axes[1][1]) / dv).ceil() as i64 + 2;
        let b3 = |x: f64| {
            let x = x.abs();
            if x < 1.0 {
                (4.0 - 6.0 * x * x + 3.0 * x * x * x) / 6.0
            } else if x < 2.0 {
                (2.0 - x).powi(3) / 6.0
            } else {
                0.0
            }
        };
        let mut taps = Vec::new();
        for mv in -reach_v..=reach_v {
            for mu in -reach_u..=reach_u {
                let w: f64 = pts
                    .iter()
                    .map(|&(x, y)| b3(mu as f64 - x) * b3(mv as f64 - y))
                    .sum::<f64>()
                    / pts.len() as f64;
                if w > 1e-12 {
                    taps.push((mu, mv, w));
                }
            }
        }
        taps
    }
}

/// Convolves every slice of `slices` (nodes over `region`) with the disc `kernel`: each node
/// becomes the disc's average of the cubic-spline interpolant of its slice around it
/// ([`DiscKernel::taps`]). Near the edges the coefficients are clamped to the border.
pub fn prefilter_disc(slices: &mut Slices, region: &Region, kernel: &DiscKernel) {
    let (nu, nv) = (slices.nu, slices.nv);
    let e = region.extent();
    let (du, dv) = (e[0] / (nu - 1) as f64, e[1] / (nv - 1) as f64);
    let taps = kernel.taps(du, dv);
    slices.data.par_iter_mut().for_each(|plane| {
        let c = spline_plane(plane, nu, nv);
        let su = nu + 2;
        let clamp = |x: i64, n: usize| x.clamp(0, n as i64 + 1) as usize;
        for j in 0..nv {
            for i in 0..nu {
                let mut acc = [0.0; 3];
                for &(mu, mv, w) in &taps {
                    // Node i's coefficient is stored at i + 1 (one ghost before).
                    let ci = clamp(i as i64 + 1 - mu, nu);
                    let cj = clamp(j as i64 + 1 - mv, nv);
                    let x = c[cj * su + ci];
                    for ch in 0..3 {
                        acc[ch] += w * x[ch];
                    }
                }
                plane[j * nu + i] = acc;
            }
        }
    });
}

/// Uniform `w` nodes over `[lo, hi]`, both ends included (volume slices).
pub fn uniform_nodes(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| lo + (hi - lo) * k as f64 / (n - 1).max(1) as f64)
        .collect()
}

/// Chebyshev nodes of the first kind mapped to `[lo, hi]`:
/// `w_k = mid + half·cos(π(k + ½)/K)`.
pub fn chebyshev_nodes(lo: f64, hi: f64, k: usize) -> Vec<f64> {
    let (mid, half) = (0.5 * (lo + hi), 0.5 * (hi - lo));
    (0..k)
        .map(|i| mid + half * (std::f64::consts::PI * (i as f64 + 0.5) / k as f64).cos())
        .collect()
}

/// Fractional grid position of `x` on `n` nodes spanning `[lo, hi]`, or `None` outside.
fn grid_pos(x: f64, lo: f64, hi: f64, n: usize) -> Option<(usize, f64)> {
    if !(x >= lo && x <= hi) {
        return None;
    }
    let t = (x - lo) / (hi - lo) * (n - 1) as f64;
    let i = (t.floor() as usize).min(n - 2);
    Some((i, t - i as f64))
}

/// Bilinear interpolation of `plane` (`nu × nv`, row-major) at `(u, v)` of `region`.
fn bilinear(
    plane: &[[f64; 3]],
    nu: usize,
    nv: usize,
    region: &Region,
    u: f64,
    v: f64,
) -> Option<[f64; 3]> {
    let (i, fx) = grid_pos(u, region.lo[0], region.hi[0], nu)?;
    let (j, fy) = grid_pos(v, region.lo[1], region.hi[1], nv)?;
    let at = |i: usize, j: usize| plane[j * nu + i];
    Some([0, 1, 2].map(|c| {
        let a = at(i, j)[c] * (1.0 - fx) + at(i + 1, j)[c] * fx;
        let b = at(i, j + 1)[c] * (1.0 - fx) + at(i + 1, j + 1)[c] * fx;
        a * (1.0 - fy) + b * fy
    }))
}

/// Cubic B-spline coefficients that interpolate `values` (`n` nodes along one axis, any
/// stride): `(c_{i−1} + 4c_i + c_{i+1})/6 = f_i`, with `c_0 = f_0` and `c_{n−1} = f_{n−1}`,
/// returned with one ghost on each side (`c_{−1} = 2c_0 − c_1`, `c_n = 2c_{n−1} − c_{n−2}`,
/// which makes the end nodes exact): `n + 2` values.
fn spline_axis(values: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let n = values.len();
    let mut c = values.to_vec();
    if n > 2 {
        // Thomas algorithm on the interior rows i = 1..n−2 of the (1, 4, 1)/6 system.
        let m = n - 2;
        let mut diag = vec![4.0f64; m];
        let mut rhs: Vec<[f64; 3]> = (1..n - 1).map(|i| values[i].map(|x| 6.0 * x)).collect();
        for ch in 0..3 {
            rhs[0][ch] -= values[0][ch];
            rhs[m - 1][ch] -= values[n - 1][ch];
        }
        for k in 1..m {
            let f = 1.0 / diag[k - 1];
            diag[k] -= f;
            let prev = rhs[k - 1];
            for (r, p) in rhs[k].iter_mut().zip(prev) {
                *r -= f * p;
            }
        }
        let mut x = vec![[0.0; 3]; m];
        x[m - 1] = rhs[m - 1].map(|r| r / diag[m - 1]);
        for k in (0..m - 1).rev() {
            x[k] = [0, 1, 2].map(|ch| (rhs[k][ch] - x[k + 1][ch]) / diag[k]);
        }
        c[1..n - 1].copy_from_slice(&x);
    }
    let ghost = |a: [f64; 3], b: [f64; 3]| [0, 1, 2].map(|ch| 2.0 * a[ch] - b[ch]);
    let mut out = Vec::with_capacity(n + 2);
    out.push(ghost(c[0], c[1]));
    out.extend_from_slice(&c);
    out.push(ghost(c[n - 1], c[n - 2]));
    out
}

/// The `(nu + 2) × (nv + 2)` cubic B-spline coefficients interpolating an `nu × nv` plane
/// (row-major), separably: rows, then columns.
pub fn spline_plane(plane: &[[f64; 3]], nu: usize, nv: usize) -> Vec<[f64; 3]> {
    let rows: Vec<Vec<[f64; 3]>> = plane.chunks_exact(nu).map(spline_axis).collect();
    let (su, sv) = (nu + 2, nv + 2);
    let mut out = vec![[0.0; 3]; su * sv];
    for i in 0..su {
        let column: Vec<[f64; 3]> = rows.iter().map(|r| r[i]).collect();
        for (j, c) in spline_axis(&column).into_iter().enumerate() {
            out[j * su + i] = c;
        }
    }
    out
}

/// The uniform cubic B-spline weights of the four coefficients around fraction `f`.
pub fn spline_weights(f: f64) -> [f64; 4] {
    let (f2, f3) = (f * f, f * f * f);
    [
        (1.0 - f) * (1.0 - f) * (1.0 - f) / 6.0,
        (3.0 * f3 - 6.0 * f2 + 4.0) / 6.0,
        (-3.0 * f3 + 3.0 * f2 + 3.0 * f + 1.0) / 6.0,
        f3 / 6.0,
    ]
}

/// Evaluates the spline of [`spline_plane`] coefficients at `(u, v)` of `region`.
fn spline(
    coeffs: &[[f64; 3]],
    nu: usize,
    nv: usize,
    region: &Region,
    u: f64,
    v: f64,
) -> Option<[f64; 3]> {
    let (i, fx) = grid_pos(u, region.lo[0], region.hi[0], nu)?;
    let (j, fy) = grid_pos(v, region.lo[1], region.hi[1], nv)?;
    let (wx, wy) = (spline_weights(fx), spline_weights(fy));
    let su = nu + 2;
    let mut out = [0.0; 3];
    // c_{i−1} sits at stored index i (one ghost before the first node).
    for (b, wyb) in wy.iter().enumerate() {
        for (a, wxa) in wx.iter().enumerate() {
            let c = coeffs[(j + b) * su + i + a];
            for (o, x) in out.iter_mut().zip(c) {
                *o += wxa * wyb * x;
            }
        }
    }
    Some(out)
}

/// A stored representation of `G` with its CPU model.
pub trait GTable: Send + Sync {
    /// The region the table covers.
    fn region(&self) -> &Region;
    /// `G(u, v, w)` as the representation interpolates it (in f64), before the clamp to
    /// `G ≥ 0`; `None` outside the region. Cubic splines and series in `w` may overshoot
    /// below zero between nodes.
    fn g_unclamped(&self, uvw: [f64; 3]) -> Option<[f64; 3]>;

    /// `G(u, v, w)` as the GPU variant computes it (in f64): the interpolant clamped to
    /// `G ≥ 0` per channel, as the shaders clamp it (light cannot be negative); `None`
    /// outside the region, where the GPU writes black.
    fn g(&self, uvw: [f64; 3]) -> Option<[f64; 3]> {
        self.g_unclamped(uvw).map(|g| g.map(|x| x.max(0.0)))
    }
    /// The stored planes, each `nu × nv` XYZ, in upload order.
    fn planes(&self) -> &[Vec<[f64; 3]>];
    /// Nodes along `u` and `v`.
    fn nodes_uv(&self) -> (usize, usize);
    /// Texels of each stored plane along `u` and `v` (the nodes, plus ghosts where the
    /// representation has them).
    fn plane_dims(&self) -> (usize, usize) {
        self.nodes_uv()
    }

    /// How much float32 rounding the representation amplifies (the condition number of its
    /// sum), where that is the limiting factor; `None` for stable representations.
    fn conditioning(&self) -> Option<f64> {
        None
    }

    /// Bound on float32's rounding error in `G` (absolute), where the representation
    /// amplifies it beyond the stored values' own rounding; `None` for stable ones.
    fn f32_error(&self) -> Option<f64> {
        None
    }

    /// `XYZ = C(ωi, ωr)·G(u, v, w)`; black outside the region.
    fn xyz(&self, shading: &Shading, wi: [f64; 3], wr: [f64; 3]) -> [f64; 3] {
        integrated(wi, wr, shading, |d| self.g(d).unwrap_or([0.0; 3]))
    }
}

/// `G` in slices at uniform `w` nodes, interpolated trilinearly (the `volume` variant).
#[derive(Debug, Clone, PartialEq)]
pub struct Volume {
    pub region: Region,
    pub slices: Slices,
}

impl Volume {
    /// The `w` nodes of its slices: uniform over the region's `w` range.
    pub fn nodes(spec: &TableSpec) -> Vec<f64> {
        uniform_nodes(spec.region.lo[2], spec.region.hi[2], spec.w_nodes)
    }

    /// Samples `G` at `spec.w_nodes` uniform slices over the region's `w` range.
    pub fn build(
        hf: &HeightField,
        coherence_um: f64,
        spec: &TableSpec,
        progress: &(dyn Fn() + Sync),
    ) -> Result<Self> {
        let slices = sample_g(hf, coherence_um, spec, &Self::nodes(spec), progress)?;
        Ok(Self::from_slices(spec.region, slices))
    }

    /// The volume of samples taken at [`Volume::nodes`].
    pub fn from_slices(region: Region, slices: Slices) -> Self {
        Self { region, slices }
    }
}

impl GTable for Volume {
    fn region(&self) -> &Region {
        &self.region
    }
    fn g_unclamped(&self, [u, v, w]: [f64; 3]) -> Option<[f64; 3]> {
        let s = &self.slices;
        let r = &self.region;
        let (k, fz) = grid_pos(w, r.lo[2], r.hi[2], s.data.len())?;
        let a = bilinear(&s.data[k], s.nu, s.nv, r, u, v)?;
        let b = bilinear(&s.data[k + 1], s.nu, s.nv, r, u, v)?;
        Some([0, 1, 2].map(|c| a[c] * (1.0 - fz) + b[c] * fz))
    }
    fn planes(&self) -> &[Vec<[f64; 3]>] {
        &self.slices.data
    }
    fn nodes_uv(&self) -> (usize, usize) {
        (self.slices.nu, self.slices.nv)
    }
}

/// `G = Σ_j c_j(u, v) T_j(ŵ)`, `ŵ` the region's `w` range mapped to `[−1, 1]`, coefficients
/// from `G` at the Chebyshev nodes (the `chebyshev-w` variant). Each coefficient plane is
/// interpolated in `(u, v)` by a cubic B-spline through the nodes: error `O(h⁴)`, where
/// bilinear interpolation of lobes about two texels wide errs by several per cent.
#[derive(Debug, Clone, PartialEq)]
pub struct ChebyshevW {
    pub region: Region,
    pub nu: usize,
    pub nv: usize,
    /// `coeffs[j][texel]` at the nodes.
    pub coeffs: Vec<Vec<[f64; 3]>>,
    /// `splines[j]`: the `(nu + 2) × (nv + 2)` B-spline coefficients of `coeffs[j]`.
    pub splines: Vec<Vec<[f64; 3]>>,
}

impl ChebyshevW {
    /// Samples `G` at `spec.w_nodes` Chebyshev nodes and transforms to coefficients:
    /// `c_j = (2/K) Σ_k G(w_k) T_j(ŵ_k)`, `c_0` halved.
    pub fn build(
        hf: &HeightField,
        coherence_um: f64,
        spec: &TableSpec,
        progress: &(dyn Fn() + Sync),
    ) -> Result<Self> {
        let slices = sample_g(hf, coherence_um, spec, &Self::nodes(spec), progress)?;
        Ok(Self::from_nodes(spec.region, &slices))
    }

    /// The `w` nodes it samples: the Chebyshev nodes of the region's `w` range.
    pub fn nodes(spec: &TableSpec) -> Vec<f64> {
        chebyshev_nodes(spec.region.lo[2], spec.region.hi[2], spec.w_nodes)
    }

    /// Coefficients from samples at the Chebyshev nodes (as made by [`chebyshev_nodes`]).
    pub fn from_nodes(region: Region, slices: &Slices) -> Self {
        let k = slices.data.len();
        let n = slices.nu * slices.nv;
        let coeffs = (0..k)
            .into_par_iter()
            .map(|j| {
                let scale = if j == 0 { 1.0 } else { 2.0 } / k as f64;
                let t: Vec<f64> = (0..k)
                    .map(|i| (j as f64 * std::f64::consts::PI * (i as f64 + 0.5) / k as f64).cos())
                    .collect();
                (0..n)
                    .map(|p| {
                        let mut c = [0.0; 3];
                        for (sample, ti) in slices.data.iter().map(|s| s[p]).zip(&t) {
                            for (cc, x) in c.iter_mut().zip(sample) {
                                *cc += x * ti;
                            }
                        }
                        c.map(|x| x * scale)
                    })
                    .collect()
            })
            .collect::<Vec<Vec<[f64; 3]>>>();
        let splines = coeffs
            .par_iter()
            .map(|c| spline_plane(c, slices.nu, slices.nv))
            .collect();
        Self {
            region,
            nu: slices.nu,
            nv: slices.nv,
            coeffs,
            splines,
        }
    }

    /// `ŵ ∈ [−1, 1]` of `w`.
    pub fn w_hat(&self, w: f64) -> f64 {
        let (lo, hi) = (self.region.lo[2], self.region.hi[2]);
        (2.0 * w - lo - hi) / (hi - lo)
    }

    /// The largest `|c_j|` (over texels and channels) relative to the largest `|c_0|`, per
    /// `j`: how fast the series decays.
    pub fn decay(&self) -> Vec<f64> {
        let max_of = |c: &Vec<[f64; 3]>| c.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        let c0 = max_of(&self.coeffs[0]).max(f64::MIN_POSITIVE);
        self.coeffs.iter().map(|c| max_of(c) / c0).collect()
    }
}

/// Clenshaw's recurrence for `Σ_j c_j T_j(x)`.
pub fn clenshaw(c: &[[f64; 3]], x: f64) -> [f64; 3] {
    let (mut b1, mut b2) = ([0.0; 3], [0.0; 3]);
    for cj in c.iter().skip(1).rev() {
        let b0 = [0, 1, 2].map(|ch| cj[ch] + 2.0 * x * b1[ch] - b2[ch]);
        b2 = b1;
        b1 = b0;
    }
    [0, 1, 2].map(|ch| c[0][ch] + x * b1[ch] - b2[ch])
}

impl GTable for ChebyshevW {
    fn region(&self) -> &Region {
        &self.region
    }
    fn g_unclamped(&self, [u, v, w]: [f64; 3]) -> Option<[f64; 3]> {
        if !(w >= self.region.lo[2] && w <= self.region.hi[2]) {
            return None;
        }
        let c: Option<Vec<[f64; 3]>> = self
            .splines
            .iter()
            .map(|p| spline(p, self.nu, self.nv, &self.region, u, v))
            .collect();
        Some(clenshaw(&c?, self.w_hat(w)))
    }
    fn planes(&self) -> &[Vec<[f64; 3]>] {
        &self.splines
    }
    fn nodes_uv(&self) -> (usize, usize) {
        (self.nu, self.nv)
    }
    fn plane_dims(&self) -> (usize, usize) {
        (self.nu + 2, self.nv + 2)
    }
}

/// Float32's unit roundoff (`2⁻²⁴`): the relative error of one stored value or operation.
pub const F32_ROUNDOFF: f64 = 5.960_464_477_539_063e-8;

/// `G = Σ_p a_p(u, v)·ŵ^p`: Dhillon et al. 2014's representation, tables of the powers of
/// the view variable `w`, Horner at lookup. Two differences from the paper, both stated in
/// the variant's summary:
///
/// - the powers are of `ŵ = (w − w_c)/w_h`, the reachable interval `[w_c − w_h, w_c + w_h]`
///   mapped onto `[−1, 1]`: on a narrow interval (a distant camera, a plane) raw powers of
///   `w` are hopelessly conditioned, powers of `ŵ` are not;
/// - the planes are fitted from the exact f64 table (the Chebyshev interpolant of
///   [`ChebyshevW`] rewritten in powers of `ŵ`), not built from products of Taylor terms.
///
/// Coefficients whose whole tail changes `G` by less than a tenth of the tolerance are
/// dropped before the conversion (they carry only f64 noise, which the conversion would
/// amplify like `(1 + √2)^K`). [`Dhillon::expected_error`] bounds the float32 error of the
/// sum; [`Dhillon::check`] refuses a table whose bound exceeds the tolerance.
#[derive(Debug, Clone, PartialEq)]
pub struct Dhillon {
    pub region: Region,
    pub nu: usize,
    pub nv: usize,
    /// `powers[p][texel]` = `a_p`.
    pub powers: Vec<Vec<[f64; 3]>>,
    /// Chebyshev coefficients sampled (`K`, the `w` nodes).
    pub sampled: usize,
    /// What the truncation in `w` may cost, absolute in `G`: the dropped tail
    /// `Σ_{j≥P} max|c_j|`, or, when nothing could be dropped, the last coefficient's size
    /// (the series has not converged and that is the order of its remainder).
    pub truncation: f64,
}

impl Dhillon {
    /// Converts `cheb` to powers of `ŵ`, dropping the tail of coefficients whose sum of
    /// maxima stays under `drop_below` (absolute, in units of `G`).
    pub fn from_chebyshev(cheb: &ChebyshevW, drop_below: f64) -> Self {
        let k = cheb.coeffs.len();
        let max_of = |c: &Vec<[f64; 3]>| c.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        let sizes: Vec<f64> = cheb.coeffs.iter().map(max_of).collect();
        let (mut kept, mut tail) = (k, 0.0);
        while kept > 1 && tail + sizes[kept - 1] <= drop_below {
            tail += sizes[kept - 1];
            kept -= 1;
        }
        let truncation = if kept == k { sizes[k - 1] } else { tail };
        // m[j][p]: coefficient of ŵ^p in T_j(ŵ), by T_{j+1} = 2ŵ T_j − T_{j−1}.
        let mut m = vec![vec![0.0f64; kept]; kept];
        m[0][0] = 1.0;
        if kept > 1 {
            m[1][1] = 1.0;
        }
        for j in 1..kept.saturating_sub(1) {
            for p in 0..kept {
                let mut x = -m[j - 1][p];
                if p > 0 {
                    x += 2.0 * m[j][p - 1];
                }
                m[j + 1][p] = x;
            }
        }
        let n = cheb.nu * cheb.nv;
        let powers = (0..kept)
            .map(|p| {
                (0..n)
                    .map(|t| {
                        let mut a = [0.0; 3];
                        for (j, cj) in cheb.coeffs.iter().take(kept).enumerate() {
                            for ch in 0..3 {
                                a[ch] += cj[t][ch] * m[j][p];
                            }
                        }
                        a
                    })
                    .collect()
            })
            .collect();
        Self {
            region: cheb.region,
            nu: cheb.nu,
            nv: cheb.nv,
            powers,
            sampled: k,
            truncation,
        }
    }

    /// `ŵ ∈ [−1, 1]` of `w` (the GPU computes it as `2f − 1` from the table's fraction).
    pub fn w_hat(&self, w: f64) -> f64 {
        let (lo, hi) = (self.region.lo[2], self.region.hi[2]);
        (2.0 * w - lo - hi) / (hi - lo)
    }

    /// The largest `Σ_p |a_p|` over texels and channels: the largest magnitude Horner's
    /// partial sums can reach (at `|ŵ| = 1`), which float32 rounds.
    pub fn magnitude(&self) -> f64 {
        let n = self.nu * self.nv;
        (0..n)
            .flat_map(|t| (0..3).map(move |c| (t, c)))
            .map(|(t, c)| self.powers.iter().map(|p| p[t][c].abs()).sum::<f64>())
            .fold(0.0, f64::max)
    }

    /// The largest `G` the table holds (over its nodes, both ends of `w`, every channel).
    pub fn peak(&self) -> f64 {
        let n = self.nu * self.nv;
        let mut peak = 0.0f64;
        for x in [-1.0, 1.0f64] {
            for t in 0..n {
                for c in 0..3 {
                    let g = self
                        .powers
                        .iter()
                        .rev()
                        .fold(0.0, |acc, p| acc * x + p[t][c]);
                    peak = peak.max(g.abs());
                }
            }
        }
        peak
    }

    /// Condition number of the sum relative to the table's peak: `max Σ_p |a_p| / max G`.
    /// 1 for a constant; `(1 + √2)^P`-like for a series that needs all its terms.
    pub fn conditioning(&self) -> f64 {
        let peak = self.peak();
        if peak > 0.0 {
            (self.magnitude() / peak).max(1.0)
        } else {
            1.0
        }
    }

    /// Bound on float32's error in `G` (absolute, units of `G`): each of the `P` planes is
    /// stored and filtered in float32 (about two roundings of `|a_p|`), and Horner's `P`
    /// multiply-adds round partial sums no larger than `Σ|a_p|`: `(2P + 3)·u·Σ|a_p|`.
    pub fn rounding(&self) -> f64 {
        (2 * self.powers.len() + 3) as f64 * F32_ROUNDOFF * self.magnitude()
    }

    /// Float32 rounding plus the truncation in `w` (absolute, units of `G`).
    pub fn expected_error(&self) -> f64 {
        self.rounding() + self.truncation
    }

    /// Refuses the table when its expected error exceeds `tolerance` (absolute in `G`,
    /// which is `|P̂|²` weighted: a mirror's specular value is 1), with the reason.
    pub fn check(&self, tolerance: f64) -> Result<()> {
        let e = self.expected_error();
        if e <= tolerance {
            return Ok(());
        }
        let (lo, hi) = (self.region.lo[2], self.region.hi[2]);
        let reason = if self.rounding() >= self.truncation {
            format!(
                "its {} powers of ŵ over w ∈ [{lo:.4}, {hi:.4}] sum to {:.1e} where G peaks at {:.1e} (condition number {:.1e}), which float32 cannot hold",
                self.powers.len(),
                self.magnitude(),
                self.peak(),
                self.conditioning()
            )
        } else {
            format!(
                "its series in w over [{lo:.4}, {hi:.4}] has not converged with {} nodes (last coefficient {:.1e}): raise --table-w-nodes",
                self.sampled, self.truncation
            )
        };
        Err(Error::invalid(
            "variant",
            format!(
                "dhillon refused: {reason}; expected error {e:.1e} exceeds the tolerance {tolerance:.1e}; chebyshev-w draws this table stably"
            ),
        ))
    }
}

impl GTable for Dhillon {
    fn region(&self) -> &Region {
        &self.region
    }
    fn conditioning(&self) -> Option<f64> {
        Some(Dhillon::conditioning(self))
    }
    fn f32_error(&self) -> Option<f64> {
        Some(self.rounding())
    }
    fn g_unclamped(&self, [u, v, w]: [f64; 3]) -> Option<[f64; 3]> {
        if !(w >= self.region.lo[2] && w <= self.region.hi[2]) {
            return None;
        }
        let x = self.w_hat(w);
        let mut acc = [0.0; 3];
        for p in self.powers.iter().rev() {
            let a = bilinear(p, self.nu, self.nv, &self.region, u, v)?;
            acc = [0, 1, 2].map(|c| acc[c] * x + a[c]);
        }
        Some(acc)
    }
    fn planes(&self) -> &[Vec<[f64; 3]>] {
        &self.powers
    }
    fn nodes_uv(&self) -> (usize, usize) {
        (self.nu, self.nv)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn clenshaw_matches_the_cosine_form() {
        let c: Vec<[f64; 3]> = (0..7)
            .map(|j| [1.0 / (j + 1) as f64, j as f64, 0.5])
            .collect();
        for x in [-1.0, -0.3, 0.0, 0.7, 1.0f64] {
            let th = x.acos();
            let want: f64 = c
                .iter()
                .enumerate()
                .map(|(j, cj)| cj[0] * (j as f64 * th).cos())
                .sum();
            assert!((clenshaw(&c, x)[0] - want).abs() < 1e-12);
        }
    }

    #[test]
    fn chebyshev_and_powers_reproduce_a_polynomial_in_w() {
        // G = 1 + 2w − w³ on one texel pair: K = 5 nodes reproduce it exactly.
        let region = Region {
            lo: [0.0, 0.0, -1.7],
            hi: [1.0, 1.0, -0.4],
        };
        let nodes = chebyshev_nodes(-1.7, -0.4, 5);
        let f = |w: f64| 1.0 + 2.0 * w - w * w * w;
        let slices = Slices {
            nu: 2,
            nv: 2,
            w: nodes.clone(),
            data: nodes
                .iter()
                .map(|&w| vec![[f(w), 2.0 * f(w), 0.0]; 4])
                .collect(),
        };
        let cheb = ChebyshevW::from_nodes(region, &slices);
        let dh = Dhillon::from_chebyshev(&cheb, 0.0);
        for w in [-1.7, -1.2, -0.9, -0.4] {
            // Unclamped: this polynomial dips below zero (G itself cannot).
            let a = cheb.g_unclamped([0.3, 0.6, w]).unwrap();
            let b = dh.g_unclamped([0.3, 0.6, w]).unwrap();
            assert!((a[0] - f(w)).abs() < 1e-12 && (a[1] - 2.0 * f(w)).abs() < 1e-12);
            assert!((b[0] - f(w)).abs() < 1e-10, "{} vs {}", b[0], f(w));
        }
        assert!(cheb.g([0.3, 0.6, -0.3]).is_none());
        assert_eq!(
            cheb.g([0.3, 0.6, -0.9]).unwrap()[0],
            0.0,
            "clamped to G ≥ 0"
        );
        // w = −1.05 + 0.65ŵ: the ŵ³ coefficient of −w³ is −0.65³.
        assert!((dh.powers[3][0][0] + 0.65f64.powi(3)).abs() < 1e-12);
        // Exact in three powers: the coefficient of T_4 is f64 noise and is dropped.
        let dropped = Dhillon::from_chebyshev(&cheb, 1e-9);
        assert_eq!(dropped.powers.len(), 4);
        assert!(dropped.truncation < 1e-12 && dropped.check(1e-3).is_ok());
    }

    #[test]
    fn dhillon_on_a_narrow_w_interval_is_well_conditioned_or_refused() {
        // A smooth G on a narrow interval (a distant camera): nearly constant in w.
        let region = Region {
            lo: [0.0, 0.0, -1.99],
            hi: [1.0, 1.0, -1.97],
        };
        let f = |w: f64| 0.77 + 0.3 * (40.0 * w).sin();
        for k in [12, 24, 64] {
            let nodes = chebyshev_nodes(-1.99, -1.97, k);
            let slices = Slices {
                nu: 2,
                nv: 2,
                w: nodes.clone(),
                data: nodes.iter().map(|&w| vec![[f(w); 3]; 4]).collect(),
            };
            let cheb = ChebyshevW::from_nodes(region, &slices);
            let dh = Dhillon::from_chebyshev(&cheb, 1e-4);
            assert!(dh.check(1e-3).is_ok(), "K = {k}: {:?}", dh.check(1e-3));
            assert!(dh.conditioning() < 10.0, "K = {k}: {}", dh.conditioning());
            // Float32 evaluation of the stored planes, as the shader does it.
            for w in [-1.99, -1.985, -1.9731, -1.97] {
                let x = dh.w_hat(w) as f32;
                let g = dh
                    .powers
                    .iter()
                    .rev()
                    .fold(0.0f32, |acc, p| acc * x + p[0][1] as f32);
                assert!(((g as f64) - f(w)).abs() < 1e-4, "K = {k}, w = {w}: {g}");
            }
        }
        // A series that needs all its terms over a wide interval: refused, saying why.
        let wide = Region {
            lo: [0.0, 0.0, -2.0],
            hi: [1.0, 1.0, 0.0],
        };
        let g = |w: f64| 1.0 + (60.0 * w).cos();
        let nodes = chebyshev_nodes(-2.0, 0.0, 64);
        let slices = Slices {
            nu: 2,
            nv: 2,
            w: nodes.clone(),
            data: nodes.iter().map(|&w| vec![[g(w); 3]; 4]).collect(),
        };
        let dh = Dhillon::from_chebyshev(&ChebyshevW::from_nodes(wide, &slices), 1e-4);
        let err = dh.check(1e-3).unwrap_err().to_string();
        assert!(
            err.contains("expected error") && !err.contains('\n'),
            "{err}"
        );
        println!("{err}");
    }

    #[test]
    fn splines_interpolate_nodes_exactly_and_cubics_everywhere() {
        let region = Region {
            lo: [-1.0, 0.0, -1.0],
            hi: [1.0, 3.0, 0.0],
        };
        let (nu, nv) = (9, 7);
        let f = |u: f64, v: f64| 1.0 + u - 0.5 * u * u * v + 0.25 * v * v * v;
        let node =
            |i: usize, n: usize, lo: f64, hi: f64| lo + (hi - lo) * i as f64 / (n - 1) as f64;
        let plane: Vec<[f64; 3]> = (0..nv)
            .flat_map(|j| (0..nu).map(move |i| (i, j)))
            .map(|(i, j)| {
                let x = f(node(i, nu, -1.0, 1.0), node(j, nv, 0.0, 3.0));
                [x, -x, 0.0]
            })
            .collect();
        let c = spline_plane(&plane, nu, nv);
        assert_eq!(c.len(), (nu + 2) * (nv + 2));
        for j in 0..nv {
            for i in 0..nu {
                let (u, v) = (node(i, nu, -1.0, 1.0), node(j, nv, 0.0, 3.0));
                let g = spline(&c, nu, nv, &region, u, v).unwrap();
                assert!((g[0] - plane[j * nu + i][0]).abs() < 1e-12, "node {i},{j}");
            }
        }
        // Between nodes: a smooth function is matched far better than linearly.
        let (u, v) = (0.37, 1.61);
        let g = spline(&c, nu, nv, &region, u, v).unwrap()[0];
        let lin = bilinear(&plane, nu, nv, &region, u, v).unwrap()[0];
        assert!(
            (g - f(u, v)).abs() < 0.2 * (lin - f(u, v)).abs(),
            "{g} {lin} {}",
            f(u, v)
        );
        assert!(spline(&c, nu, nv, &region, 1.1, 1.0).is_none());
    }

    #[test]
    fn the_disc_footprint_is_the_projected_ellipse() {
        let a = 0.0046;
        // At normal incidence a circle; at θi = 60° the axis along the plane of incidence
        // (azimuth 30° here) shrinks to α·cosθi, the other stays α.
        let c0 = DiscKernel::footprint([0.0, 0.0, 1.0], a).covariance();
        assert!((c0[0][0] - a * a / 4.0).abs() < 1e-15 && c0[0][1].abs() < 1e-15);
        let wi = super::super::direction(60.0, 30.0);
        let k = DiscKernel::footprint(wi, a);
        let c = k.covariance();
        let along = [30f64.to_radians().cos(), 30f64.to_radians().sin()];
        let across = [-along[1], along[0]];
        let q = |d: [f64; 2]| {
            d[0] * (c[0][0] * d[0] + c[0][1] * d[1]) + d[1] * (c[1][0] * d[0] + c[1][1] * d[1])
        };
        assert!((q(along) / (a * a / 4.0 * 0.25) - 1.0).abs() < 1e-9);
        assert!((q(across) / (a * a / 4.0) - 1.0).abs() < 1e-9);
        assert!((k.reach() - a).abs() < 1e-12);
        // The ellipse of a covariance has that covariance; the mean of one is itself.
        let back = DiscKernel::with_covariance(c).covariance();
        let m = DiscKernel::mean(&[k, k]).unwrap().covariance();
        for i in 0..2 {
            for j in 0..2 {
                assert!((back[i][j] - c[i][j]).abs() < 1e-15);
                assert!((m[i][j] - c[i][j]).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn blurring_a_delta_gives_the_disc_with_unit_mass() {
        // One node set to 1 on a 41² grid of spacing h: the spline interpolant of a delta
        // (mass h², no second moment), pre-filtered by an ellipse 4 × 2.5 texels across,
        // rotated. Node sums of the result: mass h², and the ellipse's covariance.
        let h = 0.001;
        let n = 41;
        let region = Region {
            lo: [0.0, 0.0, -1.0],
            hi: [h * (n - 1) as f64, h * (n - 1) as f64, -0.5],
        };
        let mut plane = vec![[0.0; 3]; n * n];
        plane[20 * n + 20] = [1.0, 2.0, 0.0];
        let mut slices = Slices {
            nu: n,
            nv: n,
            w: vec![-0.7],
            data: vec![plane],
        };
        let kernel = DiscKernel::footprint(super::super::direction(51.3, 120.0), 4.0 * h);
        let taps = kernel.taps(h, h);
        let total: f64 = taps.iter().map(|t| t.2).sum();
        assert!((total - 1.0).abs() < 1e-12, "{total}");
        prefilter_disc(&mut slices, &region, &kernel);
        let p = &slices.data[0];
        let (mut mass, mut m) = (0.0, [[0.0; 2]; 2]);
        for j in 0..n {
            for i in 0..n {
                let x = [(i as f64 - 20.0) * h, (j as f64 - 20.0) * h];
                let g = p[j * n + i][0];
                mass += g;
                for a in 0..2 {
                    for b in 0..2 {
                        m[a][b] += g * x[a] * x[b];
                    }
                }
                assert!((p[j * n + i][1] - 2.0 * g).abs() < 1e-15);
            }
        }
        assert!((mass - 1.0).abs() < 1e-9, "mass {mass}");
        let c = kernel.covariance();
        for a in 0..2 {
            for b in 0..2 {
                assert!(
                    (m[a][b] - c[a][b]).abs() < 0.01 * c[0][0].max(c[1][1]),
                    "moment {a}{b}: {} vs {}",
                    m[a][b],
                    c[a][b]
                );
            }
        }
        // Nothing beyond the ellipse and the spline's reach.
        for j in 0..n {
            for i in 0..n {
                let r = ((i as f64 - 20.0).hypot(j as f64 - 20.0)) * h;
                if r > kernel.reach() + 6.0 * h {
                    assert!(p[j * n + i][0].abs() < 1e-3, "{i},{j}: {}", p[j * n + i][0]);
                }
            }
        }
    }

    #[test]
    fn brdf_map_region_covers_every_pixel_direction() {
        let wi = super::super::direction(60.0, 20.0);
        let r = Region::brdf_map(wi);
        for k in 0..200 {
            let a = k as f64 * 0.1;
            let rad = (k % 10) as f64 / 10.0;
            let wr = [rad * a.cos(), rad * a.sin(), (1.0 - rad * rad).sqrt()];
            assert!(r.contains(super::super::uvw(wi, wr)));
        }
    }
}
