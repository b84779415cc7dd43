//! A rigorous reference for the scalar model (MODEL §11): the Fourier modal method (RCWA)
//! for a 1-D surface-relief grating, in f64, on the CPU.
//!
//! **Geometry.** Air (`ε = 1`) above; a periodic profile `h(x)` of period `Λ` (sampled at
//! `M` points over one period, linear in between) cut into `S` horizontal slices of equal
//! thickness; a substrate of index `n` below. In a slice at height level `y`, the material
//! fills `h(x) > y` (its interval ends are the profile's level crossings, so the staircase
//! is exact for the linear profile and only the slicing approximates it).
//!
//! **Orders.** The light travels in the `xz` plane with `k_x = −k sinθi` (it comes from
//! the `+x` side, MODEL §1's `ωi = (sinθi, 0, cosθi)`); harmonic `m` has
//! `K_x,m = −sinθi + mλ/Λ`, and a propagating reflected order leaves along `ωr` with
//! `ωr,x = K_x,m`, i.e. `sinθr = −sinθi + mλ/Λ` (θr signed, positive on the `+x` side,
//! so specular is `θr = −θi`). That is the direction the scalar model puts the `m`-th
//! Fourier coefficient of `exp(i k w h)` (MODEL §2's `+i` transform at `u = −ωi,x − ωr,x =
//! −mλ/Λ`), with the same `exp(−iωt)` time convention.
//!
//! **Fields** (lengths in units of `1/k`, `z` pointing down into the grating).
//! - TE (`E_y = F`): `∂²F/∂z² = (K_x² − [[ε]]) F`; the other tangential field is `G = ∂F/∂z`.
//! - TM (`H_y = F`): with Li's inverse rule, `∂²F/∂z² = [[1/ε]]⁻¹ (K_x [[ε]]⁻¹ K_x − I) F`,
//!   and `G = E_x ∝ [[1/ε]] ∂F/∂z`: `E_x` is discontinuous where `εE_x` is not, so its
//!   product with `ε` is Fourier-factorised through `1/ε` (Li 1996, Lalanne & Morris 1996).
//!
//! A slice's modes `F = W (e^{−qz} a + e^{q(z−d)} b)`, `G = V (−e^{−qz} a + e^{q(z−d)} b)`
//! come from the eigen-decomposition `Ω = W q² W⁻¹` (`Re q ≥ 0`, downward for `Re q = 0`).
//! Amplitudes are referenced at the interface they leave from, so every exponential is
//! `|e^{−qd}| ≤ 1`, and the slices are chained by scattering matrices (Redheffer's star
//! product): no growing exponential is ever formed, whatever the depth.

use faer::prelude::*;
use faer::Mat;
use rayon::prelude::*;

use crate::spectrum::num_complex::Complex64 as C;
use crate::{Error, Result};

/// Polarisation of the incident plane wave.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Polarisation {
    /// Electric field along the grooves (`E_y`).
    Te,
    /// Magnetic field along the grooves (`H_y`).
    Tm,
}

/// A 1-D surface-relief grating on a substrate.
#[derive(Debug, Clone, PartialEq)]
pub struct Grating {
    /// Period `Λ` (µm).
    pub period_um: f64,
    /// Heights (µm) at `x = jΛ/M`, `j = 0..M`; periodic, linear between samples.
    pub profile_um: Vec<f64>,
    /// Complex refractive index of the material below the relief (`n + iκ`, `κ ≥ 0`).
    pub index: C,
}

impl Grating {
    /// Peak-to-valley depth (µm).
    pub fn depth_um(&self) -> f64 {
        let (lo, hi) = self.range();
        hi - lo
    }

