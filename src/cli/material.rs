//! The material flags: the height field and the material's numbers, applied on top of a
//! scene's material (or the default).

use crate::brdf::truncation::Terms;
use crate::material::Material;
use crate::spectrum::Expansion;

/// The material flags shared by `render`, `view`, `brdf`, `profile` and `eval-grating`.
#[derive(Debug, Clone, clap::Args)]
pub struct MaterialArgs {
    /// Height field: PNG (8/16-bit grey) or .f32 with a .toml sidecar, a Gwyddion scan
    /// (.gsf, .gwy), or builtin:<kind>.
    #[arg(long)]
    pub heightfield: Option<String>,
    /// Scan channel by index or title [default: the first height channel].
    #[arg(long)]
    pub channel: Option<String>,
    /// Levelling, a comma list of none, plane, poly:N, rows [default: plane,rows for scans,
    /// none otherwise].
    #[arg(long)]
    pub level: Option<String>,
    /// Make the field tile: none, mirror, window or grow [default: none].
    #[arg(long)]
    pub tile: Option<crate::heightfield::Tile>,
    /// Pixel size of the height field in µm (overrides the sidecar).
    #[arg(long, allow_negative_numbers = true)]
    pub dh_um: Option<f64>,
    /// Height of grey level 1 in µm; scans and builtin: the peak-to-valley height (overrides
    /// the sidecar).
    #[arg(
        long = "hmax-um",
        value_name = "HMAX_UM",
        allow_negative_numbers = true
    )]
    pub h_max_um: Option<f64>,
    /// Highest expansion term T (terms 0..=T), or auto: the smallest T (and the expansion)
    /// meeting --tolerance [default: auto].
    #[arg(long)]
    pub terms: Option<Terms>,
    /// Tolerance of auto terms on ρ/C = |P̂|², relative to a mirror's specular value
    /// [default: 1e-3].
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Gaussian-window gather radius R in texels (thesis: 1).
    #[arg(long)]
    pub window_radius: Option<usize>,
    /// chebyshev (stable; default) or taylor (thesis; cancels in float32 on tall structures).
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
        if self.channel.is_some() {
            base.channel.clone_from(&self.channel);
        }
        if self.level.is_some() {
            base.level.clone_from(&self.level);
        }
        if self.tile.is_some() {
            base.tile = self.tile;
        }
        if self.h_max_um.is_some() {
            base.h_max_um = self.h_max_um;
        }
        if let Some(t) = self.terms {
            base.terms = t;
        }
        if let Some(t) = self.tolerance {
            base.tolerance = t;
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
