//! A scene's ambient light as what it is: a uniform sky, an environment of one radiance
//! `L` in every direction (MODEL §10). The sun-lit pass adds it in closed form, so that a
//! scene renders the same picture whether its sky is `[texture] ambient` or a map of that
//! radiance.
//!
//! Per direction a surface reflects thesis Algorithm 4 with absolute units (as the
//! environment-lit stages do, glsl/env_common.glsl):
//! `L·cos θi·[(1 − w_d)·f_r + ((1 − α) + w_d)·t]`, `α` the Schlick reflectance at the half
//! vector. Under a uniform `L` the hemisphere's integrals are:
//! - **the texture part**, `L·t·[π(1 + w_d) − A_α(θr)]` with
//!   `A_α(θr) = ∫ α cos θi dωi = π·R0 + (1 − R0)·J(θr)` and
//!   `J(θr) = ∫ (1 − ωr·h)⁵ cos θi dωi`. `ωr·h = √((1 + ωi·ωr)/2)`, so `J` depends on `θr`
//!   alone; it is tabulated here in f64 ([`fresnel_tail`]) and read linearly in `cos θr`
//!   by the shader ([`TAIL_NODES`] nodes);
//! - **the diffraction part**, `L·(1 − w_d)·∫ f_r cos θi dωi`, which for a lobe about the
//!   mirror direction is the mirror's `R(θr)` (Schlick's with Fresnel on, 1 without: the
//!   white furnace, MODEL §10; shadowing is 1 at the mirror direction), in white. A lobe
//!   that reaches past the horizon reflects less; the closed form is exact for a mirror.
//!
//! `[texture] ambient` is the sky's irradiance on a surface facing up, relative to the
//! light's intensity `I`: `L = ambient·I/π`.

use std::f64::consts::PI;
use std::sync::OnceLock;

/// Nodes of [`fresnel_tail`] in `cos θr ∈ [0, 1]`, evenly spaced (the shader's table).
pub const TAIL_NODES: usize = 16;

/// `J(cos θr) = ∫_H (1 − ωr·h)⁵ cos θi dωi` in f64 (module notes), by a product midpoint
/// rule in `cos θi` and azimuth (the integrand is smooth; 512² points hold it to 1e-7).
pub fn fresnel_tail(cos_r: f64) -> f64 {
    let c = cos_r.clamp(0.0, 1.0);
    let s = (1.0 - c * c).sqrt();
    let n = 512;
    let mut sum = 0.0;
    for i in 0..n {
        let mu = (i as f64 + 0.5) / n as f64;
        let st = (1.0 - mu * mu).sqrt();
        let mut ring = 0.0;
        // Symmetric in azimuth about the plane of ωr: half the circle, twice.
        for j in 0..n {
            let phi = PI * (j as f64 + 0.5) / n as f64;
            let dot = st * phi.cos() * s + mu * c;
            let cos_h = ((1.0 + dot) / 2.0).max(0.0).sqrt();
            ring += (1.0 - cos_h).powi(5);
        }
        sum += mu * ring * 2.0 * PI / n as f64;
    }
    sum / n as f64
}

/// [`fresnel_tail`] at the shader's nodes `cos θr = i/(TAIL_NODES − 1)`, computed once.
pub fn tail_table() -> &'static [f64; TAIL_NODES] {
    static TABLE: OnceLock<[f64; TAIL_NODES]> = OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|i| fresnel_tail(i as f64 / (TAIL_NODES - 1) as f64)))
}

/// `J` read from [`tail_table`] as the shader reads it (linear in `cos θr`).
pub fn tail_lookup(cos_r: f64) -> f64 {
    let t = tail_table();
    let x = cos_r.clamp(0.0, 1.0) * (TAIL_NODES - 1) as f64;
    let i = (x.floor() as usize).min(TAIL_NODES - 2);
    let f = x - i as f64;
    t[i] * (1.0 - f) + t[i + 1] * f
}

/// A uniform sky of radiance `radiance` (in the light's units per steradian).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UniformSky {
    pub radiance: f64,
}

impl UniformSky {
    /// The sky of `[texture] ambient`: irradiance `ambient·intensity` on a surface facing
    /// up.
    pub fn of_ambient(ambient: f64, intensity: f64) -> Self {
        Self {
            radiance: ambient * intensity / PI,
        }
    }

