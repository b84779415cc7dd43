//! Where the scalar model is wrong: the power diffract's own (Stam, scalar) model puts in each
//! diffraction order, against a rigorous solution of Maxwell's equations ([`rcwa`]) for the
//! same 1-D grating (MODEL §11).
//!
//! **The grating.** A height field's dominant period and the direction across its ridges come
//! from the strongest peak of its spectrum (as the NMM variant's `estimate_grating` and
//! `eval-grating` find them, without their refusal of weak peaks). Averaging the heights
//! along the ridges, at the ridges' local phase, gives one period's mean profile
//! ([`extract_profile`]); the share of the field's height variance (its non-DC spectral
//! energy, by Parseval) that this 1-D profile reproduces says how much of the material the
//! check speaks for.
//!
//! **The light** lies in the plane across the ridges, on the side the grating vector points
//! to when it is turned to the height field's `+x` (growing column index): `ωi = (sinθi ĝ,
//! cosθi)`. Order `m` leaves at `sinθr = −sinθi + mλ/Λ`, `θr` positive on the light's side
//! (specular is `θr = −θi`).
//!
//! **Order powers, in one unit.** RCWA gives efficiencies: each order's share of the incident
//! power. The scalar model gives a relative BRDF `ρ = C·|P̂|²` (MODEL §2), 1 at a flat
//! mirror's specular peak. The reflected share of the incident power is
//! `∫ f_r cosθr dΩr = ∫ f_r du dv` (at fixed `ωi`, `du dv = cosθr dΩr`). A flat surface's
//! `|P̂|²` is the window's lobe `exp(−k²σs²(u² + v²))`, of area `A = π/(kσs)²` in `(u, v)`,
//! and `C = R(θi)/R0` at specular; so `f_r = R0·ρ/A` makes a flat surface reflect exactly its
//! Fresnel factor `R(θi)` (the model's Schlick `R`; `R0` at normal incidence, where it is
//! Fresnel's exactly). A tiled grating's `P̂` is a sum of the same lobes, one per order, each
//! weighted by the Fourier coefficient `a_m(w) = (1/Λ)∫ exp(ikwh(x)) e^{−2πimx/Λ} dx`;
//! so the model's power in order `m` is
//!
//! `η_scalar,m = R0 · (1/A) ∫_lobe C(ωi, ωr) |a_m(w)|² |ĝ(u − u_m, v)|² du dv`,
//!
//! integrated here by a 3×3 Gauss–Hermite rule over the lobe (the gain `C` and `w` vary
//! little across it). Both sides use the same 1-D profile, so their difference is the
//! model's, not the profile's.
//!
//! **The verdict.** As in the external check that motivated it, the comparison is of order
//! ratios, unpolarised (`(η_TE + η_TM)/2`): `η±1/η0` and `η±2/η±1`. An order `m ≠ 0`'s error is
//! `|(η_s,m/η_s,m') / (η_m/η_m') − 1|`, `m'` its neighbour towards specular; the specular
//! order's is `|η_s,0/η_0 − 1|`. The overall error is the worst ratio error over `|m| ≤ 2`
//! (orders fainter than [`rcwa::FAINT_SHARE`] of the reflectance on both sides are skipped);
//! without any ratio, the specular order's. Within 10 %, within 25 %, or not valid.

pub mod plot;

use std::path::Path;

use rayon::prelude::*;

use crate::brdf::rcwa::{self, Grating, Pair};
use crate::brdf::{gain, schlick_r0, Shading};
use crate::heightfield::HeightField;
use crate::material::Material;
use crate::spectrum::num_complex::Complex64;
use crate::{Error, Result};

/// Samples of the mean profile over one period.
pub const PROFILE_BINS: usize = 64;

/// A height field's dominant 1-D grating.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    /// Period across the ridges (µm).
    pub period_um: f64,
    /// Direction of the grating vector from `+x`, turned to `+x`'s side (degrees, in
    /// `(−90, 90]`).
    pub direction_deg: f64,
    /// Mean height (µm) along the ridges at `t = (b + ½)/M` of a period, `b = 0..M`.
    pub heights_um: Vec<f64>,
    /// Share of the height variance the 1-D profile reproduces (0..1).
    pub explained: f64,
}

impl Profile {
    /// Peak-to-valley depth of the mean profile (µm).
    pub fn depth_um(&self) -> f64 {
        let (lo, hi) = self
            .heights_um
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
                (a.min(h), b.max(h))
            });
        hi - lo
    }

    /// The grating on a substrate of index `n`.
    pub fn grating(&self, n: f64) -> Grating {
        Grating {
            period_um: self.period_um,
            profile_um: self.heights_um.clone(),
            index: Complex64::new(n, 0.0),
        }
    }

    /// Height at phase `t` (periods), linear between bins, periodic.
    fn at(&self, t: f64) -> f64 {
        let m = self.heights_um.len();
        let x = (t.rem_euclid(1.0) * m as f64 - 0.5).rem_euclid(m as f64);
        let i = x.floor() as usize % m;
        let f = x - x.floor();
        self.heights_um[i] * (1.0 - f) + self.heights_um[(i + 1) % m] * f
    }
}

/// Periods longer than this (µm) are not taken for the ridges: a field's slow undulation
/// (a tilt, a bend of the scale) is not a grating.
pub const MAX_PERIOD_UM: f64 = 10.0;

/// Width of the band around the ridge frequency that gives their local phase, relative to
/// that frequency (Gaussian std).
const BAND: f64 = 0.25;

