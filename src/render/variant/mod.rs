//! Shader variants (MODEL §7): each one owns its fragment shader, the descriptor bindings
//! beyond the shared ones, its GPU resources and its specialisation constants, behind
//! [`Variant`] and [`PreparedVariant`]. The renderer only knows this interface; adding a
//! variant is one new file here plus one line in [`VariantKind`].
//!
//! Shared bindings (every variant's layout has them): 0 `Params` uniform block, 2 colour
//! weights, 3 surface texture. A variant adds binding 1 (its main table) and 4 onwards.

mod chebyshev_w;
mod dhillon;
mod flss;
mod nmm;
mod pq;
mod table;
mod volume;

use std::sync::Arc;

use crate::brdf::table::{DiscKernel, Region, TableSpec};
use crate::gpu::pipeline::{Binding, Resource};
use crate::gpu::{Device, StorageFormat};
use crate::material::{Material, PreparedMaterial};
use crate::{Error, Result};

use super::{OutputMode, ParamsUbo};

/// Number of specialisation constants (`constant_id` 0..=9 of glsl/interface.glsl, 10 of
/// glsl/shade.glsl).
pub(crate) const SPEC_COUNT: usize = 11;

/// The variants, by name.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, clap::ValueEnum, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
#[value(rename_all = "kebab-case")]
pub enum VariantKind {
    /// Thesis Algorithm 3: the whole spectrum, every term and tap, per pixel.
    Flss,
    /// Thesis §1.5.2 done right: FLSS at the wavelengths of the grating's orders only.
    Nmm,
    /// Thesis §1.5.3 done right: one period's spectrum (3×3 sinc taps) × the periodic factor.
    Pq,
    /// Dhillon et al. 2014: tables of the powers of w, Horner per pixel.
    Dhillon,
    /// G as a Chebyshev series in w: K bilinear fetches, Clenshaw.
    ChebyshevW,
    /// G(u, v, w) in a 3D texture: one trilinear fetch.
    Volume,
    /// The default variant (an alias; see [`VariantKind::DEFAULT`]).
    Default,
}

impl VariantKind {
    /// Every variant, the alias excluded, in listing order.
    pub const ALL: [VariantKind; 6] = [
        VariantKind::Flss,
        VariantKind::Nmm,
        VariantKind::Pq,
        VariantKind::Dhillon,
        VariantKind::ChebyshevW,
        VariantKind::Volume,
    ];

    /// What `default` stands for: the fastest variant whose error against the 1 nm
    /// reference stays within ΔE2000 p99 ≤ 1 on the shipped gratings (README, profile).
    pub const DEFAULT: VariantKind = VariantKind::ChebyshevW;

    /// The variant an alias stands for.
    pub fn resolve(self) -> VariantKind {
        match self {
            VariantKind::Default => Self::DEFAULT,
            k => k,
        }
    }

