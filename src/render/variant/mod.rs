//! Shader variants (MODEL §7). Each variant is one room: its file declares everything about
//! it through [`Variant`] — name, one line, shader stages, `w`-node default, fetches and
//! table layout, what it refuses, its profile rows, its stability cases — and builds its
//! GPU resources behind [`PreparedVariant`], which also hands out its CPU model
//! ([`CpuModel`]); its GLSL lives in glsl/ (build.rs embeds every stage there and names
//! the specialisation constants, [`SpecConstant`]). The registry below is the one list of
//! variants: the enum [`VariantKind`], `--variant` parsing, `diffract variants`, the
//! profiler's rows, the stability matrix and the viewer's `V` cycle all come from it. Adding
//! a variant is its file, its GLSL and one registry line; the trait methods without a
//! default (the model, the stability cases, the fetches) make the compiler ask for the rest.
//!
//! Shared bindings (every variant's layout has them): 0 `Params` uniform block, 2 colour
//! weights, 3 surface texture. A variant adds binding 1 (its main table) and 4 onwards.

mod chebyshev_w;
mod coverage;
mod dhillon;
mod flss;
mod nmm;
mod packed;
mod pq;
mod spec;
pub mod table;
#[cfg(test)]
mod throwaway;
mod volume;

use std::sync::Arc;

use crate::brdf::table::{chebyshev_w_nodes, DiscKernel, Region, TableSpec};
pub use crate::brdf::table::{CHEBYSHEV_W_TOLERANCE, MIN_CHEBYSHEV_W_NODES};
use crate::gpu::pipeline::{Binding, Resource};
use crate::gpu::{Device, StorageFormat};
use crate::material::{Material, PreparedMaterial};
use crate::spectrum::Expansion;
use crate::{Error, Result};

use super::{OutputMode, ParamsUbo};

pub(crate) use spec::{SpecConstant, Specialisation};