    /// What the sky reflects towards `ωr` (`cos θr`), per linear-sRGB channel: the
    /// diffraction part in white over `scale` (the picture's radiance scale,
    /// [`crate::brdf::table::Response::scale`]) plus the texture part of albedo `t` (on
    /// the picture's scale already, as `[texture] gain` gives it). `r0`: Schlick's `R0`,
    /// which Algorithm 4's `α` uses whether or not the BRDF has Fresnel on (`fresnel`).
    pub fn reflected(
        &self,
        cos_r: f64,
        t: [f64; 3],
        w_diffuse: f64,
        (r0, fresnel): (f64, bool),
        scale: f64,
    ) -> [f64; 3] {
        let c = cos_r.clamp(0.0, 1.0);
        let mirror = if fresnel {
            r0 + (1.0 - r0) * (1.0 - c).powi(5)
        } else {
            1.0
        };
        let a_alpha = PI * r0 + (1.0 - r0) * tail_lookup(c);
        let texture = PI * (1.0 + w_diffuse) - a_alpha;
        let diffraction = (1.0 - w_diffuse) * mirror / scale;
        t.map(|tc| self.radiance * (diffraction + tc * texture))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `J` against an independent estimate: uniform directions on the hemisphere (a
    /// different parametrisation: `ωi` by its Cartesian components, the half vector
    /// normalised explicitly) with a fixed low-discrepancy sequence.
    #[test]
    fn the_fresnel_tail_matches_a_second_quadrature() {
        for cos_r in [0.0, 0.1, 0.35, 0.7, 1.0] {
            let wr = glam::DVec3::new((1.0f64 - cos_r * cos_r).sqrt(), 0.0, cos_r);
            let n = 400_000;
            let g = 1.324_717_957_244_746;
            let (a1, a2) = (1.0 / g, 1.0 / (g * g));
            let mut sum = 0.0;
            for k in 0..n {
                let (x, y) = ((0.5 + a1 * k as f64).fract(), (0.5 + a2 * k as f64).fract());
                // Uniform on the hemisphere: z = x, φ = 2πy; density 1/(2π).
                let z = x;
                let r = (1.0 - z * z).sqrt();
                let wi = glam::DVec3::new(r * (2.0 * PI * y).cos(), r * (2.0 * PI * y).sin(), z);
                let h = (wi + wr).normalize();
                sum += (1.0 - wr.dot(h)).powi(5) * z * 2.0 * PI;
            }
            let mc = sum / n as f64;
            let j = fresnel_tail(cos_r);
            assert!(
                (j - mc).abs() < 2e-4 * j.max(1e-3),
                "cos θr {cos_r}: J {j} vs {mc}"
            );
            // The table's linear reading: J enters beside π(1 + w_d) ≥ π, so an absolute
            // error of 5e-4 is 1.6e-4 of the sky's texture part at most.
            let read = tail_lookup(cos_r);
            assert!(
                (read - j).abs() < 5e-4,
                "cos θr {cos_r}: table {read} vs {j}"
            );
        }
    }

    /// A white furnace of radiance 1 over a flat mirror without texture reflects `R(θr)`
    /// on the scale 1, and the texture part of a white albedo is `π(1 + w_d) − A_α`.
    #[test]
    fn the_sky_reflects_the_mirror_and_the_albedo() {
        let sky = UniformSky { radiance: 1.0 };
        let r0 = 0.04;
        let no_texture = sky.reflected(1.0, [0.0; 3], 0.0, (r0, true), 1.0);
        assert!((no_texture[0] - r0).abs() < 1e-12);
        let off = sky.reflected(0.5, [0.0; 3], 0.0, (r0, false), 1.0);
        assert!((off[1] - 1.0).abs() < 1e-12);
        let albedo = sky.reflected(1.0, [1.0; 3], 0.3, (r0, true), f64::INFINITY);
        let want = PI * 1.3 - PI * r0 - (1.0 - r0) * fresnel_tail(1.0);
        assert!((albedo[2] - want).abs() < 1e-9, "{albedo:?} {want}");
        assert_eq!(UniformSky::of_ambient(0.5, 2.0).radiance, 1.0 / PI);
    }
}