/// The dominant grating of `hf` and its mean profile along the ridges.
///
/// The ridge frequency is the strongest 3×3 neighbourhood of the height field's power
/// spectrum (periods up to [`MAX_PERIOD_UM`]), refined to its power-weighted centroid. The
/// ridges' local phase comes from the field band-passed around that frequency (one side
/// only: the analytic signal of the ridges, a Gaussian band of std 25 % of the frequency);
/// each sample is binned by its phase. On a regular grating the phase is the plane wave's;
/// on an irregular field (a measured or grown skin, whose ridges wander and change
/// period) the profile follows the ridges instead of washing them out. The explained
/// share compares the field with the profile laid out at those phases.
pub fn extract_profile(hf: &HeightField) -> Result<Profile> {
    let (nx, ny) = (hf.nx(), hf.ny());
    let (lx, ly) = hf.extent_um();
    let mean = hf.mean();
    let h = hf.heights_um();
    let mut spec: Vec<Complex64> = h.iter().map(|v| Complex64::new(v - mean, 0.0)).collect();
    fft2(&mut spec, nx, ny, false);
    let signed = |i: usize, n: usize| {
        if i > n / 2 {
            i as i64 - n as i64
        } else {
            i as i64
        }
    };
    let power = |mx: i64, my: i64| {
        spec[my.rem_euclid(ny as i64) as usize * nx + mx.rem_euclid(nx as i64) as usize].norm_sqr()
    };
    let freq = |mx: f64, my: f64| (mx / lx).hypot(my / ly);
    let mut best = (0.0, 0i64, 0i64);
    for r in 0..ny {
        for c in 0..nx {
            let (mx, my) = (signed(c, nx), signed(r, ny));
            let f = freq(mx as f64, my as f64);
            // One half-plane: the mirror peak carries the same power.
            if f * MAX_PERIOD_UM < 1.0 || mx < 0 || (mx == 0 && my < 0) {
                continue;
            }
            let mut p = 0.0;
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if (mx + dx, my + dy) != (0, 0) {
                        p += power(mx + dx, my + dy);
                    }
                }
            }
            if p > best.0 {
                best = (p, mx, my);
            }
        }
    }
    if best.0 <= 0.0 {
        return Err(Error::invalid(
            "validity",
            format!("no ridges: the height field has no spectral peak at periods up to {MAX_PERIOD_UM} µm"),
        ));
    }
    // Power-weighted centroid of the 3×3 neighbourhood (cycles per patch).
    let (mut fx, mut fy, mut w) = (0.0, 0.0, 0.0);
    for dy in -1..=1 {
        for dx in -1..=1 {
            let p = power(best.1 + dx, best.2 + dy);
            fx += p * (best.1 + dx) as f64;
            fy += p * (best.2 + dy) as f64;
            w += p;
        }
    }
    let (fx, fy) = (fx / w, fy / w);
    let (kx, ky) = (fx / lx, fy / ly);
    let f0 = kx.hypot(ky);
    // The analytic band around +f: its phase is the ridges' local phase.
    for r in 0..ny {
        for c in 0..nx {
            let (mx, my) = (signed(c, nx) as f64, signed(r, ny) as f64);
            let d = (mx / lx - kx).hypot(my / ly - ky) / (BAND * f0);
            spec[r * nx + c] *= (-0.5 * d * d).exp();
        }
    }
    fft2(&mut spec, nx, ny, true);
    let phase: Vec<f64> = spec
        .iter()
        .map(|z| (z.arg() / (2.0 * std::f64::consts::PI)).rem_euclid(1.0))
        .collect();
    let mut sum = vec![0.0f64; PROFILE_BINS];
    let mut count = vec![0usize; PROFILE_BINS];
    for (v, t) in h.iter().zip(&phase) {
        let b = (t * PROFILE_BINS as f64) as usize % PROFILE_BINS;
        sum[b] += v;
        count[b] += 1;
    }
    let mut profile = Profile {
        period_um: 1.0 / f0,
        // (+ 0.0 turns a −0° into 0°.)
        direction_deg: ky.atan2(kx).to_degrees() + 0.0,
        heights_um: fill_empty(&sum, &count),
        explained: 0.0,
    };
    let (mut total, mut residual) = (0.0, 0.0);
    for (v, &t) in h.iter().zip(&phase) {
        total += (v - mean).powi(2);
        residual += (v - profile.at(t)).powi(2);
    }
    profile.explained = if total > 0.0 {
        (1.0 - residual / total).max(0.0)
    } else {
        0.0
    };
    Ok(profile)
}

/// In-place 2-D FFT of a row-major `nx × ny` grid (`inverse`: the `+i` direction, unscaled).
fn fft2(data: &mut [Complex64], nx: usize, ny: usize, inverse: bool) {
    let mut planner = rustfft::FftPlanner::new();
    let (row, col) = if inverse {
        (planner.plan_fft_inverse(nx), planner.plan_fft_inverse(ny))
    } else {
        (planner.plan_fft_forward(nx), planner.plan_fft_forward(ny))
    };
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
}

/// Bin means, with empty bins interpolated between their filled neighbours (cyclically).
fn fill_empty(sum: &[f64], count: &[usize]) -> Vec<f64> {
    let m = sum.len();
    let filled: Vec<usize> = (0..m).filter(|&b| count[b] > 0).collect();
    (0..m)
        .map(|b| {
            if count[b] > 0 {
                return sum[b] / count[b] as f64;
            }
            let next = filled
                .iter()
                .copied()
                .find(|&f| f > b)
                .unwrap_or(filled[0] + m);
            let prev = filled.iter().rev().copied().find(|&f| f < b);
            let prev = prev.map_or(filled[filled.len() - 1] as i64 - m as i64, |p| p as i64);
            let value = |i: i64| {
                let i = i.rem_euclid(m as i64) as usize;
                sum[i] / count[i] as f64
            };
            let f = (b as i64 - prev) as f64 / (next as i64 - prev) as f64;
            value(prev) * (1.0 - f) + value(next as i64) * f
        })
        .collect()
}

/// The material's numbers the scalar model needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScalarModel {
    pub shading: Shading,
    /// Spatial coherence length (µm); the window std is a quarter of it.
    pub coherence_um: f64,
}

