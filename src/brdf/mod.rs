//! CPU evaluators of the diffraction BRDF, in f64 (MODEL §2, §6): the geometry shared by all
//! of them (`(u, v, w)`, the gain factor with Fresnel and shadowing), the direct-sum
//! [`reference`], the [`model`] of the GPU's FLSS algorithm, Bessel functions for the
//! Chebyshev expansion, and batch CSV [`query`]s. No Vulkan here.
//!
//! Directions are unit vectors in the tangent frame of MODEL §1: `N = (0,0,1)`, `x` along the
//! height-field columns; `ωi` points towards the light, `ωr` towards the eye.

pub mod bessel;
pub mod env_reference;
pub mod model;
pub mod nmm;
pub mod pq;
pub mod query;
pub mod rcwa;
pub mod reference;
pub mod table;
pub mod table_cache;
pub mod truncation;

/// Switches and constants of the gain factor `C(ωi, ωr)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shading {
    /// Multiply by the Schlick reflectance relative to normal incidence, `R/R0`.
    pub fresnel: bool,
    /// Multiply by Stam's V-cavity shadowing/masking `S`.
    pub shadowing: bool,
    /// Refractive index `n` (`R0 = ((n−1)/(n+1))²`).
    pub ior: f64,
}

impl Default for Shading {
    fn default() -> Self {
        Self {
            fresnel: true,
            shadowing: true,
            ior: 1.5,
        }
    }
}

impl Shading {
    /// Plain geometry: no Fresnel, no shadowing.
    pub const GEOMETRIC: Shading = Shading {
        fresnel: false,
        shadowing: false,
        ior: 1.5,
    };
}

/// Tangential components of `ωi + ωr` at or below this are rounding residue of unit
/// vectors (8 ulps of 1), not a direction.
const TANGENTIAL_RESIDUE: f64 = 8.0 * f64::EPSILON;

