//! The environment flags of `render` (`--env`, `--env-samples`, `--env-intensity`,
//! `--env-rotate-deg`, `--no-sun`) and the environment-lit BRDF map they draw
//! (`render --brdf-map --env SOURCE`, [`crate::render::env`]).

use crate::brdf::table::{Region, TableSpec};
use crate::light::env::{EnvMap, EnvSource};
use crate::render::env::{
    render_env_brdf_map, EnvLighting, EnvMapRequest, DEFAULT_SAMPLES, MAX_SAMPLES,
};
use crate::scene::Scene;
use crate::{Error, Result};

/// Default `w` nodes of an environment table (its `w` range is the whole `[−2, 0]`).
pub const DEFAULT_ENV_W_NODES: usize = 16;

/// `render`'s environment flags.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct EnvArgs {
    /// Light a BRDF map (--brdf-map) with an environment: an equirectangular .hdr or .exr,
    /// or builtin:white, builtin:sky, builtin:studio. A scene's [environment] is the default.
    #[arg(long, value_name = "SOURCE")]
    pub env: Option<String>,
    /// Samples per pixel of the environment [default: 256].
    #[arg(long, value_name = "N")]
    pub env_samples: Option<u32>,
    /// The environment's radiance scale [default: 1, or the scene's].
    #[arg(long)]
    pub env_intensity: Option<f64>,
    /// The environment's rotation about +Y in degrees [default: 0, or the scene's].
    #[arg(long, allow_negative_numbers = true)]
    pub env_rotate_deg: Option<f64>,
    /// Turn the directional light (the sun) off.
    #[arg(long)]
    pub no_sun: bool,
}

impl EnvArgs {
    /// The environment the command lights with, loaded and checked (before any device
    /// work): `--env`, else the scene's `[environment]`; `None` without either. Scenes lit
    /// by environments or disc lights are refused with one line: only BRDF maps draw them.
    pub fn load(&self, brdf_map: bool, scene: &Scene) -> Result<Option<EnvMap>> {
        let asks = self.env.is_some()
            || self.env_samples.is_some()
            || self.env_intensity.is_some()
            || self.env_rotate_deg.is_some()
            || self.no_sun;
        if !brdf_map && (asks || scene.environment.is_some() || !scene.disc_lights.is_empty()) {
            return Err(Error::invalid(
                "lighting",
                "environments, disc lights and --no-sun light BRDF maps (--brdf-map --env SOURCE); a scene lit by them is not drawn yet",
            ));
        }
        if let Some(n) = self.env_samples {
            if !(1..=MAX_SAMPLES).contains(&n) {
                return Err(Error::invalid(
                    "env samples",
                    format!("{n}; expected 1 to {MAX_SAMPLES}"),
                ));
            }
        }
        let spec = scene.environment.as_ref();
        let source = match (&self.env, spec) {
            (Some(s), _) => EnvSource::parse(s)?,
            (None, Some(e)) => e.source()?,
            (None, None) if asks => {
                return Err(Error::invalid(
                    "lighting",
                    "--env-samples, --env-intensity, --env-rotate-deg and --no-sun need an environment (--env SOURCE)",
                ))
            }
            (None, None) => return Ok(None),
        };
        let intensity = self
            .env_intensity
            .unwrap_or_else(|| spec.map_or(1.0, |e| e.intensity));
        let rotate = self
            .env_rotate_deg
            .unwrap_or_else(|| spec.map_or(0.0, |e| e.rotate_deg));
        EnvMap::load(&source, intensity, rotate).map(Some)
    }
}

/// The table an environment-lit BRDF map needs: every `(u, v)` within 2 and `w ∈ [−2, 0]`
/// (each view direction reaches the whole disc `|ωi_xy| < 1` around `−ωr_xy`).
pub fn map_table_spec(
    texel: Option<f64>,
    w_nodes: Option<usize>,
    step_nm: Option<u32>,
    coherence_um: f64,
) -> Result<TableSpec> {
    let spec = TableSpec {
        region: Region {
            lo: [-2.0, -2.0, -2.0],
            hi: [2.0, 2.0, 0.0],
        },
        // Twice the sun's spacing: the whole disc at the sun's would be 1.5k² nodes a plane.
        texel_uv: texel.unwrap_or(2.0 * TableSpec::default_texel(coherence_um)),
        w_nodes: w_nodes.unwrap_or(DEFAULT_ENV_W_NODES),
        step_nm: step_nm.unwrap_or(5),
    };
    spec.validate()?;
    Ok(spec)
}

/// What [`draw_map`] drew.
pub struct EnvMapOutput {
    /// Linear-sRGB radiance, row-major from the top.
    pub rgb: Vec<[f32; 3]>,
    pub size: u32,
    pub gpu_ms: f64,
    pub table_line: String,
    pub samples: u32,
}

/// Builds the radiance table of `hf` and draws the environment-lit map.
#[allow(clippy::too_many_arguments)]
pub fn draw_map(
    dev: &std::sync::Arc<crate::gpu::Device>,
    hf: &crate::heightfield::HeightField,
    material: &crate::material::Material,
    spec: &TableSpec,
    env: &EnvMap,
    args: &EnvArgs,
    size: u32,
    sun_deg: (f64, f64),
) -> Result<EnvMapOutput> {
    let shading = material.shading();
    let lighting = EnvLighting::build(hf, material.coherence_um, &shading, spec)?;
    let samples = args.env_samples.unwrap_or(DEFAULT_SAMPLES);
    let sun = (!args.no_sun).then(|| (crate::brdf::direction(sun_deg.0, sun_deg.1), 1.0));
    let req = EnvMapRequest {
        env,
        shading,
        samples,
        size,
        sun,
        seed: 0,
    };
    let pic = render_env_brdf_map(dev, &lighting, &req)?;
    let t = &lighting.table;
    let mb = (t.nu + 2) * (t.nv + 2) * t.coeffs.len() * 12;
    let table_line = format!(
        "environment table: u, v ∈ [−2, 2], w ∈ [−2, 0], texel {:.4}, K = {}, {}×{} nodes, {:.1} MB float32, {} nm, built on the CPU in {:.1} s; BRDF density {}×{} cells",
        spec.texel_uv,
        t.coeffs.len(),
        t.nu,
        t.nv,
        mb as f64 / 1e6,
        spec.step_nm,
        lighting.build_ms / 1e3,
        lighting.density.bins[0],
        lighting.density.bins[1]
    );
    let rgb = pic
        .xyz
        .iter()
        .map(|p| crate::colour::xyz_to_linear_srgb(p.map(f64::from)).map(|x| x as f32))
        .collect();
    Ok(EnvMapOutput {
        rgb,
        size: pic.size,
        gpu_ms: pic.gpu_ms,
        table_line,
        samples,
    })
}
