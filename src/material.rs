//! The diffraction material: which height field, its physical scale, and the numerical
//! choices of MODEL §3–5 (expansion, terms `T`, window radius `R`, coherence length, `Δλ`,
//! Fresnel/shadowing). Shared by `diffract brdf`, BRDF maps and scene files, so all three
//! describe a material with the same words and defaults.

use crate::brdf::truncation::{self, Geometry, Precision, Reach, TermPlan};
use crate::brdf::Shading;
use crate::colour::ColourTable;
use crate::heightfield::{HeightField, Source, Tile};
use crate::report::Report;
use crate::spectrum::{self, Expansion, TermRequest, TermStack, Window};
use crate::{Error, Result};

pub use crate::brdf::truncation::Terms;

/// Largest accepted coherence length (µm, 10 mm). Beyond it the window is narrower than
/// float32 lookups resolve and the direct-sum reference (`3·coherence/dH` samples a side)
/// cannot be afforded; at `1e308` the window's variance underflows and every value is NaN.
pub const MAX_COHERENCE_UM: f64 = 1e4;

/// Default coherence length of sunlight (µm), MODEL §3.
pub const DEFAULT_COHERENCE_UM: f64 = 65.0;

/// A fully specified material.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Material {
    /// Height-field image path, or `builtin:elaphe|blazed|sinusoidal|xenopeltis`.
    pub heightfield: String,
    /// Pixel size (µm); overrides the sidecar.
    pub dh_um: Option<f64>,
    /// Height of grey level 1 (µm); for scans and built-in fields the peak-to-valley
    /// height. Overrides the sidecar.
    pub h_max_um: Option<f64>,
    /// Scans (`.gsf`, `.gwy`): the channel, by index or title (default: the first height
    /// channel).
    pub channel: Option<String>,
    /// Levelling steps, a comma list of `none`, `plane`, `poly:N`, `rows` (default:
    /// `plane,rows` for scans, `none` for images, `.f32` and built-in fields).
    pub level: Option<String>,
    /// How the field is made to tile: `none` (default), `mirror`, `window` or `grow`.
    pub tile: Option<Tile>,
    /// Chebyshev (stable, the default) or Taylor (thesis) expansion. With `terms = auto`
    /// this is a preference: where it cannot meet the tolerance the other one is used, with
    /// a warning.
    pub expansion: Expansion,
    /// Highest term index `T` (terms `0..=T`), or `auto` (the default): the smallest `T`
    /// and the expansion meeting `tolerance` (MODEL §4; see [`truncation`]).
    pub terms: Terms,
    /// Tolerance on `ρ/C = |P̂|²` relative to a flat mirror's specular value, for `auto`.
    pub tolerance: f64,
    /// Gather radius `R` of the Gaussian window, in texels (thesis: 1).
    pub window_radius: usize,
    /// Spatial coherence length (µm); the window std is a quarter of it.
    pub coherence_um: f64,
    /// Wavelength step `Δλ` (nm); divides 400.
    pub lambda_step_nm: u32,
    /// Schlick Fresnel factor relative to normal incidence.
    pub fresnel: bool,
    /// V-cavity shadowing/masking.
    pub shadowing: bool,
    /// Refractive index of the material (snake keratin ≈ 1.5).
    pub ior: f64,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            heightfield: "builtin:elaphe".into(),
            dh_um: None,
            h_max_um: None,
            channel: None,
            level: None,
            tile: None,
            expansion: Expansion::Chebyshev,
            terms: Terms::Auto,
            tolerance: truncation::DEFAULT_TOLERANCE,
            window_radius: 2,
            coherence_um: DEFAULT_COHERENCE_UM,
            lambda_step_nm: 5,
            fresnel: true,
            shadowing: true,
            ior: 1.5,
        }
    }
}

/// Everything an evaluator needs, loaded and precomputed from a [`Material`].
#[derive(Debug, Clone)]
pub struct PreparedMaterial {
    pub material: Material,
    pub heightfield: HeightField,
    /// The DFT terms ([`PreparedMaterial::load_terms`] computes them when they were
    /// deferred).
    pub stack: TermCell,
    pub window: Window,
    pub shading: Shading,
    pub colour: ColourTable,
    /// The resolved expansion and `T`, with their error budget.
    pub plan: TermPlan,
}

/// A material's DFT-term stack, computed when the material is prepared or, for a draw that
/// may never read it (the table variants build from the height field), on first
/// [`PreparedMaterial::load_terms`]. [`TermCell::get`] reads it.
#[derive(Debug, Clone, Default)]
pub struct TermCell {
    stack: std::sync::OnceLock<TermStack>,
    /// Where the deferred stack is cached.
    cache_dir: Option<std::path::PathBuf>,
}