    /// Command-line name.
    pub fn name(self) -> &'static str {
        match self.resolve() {
            VariantKind::Flss => "flss",
            VariantKind::Nmm => "nmm",
            VariantKind::Pq => "pq",
            VariantKind::Dhillon => "dhillon",
            VariantKind::ChebyshevW => "chebyshev-w",
            VariantKind::Volume => "volume",
            VariantKind::Default => unreachable!("resolved above"),
        }
    }

    /// One line for `diffract variants`.
    pub fn summary(self) -> &'static str {
        match self.resolve() {
            VariantKind::Flss => "thesis Algorithm 3: every wavelength × term × window tap per pixel (exact to its T, R, Δλ)",
            VariantKind::Nmm => "thesis §1.5.2 done right: FLSS at the wavelengths of the grating's orders only, Jacobian-weighted (needs a dominant period)",
            VariantKind::Pq => "thesis §1.5.3 done right: one period's spectrum from 3×3 periodic-sinc taps × |F_x F_y|² of N copies, N·L = 2√π σs (needs whole copies of one period)",
            VariantKind::Dhillon => "Dhillon et al. 2014: G = Σ_p I_p(u,v)·w^p from f64 tables, Horner (monomials: ill-conditioned in f32)",
            VariantKind::ChebyshevW => "G = Σ_j c_j(u,v)·T_j(ŵ) from f64 tables, Clenshaw in w, cubic B-spline in (u,v): 4K bilinear fetches",
            VariantKind::Volume => "G(u,v,w) in a 3D texture from f64 tables: one trilinear fetch (the floor)",
            VariantKind::Default => unreachable!("resolved above"),
        }
    }

    /// Whether it can draw a single wavelength (FLSS evaluates every one per pixel).
    pub fn is_spectral(self) -> bool {
        self.resolve() == VariantKind::Flss
    }

    /// Whether it reads a pre-integrated table of `G` (and so can hold the sun's disc in it).
    pub fn is_table(self) -> bool {
        matches!(
            self.resolve(),
            VariantKind::Dhillon | VariantKind::ChebyshevW | VariantKind::Volume
        )
    }

    /// Texel fetches per pixel for `material` with highest term `terms` (FLSS and NMM) and
    /// the table options.
    pub fn fetches(self, terms: usize, material: &Material, table: &TableOptions) -> usize {
        match self.resolve() {
            VariantKind::Flss => {
                let lambdas = (400 / material.lambda_step_nm.max(1) + 1) as usize;
                let taps = (2 * material.window_radius + 1).pow(2);
                lambdas * (terms + 1) * taps
            }
            VariantKind::Nmm => {
                let taps = (2 * material.window_radius + 1).pow(2);
                (2 * crate::brdf::nmm::HALF_SAMPLES as usize + 1) * (terms + 1) * taps
            }
            VariantKind::Pq => {
                let lambdas = (400 / material.lambda_step_nm.max(1) + 1) as usize;
                lambdas * (terms + 1) * crate::brdf::pq::TAPS.pow(2)
            }
            VariantKind::Volume => 1,
            VariantKind::ChebyshevW => 4 * table.w_nodes_for(self),
            k => table.w_nodes_for(k),
        }
    }

    pub(crate) fn implementation(self) -> &'static dyn Variant {
        match self.resolve() {
            VariantKind::Flss => &flss::Flss,
            VariantKind::Nmm => &nmm::Nmm,
            VariantKind::Pq => &pq::Pq,
            VariantKind::Dhillon => &dhillon::Dhillon,
            VariantKind::ChebyshevW => &chebyshev_w::ChebyshevW,
            VariantKind::Volume => &volume::Volume,
            VariantKind::Default => unreachable!("resolved above"),
        }
    }
}

impl std::fmt::Display for VariantKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Storage of the pre-integrated tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum TableFormat {
    /// 16 bytes a texel; linear filtering in float32.
    Rgba32f,
    /// 8 bytes a texel; 11-bit mantissa (relative rounding 5e-4).
    Rgba16f,
}

impl TableFormat {
    /// Bytes a texel.
    pub fn texel_bytes(self) -> usize {
        match self {
            TableFormat::Rgba32f => 16,
            TableFormat::Rgba16f => 8,
        }
    }

    /// As the listings name it.
    pub fn name(self) -> &'static str {
        match self {
            TableFormat::Rgba32f => "RGBA32F",
            TableFormat::Rgba16f => "RGBA16F",
        }
    }
}

/// How the table variants sample `G` (MODEL §7).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableOptions {
    /// `(u, v)` node spacing; `None`: half the coherence lobe ([`TableSpec::default_texel`]).
    pub texel_uv: Option<f64>,
    /// Nodes along `w`; `None`: the variant's default (volume 32, chebyshev-w 16, dhillon 12).
    pub w_nodes: Option<usize>,
    /// Wavelength step of the offline spectral integral (nm). 1 by default: a line of
    /// the 65 µm coherence window is about 1 nm wide at |u| ≈ 2, and the table pays the
    /// step only once, offline.
    pub step_nm: u32,
    /// GPU memory a table may take; the `(u, v)` spacing is coarsened to fit (and said so).
    pub budget_bytes: usize,
    pub format: TableFormat,
}