    fn range(&self) -> (f64, f64) {
        self.profile_um
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &h| {
                (lo.min(h), hi.max(h))
            })
    }

    fn validate(&self) -> Result<()> {
        if !(self.period_um.is_finite() && self.period_um > 0.0) {
            return Err(Error::invalid(
                "rcwa",
                format!("period {} µm; must be > 0", self.period_um),
            ));
        }
        if self.profile_um.len() < 2 || self.profile_um.iter().any(|h| !h.is_finite()) {
            return Err(Error::invalid(
                "rcwa",
                "the profile needs at least 2 finite heights",
            ));
        }
        let n = self.index;
        if !(n.re.is_finite() && n.im.is_finite() && n.re > 0.0 && n.im >= 0.0) {
            return Err(Error::invalid(
                "rcwa",
                format!("index {n}; need Re n > 0 and Im n ≥ 0"),
            ));
        }
        Ok(())
    }

    /// Fourier coefficients `χ_k`, `k = −2N..=2N`, of the indicator of `h(x) > level` over
    /// one period (`χ_k = ∫₀¹ χ(t) e^{−2πikt} dt`, `t = x/Λ`), from the exact level
    /// crossings of the linear profile.
    fn indicator(&self, level: f64, n: usize) -> Vec<C> {
        let h = &self.profile_um;
        let m = h.len();
        // Crossings (t, entering): entering where the profile rises through `level`.
        let mut crossings: Vec<(f64, bool)> = Vec::new();
        for j in 0..m {
            let (a, b) = (h[j], h[(j + 1) % m]);
            let (ia, ib) = (a > level, b > level);
            if ia != ib {
                let f = (level - a) / (b - a);
                crossings.push(((j as f64 + f) / m as f64, ib));
            }
        }
        let mut intervals = Vec::new();
        if crossings.is_empty() {
            if h[0] > level {
                intervals.push((0.0, 1.0));
            }
        } else {
            // Each entering crossing opens an interval that the next crossing (cyclically)
            // closes: crossings alternate along a closed loop.
            let c = crossings.len();
            for i in 0..c {
                let (t, entering) = crossings[i];
                if entering {
                    let (mut end, _) = crossings[(i + 1) % c];
                    if end <= t {
                        end += 1.0;
                    }
                    intervals.push((t, end));
                }
            }
        }
        let two_pi = 2.0 * std::f64::consts::PI;
        (-(2 * n as i64)..=2 * n as i64)
            .map(|k| {
                intervals.iter().fold(C::new(0.0, 0.0), |acc, &(a, b)| {
                    if k == 0 {
                        acc + C::new(b - a, 0.0)
                    } else {
                        let w = -two_pi * k as f64;
                        // ∫_a^b e^{iwt} dt = (e^{iwb} − e^{iwa}) / (iw)
                        let e = C::from_polar(1.0, w * b) - C::from_polar(1.0, w * a);
                        acc + e / C::new(0.0, w)
                    }
                })
            })
            .collect()
    }
}

/// One propagating order's efficiency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Order {
    pub m: i64,
    /// `sinθ` of the order's direction in its medium (signed, `+x` side positive; in the
    /// substrate `n·sinθt = K_x,m`, this is `K_x,m / n`).
    pub sin_theta: f64,
    /// Share of the incident power.
    pub eta: f64,
}

/// Reflected and transmitted orders of one solve.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    pub reflected: Vec<Order>,
    pub transmitted: Vec<Order>,
    pub harmonics: usize,
    pub slices: usize,
}

impl Solution {
    /// `Σ η_R + Σ η_T` (1 for a lossless substrate).
    pub fn total(&self) -> f64 {
        self.reflected
            .iter()
            .chain(&self.transmitted)
            .map(|o| o.eta)
            .sum()
    }

    /// The reflected efficiency of order `m` (0 when it does not propagate).
    pub fn eta_r(&self, m: i64) -> f64 {
        self.reflected
            .iter()
            .find(|o| o.m == m)
            .map_or(0.0, |o| o.eta)
    }
}

/// A layer's modes: `F = W(…)`, `G = V(…)`, and the propagation constants `q`.
struct Modes {
    w: Mat<C>,
    v: Mat<C>,
    q: Vec<C>,
}

/// `q = √λ` on the branch of a downward wave: `Re q ≥ 0` (decaying into the structure),
/// and `Im q ≤ 0` when `Re q` is rounding residue (`e^{−qz}` then travels down).
fn branch(lambda: C) -> C {
    let q = lambda.sqrt();
    if q.re.abs() <= 1e-12 * q.norm() {
        C::new(0.0, -q.im.abs())
    } else {
        q
    }
}