impl TermCell {
    /// Whether the stack has been computed (or loaded).
    pub fn is_loaded(&self) -> bool {
        self.stack.get().is_some()
    }

    /// The stack. Code that prepares with deferred terms calls
    /// [`PreparedMaterial::load_terms`] before reading them; reading them unloaded is an
    /// [`Error::Internal`] (a bug in that code, not in the input), never a panic.
    pub fn get(&self) -> Result<&TermStack> {
        self.stack.get().ok_or(Error::Internal(
            "the DFT terms were read before PreparedMaterial::load_terms computed them",
        ))
    }
}

impl PreparedMaterial {
    /// The term stack, computed (or loaded from the cache) on the first call when the
    /// material was prepared with deferred terms
    /// ([`Material::prepare_planned_deferred`]).
    /// A corrupt or stale cache file, or one that cannot be written, is a warning to
    /// `report`: the terms are recomputed and still correct.
    pub fn load_terms(&self, report: &dyn Report) -> Result<&TermStack> {
        if let Some(stack) = self.stack.stack.get() {
            return Ok(stack);
        }
        let req = self
            .material
            .term_request(self.plan.expansion, self.plan.terms);
        let stack = spectrum::cache::terms_cached(
            &self.heightfield,
            &req,
            self.stack.cache_dir.as_deref(),
            report,
        )?;
        Ok(self.stack.stack.get_or_init(|| stack))
    }

    /// The resolved highest term index `T` every evaluator uses (the stack holds `0..=T`).
    pub fn terms(&self) -> usize {
        self.plan.terms
    }
}

impl Material {
    /// What to precompute for a resolved expansion and `T`, for wavelengths from 380 nm,
    /// cropped to the reachable band.
    pub fn term_request(&self, expansion: Expansion, max_term: usize) -> TermRequest {
        TermRequest {
            expansion,
            max_term,
            lambda_min_um: crate::colour::LAMBDA_MIN_NM as f64 * 1e-3,
            window_radius: self.window_radius,
            full_band: false,
        }
    }

    /// Where the height field comes from: the one loader's [`Source`].
    pub fn source(&self) -> Source {
        Source {
            spec: self.heightfield.clone(),
            dh_um: self.dh_um,
            h_max_um: self.h_max_um,
            channel: self.channel.clone(),
            level: self.level.clone(),
            tile: self.tile,
        }
    }

    /// Loads (reads, levels, tiles) the height field; what was done goes to `report`.
    pub fn load_heightfield(&self, report: &dyn Report) -> Result<HeightField> {
        self.source().load(report)
    }

    /// Checks every numeric field (and the height field's options) for sense.
    pub fn validate(&self) -> Result<()> {
        self.source().validate()?;
        let max_term = match self.terms {
            Terms::Auto => 0,
            Terms::Fixed(t) => t,
        };
        self.term_request(self.expansion, max_term).validate()?;
        if !(self.tolerance.is_finite() && self.tolerance > 0.0 && self.tolerance < 1.0) {
            return Err(Error::invalid(
                "tolerance",
                format!("{}; must be in (0, 1)", self.tolerance),
            ));
        }
        if !(self.coherence_um.is_finite() && self.coherence_um > 0.0) {
            return Err(Error::invalid(
                "coherence length",
                format!("{} µm; must be positive", self.coherence_um),
            ));
        }
        if self.coherence_um > MAX_COHERENCE_UM {
            return Err(Error::invalid(
                "coherence length",
                format!(
                    "{:e} µm; at most {MAX_COHERENCE_UM} µm (10 mm): a longer window is narrower \
                     than float32 lookups resolve and its direct sum cannot be afforded",
                    self.coherence_um
                ),
            ));
        }
        if !(self.ior.is_finite() && self.ior >= 1.0 && self.ior <= 4.0) {
            return Err(Error::invalid(
                "refractive index",
                format!("{}; expected 1 ≤ n ≤ 4", self.ior),
            ));
        }
        ColourTable::new(self.lambda_step_nm)?;
        Ok(())
    }

    /// The shading switches of this material.
    pub fn shading(&self) -> Shading {
        Shading {
            fresnel: self.fresnel,
            shadowing: self.shadowing,
            ior: self.ior,
        }
    }

    /// Resolves `terms` (and, for `auto`, the expansion) for `hf` at `reach` and
    /// `precision` without printing anything (MODEL §4, [`truncation::plan_terms`]).
    pub fn plan(&self, hf: &HeightField, reach: &Reach, precision: Precision) -> Result<TermPlan> {
        let geometry = Geometry::of(hf, self.coherence_um, self.window_radius);
        truncation::plan_terms(
            self.expansion,
            self.terms,
            self.tolerance,
            &geometry,
            reach,
            precision,
        )
    }