impl Default for TableOptions {
    fn default() -> Self {
        Self {
            texel_uv: None,
            w_nodes: None,
            step_nm: 1,
            budget_bytes: 512 << 20,
            format: TableFormat::Rgba32f,
        }
    }
}

impl TableOptions {
    /// `w` nodes of variant `kind` unless the height field asks for more
    /// ([`TableOptions::w_nodes_for_field`]).
    pub fn w_nodes_for(&self, kind: VariantKind) -> usize {
        self.w_nodes.unwrap_or(match kind.resolve() {
            VariantKind::Volume => 32,
            VariantKind::Dhillon => 12,
            _ => 16,
        })
    }

    /// `w` nodes of `kind` for a height range `h_range_um` over `w ∈ [w0, w1]`: for
    /// `chebyshev-w`, fitted to that range, as many as the series needs to meet
    /// [`CHEBYSHEV_W_TOLERANCE`] (at least [`MIN_CHEBYSHEV_W_NODES`]); the default otherwise.
    /// `G = Σ_λ |P̂|²` varies with `w` through phases `s·(h − h')`, `s = 2πw/λ`, so its
    /// Chebyshev coefficients in `ŵ` decay like the Bessel functions `J_j(a)` of
    /// `a = (2π/λ_min)·(h_max − h_min)·(w1 − w0)/2`; K is two more than the first `j` with
    /// `|J_j(a)| ≤` the tolerance (at most [`MAX_NODES_W`](crate::brdf::table::MAX_NODES_W)).
    /// An explicit `w_nodes` is kept as given.
    pub fn w_nodes_for_field(&self, kind: VariantKind, h_range_um: f64, w: [f64; 2]) -> usize {
        let base = self.w_nodes_for(kind);
        if self.w_nodes.is_some() || kind.resolve() != VariantKind::ChebyshevW {
            return base;
        }
        let k_max = 2.0 * std::f64::consts::PI / (crate::colour::LAMBDA_MIN_NM as f64 * 1e-3);
        let a = k_max * h_range_um.max(0.0) * 0.5 * (w[1] - w[0]).abs();
        let max = crate::brdf::table::MAX_NODES_W;
        let j = crate::brdf::bessel::jn_all(a, max);
        let first = (0..=max)
            .find(|&n| n as f64 > a && j[n..].iter().all(|x| x.abs() <= CHEBYSHEV_W_TOLERANCE))
            .unwrap_or(max);
        (first + 2).clamp(MIN_CHEBYSHEV_W_NODES, max)
    }

    /// The sampling of `G` for `kind` over `region`: the requested spacing, coarsened where
    /// the table would exceed the memory budget. The second value is the spacing asked for
    /// when it had to be coarsened.
    /// `h_range_um` is the height field's peak-to-valley (it sets the `w` nodes).
    pub fn spec(
        &self,
        kind: VariantKind,
        material: &Material,
        h_range_um: f64,
        region: Region,
    ) -> Result<(TableSpec, Option<f64>)> {
        let asked = self
            .texel_uv
            .unwrap_or_else(|| TableSpec::default_texel(material.coherence_um));
        if !(asked.is_finite() && asked > 0.0) {
            return Err(Error::invalid(
                "table texel",
                format!("{asked}; must be a positive spacing in u and v"),
            ));
        }
        let w_nodes = self.w_nodes_for_field(kind, h_range_um, [region.lo[2], region.hi[2]]);
        let texel_bytes = self.format.texel_bytes();
        let e = region.extent();
        let bytes = |t: f64| {
            let nodes = |len: f64| ((len / t).ceil() + 1.0).max(2.0);
            nodes(e[0]) * nodes(e[1]) * (w_nodes * texel_bytes) as f64
        };
        // The smallest table (2×2 nodes) must fit, else no spacing does.
        if bytes(f64::INFINITY) > self.budget_bytes as f64 {
            return Err(Error::invalid(
                "table budget",
                format!(
                    "{} bytes cannot hold even 2×2×{w_nodes} texels",
                    self.budget_bytes
                ),
            ));
        }
        let mut texel = asked;
        while bytes(texel) > self.budget_bytes as f64 {
            texel *= 1.1;
        }
        let spec = TableSpec {
            region,
            texel_uv: texel,
            w_nodes,
            step_nm: self.step_nm,
        };
        spec.validate()?;
        Ok((spec, (texel > asked).then_some(asked)))
    }
}

