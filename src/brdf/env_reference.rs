//! Light from every direction (MODEL §10): the absolute BRDF that the relative reflectance
//! `ρ` of MODEL §2 implies, and an f64 reference of the radiance an environment map and disc
//! lights reflect, by dense quadrature over `(u, v)`. No Vulkan here.
//!
//! # The absolute BRDF of the windowed lobe
//!
//! The reflected radiance is `L_o(ωr) = ∫ L(ωi)·f_r(ωi, ωr)·cos θi dωi`. At fixed `ωr`,
//! `(u, v) = −(ωi + ωr)_xy` is a change of variables over the hemisphere with
//! `dωi = du dv / cos θi` (the Jacobian of the projection of the unit sphere on its tangent
//! plane), so the cosine cancels:
//!
//! `L_o(ωr) = ∫∫ L(ωi(u, v))·f_r·du dv` over the disc `|ωi_xy| < 1`.
//!
//! With `f_r = A_λ·ρ_λ = A_λ·C·|P̂_λ(ku, kv)|²`, the energy of the lobe is fixed by
//! Parseval's theorem whatever the height field: the windowed transform of `p = exp(i·k·w·h)`,
//! `|p| = 1`, normalised by `Σg`, has
//!
//! `∫∫ |P̂(ku, kv)|² du dv = (2π)²/k² · Σ g² dH² / (Σ g dH²)² = (2π)²/k² · πσs² / (2πσs²)²
//!  = π / (k² σs²)`
//!
//! (for a flat surface, directly: `|P̂|² = exp(−k²σs²(u² + v²))`). Near the specular
//! direction the gain factor is `C = 1 + O(|u, v|²)` with Fresnel and shadowing off, and the
//! lobe is about `1/(kσs) ≈ 0.005` wide, so a flat mirror under any smooth `L` reflects
//! `L·A_λ·π/(k²σs²)`. It reflects `L` exactly (the white furnace: 1 under radiance 1) when
//!
//! `A_λ = k² σs² / π = 4π σs² / λ²`   (σs = coherence/4; ≈ 1.1·10⁴ at 550 nm for 65 µm).
//!
//! With Fresnel on, `ρ` carries `R/R0` (it is normalised to a mirror at normal incidence),
//! so `f_r = R0·A_λ·ρ` and the mirror reflects `R(θ)`, Schlick's reflectance. Both factors
//! are in [`Response::absolute`](super::table::Response::absolute). `A_λ` depends on the wavelength: a shorter wavelength has a
//! narrower lobe of the same energy, so its peak `f_r` is higher; the factor must therefore
//! enter the spectral sum of `G`, not the finished colour.
//!
//! # Colour
//!
//! The BRDF's colour is its tristimulus response under D65 (MODEL §5), `Σ_λ f_r,λ w_λ`, which
//! for a mirror is D65's white `W = Σ_λ w_λ` (`Y = 1`). An environment's RGB radiance is
//! converted to XYZ and applied channel by channel against the BRDF's response relative
//! to that white: `L_o,c = ∫ L_c·f_r,c / W_c`. That is the usual approximation (MODEL §10):
//! exact for white light and for a spectrally flat BRDF; the dispersion lives in the BRDF's
//! spectral integral, not in the light. A D65-white light of irradiance `I` then gives
//! `I·Σ_λ f_r,λ w_λ`, the sun's colour as the sun-lit render has it.

use rayon::prelude::*;

use crate::colour::ColourTable;
use crate::heightfield::HeightField;
use crate::light::set::Light;
use crate::light::DiskSample;
use crate::Result;

use super::table::{sample_g_lines_in, ChebyshevW, Sampled, Slices, TableSpec};
use super::truncation::Precision;
use super::{gain, Shading};

/// D65's white in the colour table's units: `Σ_λ w_λ` (`Y = 1`).
pub fn white(table: &ColourTable) -> [f64; 3] {
    table
        .weights
        .iter()
        .fold([0.0; 3], |a, w| [a[0] + w[0], a[1] + w[1], a[2] + w[2]])
}

/// Per wavelength line of `table`, the factor its `G` contribution is scaled by for
/// radiance: `f_r/ρ = A_λ·R0` over D65's white in each channel
/// ([`Response::absolute`](super::table::Response::absolute)). A `G` summed with these
/// weights gives `L_o,c = ∫∫ L_c·C·G_c du dv` (module notes).
pub fn radiance_scale(table: &ColourTable, coherence_um: f64, shading: &Shading) -> Vec<[f64; 3]> {
    super::table::Response::absolute(coherence_um, shading).line_factors(table)
}