impl ScalarModel {
    pub fn of(material: &Material) -> Self {
        Self {
            shading: material.shading(),
            coherence_um: material.coherence_um,
        }
    }
}

/// `a_m(w) = ∫₀¹ exp(i·k·w·h(t)) e^{−2πimt} dt` for the linear-between-samples profile
/// (exact per segment).
pub fn fourier_coefficient(heights_um: &[f64], k: f64, w: f64, m: i64) -> Complex64 {
    let n = heights_um.len();
    let dt = 1.0 / n as f64;
    let two_pi = 2.0 * std::f64::consts::PI;
    let mut acc = Complex64::new(0.0, 0.0);
    for j in 0..n {
        let (t0, t1) = (j as f64 * dt, (j + 1) as f64 * dt);
        let p0 = k * w * heights_um[j] - two_pi * m as f64 * t0;
        let p1 = k * w * heights_um[(j + 1) % n] - two_pi * m as f64 * t1;
        let d = p1 - p0;
        // ∫ e^{i(p0 + d s)} dt over the segment, s ∈ [0, 1]: dt·e^{ip0}(e^{id} − 1)/(id).
        let factor = if d.abs() < 1e-8 {
            Complex64::new(1.0, 0.5 * d)
        } else {
            (Complex64::from_polar(1.0, d) - 1.0) / Complex64::new(0.0, d)
        };
        acc += Complex64::from_polar(dt, p0) * factor;
    }
    acc
}

/// The scalar model's power in reflected order `m` (see the module's documentation):
/// `R0·∫ C |a_m|² over the lobe / A`; 0 when the order's centre does not propagate.
pub fn eta_scalar(
    profile: &Profile,
    model: &ScalarModel,
    lambda_nm: f64,
    theta_i_deg: f64,
    m: i64,
) -> f64 {
    let lambda_um = lambda_nm * 1e-3;
    let k = 2.0 * std::f64::consts::PI / lambda_um;
    let (si, ci) = theta_i_deg.to_radians().sin_cos();
    let wi = [si, 0.0, ci];
    let u_m = -(m as f64) * lambda_um / profile.period_um;
    if (si + u_m).abs() >= 1.0 {
        return 0.0;
    }
    let sigma_s = model.coherence_um / 4.0;
    // Gauss–Hermite (weight e^{−t²}), 3 nodes, normalised weights; |ĝ|² = e^{−(kσs δu)²}.
    let nodes = [
        (-(1.5f64).sqrt(), 1.0 / 6.0),
        (0.0, 2.0 / 3.0),
        ((1.5f64).sqrt(), 1.0 / 6.0),
    ];
    let step = 1.0 / (k * sigma_s);
    let mut eta = 0.0;
    for &(tu, wu) in &nodes {
        for &(tv, wv) in &nodes {
            let (u, v) = (u_m + tu * step, tv * step);
            let (x, y) = (-si - u, -v);
            let z2 = 1.0 - x * x - y * y;
            if z2 <= 0.0 {
                continue;
            }
            let wr = [x, y, z2.sqrt()];
            let c = gain(wi, wr, &model.shading);
            if c == 0.0 {
                continue;
            }
            let w = -(ci + wr[2]);
            eta += wu * wv * c * fourier_coefficient(&profile.heights_um, k, w, m).norm_sqr();
        }
    }
    schlick_r0(model.shading.ior) * eta
}

/// How well the scalar model holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Verdict {
    Within10,
    Within25,
    NotValid,
}

impl Verdict {
    /// The class of a relative error (NaN: not valid).
    pub fn of(error: f64) -> Self {
        if error <= 0.10 {
            Verdict::Within10
        } else if error <= 0.25 {
            Verdict::Within25
        } else {
            Verdict::NotValid
        }
    }

    pub fn label(self) -> &'static str {
        match self {
            Verdict::Within10 => "within 10 %",
            Verdict::Within25 => "within 25 %",
            Verdict::NotValid => "not valid",
        }
    }
}

/// One propagating reflected order.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderRow {
    pub m: i64,
    /// Signed angle (degrees), positive on the light's side.
    pub theta_r_deg: f64,
    pub eta_te: f64,
    pub eta_tm: f64,
    pub eta_unpolarised: f64,
    pub eta_scalar: f64,
    /// `η_scalar/η_unpolarised − 1`.
    pub rel_error: f64,
    /// Error of the ratio to the neighbour towards specular (see the module's docs).
    pub ratio_error: Option<f64>,
    pub verdict: Verdict,
}

/// The comparison at one wavelength and angle.
#[derive(Debug, Clone, PartialEq)]
pub struct Check {
    pub lambda_nm: f64,
    pub theta_i_deg: f64,
    pub rows: Vec<OrderRow>,
    /// The overall error (see the module's docs) and what it was measured on.
    pub error: f64,
    pub error_of: String,
    pub verdict: Verdict,
    pub harmonics: usize,
    pub slices: usize,
    /// How far the last refinement in harmonics and in slices moved an order (NaN where the
    /// solve used fixed numbers).
    pub harmonic_change: f64,
    pub slice_change: f64,
    /// `max |R + T − 1|` over both polarisations.
    pub energy_error: f64,
}

impl Check {
    /// The rigorous solve's estimated error when it did not converge to `tolerance`: the
    /// larger of the last refinements' changes (in harmonics, in slices); `None` when both
    /// met it (or the solve used fixed numbers).
    pub fn unconverged(&self, tolerance: f64) -> Option<f64> {
        let change = self.harmonic_change.max(self.slice_change);
        (change > tolerance).then_some(change)
    }
}

/// Smallest normal-incidence Fresnel reflectance `R0 = ((n − 1)/(n + 1))²` the rigorous
/// check accepts: the energy balance of the solver is held to 1e-8 (`|R + T − 1|`), and the
/// orders it compares go down to [`rcwa::FAINT_SHARE`] of the reflectance, so a weaker
/// interface (an index closer to 1 than about 1.0002) reflects less than the solver
/// resolves; at `n = 1` there is no interface at all and every ratio is 0/0.
pub const MIN_REFLECTANCE: f64 = 1e-8;