/// Largest `|c_K|/|c_0|` the default `chebyshev-w` coefficient count allows.
pub const CHEBYSHEV_W_TOLERANCE: f64 = 1e-4;

/// Fewest `chebyshev-w` coefficients fitted to a narrow `w` range.
pub const MIN_CHEBYSHEV_W_NODES: usize = 4;

/// What a frame reports about the variant that drew it.
#[derive(Debug, Clone, PartialEq)]
pub struct VariantStats {
    /// Variant name and its main settings.
    pub name: String,
    /// Time to build and upload its resources (ms): the table build for table variants,
    /// the term upload for flss. Measured once; cached variants report the original time.
    pub build_ms: f64,
    /// GPU memory of its resources (bytes).
    pub gpu_bytes: usize,
    /// Texel fetches per pixel.
    pub fetches: usize,
}

/// What a variant is prepared for.
pub(crate) struct DrawSetup<'a> {
    pub prepared: &'a PreparedMaterial,
    /// The `(u, v, w)` the draw can reach.
    pub region: Region,
    pub output: OutputMode,
    pub storage: StorageFormat,
    pub table: &'a TableOptions,
    /// Keep the f64 table on the CPU after upload ([`PreparedVariant::table_model`]).
    pub keep_model: bool,
    /// Where sampled tables are cached (none: always build).
    pub cache_dir: Option<&'a std::path::Path>,
    /// Leave out what the draw cannot need at the material's tolerance (wavelengths,
    /// DFT texels outside `region`); false keeps everything.
    pub leave_out: bool,
    /// The light's disc as a `(u, v)` footprint for table variants to pre-filter into their
    /// table (then the shader evaluates the disc's centre once); `None`: a point light, a
    /// map, or a variant that loops over the disc's directions.
    pub disc: Option<DiscKernel>,
}

impl DrawSetup<'_> {
    /// The tolerance wavelengths are left out at, `None` when everything is kept.
    pub fn lambda_tolerance(&self) -> Option<f64> {
        self.leave_out.then_some(self.prepared.material.tolerance)
    }
}

/// A variant: its fragment shader and how to build its resources.
pub(crate) trait Variant: Sync {
    fn kind(&self) -> VariantKind;
    /// SPIR-V of its fragment shader (the vertex stages are shared).
    fn fragment_spirv(&self) -> &'static [u8];
    /// SPIR-V of its per-vertex stage (thesis §1.5.1: the BRDF evaluated per vertex, the
    /// colour interpolated), where the variant has one.
    fn per_vertex_spirv(&self) -> Option<&'static [u8]> {
        None
    }
    /// Builds and uploads what the shader reads for `setup`.
    fn prepare(&self, dev: &Arc<Device>, setup: &DrawSetup<'_>)
        -> Result<Box<dyn PreparedVariant>>;
}

