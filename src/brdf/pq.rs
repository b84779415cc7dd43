//! The PQ variant's physics (thesis §1.5.3, Algorithm 5; MODEL §7 "PQ done right"), in f64.
//! No Vulkan here; glsl/pq.glsl follows [`p_hat`] tap for tap.
//!
//! **What PQ computes.** A surface made of `N` copies of one period `L` along an axis has
//! the transform `P(α) = P₁(α)·Σ_{n=0}^{N−1} e^{i n α L}`: the (smooth) spectrum of one period
//! times a sharp periodic factor. `P₁` is known only at the period's DFT bins `s = m`
//! (`s = u·L/λ`); between them it is interpolated from 3 taps per axis (9 in 2D) with the
//! periodic sinc (Dirichlet kernel `e^{iπx(n₁−1)/n₁}·sin(πx)/(n₁ sin(πx/n₁))`, `n₁` samples
//! per period: the exact interpolator of a sampled period's transform, and the thesis's
//! sinc for large `n₁` — with the phase the thesis dropped). The period's bins are read from
//! the patch's DFT terms (FLSS's stack): a patch of `M` copies has its spectrum on every
//! `M`-th bin, and bin `M·m` holds the period's bin `m`.
//!
//! **Done right** (MODEL §7): the periodic factor is `Σ_{n=0}^{N−1} e^{−i n ω L}` per axis
//! (here with Stam's `+i` sign, which only conjugates it); in 2D the two factors multiply as
//! complex numbers `p + iq`, and the intensity scales with `|p + iq|²`. The thesis code
//! scaled it with `√(p² + q²)`, whose lobe area grows like `ln N / N` instead of `1/N`:
//! [`Form::Thesis`] keeps that form for the test that shows it fails.
//!
//! **How many copies.** The Gaussian coherence window `exp(−x²/2σs²)` (σs = coherence/4)
//! and a box of `N` copies give the same peak (both normalised to 1 at an order) but lobes
//! of different shape. Their areas (the integral of `|P̂|²` over frequency, which is what a
//! spectral integral sees) are `1/(2√π σs)` for the Gaussian (Parseval: `∫g²/(∫g)²`) and
//! `1/(N L)` for the box. Equal areas need `N·L = 2√π·σs = (√π/2)·coherence ≈ 57.6 µm`;
//! `N` is rounded to the nearest whole number, which leaves an area (and colour) ratio
//! `2√πσs/(N L)` of at most `1 + L/(2·57.6 µm)` ([`Axis::area_ratio`]). Off the orders'
//! centre lines the shapes differ (the box has sinc² side lobes, the Gaussian none).
//! An axis along which the field is constant has no period to repeat: there the lobe is
//! the coherence window's own Gaussian (as FLSS). A box of copies along it would spread
//! every line's sinc² side lobes, `~1/(π·57.6 µm·v/λ)²` of its peak, over the whole
//! hemisphere: on a BRDF map of the blazed grating they made PQ's rel L2 against the
//! reference 29.5 (measured before this rule).
//!
//! **What PQ refuses.** A field that is not a whole number of copies of a shorter period
//! along an axis that has structure: more than [`MAX_OFF_LATTICE`] of the non-DC power off
//! every lattice of every `M`-th bin (`M ≥ 2`), e.g. measured skin (`builtin:elaphe-measured`,
//! `builtin:elaphe-grown`), the irregular Elaphe-like fingers or two domains of different
//! period (Xenopeltis-like). Of the lattices within the bound it takes the coarsest bins
//! (largest `M`, the shortest period), and ignores the power off it (stated on stderr when
//! above [`WARN_OFF_LATTICE`]). An axis along which the field
//! is constant is a period of one sample (one tap, exact).

use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;

use super::{bessel, integrated, spectral, Shading};
use crate::colour::ColourTable;
use crate::heightfield::HeightField;
use crate::spectrum::{Expansion, TermStack};
use crate::{Error, Result};

/// Largest share of the non-DC power (per axis) that may lie off the period's lattice. PQ
/// reads only the lattice, so this bounds the power it ignores. A sampled profile with
/// edges whose period is not a whole number of samples is periodic only up to its aliased
/// harmonics: the shipped blazed grating (2.5 µm = 27.08 samples) has 4.5% of its power
/// off the 2.5 µm lattice (its exact period on the sample grid is 13 ridges, 32.5 µm, too
/// long for the coherence window). Measured and irregular skin misses by 16% or more.
pub const MAX_OFF_LATTICE: f64 = 0.05;