fn diag(d: &[C]) -> Mat<C> {
    Mat::from_fn(d.len(), d.len(), |i, j| {
        if i == j {
            d[i]
        } else {
            C::new(0.0, 0.0)
        }
    })
}

/// Modes of a homogeneous medium of permittivity `eps`: plane waves, `W = I`.
fn homogeneous(kx: &[C], eps: C, pol: Polarisation) -> Modes {
    let q: Vec<C> = kx.iter().map(|&k| branch(k * k - eps)).collect();
    let g: Vec<C> = match pol {
        Polarisation::Te => q.clone(),
        Polarisation::Tm => q.iter().map(|&q| q / eps).collect(),
    };
    Modes {
        w: Mat::identity(kx.len(), kx.len()),
        v: diag(&g),
        q,
    }
}

/// Modes of a slice whose material fills the indicator `chi` (coefficients `−2N..=2N`).
fn slice_modes(kx: &[C], chi: &[C], eps: C, pol: Polarisation) -> Result<Modes> {
    let n = kx.len();
    let centre = n - 1; // index of k = 0 in chi (length 2n − 1)
    let one = C::new(1.0, 0.0);
    let toeplitz = |f: &dyn Fn(usize) -> C| Mat::from_fn(n, n, |i, j| f(centre + i - j));
    let delta = |k: usize| if k == centre { one } else { C::new(0.0, 0.0) };
    let e_mat = toeplitz(&|k| delta(k) + (eps - one) * chi[k]);
    let omega = match pol {
        Polarisation::Te => {
            let mut o = -&e_mat;
            for (i, &k) in kx.iter().enumerate() {
                o[(i, i)] += k * k;
            }
            o
        }
        Polarisation::Tm => {
            let p_mat = toeplitz(&|k| delta(k) + (one / eps - one) * chi[k]);
            let kx_d = diag(kx);
            let mut inner = &kx_d * e_mat.partial_piv_lu().solve(&kx_d);
            for i in 0..n {
                inner[(i, i)] -= one;
            }
            let o = p_mat.partial_piv_lu().solve(&inner);
            let v_factor = p_mat;
            return finish_modes(o, Some(v_factor));
        }
    };
    finish_modes(omega, None)
}

/// Eigen-decomposes `Ω` into modes; `V = P W q` (TM) or `W q` (TE).
fn finish_modes(omega: Mat<C>, p: Option<Mat<C>>) -> Result<Modes> {
    let eig = omega
        .eigen()
        .map_err(|e| Error::invalid("rcwa", format!("eigen-decomposition failed: {e:?}")))?;
    let w = eig.U().to_owned();
    let s = eig.S();
    let q: Vec<C> = (0..w.ncols())
        .map(|i| branch(s.column_vector()[i]))
        .collect();
    let wq = Mat::from_fn(w.nrows(), w.ncols(), |i, j| w[(i, j)] * q[j]);
    let v = match p {
        Some(p) => &p * &wq,
        None => wq,
    };
    Ok(Modes { w, v, q })
}

/// A scattering matrix: `[down out at the bottom; up out at the top] = [[td, rb], [rt, tu]]
/// · [down in at the top; up in at the bottom]`.
struct SMatrix {
    td: Mat<C>,
    rb: Mat<C>,
    rt: Mat<C>,
    tu: Mat<C>,
}

impl SMatrix {
    fn identity(n: usize) -> Self {
        Self {
            td: Mat::identity(n, n),
            rb: Mat::zeros(n, n),
            rt: Mat::zeros(n, n),
            tu: Mat::identity(n, n),
        }
    }