/// Refuses an index the rigorous check cannot speak for: not finite, not above 1, or so
/// close to 1 that its reflectance is below [`MIN_REFLECTANCE`].
pub fn check_index(n: f64) -> Result<()> {
    let r0 = ((n - 1.0) / (n + 1.0)).powi(2);
    if n.is_finite() && n > 1.0 && r0 >= MIN_REFLECTANCE {
        return Ok(());
    }
    let root = MIN_REFLECTANCE.sqrt();
    // The smallest index that passes, rounded up to 4 decimals (1.0003).
    let n_min = ((1.0 + root) / (1.0 - root) * 1e4).ceil() / 1e4;
    let reflects = if n.is_finite() && n > 1.0 {
        format!("; n = {n} reflects R0 = {r0:.1e}")
    } else {
        String::new()
    };
    Err(Error::invalid(
        "ior",
        format!(
            "{n}; the rigorous check needs n ≥ {n_min}, whose interface reflects at least the \
             {MIN_REFLECTANCE:.0e} (R0, at normal incidence) the solver resolves{reflects}; n = 1 \
             is no interface: nothing is reflected and every order ratio is 0/0"
        ),
    ))
}

/// How the rigorous side is solved: converged to a tolerance, or at fixed numbers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Solve {
    Converge(f64),
    Fixed { harmonics: usize, slices: usize },
}

/// Compares the two models for `profile` on a substrate of index `n`.
pub fn check(
    profile: &Profile,
    model: &ScalarModel,
    lambda_nm: f64,
    theta_i_deg: f64,
    how: Solve,
) -> Result<Check> {
    let grating = profile.grating(model.shading.ior);
    let lambda_um = lambda_nm * 1e-3;
    let (pair, hc, sc) = match how {
        Solve::Converge(tol) => {
            let c = rcwa::converge(&grating, lambda_um, theta_i_deg, tol, None)?;
            (c.pair, c.harmonic_change, c.slice_change)
        }
        Solve::Fixed { harmonics, slices } => (
            Pair::solve(&grating, lambda_um, theta_i_deg, harmonics, slices)?,
            f64::NAN,
            f64::NAN,
        ),
    };
    Ok(compare(
        profile,
        model,
        lambda_nm,
        theta_i_deg,
        &pair,
        hc,
        sc,
    ))
}

fn compare(
    profile: &Profile,
    model: &ScalarModel,
    lambda_nm: f64,
    theta_i_deg: f64,
    pair: &Pair,
    harmonic_change: f64,
    slice_change: f64,
) -> Check {
    let total: f64 = pair
        .te
        .reflected
        .iter()
        .chain(&pair.tm.reflected)
        .map(|o| 0.5 * o.eta)
        .sum();
    let faint = rcwa::FAINT_SHARE * total;
    let mut rows: Vec<OrderRow> = pair
        .te
        .reflected
        .iter()
        .map(|o| {
            let eta_u = pair.eta_unpolarised(o.m);
            let eta_s = eta_scalar(profile, model, lambda_nm, theta_i_deg, o.m);
            OrderRow {
                m: o.m,
                theta_r_deg: o.sin_theta.clamp(-1.0, 1.0).asin().to_degrees(),
                eta_te: o.eta,
                eta_tm: pair.tm.eta_r(o.m),
                eta_unpolarised: eta_u,
                eta_scalar: eta_s,
                rel_error: eta_s / eta_u - 1.0,
                ratio_error: None,
                verdict: Verdict::NotValid,
            }
        })
        .collect();
    let find = |rows: &[OrderRow], m: i64| rows.iter().position(|r| r.m == m);
    for i in 0..rows.len() {
        let m = rows[i].m;
        if m != 0 {
            if let Some(j) = find(&rows, m - m.signum()) {
                let (a, b) = (&rows[i], &rows[j]);
                let e = ((a.eta_scalar / b.eta_scalar) / (a.eta_unpolarised / b.eta_unpolarised)
                    - 1.0)
                    .abs();
                rows[i].ratio_error = Some(if e.is_finite() { e } else { f64::INFINITY });
            }
        }
        let r = &rows[i];
        rows[i].verdict = Verdict::of(r.ratio_error.unwrap_or(r.rel_error.abs()));
    }
    let mut error = f64::NAN;
    let mut error_of = String::new();
    for r in &rows {
        let Some(e) = r.ratio_error else { continue };
        let j = find(&rows, r.m - r.m.signum()).unwrap_or(0);
        let significant = |x: &OrderRow| x.eta_unpolarised >= faint || x.eta_scalar >= faint;
        if r.m.abs() > 2 || !(significant(r) || significant(&rows[j])) {
            continue;
        }
        if error.is_nan() || e > error {
            error = e;
            error_of = format!("η{:+}/η{}", r.m, fmt_order(rows[j].m));
        }
    }
    if error.is_nan() {
        if let Some(r) = rows.iter().find(|r| r.m == 0) {
            error = r.rel_error.abs();
            error_of = "η0 (no other order propagates)".into();
        }
    }
    let energy_error = (pair.te.total() - 1.0)
        .abs()
        .max((pair.tm.total() - 1.0).abs());
    Check {
        lambda_nm,
        theta_i_deg,
        rows,
        verdict: Verdict::of(error),
        error,
        error_of,
        harmonics: pair.te.harmonics,
        slices: pair.te.slices,
        harmonic_change,
        slice_change,
        energy_error,
    }
}

fn fmt_order(m: i64) -> String {
    if m == 0 {
        "0".into()
    } else {
        format!("{m:+}")
    }
}