/// A variant's GPU resources for one material and region.
pub(crate) trait PreparedVariant {
    /// Its descriptor bindings beyond the shared ones.
    fn bindings(&self) -> Vec<Binding>;
    /// What those bindings point at.
    fn resources(&self) -> Vec<(u32, Resource<'_>)>;
    /// Sets its specialisation constants.
    fn specialise(&self, spec: &mut [u32; SPEC_COUNT]);
    /// Fills its part of the shared uniform block.
    fn fill_params(&self, _params: &mut ParamsUbo) {}
    fn stats(&self) -> VariantStats;
    /// The grating NMM estimated from the height field.
    fn grating(&self) -> Option<crate::brdf::nmm::Grating> {
        None
    }
    /// The periodic structure `pq` found in the height field.
    fn periodicity(&self) -> Option<crate::brdf::pq::Periodicity> {
        None
    }
    /// The f64 CPU model of a table variant, when it was kept.
    fn table_model(&self) -> Option<&dyn crate::brdf::table::GTable> {
        None
    }
    /// The pipeline's name (validation messages and captures show it).
    fn pipeline_name(&self) -> String {
        self.stats().name
    }
    /// Indices into the material's colour table of the wavelengths the shader loops over
    /// (binding 2 holds only these); `None`: all of them.
    fn kept_wavelengths(&self) -> Option<&[usize]> {
        None
    }
    /// What it left out of what the scene does not need (`None`: nothing recorded).
    fn left_out(&self) -> Option<crate::leave_out::LeftOut> {
        None
    }
}

/// The glsl file of a variant's per-vertex stage (the key of hot-reloaded SPIR-V).
pub(crate) fn per_vertex_file(kind: VariantKind) -> Option<&'static str> {
    match kind.resolve() {
        VariantKind::Flss => Some("flss_vertex.vert"),
        VariantKind::Nmm => Some("nmm_vertex.vert"),
        VariantKind::Pq => Some("pq_vertex.vert"),
        _ => None,
    }
}

/// Rejects a spectral (single-wavelength) draw for a variant that integrates offline.
pub(crate) fn require_spectral(kind: VariantKind, output: OutputMode) -> Result<()> {
    if output == OutputMode::MapSpectral && !kind.is_spectral() {
        return Err(Error::invalid(
            "variant",
            format!(
                "'{kind}' integrates the spectrum offline and cannot draw one wavelength; use --variant flss with --lambda-nm"
            ),
        ));
    }
    Ok(())
}