    /// The interface from `above` to `below`: continuity of `F` and `G` solved for the
    /// outgoing amplitudes (`A = ½(W'⁻¹W + V'⁻¹V)`, `B = ½(W'⁻¹W − V'⁻¹V)`).
    fn interface(above: &Modes, below: &Modes) -> Self {
        let ww = below.w.partial_piv_lu().solve(&above.w);
        let vv = below.v.partial_piv_lu().solve(&above.v);
        let a = (&ww + &vv) * Scale(C::new(0.5, 0.0));
        let b = (&ww - &vv) * Scale(C::new(0.5, 0.0));
        let lu = a.partial_piv_lu();
        let a_inv_b = lu.solve(&b);
        let n = a.nrows();
        let tu = lu.solve(&Mat::<C>::identity(n, n));
        Self {
            td: &a - &b * &a_inv_b,
            rb: &b * &tu,
            rt: -a_inv_b,
            tu,
        }
    }

    /// Carries the bottom reference through a layer of transmission `x = e^{−qd}`.
    fn propagate(&mut self, x: &[C]) {
        let n = x.len();
        for i in 0..n {
            for j in 0..n {
                self.td[(i, j)] *= x[i];
                self.rb[(i, j)] *= x[i] * x[j];
                self.tu[(i, j)] *= x[j];
            }
        }
    }

    /// Redheffer's star product: `self` on top of `below`.
    fn star(&self, below: &SMatrix) -> Self {
        let n = self.td.nrows();
        let eye = Mat::<C>::identity(n, n);
        let lu1 = (&eye - &self.rb * &below.rt).partial_piv_lu();
        let lu2 = (&eye - &below.rt * &self.rb).partial_piv_lu();
        let m1_td = lu1.solve(&self.td);
        let m1_rb_tu = lu1.solve(&self.rb * &below.tu);
        let m2_rt_td = lu2.solve(&below.rt * &self.td);
        let m2_tu = lu2.solve(&below.tu);
        Self {
            td: &below.td * &m1_td,
            rb: &below.rb + &below.td * &m1_rb_tu,
            rt: &self.rt + &self.tu * &m2_rt_td,
            tu: &self.tu * &m2_tu,
        }
    }
}

/// Solves the grating for light at `theta_i_deg` (from the `+x` side), wavelength
/// `lambda_um`, `2·harmonics + 1` Fourier orders and `slices` slices.
pub fn solve(
    grating: &Grating,
    lambda_um: f64,
    theta_i_deg: f64,
    pol: Polarisation,
    harmonics: usize,
    slices: usize,
) -> Result<Solution> {
    grating.validate()?;
    if !(lambda_um.is_finite() && lambda_um > 0.0) {
        return Err(Error::invalid("rcwa", format!("wavelength {lambda_um} µm")));
    }
    if !(theta_i_deg.is_finite() && theta_i_deg.abs() < 90.0) {
        return Err(Error::invalid(
            "rcwa",
            format!("θi = {theta_i_deg}°; must be in (−90, 90)"),
        ));
    }
    let count = 2 * harmonics + 1;
    let nh = harmonics as i64;
    let s = theta_i_deg.to_radians().sin();
    let ratio = lambda_um / grating.period_um;
    let kx: Vec<C> = (-nh..=nh)
        .map(|m| C::new(-s + m as f64 * ratio, 0.0))
        .collect();
    let eps_sub = grating.index * grating.index;
    let air = homogeneous(&kx, C::new(1.0, 0.0), pol);
    let sub = homogeneous(&kx, eps_sub, pol);
    let (lo, hi) = grating.range();
    let depth = hi - lo;
    let k0d = 2.0 * std::f64::consts::PI / lambda_um * depth;
    let layers = if depth > 0.0 { slices.max(1) } else { 0 };
    // The slices' modes and the interfaces between them are independent of each other;
    // only the chaining of the interfaces is sequential.
    let modes: Vec<Modes> = (0..layers)
        .into_par_iter()
        .map(|l| {
            let level = hi - (l as f64 + 0.5) * depth / layers as f64;
            slice_modes(&kx, &grating.indicator(level, harmonics), eps_sub, pol)
        })
        .collect::<Result<_>>()?;
    let interfaces: Vec<SMatrix> = (0..=layers)
        .into_par_iter()
        .map(|i| {
            let above = if i == 0 { &air } else { &modes[i - 1] };
            let below = modes.get(i).unwrap_or(&sub);
            SMatrix::interface(above, below)
        })
        .collect();
    let mut total = SMatrix::identity(count);
    for (i, interface) in interfaces.iter().enumerate() {
        total = total.star(interface);
        if let Some(m) = modes.get(i) {
            let x: Vec<C> =
                m.q.iter()
                    .map(|&q| (-q * (k0d / layers as f64)).exp())
                    .collect();
            total.propagate(&x);
        }
    }
    // Incident: unit amplitude in harmonic 0 (index nh), from the air.
    let inc = nh as usize;
    // Power along z: Re(β)/ε^{(TM)} |amplitude|², β = i q.
    let flux = |q: C, eps: C| -> f64 {
        let beta = C::new(0.0, 1.0) * q;
        match pol {
            Polarisation::Te => beta.re,
            Polarisation::Tm => (beta / eps).re,
        }
    };
    let incident = flux(air.q[inc], C::new(1.0, 0.0));
    let mut reflected = Vec::new();
    let mut transmitted = Vec::new();
    for (i, m) in (-nh..=nh).enumerate() {
        let fr = flux(air.q[i], C::new(1.0, 0.0));
        if fr > 0.0 && kx[i].re.abs() < 1.0 {
            reflected.push(Order {
                m,
                sin_theta: kx[i].re,
                eta: total.rt[(i, inc)].norm_sqr() * fr / incident,
            });
        }
        let ft = flux(sub.q[i], eps_sub);
        if ft > 0.0 && kx[i].re * kx[i].re < eps_sub.re {
            transmitted.push(Order {
                m,
                sin_theta: kx[i].re / grating.index.re,
                eta: total.td[(i, inc)].norm_sqr() * ft / incident,
            });
        }
    }
    Ok(Solution {
        reflected,
        transmitted,
        harmonics,
        slices: layers,
    })
}

