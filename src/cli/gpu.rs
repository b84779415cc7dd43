//! The GPU flags: the shader variant, the storage of the DFT terms, per-vertex evaluation
//! and the table variants' options, with their checks.

use crate::gpu::StorageFormat;
use crate::render::table_build::TableBuild;
use crate::render::variant::{TableFormat, TableOptions, VariantKind};
use crate::{Error, Result};

/// Finest `--table-texel`: a tenth of the default spacing at the longest coherence length a
/// material takes (1.75e-5 at 1e4 µm); anything finer is only ever coarsened to the budget.
pub const MIN_TABLE_TEXEL: f64 = 1e-6;

/// Coarsest `--table-step-nm`: the trapezoid rule over the CIE 1931 observer and D65 gives a
/// white spectrum's X, Y, Z within 1 % of the 1 nm integral at 20 nm, but 5 % off at 50 nm
/// and 99 % at 200 nm (a map 15 times too dark), whatever the lines of the grating do.
pub const MAX_TABLE_STEP_NM: u32 = 20;

/// Table options shared by `render`, `profile` and `view`.
#[derive(Debug, Clone, clap::Args)]
pub struct TableArgs {
    /// Table variants: node spacing in u and v (default: half the coherence lobe).
    #[arg(long)]
    pub table_texel: Option<f64>,
    /// Table variants: nodes along w (default: volume 32, chebyshev-w 16, dhillon 12; an
    /// environment's table 8).
    #[arg(long)]
    pub table_w_nodes: Option<usize>,
    /// Table variants: wavelength step of the offline spectral integral (nm) [default: 1,
    /// or 2 for a table that holds the sun's disc, whose blur hides the coarser step].
    #[arg(long)]
    pub table_step_nm: Option<u32>,
    /// Table variants: GPU memory budget (MB); the u/v spacing is coarsened to fit.
    #[arg(long, default_value_t = 512)]
    pub table_budget_mb: usize,
    /// Table variants: texel format (float16 halves the memory; on the default scene the
    /// picture moves by a ΔE2000 of 0.001).
    #[arg(long, value_enum, default_value_t = TableOptions::RENDER.format)]
    pub table_format: TableFormat,
    /// Table variants: where to build the table (auto: the device when it is a GPU, the
    /// CPU when Vulkan itself runs on the CPU, e.g. lavapipe).
    #[arg(long, value_enum, default_value_t = TableBuild::Auto)]
    pub table_build: TableBuild,
    /// chebyshev-w: reading its table over a pixel's footprint in (u, v). 1: the table alone,
    /// read at the pixel's centre. More: a raster pass reads the mean over the footprint's
    /// box from summed-area planes where the device filters float32 (else from this many
    /// levels pre-filtered, each twice as coarse as the one before); the compute stages'
    /// point lights read the same box over their footprints in the G-buffer.
    #[arg(long, default_value_t = TableOptions::RENDER.levels)]
    pub table_levels: usize,
}

impl TableArgs {
    /// The flags as the renderer takes them.
    pub fn options(&self) -> TableOptions {
        TableOptions {
            texel_uv: self.table_texel,
            w_nodes: self.table_w_nodes,
            step_nm: self.table_step_nm,
            budget_bytes: self.table_budget_mb.saturating_mul(1 << 20),
            format: self.table_format,
            build: self.table_build,
            response: crate::brdf::table::Response::Relative,
            levels: self.table_levels,
        }
    }