/// `diffract variants`: the list, with fetches and memory for the default material on a
/// BRDF map at θi = 60° (its automatic `T` planned, not computed).
pub fn list() -> String {
    let material = Material::default();
    let terms = crate::heightfield::HeightField::load_source(
        &material.heightfield,
        material.dh_um,
        material.h_max_um,
    )
    .and_then(|hf| {
        material.plan(
            &hf,
            &crate::brdf::truncation::Reach::brdf_map(60.0),
            crate::brdf::truncation::Precision::F32,
        )
    })
    .map_or(30, |p| p.terms);
    let table = TableOptions::default();
    let region = Region::brdf_map(crate::brdf::direction(60.0, 0.0));
    let mut s = String::from(
        "variant       fetches/pixel  memory (default material, BRDF map at θi = 60°)\n",
    );
    for kind in VariantKind::ALL {
        let memory = match kind {
            VariantKind::Flss | VariantKind::Nmm | VariantKind::Pq => {
                "term band × (T+1) layers, RG32F (≈ 120 MB for the 704² gratings)".to_string()
            }
            k => match table.spec(k, &material, 0.375, region) {
                Ok((spec, _)) => match spec.uv_nodes() {
                    Ok((nu, nv)) => format!(
                        "{:.0} MB ({nu}×{nv}×{} {}, u/v texel {:.4})",
                        (nu * nv * spec.w_nodes * table.format.texel_bytes()) as f64 / 1e6,
                        spec.w_nodes,
                        table.format.name(),
                        spec.texel_uv
                    ),
                    Err(e) => e.to_string(),
                },
                Err(e) => e.to_string(),
            },
        };
        let mark = if kind == VariantKind::DEFAULT {
            " (default)"
        } else {
            ""
        };
        s.push_str(&format!(
            "{:<13} {:>13}  {memory}\n    {}{mark}\n",
            kind.name(),
            kind.fetches(terms, &material, &table),
            kind.summary()
        ));
    }
    s.push_str("per-vertex (--per-vertex on render, view, profile; thesis §1.5.1): flss, nmm and pq evaluated once per mesh vertex, the colour interpolated; cost per vertex, not per pixel\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_options_refuse_nonsense_and_fit_the_budget() {
        let m = Material::default();
        let r = Region::brdf_map(crate::brdf::direction(45.0, 0.0));
        let with = |texel_uv, budget_bytes| TableOptions {
            texel_uv,
            budget_bytes,
            ..TableOptions::default()
        };
        for bad in [0.0, -0.01, f64::NAN, f64::INFINITY] {
            assert!(with(Some(bad), 1 << 29)
                .spec(VariantKind::ChebyshevW, &m, 0.375, r)
                .is_err());
        }
        assert!(with(None, 0)
            .spec(VariantKind::ChebyshevW, &m, 0.375, r)
            .is_err());
        // A small budget coarsens the spacing (and says from what); the default does not.
        let (spec, asked) = with(None, 8 << 20)
            .spec(VariantKind::ChebyshevW, &m, 0.375, r)
            .unwrap();
        let default_texel = TableSpec::default_texel(m.coherence_um);
        assert_eq!(asked, Some(default_texel));
        assert!(spec.texel_uv > default_texel);
        let (nu, nv) = spec.uv_nodes().unwrap();
        assert!(nu * nv * spec.w_nodes * TableOptions::default().format.texel_bytes() <= 8 << 20);
        let (spec, asked) = with(None, 512 << 20)
            .spec(VariantKind::ChebyshevW, &m, 0.375, r)
            .unwrap();
        assert_eq!((spec.texel_uv, asked), (default_texel, None));
    }

    #[test]
    fn chebyshev_w_nodes_grow_with_the_height_range() {
        let t = TableOptions::default();
        let w = [-1.5, -0.5];
        // The shipped Elaphe-like grating (0.37 µm): a = 16.5·0.37·0.5 ≈ 3.1, J_j(3.1) ≤ 1e-4
        // from j = 9 on: 11 coefficients (16 before they were fitted to the w range) …
        assert_eq!(t.w_nodes_for_field(VariantKind::ChebyshevW, 0.37, w), 11);
        // … fewer over a narrower range, never fewer than the floor.
        assert!(t.w_nodes_for_field(VariantKind::ChebyshevW, 0.37, [-1.2, -1.0]) < 11);
        assert_eq!(
            t.w_nodes_for_field(VariantKind::ChebyshevW, 0.0, w),
            MIN_CHEBYSHEV_W_NODES
        );
        // … a 2 µm structure needs more: a = 16.5·2·0.5 ≈ 16.5, where J_j drops under 1e-4
        // from j ≈ 27 on.
        let tall = t.w_nodes_for_field(VariantKind::ChebyshevW, 2.0, w);
        assert!((26..=32).contains(&tall), "{tall}");
        // Explicit counts and other variants are left alone.
        let fixed = TableOptions {
            w_nodes: Some(9),
            ..t
        };
        assert_eq!(fixed.w_nodes_for_field(VariantKind::ChebyshevW, 2.0, w), 9);
        assert_eq!(t.w_nodes_for_field(VariantKind::Volume, 2.0, w), 32);
    }

    #[test]
    fn names_round_trip_and_the_alias_resolves() {
        for k in VariantKind::ALL {
            assert_eq!(k.resolve(), k);
            assert!(!k.summary().is_empty());
        }
        assert_eq!(VariantKind::Default.resolve(), VariantKind::DEFAULT);
        assert_eq!(VariantKind::Default.name(), VariantKind::DEFAULT.name());
        assert!(VariantKind::Flss.is_spectral() && !VariantKind::Volume.is_spectral());
        assert!(list().contains("(default)"));
    }
}