/// TE and TM solved with the same harmonics and slices.
#[derive(Debug, Clone, PartialEq)]
pub struct Pair {
    pub te: Solution,
    pub tm: Solution,
}

impl Pair {
    /// Both polarisations at `2·harmonics + 1` orders and `slices` slices.
    pub fn solve(
        grating: &Grating,
        lambda_um: f64,
        theta_i_deg: f64,
        harmonics: usize,
        slices: usize,
    ) -> Result<Pair> {
        let (te, tm) = rayon::join(
            || {
                solve(
                    grating,
                    lambda_um,
                    theta_i_deg,
                    Polarisation::Te,
                    harmonics,
                    slices,
                )
            },
            || {
                solve(
                    grating,
                    lambda_um,
                    theta_i_deg,
                    Polarisation::Tm,
                    harmonics,
                    slices,
                )
            },
        );
        Ok(Pair { te: te?, tm: tm? })
    }

    /// Unpolarised reflected efficiency of order `m`, `(η_TE + η_TM)/2`.
    pub fn eta_unpolarised(&self, m: i64) -> f64 {
        0.5 * (self.te.eta_r(m) + self.tm.eta_r(m))
    }

    /// The largest change of a reflected order's efficiency from `other`, relative to the
    /// order's efficiency, or to [`FAINT_SHARE`] of the total reflectance for fainter
    /// orders (whose relative error says nothing about the picture). Both polarisations.
    pub fn change_from(&self, other: &Pair) -> f64 {
        let mut worst = 0.0f64;
        for (a, b) in [(&self.te, &other.te), (&self.tm, &other.tm)] {
            let total: f64 = a.reflected.iter().map(|o| o.eta).sum();
            let floor = FAINT_SHARE * total;
            for o in &a.reflected {
                let d = (o.eta - b.eta_r(o.m)).abs();
                worst = worst.max(d / o.eta.max(floor).max(f64::MIN_POSITIVE));
            }
        }
        worst
    }
}

/// Orders below this share of the total reflectance count with that share as their size in
/// the convergence test ([`Pair::change_from`]).
pub const FAINT_SHARE: f64 = 1e-3;