/// Off-lattice share above which PQ says what it ignores (`warning:` on stderr); below it
/// sits float rounding and 8-bit quantisation noise (~1e-5).
pub const WARN_OFF_LATTICE: f64 = 1e-3;

/// Taps per axis of the interpolation of the period's spectrum (thesis: 3, so 3×3 = 9).
pub const TAPS: usize = 3;

/// One axis of the periodic structure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axis {
    /// Copies of the period in the patch (`M`; the patch's spectrum lies on every `M`-th bin).
    pub copies_in_patch: usize,
    /// Samples per period `n₁ = N_patch/M` (1: the field is constant along this axis).
    pub samples_per_period: f64,
    /// The period `L = n₁·dH` (µm).
    pub period_um: f64,
    /// Copies the periodic factor sums, `N = round(2√π σs / L)` (at least 1); 0 on a
    /// constant axis, which has no period to repeat: there the coherence window itself
    /// (the Gaussian, as FLSS) gives the lobe, `exp(−(2πσs·t/λ)²)` in intensity.
    pub copies: usize,
    /// Interpolation taps: [`TAPS`], or 1 for a constant axis.
    pub taps: usize,
    /// `σs` of the coherence window (µm), for [`Axis::area_ratio`].
    pub sigma_s_um: f64,
}

impl Axis {
    fn new(n: usize, m: usize, dh_um: f64, coherence_um: f64) -> Self {
        let n1 = n as f64 / m as f64;
        let period = n1 * dh_um;
        let sigma_s = coherence_um / 4.0;
        let copies = if m == n {
            0
        } else {
            ((2.0 * std::f64::consts::PI.sqrt() * sigma_s / period).round() as usize).max(1)
        };
        Self {
            copies_in_patch: m,
            samples_per_period: n1,
            period_um: period,
            copies,
            taps: if m == n { 1 } else { TAPS },
            sigma_s_um: sigma_s,
        }
    }

    /// The lobe area of the Gaussian window over that of `N` copies, `2√π σs/(N L)`: the
    /// ratio of PQ's colour on an order to FLSS's that comes from rounding `N`.
    pub fn area_ratio(&self) -> f64 {
        if self.copies == 0 {
            return 1.0;
        }
        2.0 * std::f64::consts::PI.sqrt() * self.sigma_s_um / (self.copies as f64 * self.period_um)
    }
}

/// The periodic structure PQ found in a height field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Periodicity {
    pub axes: [Axis; 2],
    /// Share of the non-DC power off the lattice (the larger of the two axes).
    pub off_lattice: f64,
}

impl Periodicity {
    /// Largest deviation of the lobe area from the Gaussian window's over both axes.
    pub fn area_error(&self) -> f64 {
        self.axes
            .iter()
            .map(|a| (a.area_ratio() - 1.0).abs())
            .fold(0.0, f64::max)
    }
}

/// Power of the mean-centred field at each frequency along one axis, summed over the other
/// (Parseval along the other axis): `out[k]`, `k` the DFT index `0..n`.
fn marginal_power(hf: &HeightField, along_x: bool) -> Vec<f64> {
    let (nx, ny) = (hf.nx(), hf.ny());
    let (n, lines) = if along_x { (nx, ny) } else { (ny, nx) };
    let mean = hf.mean();
    let h = hf.heights_um();
    let fft = FftPlanner::new().plan_fft_forward(n);
    let mut out = vec![0.0; n];
    let mut buf = vec![Complex64::new(0.0, 0.0); n];
    for l in 0..lines {
        for (i, z) in buf.iter_mut().enumerate() {
            let idx = if along_x { l * nx + i } else { i * nx + l };
            *z = Complex64::new(h[idx] - mean, 0.0);
        }
        fft.process(&mut buf);
        for (o, z) in out.iter_mut().zip(&buf) {
            *o += z.norm_sqr();
        }
    }
    out
}

/// Share of the non-DC power of `power` (one axis, [`marginal_power`]) off the lattice of
/// every `m`-th frequency.
fn off_lattice(power: &[f64], m: usize) -> f64 {
    let n = power.len();
    let non_dc: f64 = power[1..].iter().sum();
    if non_dc <= 0.0 {
        return 0.0;
    }
    let on: f64 = (1..n)
        .filter(|&k| {
            let signed = if k > n / 2 { n - k } else { k };
            signed % m == 0
        })
        .map(|k| power[k])
        .sum();
    (non_dc - on).max(0.0) / non_dc
}

/// The share of the non-DC power off the lattice of every `m`-th frequency along x (or y),
/// for `m` = each of `ms` (diagnostics and tests).
pub fn lattice_misses(hf: &HeightField, along_x: bool, ms: &[usize]) -> Vec<f64> {
    let p = marginal_power(hf, along_x);
    ms.iter().map(|&m| off_lattice(&p, m.max(1))).collect()
}