/// The radiance-weighted `G` of a flat surface, in closed form:
/// `Σ_λ w_λ·scale_λ·exp(−k²σs²(u² + v²))`.
#[derive(Debug, Clone)]
pub struct FlatLobe {
    /// `(k², weight·scale)` per wavelength.
    lines: Vec<(f64, [f64; 3])>,
    sigma2: f64,
}

impl FlatLobe {
    pub fn new(table: &ColourTable, coherence_um: f64, shading: &Shading) -> Self {
        let scale = radiance_scale(table, coherence_um, shading);
        let lines = table
            .lambdas_nm
            .iter()
            .zip(&table.weights)
            .zip(&scale)
            .map(|((l, w), s)| {
                let k = 2.0 * std::f64::consts::PI / (l * 1e-3);
                (k * k, [w[0] * s[0], w[1] * s[1], w[2] * s[2]])
            })
            .collect();
        let sigma = coherence_um / 4.0;
        FlatLobe {
            lines,
            sigma2: sigma * sigma,
        }
    }

    /// `G(u, v, w)` (independent of `w` for a flat surface).
    pub fn g(&self, uvw: [f64; 3]) -> [f64; 3] {
        let r2 = uvw[0] * uvw[0] + uvw[1] * uvw[1];
        let mut acc = [0.0; 3];
        for (k2, w) in &self.lines {
            let e = (-k2 * self.sigma2 * r2).exp();
            for c in 0..3 {
                acc[c] += w[c] * e;
            }
        }
        acc
    }
}

/// The radiance-weighted `G` of a height field as the f64 `chebyshev-w` model holds it:
/// each wavelength's `|P̂|²` sampled exactly ([`sample_g_lines_in`]) and summed with
/// [`radiance_scale`] over the spec's region, Chebyshev in `w`, cubic splines in `(u, v)`.
pub fn radiance_table(
    hf: &HeightField,
    coherence_um: f64,
    shading: &Shading,
    spec: &TableSpec,
) -> Result<ChebyshevW> {
    let slices = radiance_slices(hf, coherence_um, shading, spec, &|| {})?;
    Ok(ChebyshevW::from_nodes(spec.region, &slices))
}

/// The samples of [`radiance_table`] at its Chebyshev nodes in `w`.
/// `progress` is called once per (w node, wavelength) plane, [`radiance_planes`] times.
pub fn radiance_slices(
    hf: &HeightField,
    coherence_um: f64,
    shading: &Shading,
    spec: &TableSpec,
    progress: &(dyn Fn() + Sync),
) -> Result<Slices> {
    radiance_slices_in(hf, coherence_um, shading, spec, Precision::F64, progress).map(|s| s.slices)
}

/// [`radiance_slices`] with the sums in `precision` ([`sample_g_lines_in`]: float32 is the
/// fast build, its measured difference from float64 in [`Sampled::probe`]).
pub fn radiance_slices_in(
    hf: &HeightField,
    coherence_um: f64,
    shading: &Shading,
    spec: &TableSpec,
    precision: Precision,
    progress: &(dyn Fn() + Sync),
) -> Result<Sampled> {
    let table = ColourTable::new(spec.step_nm)?;
    let scale = radiance_scale(&table, coherence_um, shading);
    let nodes = ChebyshevW::nodes(spec);
    let lines: Vec<(f64, [f64; 3])> = table
        .lambdas_nm
        .iter()
        .zip(&table.weights)
        .zip(&scale)
        .map(|((&l, w), s)| (l, [0, 1, 2].map(|c| w[c] * s[c])))
        .collect();
    sample_g_lines_in(hf, coherence_um, spec, &nodes, &lines, precision, progress)
}

/// The (w node, wavelength) planes [`radiance_slices`] samples: its progress's length.
pub fn radiance_planes(spec: &TableSpec) -> Result<u64> {
    let lines = ColourTable::new(spec.step_nm)?.len();
    Ok(lines as u64 * ChebyshevW::nodes(spec).len() as u64)
}

/// A surface's tangent frame in world space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    pub t: [f64; 3],
    pub b: [f64; 3],
    pub n: [f64; 3],
}

impl Frame {
    /// The BRDF map's patch facing the zenith (MODEL §10): `N = +Y`, `T = +X`, `B = N × T = −Z`.
    pub const BRDF_MAP: Frame = Frame {
        t: [1.0, 0.0, 0.0],
        b: [0.0, 0.0, -1.0],
        n: [0.0, 1.0, 0.0],
    };