/// Unit vector of polar angle `theta_deg` from the normal and azimuth `phi_deg` from `+x`.
pub fn direction(theta_deg: f64, phi_deg: f64) -> [f64; 3] {
    let (st, ct) = theta_deg.to_radians().sin_cos();
    let (sp, cp) = phi_deg.to_radians().sin_cos();
    [st * cp, st * sp, ct]
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `(u, v, w) = −ωi − ωr` (MODEL §1).
pub fn uvw(wi: [f64; 3], wr: [f64; 3]) -> [f64; 3] {
    [-wi[0] - wr[0], -wi[1] - wr[1], -wi[2] - wr[2]]
}

/// Schlick reflectance at normal incidence, `R0 = ((n−1)/(n+1))²`.
pub fn schlick_r0(ior: f64) -> f64 {
    let r = (ior - 1.0) / (ior + 1.0);
    r * r
}

/// The gain factor `C(ωi, ωr)` of MODEL §2 with Stam's geometric term:
///
/// `C = [R/R0] · (1 + ωi·ωr)² / (w² cosθi cosθr) · [S]`, and `C = 0` when either cosine ≤ 0.
///
/// MODEL.md writes the denominator as `w² cosθr`; with that, a flat mirror seen in the
/// specular direction would give `ρ = cosθi`, not the documented 1. Stam's
/// `G = (1 + ωi·ωr)²/(cosθi cosθr)` restores `ρ = 1` (Fresnel off) at every angle, so that is
/// what every evaluator uses; renderers multiply by `cosθi` for irradiance.
///
/// **Grazing limit.** Write `ωi + ωr = (t, w)` with `t` the tangential part. Then
/// `(1 + ωi·ωr)² = (|t|² + w²)²/4` and the geometric term is `(|t|² + w²)²/(4w² cosθi cosθr)`.
/// Along the specular direction `t = 0` and `cosθi = cosθr = w/2`, so it is exactly 1 at
/// every angle; `H = N`, `ωr·H = cosθr → 0`, so Schlick's `R → 1` and `S = min(1, 2, 2) = 1`:
/// `C → 1/R0` (25 for `n = 1.5`) with Fresnel, 1 without, as `θ → 90°`. At exactly 90°
/// the directions built from angles carry `cos 90° ≈ 6e-17` and a tangential residue of the
/// same size (`sin 180° ≈ 1.2e-16`), which made `C` read 4 (66.7 with Fresnel). A
/// tangential sum below a few ulps of the unit components cannot be told from zero, so it
/// is taken as zero: the value at 90° is then the limit, and nothing changes where `|t|`
/// is resolvable. Away from specular the factor keeps its `1/(cosθi cosθr)` growth at
/// grazing (Kirchhoff's; shadowing tames it); the result stays finite for unit vectors.
pub fn gain(wi: [f64; 3], wr: [f64; 3], shading: &Shading) -> f64 {
    let (ci, cr) = (wi[2], wr[2]);
    if ci <= 0.0 || cr <= 0.0 {
        return 0.0;
    }
    let w = ci + cr;
    // 1 + ωi·ωr = |ωi + ωr|²/2, which does not cancel near grazing specular.
    let mut h = [wi[0] + wr[0], wi[1] + wr[1], wi[2] + wr[2]];
    if h[0].abs() <= TANGENTIAL_RESIDUE && h[1].abs() <= TANGENTIAL_RESIDUE {
        h[0] = 0.0;
        h[1] = 0.0;
    }
    let h2 = dot(h, h);
    let geometric = 0.25 * h2 * h2 / (w * w * ci * cr);
    let mut c = geometric;
    if shading.fresnel || shading.shadowing {
        let hl = h2.sqrt();
        // hl ≥ w > 0 here because both z components are positive.
        let h = [h[0] / hl, h[1] / hl, h[2] / hl];
        let cos_rh = dot(wr, h).clamp(0.0, 1.0);
        if shading.fresnel {
            let r0 = schlick_r0(shading.ior);
            let r = r0 + (1.0 - r0) * (1.0 - cos_rh).powi(5);
            c *= r / r0;
        }
        if shading.shadowing {
            c *= shadowing(h[2], ci, cr, cos_rh);
        }
    }
    if c.is_finite() {
        c
    } else {
        0.0
    }
}

/// `ρ_λ = C(ωi, ωr)·|P̂|²`, where `power` gives `|P̂|²` for `(u, v, w)`; `power` is not
/// called where `C = 0` (a direction below the horizon).
pub(crate) fn spectral(
    wi: [f64; 3],
    wr: [f64; 3],
    shading: &Shading,
    power: impl FnOnce([f64; 3]) -> f64,
) -> f64 {
    let c = gain(wi, wr, shading);
    if c == 0.0 {
        return 0.0;
    }
    c * power(uvw(wi, wr))
}

/// `XYZ = C(ωi, ωr)·Σ_λ |P̂|² w_λ`, where `integrated` gives the spectral sum for `(u, v, w)`.
pub(crate) fn integrated(
    wi: [f64; 3],
    wr: [f64; 3],
    shading: &Shading,
    integrated: impl FnOnce([f64; 3]) -> [f64; 3],
) -> [f64; 3] {
    let c = gain(wi, wr, shading);
    if c == 0.0 {
        return [0.0; 3];
    }
    integrated(uvw(wi, wr)).map(|x| x * c)
}

/// Stam's V-cavity shadowing/masking `S = min(1, 2(N·H)(N·ωr)/(ωr·H), 2(N·H)(N·ωi)/(ωr·H))`.
fn shadowing(n_h: f64, ci: f64, cr: f64, cos_rh: f64) -> f64 {
    if cos_rh <= 0.0 {
        return 0.0;
    }
    let k = 2.0 * n_h / cos_rh;
    1f64.min(k * cr).min(k * ci)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specular_gain_is_one_without_fresnel_at_every_angle() {
        for t in [0.0, 10.0, 45.0, 75.0, 89.0, 89.99] {
            let wi = direction(t, 30.0);
            let wr = direction(t, 210.0);
            let g = gain(
                wi,
                wr,
                &Shading {
                    fresnel: false,
                    ..Default::default()
                },
            );
            assert!((g - 1.0).abs() < 1e-12, "θ = {t}: C = {g}");
        }
    }

    #[test]
    fn fresnel_ratio_is_one_at_normal_incidence_and_grows_towards_grazing() {
        let s = Shading::default();
        let g0 = gain([0.0, 0.0, 1.0], [0.0, 0.0, 1.0], &s);
        assert!((g0 - 1.0).abs() < 1e-12);
        let g80 = gain(direction(80.0, 0.0), direction(80.0, 180.0), &s);
        assert!(g80 > 5.0, "R(80°)/R0 = {g80}");
    }

    #[test]
    fn gain_is_finite_and_non_negative_everywhere() {
        for ti in 0..=90 {
            for tr in 0..=90 {
                for pr in [0.0, 45.0, 90.0, 180.0, 270.0] {
                    let wi = direction(ti as f64, 0.0);
                    let wr = direction(tr as f64, pr);
                    for s in [Shading::default(), Shading::GEOMETRIC] {
                        let g = gain(wi, wr, &s);
                        assert!(g.is_finite() && g >= 0.0, "{ti} {tr} {pr}: {g}");
                    }
                }
            }
        }
        // ωi = ωr, exact grazing and below the horizon.
        let wi = direction(89.999_999, 0.0);
        assert!(gain(wi, wi, &Shading::default()).is_finite());
        assert_eq!(
            gain([1.0, 0.0, 0.0], direction(30.0, 0.0), &Shading::default()),
            0.0
        );
        assert_eq!(
            gain(
                direction(100.0, 0.0),
                direction(30.0, 0.0),
                &Shading::default()
            ),
            0.0
        );
    }
}