/// Finds, per axis, the largest `M` whose lattice of every `M`-th frequency holds all but
/// [`MAX_OFF_LATTICE`] of the non-DC power (the field is then `M` copies of one period),
/// and the copies `N` of the coherence window; refuses a field without such a period.
pub fn estimate_periodicity(hf: &HeightField, coherence_um: f64) -> Result<Periodicity> {
    let mut axes = [None, None];
    let mut worst_off: f64 = 0.0;
    let total: f64 = {
        let p = marginal_power(hf, true);
        p.iter().sum()
    };
    if total.is_nan() || total <= 0.0 {
        return Err(Error::invalid(
            "pq",
            "the height field is flat: no period to find",
        ));
    }
    for (a, along_x) in [(0, true), (1, false)] {
        let n = if along_x { hf.nx() } else { hf.ny() };
        let p = marginal_power(hf, along_x);
        let non_dc: f64 = p[1..].iter().sum();
        let name = if along_x { "x" } else { "y" };
        if non_dc <= 1e-12 * total {
            // Constant along this axis: a period of one sample.
            axes[a] = Some(Axis::new(n, n, hf.dh_um(), coherence_um));
            continue;
        }
        let off = |m: usize| off_lattice(&p, m);
        let best = (2..=n / 2).rev().find(|&m| off(m) <= MAX_OFF_LATTICE);
        let Some(m) = best else {
            let best_m = (2..=(n / 2).max(2))
                .min_by(|&a, &b| off(a).total_cmp(&off(b)))
                .unwrap_or(2);
            return Err(Error::invalid(
                "pq",
                format!(
                    "the height field is not periodic along {name}: every lattice of every M-th frequency (M ≥ 2) misses more than {:.1}% of the non-DC power (the best, M = {}, misses {:.1}%); PQ needs whole copies of one period, use another variant",
                    100.0 * MAX_OFF_LATTICE,
                    best_m,
                    100.0 * off(best_m)
                ),
            ));
        };
        if (n as f64 / m as f64) < TAPS as f64 {
            return Err(Error::invalid(
                "pq",
                format!(
                    "the period along {name} is {:.2} samples; PQ interpolates the period's spectrum from {TAPS} bins and needs at least {TAPS} samples a period",
                    n as f64 / m as f64
                ),
            ));
        }
        worst_off = worst_off.max(off(m));
        axes[a] = Some(Axis::new(n, m, hf.dh_um(), coherence_um));
    }
    let [Some(x), Some(y)] = axes else {
        unreachable!("both axes are set or returned above")
    };
    if x.taps == 1 && y.taps == 1 {
        return Err(Error::invalid(
            "pq",
            "the height field is flat: no period to find",
        ));
    }
    Ok(Periodicity {
        axes: [x, y],
        off_lattice: worst_off,
    })
}

/// The periodic sinc (Dirichlet kernel) `e^{iπx(n₁−1)/n₁}·sin(πx)/(n₁ sin(πx/n₁))`: the
/// transform of one sampled period at `x` bins from a DFT bin.
pub fn dirichlet(x: f64, n1: f64) -> Complex64 {
    let pi = std::f64::consts::PI;
    let den = n1 * (pi * x / n1).sin();
    let mag = if den.abs() < 1e-12 {
        1.0
    } else {
        (pi * x).sin() / den
    };
    Complex64::from_polar(1.0, pi * x * (n1 - 1.0) / n1) * mag
}

/// The normalised periodic factor `(1/N) Σ_{n=0}^{N−1} e^{i n 2π s}` in closed form,
/// `e^{iπ(N−1)s}·sin(Nπs)/(N sin πs)`, reduced to `t = s − round(s)` first.
pub fn periodic_factor(copies: usize, s: f64) -> Complex64 {
    let pi = std::f64::consts::PI;
    let n = copies as f64;
    let t = s - s.round();
    let den = n * (pi * t).sin();
    // sin(Nπs)/sin(πs) = (−1)^{(N−1)·round(s)} sin(Nπt)/sin(πt).
    let sign = if (copies - 1) % 2 == 1 && (s.round() as i64).rem_euclid(2) == 1 {
        -1.0
    } else {
        1.0
    };
    let mag = if den.abs() < 1e-12 {
        1.0
    } else {
        (n * pi * t).sin() / den
    };
    Complex64::from_polar(1.0, pi * (n - 1.0) * s) * (sign * mag)
}