    /// Tangent-space `v` in world space.
    pub fn to_world(&self, v: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|k| v[0] * self.t[k] + v[1] * self.b[k] + v[2] * self.n[k])
    }

    /// World-space `v` in tangent space.
    pub fn to_tangent(&self, v: [f64; 3]) -> [f64; 3] {
        let d = |a: [f64; 3]| a[0] * v[0] + a[1] * v[1] + a[2] * v[2];
        [d(self.t), d(self.b), d(self.n)]
    }
}

/// A grid of `(u, v)` cells of side `h` over a box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quadrature {
    pub lo: [f64; 2],
    pub hi: [f64; 2],
    pub h: f64,
}

impl Quadrature {
    /// The whole reachable disc of `ωr` (`|ωi_xy| < 1` around `−ωr_xy`) at spacing `h`.
    pub fn reachable(wr: [f64; 3], h: f64) -> Self {
        Quadrature {
            lo: [-wr[0] - 1.0, -wr[1] - 1.0],
            hi: [-wr[0] + 1.0, -wr[1] + 1.0],
            h,
        }
    }

    /// A box of half-width `r` around `(u, v)`.
    pub fn around(u: f64, v: f64, r: f64, h: f64) -> Self {
        Quadrature {
            lo: [u - r, v - r],
            hi: [u + r, v + r],
            h,
        }
    }
}

/// `L_o(ωr)` in XYZ radiance under `light` (an environment, disc lights or a
/// [`crate::light::set::LightSet`] of them) by the midpoint rule over the cells of `q`:
/// `Σ L_xyz(ωi)·C(ωi, ωr)·G(u, v, w)·h²` over the cells whose centre is reachable
/// (`ωr` in tangent space; `frame` places the surface in the world; `g` is a
/// radiance-weighted `G`).
pub fn env_radiance(
    light: &(dyn Light + Sync),
    frame: &Frame,
    wr: [f64; 3],
    shading: &Shading,
    g: &(dyn Fn([f64; 3]) -> [f64; 3] + Sync),
    q: &Quadrature,
) -> [f64; 3] {
    let nu = ((q.hi[0] - q.lo[0]) / q.h).ceil().max(1.0) as usize;
    let nv = ((q.hi[1] - q.lo[1]) / q.h).ceil().max(1.0) as usize;
    let acc = (0..nv)
        .into_par_iter()
        .map(|j| {
            let v = q.lo[1] + (j as f64 + 0.5) * q.h;
            let mut row = [0.0; 3];
            for i in 0..nu {
                let u = q.lo[0] + (i as f64 + 0.5) * q.h;
                let (x, y) = (-u - wr[0], -v - wr[1]);
                let s = x * x + y * y;
                if s >= 1.0 {
                    continue;
                }
                let wi = [x, y, (1.0 - s).sqrt()];
                let c = gain(wi, wr, shading);
                if c == 0.0 {
                    continue;
                }
                let l = light.radiance(frame.to_world(wi));
                let gv = g([u, v, -wi[2] - wr[2]]);
                for k in 0..3 {
                    row[k] += l[k] * c * gv[k];
                }
            }
            row
        })
        .reduce(|| [0.0; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]]);
    acc.map(|x| x * q.h * q.h)
}

/// [`env_radiance`] at spacing `q.h` and `q.h/2`: the finer value and the largest
/// difference of a channel between the two, relative to the finer value's `Y` (the
/// quadrature's own error, stated beside every reference value).
pub fn env_radiance_converged(
    light: &(dyn Light + Sync),
    frame: &Frame,
    wr: [f64; 3],
    shading: &Shading,
    g: &(dyn Fn([f64; 3]) -> [f64; 3] + Sync),
    q: &Quadrature,
) -> ([f64; 3], f64) {
    let coarse = env_radiance(light, frame, wr, shading, g, q);
    let fine = env_radiance(
        light,
        frame,
        wr,
        shading,
        g,
        &Quadrature { h: q.h / 2.0, ..*q },
    );
    let diff = (0..3).fold(0.0f64, |m, k| m.max((fine[k] - coarse[k]).abs()));
    (fine, diff / fine[1].abs().max(1e-300))
}

