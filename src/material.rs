//! The diffraction material: which height field, its physical scale, and the numerical
//! choices of MODEL §3–5 (expansion, terms `T`, window radius `R`, coherence length, `Δλ`,
//! Fresnel/shadowing). Shared by `diffract brdf`, BRDF maps and scene files, so all three
//! describe a material with the same words and defaults.

use std::path::PathBuf;

use crate::brdf::Shading;
use crate::colour::ColourTable;
use crate::heightfield::HeightField;
use crate::spectrum::{self, Expansion, TermRequest, TermStack, Window};
use crate::{Error, Result};

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
    /// Height of grey level 1 (µm); overrides the sidecar.
    pub h_max_um: Option<f64>,
    /// Taylor (thesis) or Chebyshev (stable) expansion.
    pub expansion: Expansion,
    /// Highest term index `T` (terms `0..=T`).
    pub terms: usize,
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
            expansion: Expansion::Taylor,
            terms: 30,
            window_radius: 2,
            coherence_um: DEFAULT_COHERENCE_UM,
            lambda_step_nm: 5,
            fresnel: true,
            shadowing: true,
            ior: 1.5,
        }
    }
}

/// The material flags shared by `diffract brdf` and `diffract render --brdf-map`.
#[derive(Debug, Clone, clap::Args)]
pub struct MaterialArgs {
    /// Height field: PNG (8/16-bit grey) or .f32 with a .toml sidecar, or builtin:<kind>.
    #[arg(long)]
    pub heightfield: Option<String>,
    /// Pixel size of the height field in µm (overrides the sidecar).
    #[arg(long, allow_negative_numbers = true)]
    pub dh_um: Option<f64>,
    /// Height of grey level 1 in µm (overrides the sidecar).
    #[arg(long, allow_negative_numbers = true)]
    pub hmax_um: Option<f64>,
    /// Highest expansion term T (terms 0..=T).
    #[arg(long)]
    pub terms: Option<usize>,
    /// Gaussian-window gather radius R in texels (thesis: 1).
    #[arg(long)]
    pub window_radius: Option<usize>,
    /// taylor (thesis) or chebyshev (stable for tall structures).
    #[arg(long)]
    pub expansion: Option<Expansion>,
    /// Spatial coherence length in µm.
    #[arg(long, allow_negative_numbers = true)]
    pub coherence_um: Option<f64>,
    /// Wavelength step in nm (divides 400).
    #[arg(long)]
    pub lambda_step_nm: Option<u32>,
    /// Switch off the Schlick Fresnel factor.
    #[arg(long)]
    pub no_fresnel: bool,
    /// Switch off V-cavity shadowing.
    #[arg(long)]
    pub no_shadowing: bool,
}

impl MaterialArgs {
    /// Applies the flags on top of `base` (a scene's material or the default).
    pub fn apply(&self, mut base: Material) -> Material {
        if let Some(h) = &self.heightfield {
            base.heightfield = h.clone();
        }
        if self.dh_um.is_some() {
            base.dh_um = self.dh_um;
        }
        if self.hmax_um.is_some() {
            base.h_max_um = self.hmax_um;
        }
        if let Some(t) = self.terms {
            base.terms = t;
        }
        if let Some(r) = self.window_radius {
            base.window_radius = r;
        }
        if let Some(e) = self.expansion {
            base.expansion = e;
        }
        if let Some(c) = self.coherence_um {
            base.coherence_um = c;
        }
        if let Some(s) = self.lambda_step_nm {
            base.lambda_step_nm = s;
        }
        if self.no_fresnel {
            base.fresnel = false;
        }
        if self.no_shadowing {
            base.shadowing = false;
        }
        base
    }
}

/// Everything an evaluator needs, loaded and precomputed from a [`Material`].
#[derive(Debug, Clone)]
pub struct PreparedMaterial {
    pub material: Material,
    pub heightfield: HeightField,
    pub stack: TermStack,
    pub window: Window,
    pub shading: Shading,
    pub colour: ColourTable,
}

impl Material {
    /// What to precompute for this material: its expansion, `T` and `R`, for wavelengths
    /// from 380 nm, cropped to the reachable band.
    pub fn term_request(&self) -> TermRequest {
        TermRequest {
            expansion: self.expansion,
            max_term: self.terms,
            lambda_min_um: crate::colour::LAMBDA_MIN_NM as f64 * 1e-3,
            window_radius: self.window_radius,
            full_band: false,
        }
    }

    /// Checks every numeric field for sense.
    pub fn validate(&self) -> Result<()> {
        self.term_request().validate()?;
        if !(self.coherence_um.is_finite() && self.coherence_um > 0.0) {
            return Err(Error::invalid(
                "coherence length",
                format!("{} µm; must be positive", self.coherence_um),
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

    /// Loads the height field, computes (or loads from `cache_dir`) the cropped terms, and
    /// builds the window and colour table. Prints the Nyquist warning to stderr if it applies.
    pub fn prepare(&self, cache_dir: Option<&std::path::Path>) -> Result<PreparedMaterial> {
        self.validate()?;
        let heightfield = HeightField::load_source(&self.heightfield, self.dh_um, self.h_max_um)?;
        let req = self.term_request();
        if let Some(w) = heightfield.nyquist_warning(req.lambda_min_um) {
            eprintln!("warning: {w}");
        }
        let stack = spectrum::cache::terms_cached(&heightfield, &req, cache_dir)?;
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
            stack,
            window,
        })
    }
}

/// Default directory of the term cache: `$DIFFRACT_CACHE`, else `$XDG_CACHE_HOME/diffract`,
/// else `$HOME/.cache/diffract`; `None` when none is set.
pub fn default_cache_dir() -> Option<PathBuf> {
    if let Some(d) = std::env::var_os("DIFFRACT_CACHE") {
        return (!d.is_empty()).then(|| PathBuf::from(d));
    }
    if let Some(d) = std::env::var_os("XDG_CACHE_HOME") {
        return Some(PathBuf::from(d).join("diffract"));
    }
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache").join("diffract"))
}