/// A validity map: the overall error over angles and wavelengths.
#[derive(Debug, Clone, PartialEq)]
pub struct Map {
    pub thetas_deg: Vec<f64>,
    pub lambdas_nm: Vec<f64>,
    /// `error[θ index][λ index]`.
    pub error: Vec<Vec<f64>>,
    pub harmonics: usize,
    pub slices: usize,
    /// Where the solve at the hardest cell (the shortest wavelength, the steepest angle) that
    /// chose `harmonics` and `slices` did not converge to the tolerance: its last refinement's
    /// change, the estimated error of every cell's orders.
    pub unconverged: Option<f64>,
}

/// The map's angles and wavelengths: θi = 0..80° by 10°, λ = 400..700 nm by 25 nm.
pub fn map_grid() -> (Vec<f64>, Vec<f64>) {
    (
        (0..=8).map(|i| 10.0 * i as f64).collect(),
        (0..=12).map(|i| 400.0 + 25.0 * i as f64).collect(),
    )
}

/// The harmonics and slices a map uses everywhere: converged (to `tolerance`) at its
/// shortest wavelength and steepest angle, where the most orders propagate.
pub fn map_numbers(
    profile: &Profile,
    model: &ScalarModel,
    lambda_nm: f64,
    theta_deg: f64,
    tolerance: f64,
) -> Result<(usize, usize)> {
    map_solve(profile, model, lambda_nm, theta_deg, tolerance).map(|(n, s, _)| (n, s))
}

/// [`map_numbers`] and, where they did not converge to `tolerance`, the last change.
fn map_solve(
    profile: &Profile,
    model: &ScalarModel,
    lambda_nm: f64,
    theta_deg: f64,
    tolerance: f64,
) -> Result<(usize, usize, Option<f64>)> {
    let c = rcwa::converge(
        &profile.grating(model.shading.ior),
        lambda_nm * 1e-3,
        theta_deg,
        tolerance,
        None,
    )?;
    let change = c.harmonic_change.max(c.slice_change);
    let unconverged = (!c.met(tolerance)).then_some(change);
    Ok((c.pair.te.harmonics, c.pair.te.slices, unconverged))
}

/// Computes the validity map over `thetas_deg × lambdas_nm` (rayon), ticking `progress`.
pub fn map(
    profile: &Profile,
    model: &ScalarModel,
    thetas_deg: &[f64],
    lambdas_nm: &[f64],
    tolerance: f64,
    progress: &indicatif::ProgressBar,
) -> Result<Map> {
    let l_min = lambdas_nm.iter().copied().fold(f64::INFINITY, f64::min);
    let t_max = thetas_deg.iter().copied().fold(0.0, f64::max);
    let (harmonics, slices, unconverged) = map_solve(profile, model, l_min, t_max, tolerance)?;
    let how = Solve::Fixed { harmonics, slices };
    let cells: Vec<(usize, usize)> = (0..thetas_deg.len())
        .flat_map(|i| (0..lambdas_nm.len()).map(move |j| (i, j)))
        .collect();
    let values: Vec<f64> = cells
        .par_iter()
        .map(|&(i, j)| {
            let c = check(profile, model, lambdas_nm[j], thetas_deg[i], how);
            progress.inc(1);
            c.map(|c| c.error)
        })
        .collect::<Result<_>>()?;
    let error = values
        .chunks(lambdas_nm.len())
        .map(<[f64]>::to_vec)
        .collect();
    Ok(Map {
        thetas_deg: thetas_deg.to_vec(),
        lambdas_nm: lambdas_nm.to_vec(),
        error,
        harmonics,
        slices,
        unconverged,
    })
}

/// Periods of the limits table, in wavelengths.
pub const LIMITS_PERIODS: [f64; 7] = [1.6, 1.9, 2.1, 2.6, 3.3, 4.1, 5.0];
/// Peak-to-valley depths of the limits table, in wavelengths.
pub const LIMITS_DEPTHS: [f64; 8] = [0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0];

impl Profile {
    /// A sinusoidal grating of `period_um` and peak-to-valley `depth_um`, its ridges across
    /// `x`.
    pub fn sinusoid(period_um: f64, depth_um: f64) -> Self {
        let m = PROFILE_BINS;
        Profile {
            period_um,
            direction_deg: 0.0,
            heights_um: (0..m)
                .map(|b| {
                    let t = (b as f64 + 0.5) / m as f64;
                    0.5 * depth_um * (1.0 + (2.0 * std::f64::consts::PI * t).cos())
                })
                .collect(),
            explained: 1.0,
        }
    }
}

/// Where scalar theory holds for sinusoidal gratings: the worst order-ratio error of `model`
/// at `lambda_nm` for every period in `periods` and depth in `depths` (both in wavelengths),
/// one Markdown table per angle in `thetas_deg`. `progress` is called after each cell.
pub fn limits_table(
    model: &ScalarModel,
    lambda_nm: f64,
    thetas_deg: &[f64],
    periods: &[f64],
    depths: &[f64],
    tolerance: f64,
    mut progress: impl FnMut(),
) -> Result<String> {
    use std::fmt::Write as _;
    let lambda_um = lambda_nm * 1e-3;
    let mut out = String::new();
    let header: Vec<String> = depths.iter().map(|d| format!("{d}")).collect();
    for &theta in thetas_deg {
        let _ = writeln!(
            out,
            "θi = {theta}°, λ = {lambda_nm} nm, n = {}:\n",
            model.shading.ior
        );
        let _ = writeln!(out, "| Λ/λ \\ d/λ | {} |", header.join(" | "));
        let _ = writeln!(out, "|---|{}", "---|".repeat(depths.len()));
        for &p in periods {
            let mut cells = Vec::with_capacity(depths.len());
            for &d in depths {
                let g = Profile::sinusoid(p * lambda_um, d * lambda_um);
                let c = check(&g, model, lambda_nm, theta, Solve::Converge(tolerance))?;
                // An unconverged cell shows its estimated error beside its value.
                cells.push(match c.unconverged(tolerance) {
                    Some(e) => format!("{} (±{}, unconverged)", percent(c.error), percent(e)),
                    None => percent(c.error),
                });
                progress();
            }
            let _ = writeln!(out, "| {p} | {} |", cells.join(" | "));
        }
        out.push('\n');
    }
    Ok(out)
}