    /// The table variants' options (`--table-*`), checked the same way by every command
    /// that takes them, whichever variant is drawn: a spacing above zero, a `w` node count
    /// the table supports, a wavelength step that divides the visible range, a budget of at
    /// least 1 MB.
    pub fn check(&self) -> Result<()> {
        use crate::brdf::table::{MAX_LEVELS, MAX_NODES_W};
        if !(1..=MAX_LEVELS).contains(&self.table_levels) {
            return Err(Error::invalid(
                "table levels",
                format!("{}; expected 1..={MAX_LEVELS}", self.table_levels),
            ));
        }
        if let Some(texel) = self.table_texel {
            crate::guard::positive("table texel", texel, "")?;
            if texel < MIN_TABLE_TEXEL {
                return Err(Error::invalid(
                    "table texel",
                    format!(
                        "{texel:e}; expected at least {MIN_TABLE_TEXEL:e} (a tenth of the default spacing at the longest coherence length, 1.75e-5 at 1e4 µm)"
                    ),
                ));
            }
        }
        if let Some(n) = self.table_w_nodes {
            if !(2..=MAX_NODES_W).contains(&n) {
                return Err(Error::invalid(
                    "table w nodes",
                    format!("{n}; expected 2..={MAX_NODES_W}"),
                ));
            }
        }
        if let Some(step) = self.table_step_nm {
            crate::colour::ColourTable::new(step)?;
            if step > MAX_TABLE_STEP_NM {
                return Err(Error::invalid(
                    "table step",
                    format!(
                        "{step} nm; expected at most {MAX_TABLE_STEP_NM} nm (a divisor of 400: 1, 2, 4, 5, 8, 10, 16 or 20): the colour integral of a white spectrum is off by 1 % at 20 nm, 5 % at 50 nm and 99 % at 200 nm"
                    ),
                ));
            }
        }
        if self.table_budget_mb == 0 {
            return Err(Error::invalid(
                "table budget",
                "0 MB; expected at least 1 MB",
            ));
        }
        Ok(())
    }
}

/// The GPU flags shared by `render` and `view`.
#[derive(Debug, Clone, clap::Args)]
pub struct GpuArgs {
    /// Shader variant (`diffract variants` lists them; in the viewer, the first one: V
    /// cycles through them).
    #[arg(long, value_enum, default_value_t = VariantKind::Default)]
    pub variant: VariantKind,
    /// Storage format of the DFT terms on the GPU (flss).
    #[arg(long, value_enum, default_value_t = StorageFormat::Rg32f)]
    pub storage: StorageFormat,
    /// Evaluate the BRDF per vertex and interpolate the colour (thesis §1.5.1; flss, nmm,
    /// pq; scenes only: a BRDF map has no vertices; in the viewer V then cycles through
    /// those).
    #[arg(long)]
    pub per_vertex: bool,
    #[command(flatten)]
    pub table: TableArgs,
}

impl GpuArgs {
    /// Refuses `--per-vertex` where it cannot apply: on a BRDF map (no vertices) and for a
    /// variant (`variant`, as the command resolved `--variant`) without a per-vertex stage.
    /// Checked before the device is opened.
    pub fn check_per_vertex(&self, brdf_map: bool, variant: VariantKind) -> Result<()> {
        if !self.per_vertex {
            return Ok(());
        }
        if brdf_map {
            return Err(Error::invalid(
                "per-vertex",
                "a BRDF map has no vertices (every pixel is its own direction); drop --per-vertex or --brdf-map",
            ));
        }
        if variant.per_vertex_file().is_none() {
            let with: Vec<&str> = VariantKind::ALL
                .into_iter()
                .filter(|k| k.per_vertex_file().is_some())
                .map(VariantKind::name)
                .collect();
            return Err(Error::invalid(
                "per-vertex",
                format!(
                    "'{}' has no per-vertex evaluation: a table variant's lookup already costs about what a vertex does, so interpolating it would add error and save nothing; use {}",
                    variant.resolve(),
                    with.join(", ")
                ),
            ));
        }
        Ok(())
    }
}

/// Whether to enable Vulkan validation: always in debug builds, or with
/// `DIFFRACT_VALIDATION=1`.
pub fn validation_requested() -> bool {
    cfg!(debug_assertions) || std::env::var("DIFFRACT_VALIDATION").is_ok_and(|v| v == "1")
}