/// Default convergence tolerance of [`converge`]: every reflected order within 2 % (the
/// verdicts are at 10 % and 25 %).
pub const DEFAULT_TOLERANCE: f64 = 0.02;
/// Most harmonics `N` (orders `−N..=N`) [`converge`] tries.
pub const MAX_HARMONICS: usize = 60;
/// Most slices [`converge`] tries.
pub const MAX_SLICES: usize = 128;
/// Slices [`converge`] starts from.
pub const FIRST_SLICES: usize = 16;

/// A converged solve and how far the last refinement moved it.
#[derive(Debug, Clone, PartialEq)]
pub struct Converged {
    pub pair: Pair,
    /// [`Pair::change_from`] between the last two harmonic counts.
    pub harmonic_change: f64,
    /// [`Pair::change_from`] between the last two slice counts.
    pub slice_change: f64,
}

impl Converged {
    /// Whether both refinements met `tolerance`.
    pub fn met(&self, tolerance: f64) -> bool {
        self.harmonic_change <= tolerance && self.slice_change <= tolerance
    }
}

/// The harmonics a grating needs at least: every order that propagates in the substrate
/// and a margin of evanescent ones.
pub fn first_harmonics(grating: &Grating, lambda_um: f64) -> usize {
    ((1.0 + grating.index.re) * grating.period_um / lambda_um).ceil() as usize + 5
}

/// Raises the harmonics (at [`FIRST_SLICES`] slices) until no reflected order moves by more
/// than `tolerance` ([`Pair::change_from`]), then doubles the slices at those harmonics
/// until the same holds; stops at [`MAX_HARMONICS`] and [`MAX_SLICES`] (check
/// [`Converged::met`]). `start` overrides the first harmonics and slices. Each count is
/// refined at least once, so both changes are measured (a solve that starts at a cap is
/// started one step below it): a change above `tolerance` is the estimated error of the
/// answer, never a placeholder.
pub fn converge(
    grating: &Grating,
    lambda_um: f64,
    theta_i_deg: f64,
    tolerance: f64,
    start: Option<(usize, usize)>,
) -> Result<Converged> {
    let (n0, s0) = start.unwrap_or((first_harmonics(grating, lambda_um), FIRST_SLICES));
    // A long period asks for more harmonics than the cap: start one step below it (45 + 15 =
    // 60), so that one solve never costs more than a converged one may and the last step is
    // still a measured refinement.
    let (mut n, mut s) = (n0.min(MAX_HARMONICS * 3 / 4), s0.clamp(1, MAX_SLICES / 2));
    let mut pair = Pair::solve(grating, lambda_um, theta_i_deg, n, s)?;
    let mut harmonic_change = f64::INFINITY;
    loop {
        let next = (n + (n / 3).max(4)).min(MAX_HARMONICS);
        if next <= n {
            break;
        }
        let finer = Pair::solve(grating, lambda_um, theta_i_deg, next, s)?;
        harmonic_change = finer.change_from(&pair);
        n = next;
        pair = finer;
        if harmonic_change <= tolerance {
            break;
        }
    }
    let mut slice_change = 0.0;
    if grating.depth_um() > 0.0 {
        while 2 * s <= MAX_SLICES {
            let finer = Pair::solve(grating, lambda_um, theta_i_deg, n, 2 * s)?;
            slice_change = finer.change_from(&pair);
            s *= 2;
            pair = finer;
            if slice_change <= tolerance {
                break;
            }
        }
    }
    Ok(Converged {
        pair,
        harmonic_change,
        slice_change,
    })
}