/// Wavelengths of the one-line summary.
pub const SUMMARY_LAMBDAS_NM: [f64; 3] = [450.0, 550.0, 650.0];
/// Angle grid of the cached summary (degrees): requests are rounded to it.
pub const SUMMARY_THETA_STEP: f64 = 15.0;

/// The share of a field's height variance its mean 1-D profile must explain for the one-line
/// model check to run: below it the field is no grating the 1-D solver can speak for.
pub const SUMMARY_MIN_EXPLAINED: f64 = 0.1;

/// Convergence tolerance of the validity map's and the cached summary's solves: they sort
/// cells into 10 %, 25 % and worse, for which 5 % solves suffice, in a fraction of the time.
pub const MAP_TOLERANCE: f64 = 0.05;

/// The scalar model's expected error against the rigorous solver for `material` with light
/// at `thetas_deg` (rounded to [`SUMMARY_THETA_STEP`]), at [`SUMMARY_LAMBDAS_NM`], as one
/// line pointing to `diffract validity`. The cells come from a small validity map cached
/// in `cache_dir` (computed on the first request, a few seconds). A field without one
/// dominant period, or an error, gives a line that says so instead.
pub fn expected_error_line(
    material: &Material,
    thetas_deg: &[f64],
    cache_dir: Option<&Path>,
) -> String {
    match summary(material, thetas_deg, cache_dir) {
        Ok(line) => line,
        Err(e) => format!("model check: not available ({e}); see diffract validity"),
    }
}

fn summary(material: &Material, thetas_deg: &[f64], cache_dir: Option<&Path>) -> Result<String> {
    let hf = material.load_heightfield(&crate::report::Collect::default())?;
    summary_of(material, &hf, thetas_deg, cache_dir, &CheckPace::new())
}

/// The fewest whole periods the field must hold across its peak's direction for the peak
/// to be ridges: a "period" of a third of the field or more is its tilt, its bow or the
/// seam where its tiled edges meet.
pub const SUMMARY_MIN_PERIODS: f64 = 3.0;

/// The model check of a loaded field, run beside the render it annotates
/// ([`ModelCheck::start`]) and bounded by it ([`ModelCheck::finish`]).
pub struct ModelCheck {
    line: std::sync::mpsc::Receiver<String>,
    pace: std::sync::Arc<CheckPace>,
}

/// How far a running check is: the rigorous cells it has left and the CPU time its
/// finished cells took, so that the command it annotates waits for it only when it can end
/// within the wait. The cells run on one thread; CPU time, not wall, since that thread runs
/// only on cores the command leaves idle.
#[derive(Default)]
struct CheckPace {
    /// Cells still to solve; `u32::MAX` until the check knows (before its first cell).
    left: std::sync::atomic::AtomicU32,
    /// Cells solved in this run, and their CPU time (ns).
    solved: std::sync::atomic::AtomicU32,
    cpu_ns: std::sync::atomic::AtomicU64,
}

impl CheckPace {
    fn new() -> Self {
        Self {
            left: u32::MAX.into(),
            ..Self::default()
        }
    }

    /// The CPU time (s) the cells left will take at the pace of those solved; `None` while
    /// unknown (before the cells, or before the first one ends).
    fn left_s(&self) -> Option<f64> {
        use std::sync::atomic::Ordering::Relaxed;
        let left = self.left.load(Relaxed);
        let solved = self.solved.load(Relaxed);
        match (left, solved) {
            (0, _) => Some(0.0),
            (u32::MAX, _) | (_, 0) => None,
            _ => {
                Some(f64::from(left) * self.cpu_ns.load(Relaxed) as f64 * 1e-9 / f64::from(solved))
            }
        }
    }
}

/// The calling thread's CPU time (s); 0 where it cannot be read.
fn thread_cpu_s() -> f64 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes the one timespec it is given, which lives across the call.
    let ok = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) } == 0;
    if ok {
        t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
    } else {
        0.0
    }
}

impl ModelCheck {
    /// Starts the check of `hf` (the field `material` loaded) on a thread of its own. Its
    /// answer is cached per field and material in `cache_dir`, so a later render of the same
    /// material reads it in milliseconds; the rigorous cells are cached as each one ends.
    pub fn start(
        material: Material,
        hf: crate::heightfield::HeightField,
        thetas_deg: Vec<f64>,
        cache_dir: Option<std::path::PathBuf>,
    ) -> Self {
        let (tx, rx) = std::sync::mpsc::channel();
        let pace = std::sync::Arc::new(CheckPace::new());
        let shared = pace.clone();
        std::thread::spawn(move || {
            background_priority();
            let check =
                || match summary_of(&material, &hf, &thetas_deg, cache_dir.as_deref(), &shared) {
                    Ok(line) => line,
                    Err(e) => format!("model check: not available ({e}); see diffract validity"),
                };
            // Its parallel loops run on a pool of its own (the caller's table build keeps
            // the global one), on this one low-priority thread.
            let line = match rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .thread_name(|_| "model check".into())
                .start_handler(|_| background_priority())
                .build()
            {
                Ok(pool) => pool.install(check),
                Err(_) => check(),
            };
            let _ = tx.send(line);
        });
        Self { line: rx, pace }
    }

