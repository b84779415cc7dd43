//! What a profile measures: its rows (a variant with its numerical choices, from the
//! presets each registered variant declares) and the rest of its set-up.

use std::path::PathBuf;

use super::budget::Frames;
use crate::brdf::table::TableSpec;
use crate::gpu::StorageFormat;
use crate::light::env::EnvMap;
use crate::material::Material;
use crate::render::variant::{Family, Preset};
use crate::render::{TableOptions, VariantKind};
use crate::scene::Scene;
use crate::spectrum::Expansion;

/// One profiled configuration: a variant with its numerical choices (FLSS: the material's
/// expansion, `T`, `R`, `Δλ` and term storage; tables: their sampling options).
#[derive(Debug, Clone, PartialEq)]
pub struct Variant {
    pub name: String,
    pub kind: VariantKind,
    pub expansion: Expansion,
    pub terms: usize,
    pub window_radius: usize,
    pub lambda_step_nm: u32,
    pub storage: StorageFormat,
    pub table: TableOptions,
    /// Leave out what the map cannot need, as `render` does (wavelengths whose weight is
    /// under the tolerance, DFT texels outside the reached band); false: keep everything.
    pub leave_out: bool,
}

impl Variant {
    /// `base` with this variant's numerical choices (the DFT-term variants read them; the
    /// table variants read only the height field and coherence length).
    pub fn material(&self, base: &Material) -> Material {
        match self.kind.family() {
            Family::Terms => Material {
                expansion: self.expansion,
                terms: crate::material::Terms::Fixed(self.terms),
                window_radius: self.window_radius,
                lambda_step_nm: self.lambda_step_nm,
                ..base.clone()
            },
            Family::Table | Family::Debug => base.clone(),
        }
    }

    /// The row of `kind` for `preset`, with the profile's Taylor `terms` and `table` options.
    fn from_preset(kind: VariantKind, preset: &Preset, terms: usize, table: &TableOptions) -> Self {
        let table = TableOptions {
            step_nm: preset.table_step_nm.or(table.step_nm),
            format: preset.table_format.unwrap_or(table.format),
            ..*table
        };
        let name = if preset.label.is_empty() {
            kind.name().to_string()
        } else {
            preset.label.to_string()
        };
        match kind.family() {
            Family::Terms => Variant {
                name,
                kind,
                expansion: preset.expansion,
                terms: preset.terms(terms),
                window_radius: preset.window_radius,
                lambda_step_nm: preset.lambda_step_nm,
                storage: preset.storage,
                table,
                leave_out: preset.leave_out,
            },
            Family::Table | Family::Debug => Variant {
                name,
                kind,
                expansion: Expansion::Taylor,
                terms: 0,
                window_radius: 0,
                lambda_step_nm: table.step_nm.unwrap_or(TableOptions::DEFAULT_STEP_NM),
                storage: StorageFormat::Rg32f,
                table,
                leave_out: preset.leave_out,
            },
        }
    }
}

/// The rows of every registered variant of `family`, from the presets each declares.
fn rows_of(family: Family, terms: usize, table: &TableOptions) -> Vec<Variant> {
    VariantKind::ALL
        .into_iter()
        .filter(|k| k.family() == family)
        .flat_map(|k| {
            k.profile_presets()
                .iter()
                .map(move |p| Variant::from_preset(k, p, terms, table))
        })
        .collect()
}

/// The DFT-term set (flss, nmm, pq): the rows each variant declares, e.g. FLSS's thesis
/// setting (Taylor, R = 1), the default, larger R, Chebyshev, the compact storage formats,
/// and coarser and finer wavelength steps. `terms` is T of the Taylor rows; Chebyshev gets
/// about two thirds of it (it converges faster, README).
pub fn flss_variants(terms: usize) -> Vec<Variant> {
    rows_of(Family::Terms, terms, &TableOptions::default())
}

/// The pre-integrated set with `table` as the base options: each table variant at its
/// defaults, plus the extra rows each declares (`chebyshev-w` with its spectrum integrated
/// at 5 nm as FLSS samples it, `volume` in float16).
pub fn table_variants(table: &TableOptions) -> Vec<Variant> {
    rows_of(Family::Table, 0, table)
}

/// Every variant: [`flss_variants`] then [`table_variants`].
pub fn standard_variants(terms: usize) -> Vec<Variant> {
    let mut v = flss_variants(terms);
    v.extend(table_variants(&TableOptions::default()));
    v
}

/// What to profile.
#[derive(Debug, Clone)]
pub struct ProfileSetup {
    pub base: Material,
    pub variants: Vec<Variant>,
    pub theta_i_deg: f64,
    pub phi_i_deg: f64,
    /// BRDF map side in pixels.
    pub size: u32,
    /// Pixels scored, spread evenly over the disk (where errors in dark regions show).
    pub pixels: usize,
    /// Pixels scored among the brightest of the first measured row's map (where
    /// diffraction is).
    pub brightest: usize,
    /// Frames per row after a warm-up frame; the median is reported.
    pub frames: Frames,
    /// A mesh view timed per row (not scored), when given.
    pub mesh: Option<Scene>,
    /// Also evaluate the variants that have a per-vertex stage per vertex on the mesh view,
    /// and score every mesh view against a per-pixel render of it by
    /// [`VariantKind::REFERENCE`] at 1 nm.
    pub per_vertex: bool,
    pub cache_dir: Option<PathBuf>,
}

/// Samples per pixel of the environment rows unless `--env-spp` says otherwise.
pub const DEFAULT_ENV_SPP: [u32; 5] = [1, 4, 16, 64, 256];
/// Pixels scored against the environment's f64 quadrature unless `--env-pixels` says.
pub const DEFAULT_ENV_PIXELS: usize = 8;

/// What the environment rows draw.
#[derive(Debug, Clone)]
pub struct EnvProfile {
    pub map: EnvMap,
    /// Samples per pixel, one row each, ascending and distinct.
    pub samples: Vec<u32>,
    /// The radiance table (`render --brdf-map --env`'s: `u, v ∈ [−2, 2]`, `w ∈ [−2, 0]`).
    pub spec: TableSpec,
    /// Pixels scored, spread evenly over the map's disk.
    pub pixels: usize,
    /// The variants drawn, a row per sample count each, in this order (each one's rows
    /// ascend in samples).
    pub variants: Vec<crate::render::variant::VariantKind>,
}