/// The same factor summed term by term (tests).
pub fn periodic_factor_sum(copies: usize, s: f64) -> Complex64 {
    let tau = 2.0 * std::f64::consts::PI;
    (0..copies)
        .map(|j| Complex64::from_polar(1.0, tau * j as f64 * s))
        .sum::<Complex64>()
        / copies as f64
}

/// How the periodic factor `p + iq = F_x·F_y` scales the intensity.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Form {
    /// `|p + iq|²` (MODEL §7).
    Intensity,
    /// The thesis's `√(p² + q²)` (wrong; kept for the test that shows it).
    Thesis,
}

/// The factor of one axis at `t` (u or v): the periodic factor of `N` copies, or on a
/// constant axis the Gaussian window's amplitude `exp(−(2πσs·t/λ)²/2)`.
fn axis_factor(axis: &Axis, t: f64, lambda_um: f64) -> Complex64 {
    if axis.copies == 0 {
        let a = 2.0 * std::f64::consts::PI * axis.sigma_s_um * t / lambda_um;
        return Complex64::new((-0.5 * a * a).exp(), 0.0);
    }
    periodic_factor(axis.copies, bins(axis, t, lambda_um))
}

/// Lookup position `s = t·L/λ` in bins of the period's spectrum along `axis`.
fn bins(axis: &Axis, t: f64, lambda_um: f64) -> f64 {
    t * axis.period_um / lambda_um
}

/// The taps along one axis: full-spectrum texel offsets from the centre `b` and weights.
fn taps(axis: &Axis, s: f64) -> Vec<(i64, Complex64)> {
    if axis.taps == 1 {
        return vec![(0, Complex64::new(1.0, 0.0))];
    }
    let m0 = s.round() as i64;
    (m0 - 1..=m0 + 1)
        .map(|m| {
            (
                m * axis.copies_in_patch as i64,
                dirichlet(s - m as f64, axis.samples_per_period),
            )
        })
        .collect()
}

/// `P̂₁`, the normalised transform of one period at `(ku, kv)` (1 for a flat surface at
/// `u = v = 0`), from terms `0..=terms` and 3×3 interpolation taps.
pub fn p_hat_period(
    stack: &TermStack,
    terms: usize,
    pq: &Periodicity,
    uvw: [f64; 3],
    lambda_um: f64,
) -> Complex64 {
    let t = terms.min(stack.term_count().saturating_sub(1));
    let [u, v, w] = uvw;
    let tx = taps(&pq.axes[0], bins(&pq.axes[0], u, lambda_um));
    let ty = taps(&pq.axes[1], bins(&pq.axes[1], v, lambda_um));
    let (bx, by) = (stack.centre_x() as i64, stack.centre_y() as i64);
    let interpolated = |n: usize| -> Complex64 {
        let mut acc = Complex64::new(0.0, 0.0);
        for &(oy, wy) in &ty {
            let mut row = Complex64::new(0.0, 0.0);
            for &(ox, wx) in &tx {
                row += stack.texel(n, bx + ox, by + oy) * wx;
            }
            acc += row * wy;
        }
        acc
    };
    let k = 2.0 * std::f64::consts::PI / lambda_um;
    let mut p = Complex64::new(0.0, 0.0);
    match stack.expansion {
        Expansion::Taylor => {
            let kw = k * w;
            let mut scale = 1.0;
            for n in 0..=t {
                p += interpolated(n) * scale;
                scale *= kw / (n + 1) as f64;
            }
        }
        Expansion::Chebyshev => {
            let j = bessel::jn_all(k * w * stack.half_range_um, t);
            let mut i_pow = Complex64::new(1.0, 0.0);
            for (n, jn) in j.iter().enumerate() {
                let eps = if n == 0 { 1.0 } else { 2.0 };
                p += interpolated(n) * i_pow * (eps * jn);
                i_pow *= Complex64::new(0.0, 1.0);
            }
        }
    }
    p
}

/// `|P̂|²` of `N_x × N_y` copies: `|P̂₁|²` times the periodic factor in `form`.
pub fn power(
    stack: &TermStack,
    terms: usize,
    pq: &Periodicity,
    uvw: [f64; 3],
    lambda_um: f64,
    form: Form,
) -> f64 {
    let [ax, ay] = &pq.axes;
    let f = axis_factor(ax, uvw[0], lambda_um) * axis_factor(ay, uvw[1], lambda_um);
    let scale = match form {
        Form::Intensity => f.norm_sqr(),
        Form::Thesis => (f.re * f.re + f.im * f.im).sqrt(),
    };
    p_hat_period(stack, terms, pq, uvw, lambda_um).norm_sqr() * scale
}

