//! The stored representations of `G` with their f64 CPU models, which interpolate exactly as
//! the GPU variants do: [`Volume`] (trilinear in `(u, v, w)`), [`ChebyshevW`] (bilinear
//! coefficients of a Chebyshev series in `w`, Clenshaw) and [`Dhillon`] (bilinear
//! coefficients of powers of `w`, Horner).

use rayon::prelude::*;

use crate::brdf::{integrated, Shading};
use crate::heightfield::HeightField;
use crate::{Error, Result};

use super::spline::{bilinear, grid_pos, spline, spline_plane};
use super::{chebyshev_nodes, sample_g, uniform_nodes, Region, Slices, TableSpec};

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

    /// Levels of the stored planes pre-filtered for a pixel's footprint
    /// ([`super::Levelled`]); 1: the planes are the table alone.
    fn footprint_levels(&self) -> usize {
        1
    }

    /// Summed-area planes of the node values, `(nu + 1) × (nv + 1)` each, for box reads at
    /// a pixel's footprint ([`super::Summed`]); `None` where the table has none.
    fn summed(&self) -> Option<Vec<Vec<[f64; 3]>>> {
        None
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

/// A table chosen at run time (`chebyshev-w`'s levels or summed-area planes): every method
/// is the boxed table's.
impl GTable for Box<dyn GTable> {
    fn region(&self) -> &Region {
        (**self).region()
    }
    fn g_unclamped(&self, uvw: [f64; 3]) -> Option<[f64; 3]> {
        (**self).g_unclamped(uvw)
    }
    fn g(&self, uvw: [f64; 3]) -> Option<[f64; 3]> {
        (**self).g(uvw)
    }
    fn planes(&self) -> &[Vec<[f64; 3]>] {
        (**self).planes()
    }
    fn nodes_uv(&self) -> (usize, usize) {
        (**self).nodes_uv()
    }
    fn plane_dims(&self) -> (usize, usize) {
        (**self).plane_dims()
    }
    fn footprint_levels(&self) -> usize {
        (**self).footprint_levels()
    }
    fn summed(&self) -> Option<Vec<Vec<[f64; 3]>>> {
        (**self).summed()
    }
    fn conditioning(&self) -> Option<f64> {
        (**self).conditioning()
    }
    fn f32_error(&self) -> Option<f64> {
        (**self).f32_error()
    }
    fn xyz(&self, shading: &Shading, wi: [f64; 3], wr: [f64; 3]) -> [f64; 3] {
        (**self).xyz(shading, wi, wr)
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
        Self::from_nodes_within(region, slices, None).0
    }

    /// [`Self::from_nodes`] with its highest terms dropped as [`Self::truncate`] drops
    /// them at `tolerance` before the splines are fitted (only the kept terms are fitted);
    /// also what was dropped. `None` keeps every term.
    pub fn from_nodes_within(
        region: Region,
        slices: &Slices,
        tolerance: Option<f64>,
    ) -> (Self, Truncation) {
        let (mut table, truncation) = Self::coefficients_within(region, slices, tolerance);
        table.fit_splines();
        (table, truncation)
    }

    /// [`Self::from_nodes_within`] without the splines, for a caller that reads the
    /// coefficients alone or fits the splines later ([`Self::fit_splines`]).
    pub fn coefficients_within(
        region: Region,
        slices: &Slices,
        tolerance: Option<f64>,
    ) -> (Self, Truncation) {
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
        let mut table = Self {
            region,
            nu: slices.nu,
            nv: slices.nv,
            coeffs,
            splines: Vec::new(),
        };
        let decay = table.decay();
        let peak = table.peak_c0();
        let dropped = tolerance.map_or(0, |t| table.truncate(t));
        let truncation = Truncation {
            kept: k - dropped,
            of: k,
            tail: decay[k - dropped..].iter().sum(),
            peak,
        };
        (table, truncation)
    }

    /// Fits the splines of the coefficient planes ([`Self::splines`]), which
    /// [`Self::coefficients_within`] leaves empty.
    pub fn fit_splines(&mut self) {
        self.splines = self.spline_planes();
    }

    /// The splines of the coefficient planes, as [`Self::fit_splines`] fits them, for a
    /// caller that holds them apart from the table ([`Self::g_with`]).
    pub fn spline_planes(&self) -> Vec<Vec<[f64; 3]>> {
        let (nu, nv) = (self.nu, self.nv);
        self.coeffs
            .par_iter()
            .map(|c| spline_plane(c, nu, nv))
            .collect()
    }

    /// [`GTable::g_unclamped`] with the spline planes `splines` of this table's
    /// coefficients ([`Self::spline_planes`]) in place of its own.
    pub fn g_with(&self, splines: &[Vec<[f64; 3]>], [u, v, w]: [f64; 3]) -> Option<[f64; 3]> {
        if !(w >= self.region.lo[2] && w <= self.region.hi[2]) {
            return None;
        }
        let c: Option<Vec<[f64; 3]>> = splines
            .iter()
            .map(|p| spline(p, self.nu, self.nv, &self.region, u, v))
            .collect();
        Some(clenshaw(&c?, self.w_hat(w)))
    }

    /// `ŵ ∈ [−1, 1]` of `w`.
    pub fn w_hat(&self, w: f64) -> f64 {
        let (lo, hi) = (self.region.lo[2], self.region.hi[2]);
        (2.0 * w - lo - hi) / (hi - lo)
    }

    /// The largest `|c_j|` (over texels and channels) relative to the largest `|c_0|`, per
    /// `j`: how fast the series decays.
    pub fn decay(&self) -> Vec<f64> {
        let c0 = self.peak_c0().max(f64::MIN_POSITIVE);
        self.coeffs.iter().map(|c| largest(c) / c0).collect()
    }

    /// The largest `|c_0|` over texels and channels: what [`Self::decay`] is relative to.
    pub fn peak_c0(&self) -> f64 {
        self.coeffs.first().map_or(0.0, |c| largest(c))
    }

    /// Drops the highest terms while the sum of their [`Self::decay`] stays within
    /// `tolerance` (relative to the largest `|c_0|`: a bound on what they add to `G`, since
    /// `|T_j| ≤ 1`); keeps at least one. Returns the terms dropped.
    pub fn truncate(&mut self, tolerance: f64) -> usize {
        let decay = self.decay();
        let mut keep = decay.len();
        let mut tail = 0.0;
        while keep > 1 && tail + decay[keep - 1] <= tolerance {
            tail += decay[keep - 1];
            keep -= 1;
        }
        let dropped = self.coeffs.len() - keep;
        self.coeffs.truncate(keep);
        self.splines.truncate(keep);
        dropped
    }
}

/// The largest magnitude of a plane, over texels and channels.
fn largest(plane: &[[f64; 3]]) -> f64 {
    plane.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// The terms [`ChebyshevW::from_nodes_within`] kept of a series, and the most those it
/// dropped add to `G`: `tail · peak` (`|T_j| ≤ 1`), per channel, at the nodes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truncation {
    pub kept: usize,
    /// The terms the nodes gave.
    pub of: usize,
    /// The dropped terms' [`ChebyshevW::decay`] summed (0 when none were).
    pub tail: f64,
    /// The largest `|c_0|` ([`ChebyshevW::peak_c0`]), in `G`'s units.
    pub peak: f64,
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
    fn g_unclamped(&self, uvw: [f64; 3]) -> Option<[f64; 3]> {
        self.g_with(&self.splines, uvw)
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

/// A `chebyshev-w` table for unit tests: `nu × nv` nodes over a small region (u in ±0.1,
/// v in ±0.05, w in [−2, 0]), two coefficient planes, plane `j`'s XYZ at node `(i, k)`
/// `g, 2g, 3g` with `g = f(i, k, j)`.
#[cfg(test)]
pub(crate) fn test_chebyshev_w(
    nu: usize,
    nv: usize,
    f: impl Fn(usize, usize, usize) -> f64,
) -> ChebyshevW {
    let region = Region {
        lo: [-0.1, -0.05, -2.0],
        hi: [0.1, 0.05, 0.0],
    };
    let coeffs: Vec<Vec<[f64; 3]>> = (0..2)
        .map(|j| {
            (0..nu * nv)
                .map(|p| {
                    let g = f(p % nu, p / nu, j);
                    [g, 2.0 * g, 3.0 * g]
                })
                .collect()
        })
        .collect();
    let splines = coeffs
        .iter()
        .map(|c| super::spline::spline_plane(c, nu, nv))
        .collect();
    ChebyshevW {
        region,
        nu,
        nv,
        coeffs,
        splines,
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn truncation_drops_only_the_terms_within_the_tolerance() {
        // Planes of constant coefficients 1, 0.5, 1e-3, 4e-5, 3e-5, 2e-5 (one texel field).
        let (nu, nv) = (4, 4);
        let values = [1.0, 0.5, 1e-3, 4e-5, 3e-5, 2e-5];
        let coeffs: Vec<Vec<[f64; 3]>> = values.iter().map(|&c| vec![[c; 3]; nu * nv]).collect();
        let splines = coeffs.iter().map(|c| spline_plane(c, nu, nv)).collect();
        let region = Region {
            lo: [-1.0, -1.0, -2.0],
            hi: [1.0, 1.0, 0.0],
        };
        let table = ChebyshevW {
            region,
            nu,
            nv,
            coeffs,
            splines,
        };
        // The tail 2e-5 + 3e-5 + 4e-5 = 9e-5 fits 1e-4; adding 1e-3 does not.
        let mut t = table.clone();
        assert_eq!(t.truncate(1e-4), 3);
        assert_eq!((t.coeffs.len(), t.splines.len()), (3, 3));
        let mut t = table.clone();
        assert_eq!(t.truncate(4e-5), 1);
        let mut t = table.clone();
        assert_eq!(t.truncate(10.0), 5, "at least one term stays");
        let mut t = table;
        assert_eq!(t.truncate(0.0), 0);
    }

    use super::*;

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
}