/// Fresnel reflectances `(R_s, R_p)` of a flat interface from air to index `n`.
pub fn fresnel(index: C, theta_i_deg: f64) -> (f64, f64) {
    let (s, c) = theta_i_deg.to_radians().sin_cos();
    let eps = index * index;
    let ct = (eps - s * s).sqrt();
    let rs = (c - ct) / (c + ct);
    let rp = (eps * c - ct) / (eps * c + ct);
    (rs.norm_sqr(), rp.norm_sqr())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sinusoid(period_um: f64, depth_um: f64, n: f64) -> Grating {
        let m = 128;
        Grating {
            period_um,
            profile_um: (0..m)
                .map(|j| {
                    let t = j as f64 / m as f64;
                    0.5 * depth_um * (1.0 + (2.0 * std::f64::consts::PI * t).cos())
                })
                .collect(),
            index: C::new(n, 0.0),
        }
    }

    #[test]
    fn flat_surface_gives_the_fresnel_reflectances() {
        for n in [1.5, 1.55, 2.4] {
            let g = Grating {
                period_um: 1.0,
                profile_um: vec![0.3; 8],
                index: C::new(n, 0.0),
            };
            for t in [0.0, 20.0, 45.0, 56.3, 70.0, 85.0] {
                let (rs, rp) = fresnel(g.index, t);
                let p = Pair::solve(&g, 0.55, t, 6, 4).unwrap();
                let (te, tm) = (p.te.eta_r(0), p.tm.eta_r(0));
                assert!((te - rs).abs() < 1e-12, "n {n} θ {t}: TE {te} vs {rs}");
                assert!((tm - rp).abs() < 1e-12, "n {n} θ {t}: TM {tm} vs {rp}");
                for m in [-2, -1, 1, 2] {
                    assert!(p.te.eta_r(m) < 1e-24 && p.tm.eta_r(m) < 1e-24);
                }
                assert!((p.te.total() - 1.0).abs() < 1e-12);
                assert!((p.tm.total() - 1.0).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn a_lossless_grating_conserves_energy() {
        for (period, depth) in [(1.14, 0.43), (2.5, 0.25), (0.8, 1.0)] {
            let g = sinusoid(period, depth, 1.55);
            for t in [0.0, 30.0, 60.0, -45.0] {
                let p = Pair::solve(&g, 0.45, t, 20, 24).unwrap();
                for s in [&p.te, &p.tm] {
                    let e = (s.total() - 1.0).abs();
                    assert!(e < 1e-8, "Λ {period} d {depth} θ {t}: |R+T−1| = {e:e}");
                }
            }
        }
    }

    #[test]
    fn lossy_substrate_absorbs_and_still_reflects_the_fresnel_value() {
        let g = Grating {
            period_um: 1.0,
            profile_um: vec![0.0; 4],
            index: C::new(1.5, 0.1),
        };
        let (rs, rp) = fresnel(g.index, 30.0);
        let p = Pair::solve(&g, 0.5, 30.0, 4, 1).unwrap();
        assert!((p.te.eta_r(0) - rs).abs() < 1e-12);
        assert!((p.tm.eta_r(0) - rp).abs() < 1e-12);
    }

    #[test]
    fn efficiencies_converge_with_harmonics_and_slices() {
        let g = sinusoid(1.14, 0.43, 1.55);
        let eta = |n, s| {
            let p = Pair::solve(&g, 0.5, 30.0, n, s).unwrap();
            [-1, 0, 1].map(|m| (p.te.eta_r(m), p.tm.eta_r(m)))
        };
        let diff = |a: [(f64, f64); 3], b: [(f64, f64); 3]| {
            a.iter()
                .zip(&b)
                .map(|(x, y)| (x.0 - y.0).abs().max((x.1 - y.1).abs()))
                .fold(0.0, f64::max)
        };
        // Harmonics at 32 slices.
        let best = eta(40, 32);
        let (h8, h16, h28) = (
            diff(eta(8, 32), best),
            diff(eta(16, 32), best),
            diff(eta(28, 32), best),
        );
        assert!(
            h28 < h16 && h16 < h8 && h28 < 1e-4,
            "{h8:e} {h16:e} {h28:e}"
        );
        // Slices at 25 harmonics.
        let best = eta(25, 256);
        let (s8, s32, s128) = (
            diff(eta(25, 8), best),
            diff(eta(25, 32), best),
            diff(eta(25, 128), best),
        );
        assert!(
            s128 < s32 && s32 < s8 && s128 < 1e-4,
            "{s8:e} {s32:e} {s128:e}"
        );
        // The automatic choice meets its tolerance.
        let c = converge(&g, 0.5, 30.0, DEFAULT_TOLERANCE, None).unwrap();
        assert!(
            c.met(DEFAULT_TOLERANCE),
            "{} {}",
            c.harmonic_change,
            c.slice_change
        );
    }
}