    /// The check's line, waiting at most `wait` for it, and not at all when the pace of its
    /// cells says it cannot end within `wait`: a check that has not ended says so (its
    /// finished cells are cached for the next run) rather than hold the command.
    pub fn finish(self, wait: std::time::Duration) -> String {
        let left_s = self.pace.left_s().filter(|&s| s > wait.as_secs_f64());
        let line = match left_s {
            Some(_) => self.line.try_recv().ok(),
            None => self.line.recv_timeout(wait).ok(),
        };
        line.unwrap_or_else(|| {
            let how_long = match left_s {
                Some(s) => format!(
                    "its rigorous cells need about {s:.1} s more of a core, past the {:.1} s (a \
                     tenth of the render it annotates) it may take",
                    wait.as_secs_f64()
                ),
                None => format!(
                    "not finished within {:.1} s, a tenth of the render it annotates",
                    wait.as_secs_f64()
                ),
            };
            format!(
                "model check: {how_long} (its finished cells are cached for the next run); see \
                 diffract validity"
            )
        })
    }
}

/// Lowers the calling thread's scheduling priority to the lowest (Linux's `SCHED_IDLE`,
/// else nice 19), so a check beside a render takes only the CPU the render leaves idle.
/// `SCHED_IDLE` matters: a render's threads wake and sleep thousands of times (each group
/// of a table build), and the scheduler gives a waking thread the core of an idle-policy
/// thread at once, where a nice-19 thread may first run out its slice (the check cost the
/// cold render 0.45 s at nice 19 on 2 cores). Best effort.
fn background_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: gettid takes no pointer; sched_setscheduler reads the one `sched_param` it is
    // given, which lives across the call; on Linux both act on this thread only.
    unsafe {
        let tid = libc::syscall(libc::SYS_gettid) as libc::pid_t;
        let param = libc::sched_param { sched_priority: 0 };
        if libc::sched_setscheduler(tid, libc::SCHED_IDLE, &param) != 0 {
            libc::setpriority(libc::PRIO_PROCESS, tid as libc::id_t, 19);
        }
    }
}

/// [`expected_error_line`]'s summary for a field already loaded: the line cached for this
/// field, material and angles, else computed (and cached).
fn summary_of(
    material: &Material,
    hf: &crate::heightfield::HeightField,
    thetas_deg: &[f64],
    cache_dir: Option<&Path>,
    pace: &CheckPace,
) -> Result<String> {
    let line_path = cache_dir.map(|d| {
        d.join(crate::cache::file_name(
            crate::cache::VALIDITY_FILES,
            line_key(material, hf, thetas_deg),
        ))
    });
    if let Some(line) = line_path.as_deref().and_then(read_line) {
        return Ok(line);
    }
    let line = summary_uncached(material, hf, thetas_deg, cache_dir, pace)?;
    if let Some(p) = &line_path {
        // A cache that cannot be written only costs the next run the check again.
        let _ = write_line(p, &line);
    }
    Ok(line)
}

fn summary_uncached(
    material: &Material,
    hf: &crate::heightfield::HeightField,
    thetas_deg: &[f64],
    cache_dir: Option<&Path>,
    pace: &CheckPace,
) -> Result<String> {
    let profile = extract_profile(hf)?;
    let (lx, ly) = hf.extent_um();
    let dir = profile.direction_deg.to_radians();
    // The field's length along the grating vector (the distance across the ridges).
    let across = (lx / dir.cos().abs().max(1e-12)).min(ly / dir.sin().abs().max(1e-12));
    if profile.period_um * SUMMARY_MIN_PERIODS > across {
        return Ok(format!(
            "model check: not run: the field's strongest \"period\", {:.1} µm, spans over a \
             third of its {:.1} µm: a tilt, a bow or the seam of its tiled edges, not ridges \
             (--level plane removes a tilt; --tile mirror a seam); see diffract validity",
            profile.period_um, across
        ));
    }
    if profile.explained < SUMMARY_MIN_EXPLAINED || profile.depth_um() <= 0.0 {
        return Ok(format!(
            "model check: not run: the field's mean 1-D profile explains {:.0} % of its height \
             variance (a rigorous check needs a grating); see diffract validity",
            100.0 * profile.explained
        ));
    }
    let model = ScalarModel::of(material);
    let mut thetas: Vec<f64> = thetas_deg
        .iter()
        .map(|t| ((t.abs().min(89.0)) / SUMMARY_THETA_STEP).round() * SUMMARY_THETA_STEP)
        .map(|t| t.min(75.0))
        .collect();
    thetas.sort_by(f64::total_cmp);
    thetas.dedup();
    let key = cache_key(&profile, &model);
    let path =
        cache_dir.map(|d| d.join(crate::cache::file_name(crate::cache::VALIDITY_FILES, key)));
    let mut cells = path.as_deref().map(read_cells).unwrap_or_default();
    let missing: Vec<(f64, f64)> = thetas
        .iter()
        .flat_map(|&t| SUMMARY_LAMBDAS_NM.iter().map(move |&l| (t, l)))
        .filter(|&(t, l)| !cells.iter().any(|c| c.0 == t && c.1 == l))
        .collect();
    // The largest estimated error of a solve that stopped short of the tolerance.
    let short = std::sync::Mutex::new(None::<f64>);
    let left = u32::try_from(missing.len()).unwrap_or(u32::MAX - 1);
    pace.left.store(left, std::sync::atomic::Ordering::Relaxed);
    if !missing.is_empty() {
        // Each cell is cached as it ends: a run stopped before the last one (a command
        // that does not wait for its check) leaves the next run less to do.
        let done = std::sync::Mutex::new(cells);
        missing.par_iter().try_for_each(|&(t, l)| {
            use std::sync::atomic::Ordering::Relaxed;
            let cpu = thread_cpu_s();
            let c = check(&profile, &model, l, t, Solve::Converge(MAP_TOLERANCE))?;
            pace.cpu_ns
                .fetch_add(((thread_cpu_s() - cpu).max(0.0) * 1e9) as u64, Relaxed);
            pace.solved.fetch_add(1, Relaxed);
            pace.left.fetch_sub(1, Relaxed);
            if let (Some(e), Ok(mut s)) = (c.unconverged(MAP_TOLERANCE), short.lock()) {
                *s = Some(s.map_or(e, |m| m.max(e)));
            }
            if let Ok(mut d) = done.lock() {
                d.push((t, l, c.error));
                if let Some(p) = &path {
                    // A cache that cannot be written only costs the next run the same cells.
                    let _ = write_cells(p, &d);
                }
            }
            Ok::<(), Error>(())
        })?;
        cells = done.into_inner().unwrap_or_default();
    }
    let worst_at = |t: f64| {
        cells
            .iter()
            .filter(|c| c.0 == t && SUMMARY_LAMBDAS_NM.contains(&c.1))
            .map(|c| c.2)
            .fold(0.0f64, |a, e| if e.is_nan() { a } else { a.max(e) })
    };
    let parts: Vec<String> = thetas
        .iter()
        .map(|&t| format!("{} at θi ≈ {t}°", percent(worst_at(t))))
        .collect();
    let worst = thetas.iter().map(|&t| worst_at(t)).fold(0.0, f64::max);
    let unconverged = match short.into_inner().ok().flatten() {
        Some(e) => format!(
            " (a rigorous solve stopped short of {} convergence: its orders ±{})",
            percent(MAP_TOLERANCE),
            percent(e)
        ),
        None => String::new(),
    };
    Ok(format!(
        "model check: scalar order ratios vs rigorous (RCWA, n = {}) for the {:.3} µm ridges ({:.0} % of the field), 450–650 nm: off by up to {} ({}){unconverged}: {}; see diffract validity",
        model.shading.ior,
        profile.period_um,
        100.0 * profile.explained,
        parts.join(", "),
        Verdict::of(worst).label(),
        if worst <= 0.25 { "colours and their strengths hold" } else { "colours (angles) hold, order strengths do not" }
    ))
}