/// Spectral `ρ_λ = C·|P̂|²` at `lambda_nm`.
#[allow(clippy::too_many_arguments)]
pub fn rho(
    stack: &TermStack,
    terms: usize,
    pq: &Periodicity,
    shading: &Shading,
    wi: [f64; 3],
    wr: [f64; 3],
    lambda_nm: f64,
    form: Form,
) -> f64 {
    spectral(wi, wr, shading, |d| {
        power(stack, terms, pq, d, lambda_nm * 1e-3, form)
    })
}

/// The PQ colour in f64 (what glsl/pq.frag computes): `C·Σ_λ |P̂|² w_λ` over `table`.
#[allow(clippy::too_many_arguments)]
pub fn xyz(
    stack: &TermStack,
    terms: usize,
    pq: &Periodicity,
    shading: &Shading,
    table: &ColourTable,
    wi: [f64; 3],
    wr: [f64; 3],
    form: Form,
) -> [f64; 3] {
    integrated(wi, wr, shading, |d| {
        table.integrate(|l| power(stack, terms, pq, d, l * 1e-3, form))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(n: usize, f: impl Fn(usize, usize) -> f64) -> HeightField {
        HeightField::new(n, n, 0.25, (0..n * n).map(|i| f(i % n, i / n)).collect()).unwrap()
    }

    #[test]
    fn periodic_factor_closed_form_equals_the_sum() {
        for copies in [1, 2, 7, 35, 36] {
            for k in 0..200 {
                let s = -4.3 + 0.0437 * k as f64;
                let (a, b) = (periodic_factor(copies, s), periodic_factor_sum(copies, s));
                assert!((a - b).norm() < 1e-9, "N {copies} s {s}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn dirichlet_interpolates_a_sampled_period_exactly() {
        // One period of n1 samples: its transform at any s equals the Dirichlet sum over
        // all n1 bins.
        let n1 = 7usize;
        let p: Vec<f64> = (0..n1).map(|c| (c as f64 * 0.9).sin() + 0.3).collect();
        let tau = 2.0 * std::f64::consts::PI;
        let dtft = |s: f64| -> Complex64 {
            p.iter()
                .enumerate()
                .map(|(c, h)| Complex64::from_polar(*h, tau * s * c as f64 / n1 as f64))
                .sum()
        };
        for k in 0..40 {
            let s = -2.0 + 0.1 * k as f64;
            let sum: Complex64 = (0..n1 as i64)
                .map(|m| dtft(m as f64) * dirichlet(s - m as f64, n1 as f64))
                .sum();
            // Bins are periodic in n1: sum over the n1 nearest.
            let m0 = s.round() as i64 - 3;
            let near: Complex64 = (m0..m0 + n1 as i64)
                .map(|m| dtft(m as f64) * dirichlet(s - m as f64, n1 as f64))
                .sum();
            assert!(
                (near - dtft(s)).norm() < 1e-9,
                "s {s}: {near} vs {}",
                dtft(s)
            );
            assert!((sum - dtft(s)).norm() < 1e-9);
        }
    }

    #[test]
    fn periods_are_found_and_aperiodic_fields_refused() {
        let tau = 2.0 * std::f64::consts::PI;
        // 1D grating: 20 copies along x of a 6-sample period (with harmonics); constant in y.
        let g = estimate_periodicity(
            &field(120, |c, _| (tau * c as f64 / 6.0).sin().max(0.0)),
            65.0,
        )
        .unwrap();
        assert_eq!(g.axes[0].copies_in_patch, 20);
        assert!((g.axes[0].period_um - 1.5).abs() < 1e-12);
        assert_eq!(
            (
                g.axes[1].taps,
                g.axes[1].samples_per_period,
                g.axes[1].copies
            ),
            (1, 1.0, 0)
        );
        // N·L ≈ 2√π σs = 57.6 µm.
        assert_eq!(g.axes[0].copies, 38);
        assert!((g.axes[0].area_ratio() - 1.0).abs() < 0.011);
        // Two incommensurate waves: no common period shorter than the patch.
        let err = estimate_periodicity(
            &field(120, |c, r| {
                (tau * c as f64 / 6.0).sin() + 0.3 * (tau * (c + r) as f64 * 7.0 / 120.0).cos()
            }),
            65.0,
        )
        .unwrap_err();
        assert!(err.to_string().contains("not periodic along x"), "{err}");
        let flat = estimate_periodicity(&field(16, |_, _| 0.2), 65.0).unwrap_err();
        assert!(flat.to_string().contains("flat"), "{flat}");
    }
}
