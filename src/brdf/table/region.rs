//! Where a table lives and how finely it is sampled: the box of `(u, v, w)` a scene can
//! reach ([`Region`]), the sampling of `G` over it ([`TableSpec`]) and the sampled slices
//! ([`Slices`]).

use crate::colour::ColourTable;
use crate::{Error, Result};

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

/// What a table's `G` answers (MODEL §10): the relative reflectance of MODEL §2, or
/// radiance under radiance.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Response {
    /// `G = Σ_λ w_λ·|P̂_λ|²`: `ρ` of MODEL §2 (a mirror's specular value is 1), what the
    /// thesis plots and the sun-lit passes draw.
    #[default]
    Relative,
    /// Each line's weight times `f_r/ρ = A_λ·r0` over D65's white in its channel and over
    /// `scale`: `L_o,c = scale·∫∫ L_c·C·G_c du dv` (brdf::env_reference). `scale` keeps the
    /// values those of a relative table (float16's range); `r0` is Schlick's `R0` with
    /// Fresnel on, 1 without.
    Radiance {
        coherence_um: f64,
        r0: f64,
        scale: f64,
    },
}

impl Response {
    /// Radiance for a material of coherence length `coherence_um` shaded with `shading`,
    /// on the scale every radiance picture shares: `scale` is `A_λ·r0` weighted by D65's
    /// luminance (at 1 nm, whatever step a table takes), so a mirror's `Y` stays 1 and an
    /// exposure means what it means for the relative reflectance. One scale for every
    /// light: the sun-lit pass and the environment-lit stages write the same units.
    pub fn radiance(coherence_um: f64, shading: &crate::brdf::Shading) -> Response {
        let r0 = Self::r0(shading);
        let unscaled = Self::absolute(coherence_um, shading);
        let colour = ColourTable::new(1).expect("1 nm divides the visible range");
        let factors = unscaled.line_factors(&colour);
        let y: f64 = colour
            .weights
            .iter()
            .zip(&factors)
            .map(|(w, f)| w[1] * f[1])
            .sum();
        Response::Radiance {
            coherence_um,
            r0,
            scale: y,
        }
    }

    /// Radiance on the scale 1: each line's factor is the absolute BRDF over the relative
    /// reflectance, `f_r/ρ = A_λ·r0` with `A_λ = k²σs²/π` (σs a quarter of the coherence
    /// length; `brdf::env_reference` derives it), over D65's white in its channel.
    pub fn absolute(coherence_um: f64, shading: &crate::brdf::Shading) -> Response {
        Response::Radiance {
            coherence_um,
            r0: Self::r0(shading),
            scale: 1.0,
        }
    }

    /// Schlick's `R0` with Fresnel on (`f_r` carries it), 1 without.
    fn r0(shading: &crate::brdf::Shading) -> f64 {
        if shading.fresnel {
            crate::brdf::schlick_r0(shading.ior)
        } else {
            1.0
        }
    }

    /// `f_r/ρ` of a mirror over this response's scale: what a picture in these units
    /// gains per unit of relative reflectance, `r0·A_λ/scale` at D65's luminance
    /// (1 for [`Response::Relative`]).
    pub fn scale(&self) -> f64 {
        match *self {
            Response::Relative => 1.0,
            Response::Radiance { scale, .. } => scale,
        }
    }

    /// `colour` with each line's weight times its factor ([`Response::line_factors`]):
    /// the weights a DFT-term variant sums and the leaving out measures.
    pub fn colour(&self, colour: &ColourTable) -> ColourTable {
        let factors = self.line_factors(colour);
        ColourTable {
            step_nm: colour.step_nm,
            lambdas_nm: colour.lambdas_nm.clone(),
            weights: colour
                .weights
                .iter()
                .zip(&factors)
                .map(|(w, f)| [w[0] * f[0], w[1] * f[1], w[2] * f[2]])
                .collect(),
        }
    }

    /// The factor of each line of `colour` (per channel) that turns a relative `G` into
    /// this response.
    pub fn line_factors(&self, colour: &ColourTable) -> Vec<[f64; 3]> {
        match *self {
            Response::Relative => vec![[1.0; 3]; colour.len()],
            Response::Radiance {
                coherence_um,
                r0,
                scale,
            } => {
                let white = colour
                    .weights
                    .iter()
                    .fold([0.0; 3], |a, w| [a[0] + w[0], a[1] + w[1], a[2] + w[2]]);
                let sigma = coherence_um / 4.0;
                colour
                    .lambdas_nm
                    .iter()
                    .map(|&l| {
                        let k = 2.0 * std::f64::consts::PI / (l * 1e-3);
                        let a = k * k * sigma * sigma / std::f64::consts::PI * r0 / scale;
                        [a / white[0], a / white[1], a / white[2]]
                    })
                    .collect()
            }
        }
    }
}

/// How to sample `G`: the region, the `(u, v)` node spacing, the number of `w` nodes, the
/// wavelength step of the offline spectral integral and what `G` answers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableSpec {
    pub region: Region,
    /// Node spacing in `u` and `v`.
    pub texel_uv: f64,
    /// Nodes along `w` (slices of a volume, coefficients of a series).
    pub w_nodes: usize,
    /// Wavelength step of the offline integral (nm; divides 400).
    pub step_nm: u32,
    pub response: Response,
}

impl TableSpec {
    /// The wavelengths (nm) of the offline spectral integral with their XYZ weights: every
    /// line of the colour table at `step_nm`, or only those whose indices `keep` lists.
    /// The weights are those of [`TableSpec::response`].
    pub fn spectral_samples(&self, keep: Option<&[usize]>) -> Result<Vec<(f64, [f64; 3])>> {
        let colour = ColourTable::new(self.step_nm)?;
        let factors = self.response.line_factors(&colour);
        let line = |i: usize| {
            let (w, f) = (colour.weights[i], factors[i]);
            (
                colour.lambdas_nm[i],
                [w[0] * f[0], w[1] * f[1], w[2] * f[2]],
            )
        };
        Ok(match keep {
            Some(k) => k
                .iter()
                .filter(|&&i| i < colour.len())
                .map(|&i| line(i))
                .collect(),
            None => (0..colour.len()).map(line).collect(),
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

    /// The width (standard deviation in `u`) of the coherence lobe of `|P̂|²` at
    /// `lambda_nm`, `λ/(2πσs)`: 0.0037 at 380 nm for 65 µm, 0.0054 at 550 nm.
    pub fn lobe_width(coherence_um: f64, lambda_nm: f64) -> f64 {
        let sigma_s = coherence_um / 4.0;
        lambda_nm * 1e-3 / (2.0 * std::f64::consts::PI * sigma_s)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn brdf_map_region_covers_every_pixel_direction() {
        let wi = crate::brdf::direction(60.0, 20.0);
        let r = Region::brdf_map(wi);
        for k in 0..200 {
            let a = k as f64 * 0.1;
            let rad = (k % 10) as f64 / 10.0;
            let wr = [rad * a.cos(), rad * a.sin(), (1.0 - rad * rad).sqrt()];
            assert!(r.contains(crate::brdf::uvw(wi, wr)));
        }
    }
}