/// A relative error as a percentage (≥ 10: "×N").
pub fn percent(e: f64) -> String {
    if !e.is_finite() {
        "∞".into()
    } else if e >= 10.0 {
        format!("{:.0}×", e + 1.0)
    } else {
        format!("{:.0} %", 100.0 * e)
    }
}

/// The key of a field's cached model-check line: its heights and pixel size, the
/// material's numbers the check reads and the angles asked for.
fn line_key(material: &Material, hf: &crate::heightfield::HeightField, thetas_deg: &[f64]) -> u64 {
    let model = ScalarModel::of(material);
    let mut h = crate::cache::Fnv1a::new();
    // "line", format 1; then the numbers, the angles and the heights as f64 bits.
    let words = [
        f64::from(0x6c69_6e65u32),
        1.0,
        hf.nx() as f64,
        hf.ny() as f64,
        hf.extent_um().0,
        hf.extent_um().1,
        model.shading.ior,
        model.coherence_um,
        f64::from(u8::from(model.shading.fresnel)),
        f64::from(u8::from(model.shading.shadowing)),
        MAP_TOLERANCE,
        SUMMARY_MIN_PERIODS,
    ];
    for &w in words.iter().chain(thetas_deg).chain(hf.heights_um()) {
        h.u64(w.to_bits());
    }
    h.finish()
}

fn read_line(path: &Path) -> Option<String> {
    let text = crate::fsutil::read_text_bounded(path, "validity cache", 1 << 16).ok()?;
    let line = text.lines().find(|l| l.starts_with("model check: "))?;
    Some(line.to_string())
}

fn write_line(path: &Path, line: &str) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::invalid("validity cache", e.to_string()))?;
    }
    crate::fsutil::write_atomic(path, format!("# diffract model check\n{line}\n").as_bytes())
}

/// FNV-1a over the profile and the model's numbers: the cache file's name.
fn cache_key(profile: &Profile, model: &ScalarModel) -> u64 {
    let mut words = vec![
        1.0, // format version
        profile.period_um,
        model.shading.ior,
        model.coherence_um,
        f64::from(u8::from(model.shading.fresnel)),
        f64::from(u8::from(model.shading.shadowing)),
        MAP_TOLERANCE,
    ];
    words.extend(&profile.heights_um);
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for w in words {
        for b in w.to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

/// Cached cells `(θi, λ, error)`, one per line; a missing or damaged file gives none.
fn read_cells(path: &Path) -> Vec<(f64, f64, f64)> {
    let Ok(text) = crate::fsutil::read_text_bounded(path, "validity cache", 1 << 20) else {
        return Vec::new();
    };
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| {
            let v: Vec<f64> = l
                .split_whitespace()
                .filter_map(|x| x.parse().ok())
                .collect();
            (v.len() == 3).then(|| (v[0], v[1], v[2]))
        })
        .collect()
}

fn write_cells(path: &Path, cells: &[(f64, f64, f64)]) -> Result<()> {
    let mut text =
        String::from("# diffract validity cells: theta_i_deg lambda_nm worst_order_ratio_error\n");
    for (t, l, e) in cells {
        text.push_str(&format!("{t} {l} {e:e}\n"));
    }
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::invalid("validity cache", e.to_string()))?;
    }
    crate::fsutil::write_atomic(path, text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_check_s_pace_is_its_cells_left_at_the_cpu_time_of_those_solved() {
        use std::sync::atomic::Ordering::Relaxed;
        let pace = CheckPace::new();
        assert_eq!(pace.left_s(), None, "before the cells");
        pace.left.store(4, Relaxed);
        assert_eq!(pace.left_s(), None, "before the first cell ends");
        pace.solved.store(2, Relaxed);
        pace.cpu_ns.store(1_000_000_000, Relaxed);
        pace.left.store(3, Relaxed);
        assert_eq!(pace.left_s(), Some(1.5));
        pace.left.store(0, Relaxed);
        assert_eq!(pace.left_s(), Some(0.0), "every cell solved");
    }

    #[test]
    fn a_thread_s_cpu_time_advances_with_its_work() {
        let t0 = thread_cpu_s();
        let mut x = 0u64;
        for i in 0..20_000_000u64 {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(i);
        }
        std::hint::black_box(x);
        assert!(thread_cpu_s() > t0, "{t0}");
    }
}