/// `L_o(ωr)` in XYZ radiance from a light of `irradiance_xyz` (`I` times its colour in XYZ)
/// summed over the directions of its disc (world space, weights summing to 1):
/// `Σ_k weight_k·cos θi_k·C·G`. The directional light of MODEL §10.
pub fn disc_radiance(
    irradiance_xyz: [f64; 3],
    samples: &[DiskSample],
    frame: &Frame,
    wr: [f64; 3],
    shading: &Shading,
    g: &dyn Fn([f64; 3]) -> [f64; 3],
) -> [f64; 3] {
    let mut acc = [0.0; 3];
    for s in samples {
        let wi = frame.to_tangent(s.towards_light.map(f64::from));
        let c = gain(wi, wr, shading);
        if c == 0.0 {
            continue;
        }
        let gv = g([-wi[0] - wr[0], -wi[1] - wr[1], -wi[2] - wr[2]]);
        for k in 0..3 {
            acc[k] += f64::from(s.weight) * wi[2] * c * gv[k] * irradiance_xyz[k];
        }
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::{direction, reference, schlick_r0};
    use crate::colour::linear_srgb_to_xyz;
    use crate::light::env::{EnvMap, EnvSource};
    use crate::light::set::{EnvLight, SampledDisc};
    use crate::light::sun_disk_samples;

    fn white_env() -> EnvMap {
        EnvMap::load(&EnvSource::White, 1.0, 0.0).unwrap()
    }

    #[test]
    fn the_flat_lobe_is_the_reference_of_a_flat_surface() {
        // The reference's direct sum for a flat 64² patch, ρ/C = |P̂|², against the closed form.
        let hf = HeightField::new(64, 64, 1.0, vec![0.3; 64 * 64]).unwrap();
        let table = ColourTable::new(5).unwrap();
        let s = Shading::GEOMETRIC;
        let lobe = FlatLobe::new(&table, 65.0, &s);
        let wr = direction(30.0, 10.0);
        for (du, dv) in [(0.0, 0.0), (0.003, 0.0), (0.002, -0.004)] {
            let wi = [-wr[0] - du, -wr[1] - dv, 0.0];
            let wi = [wi[0], wi[1], (1.0 - wi[0] * wi[0] - wi[1] * wi[1]).sqrt()];
            let lambda = 550.0;
            let rho = reference::rho(&hf, 65.0, &s, wi, wr, lambda) / gain(wi, wr, &s);
            let k = 2.0 * std::f64::consts::PI / 0.55;
            let closed = (-k * k * (65.0f64 / 4.0).powi(2) * (du * du + dv * dv)).exp();
            assert!((rho - closed).abs() < 1e-7, "{du} {dv}: {rho} vs {closed}");
        }
        let _ = lobe;
    }

    #[test]
    fn white_furnace_on_the_cpu() {
        let table = ColourTable::new(5).unwrap();
        let w = white(&table);
        let env = white_env();
        for (fresnel, name) in [(false, "off"), (true, "on")] {
            let s = Shading {
                fresnel,
                shadowing: false,
                ior: 1.5,
            };
            let lobe = FlatLobe::new(&table, 65.0, &s);
            for theta in [0.0, 20.0, 40.0, 60.0] {
                let wr = direction(theta, 35.0);
                let q = Quadrature::around(0.0, 0.0, 0.05, 5e-4);
                let (l, err) = env_radiance_converged(
                    &EnvLight::new(&env),
                    &Frame::BRDF_MAP,
                    wr,
                    &s,
                    &|d| lobe.g(d),
                    &q,
                );
                let r0 = schlick_r0(1.5);
                let want = if fresnel {
                    r0 + (1.0 - r0) * (1.0 - wr[2]).powi(5)
                } else {
                    1.0
                };
                // White in, white out: the mirror's response in each channel is D65's white.
                for c in 0..3 {
                    let got = l[c] / w[c];
                    assert!(
                        (got / want - 1.0).abs() < 1e-3,
                        "Fresnel {name}, θr = {theta}: channel {c} {got} vs {want}"
                    );
                }
                assert!(err < 1e-6, "quadrature error {err}");
            }
        }
    }

    #[test]
    fn a_disc_in_the_map_reflects_as_the_disc_light() {
        // A 6° disc of irradiance 1 (D65 white), as a map and as 256 directions, seen in a
        // flat mirror at its specular direction and at points inside the disc's image (its
        // radius is 0.052 in (u, v); at the edge both are discretisations of a step).
        let table = ColourTable::new(10).unwrap();
        let s = Shading::GEOMETRIC;
        let lobe = FlatLobe::new(&table, 65.0, &s);
        let towards = [0.3f64, 0.8, -0.2];
        let n = (towards[0].powi(2) + towards[1].powi(2) + towards[2].powi(2)).sqrt();
        let towards = towards.map(|x| x / n);
        let light = crate::light::area::DiscLight {
            direction: towards.map(|x| -x as f32),
            angular_diameter_deg: 6.0,
            disk_samples: 256,
            ..Default::default()
        };
        let (w, h) = (1024u32, 512u32);
        let mut px = vec![[0f32; 3]; (w * h) as usize];
        let half = light.angular_radius();
        let mut om = 0.0;
        let probe = EnvMap::from_pixels(w, h, px.clone(), "disc").unwrap();
        for r in 0..h {
            for c in 0..w {
                let d = crate::light::env::map_to_direction(
                    (f64::from(c) + 0.5) / f64::from(w),
                    (f64::from(r) + 0.5) / f64::from(h),
                );
                let cosang = d[0] * towards[0] + d[1] * towards[1] + d[2] * towards[2];
                if cosang >= half.cos() {
                    px[(r * w + c) as usize] = [1.0; 3];
                    om += probe.pixel_solid_angle(r);
                }
            }
        }
        // Radiance I/Ω over the pixels that make up the disc: irradiance 1 exactly.
        px.iter_mut()
            .for_each(|p| *p = p.map(|x| (f64::from(x) / om) as f32));
        let env = EnvMap::from_pixels(w, h, px, "disc").unwrap();
        let frame = Frame::BRDF_MAP;
        let wi0 = frame.to_tangent(towards);
        let samples = sun_disk_samples(towards.map(|x| x as f32), 6.0, 256);
        let white_xyz = linear_srgb_to_xyz([1.0; 3]);
        let omega = light.solid_angle();
        let disc = SampledDisc {
            towards,
            cos_radius: half.cos(),
            solid_angle: omega,
            radiance_xyz: white_xyz.map(|c| c / omega),
        };
        for offset in [0.0, 0.02, 0.04] {
            let wr = [-wi0[0] + offset, -wi0[1], 0.0];
            let wr = [wr[0], wr[1], (1.0 - wr[0] * wr[0] - wr[1] * wr[1]).sqrt()];
            let q = Quadrature::around(-wi0[0] - wr[0], -wi0[1] - wr[1], 0.1, 2e-4);
            let from_map = env_radiance(&EnvLight::new(&env), &frame, wr, &s, &|d| lobe.g(d), &q);
            let from_light = disc_radiance(white_xyz, &samples, &frame, wr, &s, &|d| lobe.g(d));
            // The disc as a light of the light set: its radiance over its cone.
            let from_disc = env_radiance(&disc, &frame, wr, &s, &|d| lobe.g(d), &q);
            for (what, got) in [("light", from_light), ("disc", from_disc)] {
                for c in 0..3 {
                    let rel = (from_map[c] - got[c]).abs() / got[c].max(1e-3);
                    assert!(
                        rel < 0.03,
                        "offset {offset}, channel {c}: map {from_map:?} {what} {got:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_radiance_table_of_a_flat_field_is_the_flat_lobe() {
        // The table route (each wavelength's exact windowed spectrum, scaled, Chebyshev in w,
        // splines in (u, v)) against the closed form: it is what the structured references
        // and the GPU's table use.
        let hf = HeightField::new(64, 64, 65.0 / 64.0, vec![0.0; 64 * 64]).unwrap();
        let s = Shading::GEOMETRIC;
        let spec = TableSpec {
            region: crate::brdf::table::Region {
                lo: [-0.03, -0.03, -2.0],
                hi: [0.03, 0.03, -1.0],
            },
            texel_uv: 0.001,
            w_nodes: 4,
            step_nm: 10,
            response: crate::brdf::table::Response::Relative,
        };
        let t = radiance_table(&hf, 65.0, &s, &spec).unwrap();
        let lobe = FlatLobe::new(&ColourTable::new(10).unwrap(), 65.0, &s);
        let peak = lobe.g([0.0; 3])[1];
        use crate::brdf::table::GTable;
        for uvw in [
            [0.0, 0.0, -1.5],
            [0.0031, -0.0017, -1.2],
            [0.008, 0.004, -1.9],
        ] {
            let a = t.g(uvw).unwrap();
            let b = lobe.g(uvw);
            for c in 0..3 {
                assert!(
                    (a[c] - b[c]).abs() < 2e-3 * peak,
                    "{uvw:?} {c}: {} vs {}",
                    a[c],
                    b[c]
                );
            }
        }
    }
}