/// Declares the registry: the enum of variants (plus the `default` alias), [`VariantKind::ALL`]
/// in listing order, each variant's implementation, and `--variant` parsing by the names the
/// implementations declare.
macro_rules! registry {
    ($($(#[$attr:meta])* $kind:ident => $imp:path,)+) => {
        /// A registered variant (or the `default` alias); everything about it comes from its
        /// implementation ([`VariantKind::implementation`]).
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum VariantKind {
            $($(#[$attr])* #[doc = concat!("See [`", stringify!($imp), "`].")] $kind,)+
            /// The default variant (an alias; see [`VariantKind::DEFAULT`]).
            Default,
        }

        impl VariantKind {
            /// Every variant, the alias excluded, in listing order.
            pub const ALL: [VariantKind; [$($(#[$attr])* VariantKind::$kind),+].len()] =
                [$($(#[$attr])* VariantKind::$kind),+];

            /// What `--variant` accepts: every variant and the alias.
            const CHOICES: [VariantKind; [$($(#[$attr])* VariantKind::$kind),+].len() + 1] =
                [$($(#[$attr])* VariantKind::$kind,)+ VariantKind::Default];

            /// The variant's own declarations and resources.
            ///
            /// (Each implementation also knows its key, `Self::KIND`.)
            pub(crate) fn implementation(self) -> &'static dyn Variant {
                match self.resolve() {
                    $($(#[$attr])* VariantKind::$kind => &$imp,)+
                    VariantKind::Default => Self::DEFAULT.implementation(),
                }
            }
        }

        $($(#[$attr])* impl $imp {
            /// This variant's key in the registry.
            #[allow(dead_code)]
            pub(crate) const KIND: VariantKind = VariantKind::$kind;
        })+
    };
}

// The registry: one line per variant, in listing order.
registry! {
    Flss => flss::Flss,
    Nmm => nmm::Nmm,
    Pq => pq::Pq,
    Dhillon => dhillon::Dhillon,
    ChebyshevW => chebyshev_w::ChebyshevW,
    Volume => volume::Volume,
    Coverage => coverage::Coverage,
    // A throwaway registered only in the library's own tests, to show that a variant's
    // file and this one line put it everywhere: listed, profiled and in the stability
    // matrix, scored against its own model.
    #[cfg(test)]
    Throwaway => throwaway::Throwaway,
}

impl VariantKind {
    /// What `default` stands for: the fastest variant whose error against the 1 nm
    /// reference stays within ΔE2000 p99 ≤ 1 on the shipped gratings (README, profile).
    pub const DEFAULT: VariantKind = VariantKind::ChebyshevW;

    /// The variant exact to its own `T`, `R` and `Δλ`: the reference of the mesh view
    /// (`profile --per-vertex`), where no direct sum is affordable.
    pub const REFERENCE: VariantKind = VariantKind::Flss;

    /// The variant an alias stands for.
    pub fn resolve(self) -> VariantKind {
        match self {
            VariantKind::Default => Self::DEFAULT,
            k => k,
        }
    }

    /// Command-line name (the alias gives the name of what it stands for).
    pub fn name(self) -> &'static str {
        self.implementation().name()
    }

    /// One line for `diffract variants`.
    pub fn summary(self) -> &'static str {
        self.implementation().summary()
    }

    /// How it is profiled and listed.
    pub fn family(self) -> Family {
        self.implementation().family()
    }

    /// Its rows in `diffract profile`'s standard set.
    pub fn profile_presets(self) -> &'static [Preset] {
        self.implementation().profile_presets()
    }

    /// Whether it evaluates wavelengths per pixel and so can draw one wavelength.
    pub fn is_spectral(self) -> bool {
        self.implementation().spectral()
    }

    /// The variant called `name` (or the alias `default`).
    pub fn named(name: &str) -> Option<VariantKind> {
        Self::CHOICES.into_iter().find(|k| k.cli_name() == name)
    }

    /// The name `--variant` takes: `default` for the alias.
    fn cli_name(self) -> &'static str {
        match self {
            VariantKind::Default => "default",
            k => k.name(),
        }
    }

    /// Whether it reads a pre-integrated table of `G` (and so can hold the sun's disc in it).
    pub fn is_table(self) -> bool {
        self.family() == Family::Table
    }

    /// Texel fetches per pixel of a draw: what `render` reports for the same inputs (a
    /// bound where the variant fits its planes to the data, [`Footprint::at_most`]).
    pub fn fetches(self, inputs: &FetchInputs<'_>) -> usize {
        self.implementation().fetches(inputs)
    }

    /// Table variants: the table's planes, fetches and memory for `inputs`, as `render`
    /// uploads it (`None` for other variants).
    pub fn footprint(self, inputs: &FetchInputs<'_>) -> Option<Result<table::Footprint>> {
        let t = self.implementation().table_traits()?.layout;
        Some((|| {
            let (spec, _) =
                inputs
                    .table
                    .spec(self, inputs.material, inputs.h_range_um, inputs.region)?;
            let nodes = spec.uv_nodes()?;
            let dims = (nodes.0 + 2 * t.ghosts, nodes.1 + 2 * t.ghosts);
            let mut f = table::footprint(t.layout, spec.w_nodes, nodes, dims, inputs.table.format);
            // chebyshev-w leaves out the terms its table does not need, once built.
            f.at_most = t.fitted || (self == VariantKind::ChebyshevW && inputs.leave_out);
            Ok(f)
        })())
    }

    /// Refuses a draw of `output` this variant cannot make (one wavelength from a variant
    /// that integrates the spectrum offline).
    pub(crate) fn check_output(self, output: OutputMode) -> Result<()> {
        if output == OutputMode::MapSpectral && !self.is_spectral() {
            return Err(spectral_refusal(self));
        }
        Ok(())
    }

    /// The glsl file of its fragment stage (the key of hot-reloaded SPIR-V).
    pub fn fragment_file(self) -> &'static str {
        self.implementation().fragment()
    }

    /// The glsl file of its per-vertex stage (thesis §1.5.1), where it has one.
    pub fn per_vertex_file(self) -> Option<&'static str> {
        self.implementation().per_vertex()
    }
}

impl std::fmt::Display for VariantKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl clap::ValueEnum for VariantKind {
    fn value_variants<'a>() -> &'a [Self] {
        &Self::CHOICES
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        let help = match self {
            VariantKind::Default => format!("the default variant, {}", Self::DEFAULT.name()),
            k => k.summary().to_string(),
        };
        Some(clap::builder::PossibleValue::new(self.cli_name()).help(help))
    }
}

/// The one-line refusal of a single-wavelength draw by `kind`.
pub(crate) fn spectral_refusal(kind: VariantKind) -> Error {
    Error::invalid(
        "variant",
        format!(
            "'{}' integrates the spectrum offline and cannot draw one wavelength; use --variant flss with --lambda-nm",
            kind.resolve()
        ),
    )
}

/// What a draw's fetches and memory depend on: the same inputs `render` prepares a
/// variant with.
pub struct FetchInputs<'a> {
    /// Highest term index `T` of the DFT-term variants.
    pub terms: usize,
    pub material: &'a Material,
    pub table: &'a TableOptions,
    /// The `(u, v, w)` the draw reaches ([`map_region`] for a BRDF map).
    pub region: Region,
    /// The height field's peak-to-valley (µm): `chebyshev-w`'s `w` nodes follow it.
    pub h_range_um: f64,
    /// Leave out what the draw cannot need, as `render` does.
    pub leave_out: bool,
    /// The height field, where a count depends on it (`nmm`'s orders); `None`: the
    /// variant's formula without it.
    pub heightfield: Option<&'a crate::heightfield::HeightField>,
}

impl FetchInputs<'_> {
    /// Window taps per lookup, `(2R + 1)²`.
    pub fn taps(&self) -> usize {
        (2 * self.material.window_radius + 1).pow(2)
    }

    /// Wavelengths the shader loops over: the material's step over 380–780 nm, less those
    /// left out at its tolerance ([`crate::leave_out::WavelengthsLeft`], as the variants
    /// select them).
    pub fn lambdas(&self) -> usize {
        self.kept().map_or(
            (400 / self.material.lambda_step_nm.max(1) + 1) as usize,
            |k| k.kept_nm.len(),
        )
    }

    /// The shortest and longest wavelength the shader loops over (nm).
    pub fn kept_range_nm(&self) -> (f64, f64) {
        self.kept().map_or(
            (
                crate::colour::LAMBDA_MIN_NM as f64,
                crate::colour::LAMBDA_MAX_NM as f64,
            ),
            |k| k.kept_range_nm(),
        )
    }

    fn kept(&self) -> Option<crate::leave_out::WavelengthsLeft> {
        let colour = crate::colour::ColourTable::new(self.material.lambda_step_nm).ok()?;
        let colour = self.table.response.colour(&colour);
        let tolerance = self.leave_out.then_some(self.material.tolerance);
        Some(crate::leave_out::WavelengthsLeft::of(&colour, tolerance, "per pixel").1)
    }
}

/// The region of `(u, v, w)` a BRDF map under light from `wi` reaches, as `render` builds
/// its tables for it (`wi` rounded to float32, as uploaded).
pub fn map_region(wi: [f64; 3]) -> Region {
    Region::brdf_map(wi.map(|c| c as f32 as f64)).widened(1e-5)
}

/// One row of `diffract profile`'s standard set: a label and the numerical choices of the
/// variant in that row. The DFT-term variants read the expansion, `R`, `Δλ` and storage
/// (and `T`: the profile's Taylor `T`, two thirds of it for Chebyshev); the table variants
/// read the table's step and format overrides.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Preset {
    pub label: &'static str,
    pub expansion: Expansion,
    pub window_radius: usize,
    pub lambda_step_nm: u32,
    pub storage: StorageFormat,
    /// Table variants: the offline integral's step instead of the profile's.
    pub table_step_nm: Option<u32>,
    /// Table variants: the texel format instead of the profile's.
    pub table_format: Option<TableFormat>,
    /// Leave out what `render` leaves out (false: keep everything, as `render --keep-all`).
    pub leave_out: bool,
}

impl Preset {
    /// Taylor, `R = 2`, 5 nm, RG32F, the profile's table options: the base of every row.
    pub const BASE: Preset = Preset {
        label: "",
        expansion: Expansion::Taylor,
        window_radius: 2,
        lambda_step_nm: 5,
        storage: StorageFormat::Rg32f,
        table_step_nm: None,
        table_format: None,
        leave_out: true,
    };

    /// The base settings under `label`.
    pub const fn named(label: &'static str) -> Preset {
        Preset {
            label,
            ..Self::BASE
        }
    }

    /// `T` of this row for the profile's Taylor `T`: Chebyshev converges faster and gets two
    /// thirds of it.
    pub fn terms(&self, taylor_terms: usize) -> usize {
        match self.expansion {
            Expansion::Taylor => taylor_terms,
            Expansion::Chebyshev => (2 * taylor_terms).div_ceil(3),
        }
    }
}

/// How a variant is profiled and listed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// Evaluates the DFT terms per pixel (flss, nmm, pq): reads `T`, `R`, `Δλ`, storage.
    Terms,
    /// Reads a pre-integrated table of `G` (dhillon, chebyshev-w, volume).
    Table,
    /// Shows something about the draw instead of the BRDF (not profiled).
    Debug,
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
    /// Wavelength step of the offline spectral integral (nm); `None`: the variant's choice,
    /// [`TableOptions::DEFAULT_STEP_NM`], or a coarser step for a table that holds the
    /// sun's disc. An explicit step is kept as given.
    pub step_nm: Option<u32>,
    /// GPU memory a table may take; the `(u, v)` spacing is coarsened to fit (and said so).
    pub budget_bytes: usize,
    pub format: TableFormat,
    /// Where `G` is sampled: CPU or device (`--table-build`).
    pub build: crate::render::table_build::TableBuild,
    /// What `G` answers: relative reflectance (the sun-lit passes) or radiance (the
    /// environment-lit stages, [`crate::render::env_brdf`]).
    pub response: crate::brdf::table::Response,
    /// Levels of `chebyshev-w`'s table pre-filtered for a pixel's footprint
    /// ([`crate::brdf::table::Levelled`]); 1: the table alone, read at a pixel's centre.
    pub levels: usize,
}

impl Default for TableOptions {
    fn default() -> Self {
        Self {
            texel_uv: None,
            w_nodes: None,
            step_nm: None,
            budget_bytes: 512 << 20,
            format: TableFormat::Rgba32f,
            build: Default::default(),
            response: Default::default(),
            levels: 1,
        }
    }
}

impl TableOptions {
    /// What `render`, `view` and `profile` build tables with unless told otherwise: the
    /// defaults in float16, `chebyshev-w` with its levels for a pixel's footprint (measured
    /// nearer the converged picture, and faster, than the table read at the pixel's centre:
    /// docs/results/whole-picture.md). `TableOptions::default()` keeps float32 and one level
    /// for tests that compare with the f64 model point by point.
    pub const RENDER: TableOptions = TableOptions {
        texel_uv: None,
        w_nodes: None,
        step_nm: None,
        budget_bytes: 512 << 20,
        format: TableFormat::Rgba16f,
        build: crate::render::table_build::TableBuild::Auto,
        response: crate::brdf::table::Response::Relative,
        levels: crate::brdf::table::MAX_LEVELS,
    };

    /// The step of a table that holds no disc, unless another is asked for: a line of the
    /// 65 µm coherence window is about 1 nm wide at |u| ≈ 2, and the table pays the step
    /// only once, offline.
    pub const DEFAULT_STEP_NM: u32 = 1;

    /// `w` nodes of variant `kind` unless the height field asks for more
    /// ([`TableOptions::w_nodes_for_field`]).
    pub fn w_nodes_for(&self, kind: VariantKind) -> usize {
        self.w_nodes
            .or(kind.implementation().table_traits().map(|t| t.w_nodes))
            .unwrap_or(16)
    }

    /// `w` nodes of `kind` for a height range `h_range_um` over `w ∈ [w0, w1]`: for
    /// `chebyshev-w`, fitted to that range ([`chebyshev_w_nodes`]); the default otherwise.
    /// An explicit `w_nodes` is kept as given.
    pub fn w_nodes_for_field(&self, kind: VariantKind, h_range_um: f64, w: [f64; 2]) -> usize {
        let base = self.w_nodes_for(kind);
        let follows = kind
            .implementation()
            .table_traits()
            .is_some_and(|t| t.follows_field);
        if self.w_nodes.is_some() || !follows {
            return base;
        }
        chebyshev_w_nodes(h_range_um, w)
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
        // chebyshev-w read over a pixel's footprint also holds summed-area planes: three
        // float32 sums a coefficient and node (counted where the device may not filter
        // float32 and the levels take their place: they take less).
        let summed = if kind == VariantKind::ChebyshevW && self.levels > 1 {
            12 * w_nodes
        } else {
            0
        };
        let e = region.extent();
        let bytes = |t: f64| {
            let nodes = |len: f64| ((len / t).ceil() + 1.0).max(2.0);
            nodes(e[0]) * nodes(e[1]) * (w_nodes * texel_bytes + summed) as f64
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
        // The build's own limits (nodes a side, f64 samples) coarsen the spacing like the
        // budget does: a spacing finer than they allow is what a small budget gives too.
        let within_build = |t: f64| {
            let nodes = |len: f64| ((len / t).ceil() + 1.0).max(2.0);
            let (nu, nv) = (nodes(e[0]), nodes(e[1]));
            let side = crate::brdf::table::MAX_NODES_UV as f64;
            nu <= side
                && nv <= side
                && nu * nv * (3 * w_nodes) as f64 <= crate::brdf::table::MAX_SAMPLES as f64
        };
        let mut texel = asked;
        while bytes(texel) > self.budget_bytes as f64 || !within_build(texel) {
            texel *= 1.1;
        }
        let spec = TableSpec {
            region,
            texel_uv: texel,
            w_nodes,
            step_nm: self.step_nm.unwrap_or(Self::DEFAULT_STEP_NM),
            response: self.response,
        };
        spec.validate()?;
        Ok((spec, (texel > asked).then_some(asked)))
    }
}

/// What a frame reports about the variant that drew it.
#[derive(Debug, Clone, PartialEq, Default)]
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
    /// Table variants: where the table was built and in how long, or that it came from
    /// the cache.
    pub table_build: Option<String>,
    /// The light's disc is convolved into the table: a pixel evaluates the variant once per
    /// sample, not once per direction over the disc.
    pub disc_prefiltered: bool,
}

/// What a variant is prepared for.
pub(crate) struct DrawSetup<'a> {
    pub prepared: &'a PreparedMaterial,
    /// The `(u, v, w)` the draw can reach.
    pub region: Region,
    pub output: OutputMode,
    pub storage: StorageFormat,
    pub table: &'a TableOptions,
    /// Keep the f64 table on the CPU after upload ([`PreparedVariant::model`]).
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
    /// Where warnings and progress go.
    pub report: &'a dyn crate::report::Report,
}

impl DrawSetup<'_> {
    /// The tolerance wavelengths and a table's series terms are left out at, `None` when
    /// everything is kept.
    pub fn leave_out_tolerance(&self) -> Option<f64> {
        self.leave_out.then_some(self.prepared.material.tolerance)
    }

    /// `colour` weighted as this draw's `G` is ([`TableOptions::response`]): what the
    /// variant sums, and what the leaving out of wavelengths is measured against.
    pub fn colour(&self, colour: &crate::colour::ColourTable) -> crate::colour::ColourTable {
        self.table.response.colour(colour)
    }
}

/// A variant: everything it declares about itself, and how to build its resources. One
/// implementation per file; the registry lists them.
pub(crate) trait Variant: Sync {
    /// Command-line name (`--variant`, `diffract variants`, the viewer's title).
    fn name(&self) -> &'static str;
    /// One line for `diffract variants` and the README's table.
    fn summary(&self) -> &'static str;
    /// How it is profiled and listed.
    fn family(&self) -> Family;
    /// The glsl/ file of its fragment stage (build.rs embeds it; the key of hot reload).
    fn fragment(&self) -> &'static str;
    /// The glsl/ file of its per-vertex stage (thesis §1.5.1: the BRDF evaluated per vertex,
    /// the colour interpolated), where it has one.
    fn per_vertex(&self) -> Option<&'static str> {
        None
    }
    /// Whether it evaluates wavelengths per pixel and so can draw one wavelength.
    fn spectral(&self) -> bool {
        false
    }
    /// What a table variant states about its table (`None` for every other family): its
    /// `w` nodes, whether they follow the field, its layout on the GPU. Required, and one
    /// value, so a new table variant cannot inherit another's by leaving a method out
    /// (the registry's test holds it to [`Variant::family`]).
    fn table_traits(&self) -> Option<table::TableTraits>;
    /// Texel fetches per evaluation (one pixel, one direction of the light).
    fn fetches(&self, inputs: &FetchInputs<'_>) -> usize;
    /// How its fetch count grows, for the docs' table (`λ·(T+1)·(2R+1)²`).
    fn fetch_formula(&self) -> &'static str;
    /// Whether its resources depend on the region the draw reaches (leaving out on or off).
    fn reads_region(&self, _leave_out: bool) -> bool {
        true
    }
    /// Its rows in `diffract profile`'s standard set.
    fn profile_presets(&self) -> &'static [Preset] {
        &[]
    }
    /// Its cases in `diffract stability`.
    fn stability(&self) -> Stability;
    /// Builds and uploads what the shader reads for `setup`.
    fn prepare(&self, dev: &Arc<Device>, setup: &DrawSetup<'_>)
        -> Result<Box<dyn PreparedVariant>>;
}

/// A variant's GPU resources for one material and region. A variant built on another's
/// resources (nmm and pq on flss's terms) returns them from [`PreparedVariant::base`], and
/// every method it does not override answers from there.
pub(crate) trait PreparedVariant: Send + Sync {
    /// The resources this one extends, if any.
    fn base(&self) -> Option<&dyn PreparedVariant> {
        None
    }
    /// Its descriptor bindings beyond the shared ones.
    fn bindings(&self) -> Vec<Binding> {
        self.base().map_or_else(Vec::new, |b| b.bindings())
    }
    /// What those bindings point at.
    fn resources(&self) -> Vec<(u32, Resource<'_>)> {
        self.base().map_or_else(Vec::new, |b| b.resources())
    }
    /// Sets its specialisation constants.
    fn specialise(&self, spec: &mut Specialisation) {
        if let Some(b) = self.base() {
            b.specialise(spec);
        }
    }
    /// Fills its part of the shared uniform block.
    fn fill_params(&self, params: &mut ParamsUbo) {
        if let Some(b) = self.base() {
            b.fill_params(params);
        }
    }
    fn stats(&self) -> VariantStats;
    /// What its shader computes, on the CPU in f64 (`None`: a debug view, which draws no
    /// BRDF, or a table built without [`DrawSetup::keep_model`]). Required of every
    /// variant, so a new one cannot be scored against another's model by default.
    fn model(&self) -> Option<&dyn CpuModel>;
    /// The pipeline's name (validation messages and captures show it).
    fn pipeline_name(&self) -> String {
        self.stats().name
    }
    /// Indices into the material's colour table of the wavelengths the shader loops over
    /// (binding 2 holds only these); `None`: all of them.
    fn kept_wavelengths(&self) -> Option<&[usize]> {
        self.base().and_then(|b| b.kept_wavelengths())
    }
    /// What it left out of what the scene does not need (`None`: nothing recorded).
    fn left_out(&self) -> Option<crate::leave_out::LeftOut> {
        self.base().and_then(|b| b.left_out())
    }
}

/// The CPU model of a prepared variant: what its shader computes, in f64, with the
/// inputs the shader saw (ωi and ωr as uploaded, the wavelengths the draw kept). The
/// profiler scores the GPU against it, which separates float32 and driver error from the
/// variant's approximation.
pub trait CpuModel: Send + Sync {
    /// XYZ at `wr` under light from `wi` for `prepared`, summing `colour`'s weights (the
    /// material's colour table with the wavelengths the draw left out at weight 0). An
    /// error where the model reads what `prepared` has not loaded (its DFT terms).
    fn xyz(
        &self,
        prepared: &PreparedMaterial,
        colour: &crate::colour::ColourTable,
        wi: [f64; 3],
        wr: [f64; 3],
    ) -> Result<[f64; 3]>;
    /// Table variants: the f64 table itself (its conditioning, its overshoot below zero).
    fn table(&self) -> Option<&dyn crate::brdf::table::GTable> {
        None
    }
}

/// A table variant's representation, built on the CPU for a [`TableSpec`] and evaluated
/// in float32 as its shader does: the stability matrix's table cases.
pub(crate) type TableMirror =
    fn(&crate::heightfield::HeightField, f64, &TableSpec, f64) -> Result<Mirrored>;

/// A spectral variant's f64 model at one wavelength, `ρ(ωi, ωr, λ)`: the stability
/// matrix's model cells and the reference of its GPU cells (an error where `prepared` has
/// not loaded what the model reads).
pub(crate) type SpectralModel =
    fn(&PreparedMaterial, &crate::brdf::Shading, [f64; 3], [f64; 3], f64) -> Result<f64>;

/// A representation built for the stability matrix, or the variant's refusal of it.
pub(crate) enum Mirrored {
    /// `G` at `(u, v)` node `t` (row-major over the spec's nodes) and `w`, in float32 as
    /// the shader evaluates it (stored planes rounded, the sum in float32, clamped to
    /// `G ≥ 0`).
    Eval(Box<dyn Fn(usize, f64) -> [f64; 3]>),
    /// Refused, with the error the variant expected and its message.
    Refused { expected: f64, message: String },
}

/// What a variant contributes to `diffract stability`.
pub(crate) enum Stability {
    /// The spectral matrix (heights × angles × wavelengths × expansions × term counts): its
    /// f64 model and its GPU spectral map against the direct sum.
    Spectral(SpectralModel),
    /// The narrow-region table cases, its float32 mirror against `G` sampled exactly.
    Table(TableMirror),
    /// Not in the matrix, and why (a phrase that follows the variant's name: "is a debug
    /// view and draws no BRDF").
    Excluded(&'static str),
}

/// What `diffract variants` lists for one variant: the figures `render` reports for a BRDF
/// map at θi = 60° of the default material with the default options.
struct Listed {
    kind: VariantKind,
    fetches: usize,
    /// `≤` where the variant fits its planes to the data.
    bound: bool,
    memory: String,
}

/// The listed figures of every variant, from the same code `render` prepares them with
/// ([`VariantKind::fetches`], [`VariantKind::footprint`]), and what they were for.
fn listed() -> (Vec<Listed>, String) {
    let material = Material::default();
    let hf = material
        .load_heightfield(&crate::report::Collect::default())
        .ok();
    let terms = hf
        .as_ref()
        .and_then(|hf| {
            material
                .plan(
                    hf,
                    &crate::brdf::truncation::Reach::brdf_map(60.0),
                    crate::brdf::truncation::Precision::F32,
                )
                .ok()
        })
        .map_or(30, |p| p.terms);
    let table = TableOptions::RENDER;
    let inputs = FetchInputs {
        terms,
        material: &material,
        table: &table,
        region: map_region(crate::brdf::direction(60.0, 0.0)),
        h_range_um: hf.as_ref().map_or(0.375, |h| h.range().1 - h.range().0),
        leave_out: true,
        heightfield: hf.as_ref(),
    };
    let rows = VariantKind::ALL
        .into_iter()
        .map(|kind| {
            let (bound, memory) = match (kind.family(), kind.footprint(&inputs)) {
                (_, Some(Ok(f))) => (
                    f.at_most,
                    format!(
                        "{}{:.1} MB ({}×{}×{} {}, u/v texel {:.4})",
                        if f.at_most { "≤ " } else { "" },
                        f.bytes as f64 / 1e6,
                        f.dims.0,
                        f.dims.1,
                        f.layers,
                        f.format.name(),
                        inputs
                            .table
                            .texel_uv
                            .unwrap_or_else(|| { TableSpec::default_texel(material.coherence_um) })
                    ),
                ),
                (_, Some(Err(e))) => (false, e.to_string()),
                (Family::Terms, None) => (
                    false,
                    format!("the term band × {} layers, RG32F", terms + 1),
                ),
                (_, None) => (false, "none (a uniform block)".to_string()),
            };
            Listed {
                kind,
                fetches: kind.fetches(&inputs),
                bound,
                memory,
            }
        })
        .collect();
    let what = format!(
        "default material ({}, T = {terms}), BRDF map at θi = 60°, leaving out as render does, {} tables",
        material.heightfield,
        table.format.name()
    );
    (rows, what)
}

/// `diffract variants`: the list, with fetches and memory for the default material on a
/// BRDF map at θi = 60° (its automatic `T` planned, not computed), as `render` reports them.
pub fn list() -> String {
    let (rows, what) = listed();
    let mut s = format!("variant       fetches/pixel  memory ({what})\n");
    for r in &rows {
        let mark = if r.kind == VariantKind::DEFAULT {
            " (default)"
        } else {
            ""
        };
        let fetches = format!("{}{}", if r.bound { "≤ " } else { "" }, r.fetches);
        s.push_str(&format!(
            "{:<13} {:>13}  {}\n    {}{mark}\n",
            r.kind.name(),
            fetches,
            r.memory,
            r.kind.summary()
        ));
    }
    let scene = crate::scene::Scene::default_scene();
    let disc = scene.light.disk_samples().len().max(1);
    let ss = scene.output.supersample.max(1).pow(2) as usize;
    s.push_str(&format!("fetches are per evaluation: a pixel of the default scene evaluates the variant for each of {ss} supersamples and, unless the variant's table holds the sun's disc pre-filtered (the table variants on a scene), for {disc} directions over the disc: {ss}× or {}× the counts above\n", disc * ss));
    let per_vertex: Vec<&str> = VariantKind::ALL
        .into_iter()
        .filter(|k| k.per_vertex_file().is_some())
        .map(VariantKind::name)
        .collect();
    s.push_str(&format!(
        "per-vertex (--per-vertex on render, view, profile; thesis §1.5.1): {} evaluated once per mesh vertex, the colour interpolated; cost per vertex, not per pixel\n",
        per_vertex.join(", ")
    ));
    s
}

/// docs/variants.md's block: the names `--variant` takes, and each variant's fetch formula
/// with its count as [`list`] gives it.
pub fn markdown_fetches() -> String {
    let (rows, what) = listed();
    let names: Vec<&str> = VariantKind::CHOICES.iter().map(|k| k.cli_name()).collect();
    let mut s = format!(
        "    diffract render --variant {} [--per-vertex] ...\n\n| variant | fetches / pixel | {what} |\n|---|---|---|\n",
        names.join("|")
    );
    for r in &rows {
        let mark = if r.kind == VariantKind::DEFAULT {
            " (**default**)"
        } else {
            ""
        };
        s.push_str(&format!(
            "| `{}`{mark} | {} | {}{} |\n",
            r.kind.name(),
            r.kind.implementation().fetch_formula(),
            if r.bound { "≤ " } else { "" },
            r.fetches
        ));
    }
    s
}

/// The Markdown table of the variants (the README's and docs/variants.md's): name, family,
/// stages and the one line, from the registry.
pub fn markdown_table() -> String {
    let mut s = String::from("| variant | kind | stages | what it does |\n|---|---|---|---|\n");
    for kind in VariantKind::ALL {
        let v = kind.implementation();
        let family = match v.family() {
            Family::Terms => "DFT terms per pixel",
            Family::Table => "pre-integrated table",
            Family::Debug => "debug view",
        };
        let stages = match v.per_vertex() {
            Some(pv) => format!("`{}`, `{pv}`", v.fragment()),
            None => format!("`{}`", v.fragment()),
        };
        let mark = if kind == VariantKind::DEFAULT {
            " **(default)**"
        } else {
            ""
        };
        s.push_str(&format!(
            "| `{}`{mark} | {family} | {stages} | {} |\n",
            v.name(),
            v.summary().replace('|', "\\|")
        ));
    }
    s
}

#[cfg(test)]
pub(super) mod testing {
    use crate::brdf::table::{Region, Slices, TableSpec};

    /// A 2×2-node region over `w ∈ [−1.6, −1.1]`.
    pub fn spec(w_nodes: usize) -> TableSpec {
        TableSpec {
            region: Region {
                lo: [-0.1, -0.1, -1.6],
                hi: [0.1, 0.1, -1.1],
            },
            texel_uv: 0.2,
            w_nodes,
            step_nm: 10,
            response: crate::brdf::table::Response::Relative,
        }
    }

    /// A cubic in `ŵ` per texel and channel, positive over `[−1, 1]`.
    pub fn g(t: usize, w_hat: f64) -> [f64; 3] {
        std::array::from_fn(|c| {
            let a = 0.1 * (1 + t + c) as f64;
            0.5 + a * w_hat - 0.2 * w_hat.powi(3) + 0.05 * w_hat * w_hat
        })
    }

    /// `g` sampled at `w_nodes` on the four texels.
    pub fn slices(spec: &TableSpec, w_nodes: &[f64]) -> Slices {
        let (lo, hi) = (spec.region.lo[2], spec.region.hi[2]);
        Slices {
            nu: 2,
            nv: 2,
            w: w_nodes.to_vec(),
            data: w_nodes
                .iter()
                .map(|w| {
                    (0..4)
                        .map(|t| g(t, (2.0 * w - lo - hi) / (hi - lo)))
                        .collect()
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A table variant states its table (`w` nodes, whether they follow the field, layout)
    /// in one required value, and no other family states one: a variant whose family says
    /// "table" but whose traits were left `None` fails here, not silently in a draw.
    #[test]
    fn a_table_variant_states_its_table_and_no_other_does() {
        for kind in VariantKind::ALL {
            let traits = kind.implementation().table_traits();
            assert_eq!(kind.is_table(), traits.is_some(), "{kind}");
            if let Some(t) = traits {
                assert!(
                    (2..=crate::brdf::table::MAX_NODES_W).contains(&t.w_nodes),
                    "{kind}"
                );
            }
        }
    }

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
        // Read over a pixel's footprint, the summed-area planes (12 bytes a coefficient and
        // node) count against the budget too.
        let summed = TableOptions {
            levels: 6,
            ..with(None, 8 << 20)
        };
        let (spec, _) = summed.spec(VariantKind::ChebyshevW, &m, 0.375, r).unwrap();
        let (nu, nv) = spec.uv_nodes().unwrap();
        let per_node = spec.w_nodes * (TableOptions::default().format.texel_bytes() + 12);
        assert!(nu * nv * per_node <= 8 << 20);
        let plain = with(None, 8 << 20)
            .spec(VariantKind::ChebyshevW, &m, 0.375, r)
            .unwrap()
            .0;
        assert!(spec.texel_uv > plain.texel_uv);
    }

    #[test]
    fn chebyshev_w_nodes_grow_with_the_height_range() {
        let t = TableOptions::default();
        let w = [-1.5, -0.5];
        // The shipped Elaphe-like grating (0.37 µm): a = 16.5·0.37·0.5 ≈ 3.1, J_j(3.1) ≤ 1e-4
        // from j = 9 on: 11 coefficients (fitted to the w range; the unfitted default is 16) …
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

    /// Terms deferred and read before `load_terms` are an error from the cell and from
    /// every spectral model, not a panic; once loaded, the same calls give numbers.
    #[test]
    fn unloaded_terms_are_an_error_not_a_panic() {
        let material = Material {
            heightfield: "a 32² sinusoid".into(),
            terms: crate::material::Terms::Fixed(4),
            ..Material::default()
        };
        let heights = (0..32 * 32)
            .map(|k| 0.1 * (std::f64::consts::TAU * (k % 32) as f64 / 32.0).sin())
            .collect();
        let hf = crate::heightfield::HeightField::new(32, 32, 0.05, heights).unwrap();
        let plan = material
            .plan(
                &hf,
                &crate::brdf::truncation::Reach::ALL,
                crate::brdf::truncation::Precision::F64,
            )
            .unwrap();
        let p = material.prepare_planned_deferred(hf, plan, None).unwrap();
        let (wi, wr) = (
            crate::brdf::direction(30.0, 0.0),
            crate::brdf::direction(10.0, 180.0),
        );
        let models: Vec<SpectralModel> = VariantKind::ALL
            .into_iter()
            .filter_map(|k| match k.implementation().stability() {
                Stability::Spectral(rho) => Some(rho),
                _ => None,
            })
            .collect();
        assert!(!models.is_empty());
        let unloaded = p.stack.get().unwrap_err();
        assert!(matches!(unloaded, Error::Internal(_)), "{unloaded}");
        assert!(unloaded.to_string().contains("load_terms"), "{unloaded}");
        for rho in &models {
            assert!(matches!(
                rho(&p, &p.shading, wi, wr, 550.0),
                Err(Error::Internal(_))
            ));
        }
        p.load_terms(&crate::report::Collect::default()).unwrap();
        assert_eq!(p.stack.get().unwrap().term_count(), 5);
        for rho in &models {
            assert!(rho(&p, &p.shading, wi, wr, 550.0).unwrap().is_finite());
        }
    }

    #[test]
    fn names_round_trip_and_the_alias_resolves() {
        for k in VariantKind::ALL {
            assert_eq!(k.resolve(), k);
            assert!(!k.summary().is_empty());
            assert_eq!(VariantKind::named(k.name()), Some(k));
        }
        let mut names: Vec<&str> = VariantKind::ALL
            .into_iter()
            .map(VariantKind::name)
            .collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), VariantKind::ALL.len(), "names are unique");
        assert_eq!(VariantKind::Default.resolve(), VariantKind::DEFAULT);
        assert_eq!(VariantKind::Default.name(), VariantKind::DEFAULT.name());
        assert_eq!(VariantKind::named("default"), Some(VariantKind::Default));
        assert!(VariantKind::Flss.is_spectral() && !VariantKind::Volume.is_spectral());
        assert!(list().contains("(default)"));
        assert!(markdown_table().contains("**(default)**"));
    }
}