    /// Loads the height field, computes (or loads from `cache_dir`) the cropped terms, and
    /// builds the window and colour table, planned for every direction (`|w| ≤ 2`) in
    /// float32, the GPU's precision. The Nyquist warning and the plan's warnings (an
    /// expansion switch, an explicit `T` above the tolerance) go to `report`.
    pub fn prepare(
        &self,
        cache_dir: Option<&std::path::Path>,
        report: &dyn Report,
    ) -> Result<PreparedMaterial> {
        self.prepare_for(cache_dir, &Reach::ALL, Precision::F32, report)
    }

    /// [`prepare`](Self::prepare) for a known reach (e.g. [`Reach::brdf_map`]) and precision.
    pub fn prepare_for(
        &self,
        cache_dir: Option<&std::path::Path>,
        reach: &Reach,
        precision: Precision,
        report: &dyn Report,
    ) -> Result<PreparedMaterial> {
        let (heightfield, plan) = self.load_planned(reach, precision, report)?;
        self.prepare_planned(heightfield, plan, cache_dir, report)
    }

    /// The cheap first half of [`prepare_for`](Self::prepare_for): validates the numbers,
    /// loads the height field, resolves the plan (its warnings and the Nyquist warning go to
    /// `report`) and refuses a stack over the memory limit, all without computing a term.
    /// Commands call it before opening the device, so bad input never waits for Vulkan.
    pub fn load_planned(
        &self,
        reach: &Reach,
        precision: Precision,
        report: &dyn Report,
    ) -> Result<(HeightField, TermPlan)> {
        self.validate()?;
        let heightfield = self.load_heightfield(report)?;
        let plan = self.plan_loaded(&heightfield, reach, precision, report)?;
        Ok((heightfield, plan))
    }

    /// [`load_planned`](Self::load_planned)'s plan for a height field already loaded (the
    /// viewer's material edits scale a loaded field): resolves the plan, reports its warnings
    /// and the Nyquist warning, and refuses a stack over the memory limit.
    pub fn plan_loaded(
        &self,
        heightfield: &HeightField,
        reach: &Reach,
        precision: Precision,
        report: &dyn Report,
    ) -> Result<TermPlan> {
        self.validate()?;
        let plan = self.plan(heightfield, reach, precision)?;
        for w in &plan.warnings {
            report.warn(w);
        }
        let req = self.term_request(plan.expansion, plan.terms);
        if let Some(w) = heightfield.nyquist_warning(req.lambda_min_um) {
            report.warn(&w);
        }
        spectrum::cache::check_memory(heightfield, &req)?;
        Ok(plan)
    }

    /// Builds the prepared material from a loaded height field and a resolved plan.
    pub fn prepare_planned(
        &self,
        heightfield: HeightField,
        plan: TermPlan,
        cache_dir: Option<&std::path::Path>,
        report: &dyn Report,
    ) -> Result<PreparedMaterial> {
        let prepared = self.prepare_planned_deferred(heightfield, plan, cache_dir)?;
        prepared.load_terms(report)?;
        Ok(prepared)
    }

    /// `heightfield` prepared for every direction a draw can reach (`Reach::ALL`) at float32's
    /// rounding, its terms computed when a variant first reads them
    /// ([`prepare_planned_deferred`](Self::prepare_planned_deferred)); the planner's words go
    /// to `report`.
    pub fn prepare_anywhere(
        &self,
        heightfield: HeightField,
        cache_dir: Option<&std::path::Path>,
        report: &dyn Report,
    ) -> Result<PreparedMaterial> {
        let plan = self.plan_loaded(&heightfield, &Reach::ALL, Precision::F32, report)?;
        self.prepare_planned_deferred(heightfield, plan, cache_dir)
    }

    /// [`prepare_planned`](Self::prepare_planned) without computing the DFT terms: the
    /// first [`PreparedMaterial::load_terms`] does (through the cache in `cache_dir`). For
    /// draws whose variant may not read them: a table variant builds from the height field.
    pub fn prepare_planned_deferred(
        &self,
        heightfield: HeightField,
        plan: TermPlan,
        cache_dir: Option<&std::path::Path>,
    ) -> Result<PreparedMaterial> {
        self.term_request(plan.expansion, plan.terms).validate()?;
        let window = Window::new(
            heightfield.nx(),
            heightfield.ny(),
            heightfield.dh_um(),
            self.coherence_um,
            self.window_radius,
        )?;
        Ok(PreparedMaterial {
            material: self.clone(),
            shading: self.shading(),
            colour: ColourTable::new(self.lambda_step_nm)?,
            heightfield,
            stack: TermCell {
                stack: std::sync::OnceLock::new(),
                cache_dir: cache_dir.map(std::path::Path::to_path_buf),
            },
            window,
            plan,
        })
    }
}

pub use crate::cachedir::default_cache_dir;
