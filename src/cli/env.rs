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
pub const DEFAULT_ENV_W_NODES: usize = 8;

/// `render`'s environment flags.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct EnvArgs {
    /// Light the scene (or the BRDF map, with --brdf-map) with an environment: an
    /// equirectangular .hdr or .exr, or builtin:white, builtin:sky, builtin:studio. A scene's
    /// [environment] is the default.
    #[arg(long, value_name = "SOURCE")]
    pub env: Option<String>,
    /// Samples per pixel of the environment: a BRDF map's every pixel [default: 256]; the
    /// most a scene's output pixel takes [default: 1024].
    #[arg(long, value_name = "N")]
    pub env_samples: Option<u32>,
    /// A scene's output pixel stops taking samples once its estimated noise, as CIEDE2000
    /// of the picture as written, is below this; 0: every pixel takes --env-samples
    /// [default: 0.3].
    #[arg(long, value_name = "DELTA_E", allow_negative_numbers = true)]
    pub env_noise: Option<f64>,
    /// The environment's radiance scale [default: 1, or the scene's].
    #[arg(long)]
    pub env_intensity: Option<f64>,
    /// The environment's rotation about +Y in degrees [default: 0, or the scene's].
    #[arg(long, allow_negative_numbers = true)]
    pub env_rotate_deg: Option<f64>,
    /// Turn the directional light (the sun) off.
    #[arg(long)]
    pub no_sun: bool,
    /// The scrambling of the sample sequence: pictures drawn with different seeds have
    /// independent noise (a converged reference for a picture takes another seed than the
    /// picture's) [default: 0].
    #[arg(long, value_name = "N")]
    pub env_seed: Option<u32>,
}

impl EnvArgs {
    /// The environment the command lights with, loaded and checked (before any device
    /// work): `--env`, else the scene's `[environment]`; `None` without either. Flags that
    /// need an environment, and a scene left without any light, get one error line.
    pub fn load(&self, brdf_map: bool, scene: &Scene) -> Result<Option<EnvMap>> {
        if let Some(x) = self.env_noise {
            if !(0.0..=100.0).contains(&x) {
                return Err(Error::invalid(
                    "env noise",
                    format!("{x}; expected a CIEDE2000 difference in 0..=100 (0: off)"),
                ));
            }
            if brdf_map {
                return Err(Error::invalid(
                    "env noise",
                    "--env-noise applies to scenes; a BRDF map takes --env-samples at every pixel",
                ));
            }
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
            (Some(s), _) => Some(EnvSource::parse(s)?),
            (None, Some(e)) => Some(e.source()?),
            (None, None) => None,
        };
        let discs = !brdf_map && !scene.disc_lights.is_empty();
        let Some(source) = source else {
            if self.env_intensity.is_some() || self.env_rotate_deg.is_some() {
                return Err(Error::invalid(
                    "lighting",
                    "--env-intensity and --env-rotate-deg need an environment (--env SOURCE)",
                ));
            }
            let sampling = self.env_samples.is_some()
                || self.env_noise.is_some()
                || self.env_seed.is_some()
                || self.no_sun;
            if sampling && !discs {
                return Err(Error::invalid(
                    "lighting",
                    if brdf_map {
                        "--env-samples, --env-seed and --no-sun need an environment (--env SOURCE)"
                    } else {
                        "--env-samples, --env-noise, --env-seed and --no-sun need an environment (--env SOURCE) or [[disc_light]] tables in the scene"
                    },
                ));
            }
            return Ok(None);
        };
        let intensity = self
            .env_intensity
            .unwrap_or_else(|| spec.map_or(1.0, |e| e.intensity));
        let rotate = self
            .env_rotate_deg
            .unwrap_or_else(|| spec.map_or(0.0, |e| e.rotate_deg));
        EnvMap::load(&source, intensity, rotate).map(Some)
    }

    /// Whether a scene render takes the environment-lit path (radiance units): an
    /// environment, disc lights or `--no-sun`.
    pub fn lights_scene(&self, env: Option<&EnvMap>, scene: &Scene) -> bool {
        env.is_some() || !scene.disc_lights.is_empty() || self.no_sun
    }
}

/// The table an environment-lit BRDF map needs: every `(u, v)` within 2 and `w ∈ [−2, 0]`
/// (each view direction reaches the whole disc `|ωi_xy| < 1` around `−ωr_xy`).
///
/// Its default spacing is the width of the narrowest lobe the table holds, the shortest
/// wavelength's ([`TableSpec::lobe_width`], 0.0037 at 380 nm for 65 µm). The interpolating
/// spline follows a lobe sampled that finely; on a coarser grid it rings below zero beside
/// the blue lobes, and the `G ≥ 0` the estimator needs would add that energy back: a
/// white furnace at 0.0054 (the lobe at 550 nm) reflects Z 6 % high, at 0.0037 within 0.1 %.
/// (The sun's table samples at half the lobe at 550 nm and holds the disc; the whole
/// `(u, v)` disc at that spacing would be 1.5k² nodes a plane.)
pub fn map_table_spec(
    texel: Option<f64>,
    w_nodes: Option<usize>,
    step_nm: Option<u32>,
    coherence_um: f64,
) -> Result<TableSpec> {
    let step_nm = step_nm.unwrap_or(5);
    let shortest_nm = crate::colour::ColourTable::new(step_nm)?
        .lambdas_nm
        .first()
        .copied()
        .unwrap_or(380.0);
    let spec = TableSpec {
        region: Region {
            lo: [-2.0, -2.0, -2.0],
            hi: [2.0, 2.0, 0.0],
        },
        texel_uv: texel.unwrap_or(TableSpec::lobe_width(coherence_um, shortest_nm)),
        w_nodes: w_nodes.unwrap_or(DEFAULT_ENV_W_NODES),
        step_nm,
        response: crate::brdf::table::Response::Relative,
    };
    spec.validate()?;
    Ok(spec)
}

impl crate::cli::gpu::TableArgs {
    /// The environment table these flags ask for ([`map_table_spec`]), its `(u, v)`
    /// spacing coarsened, as every table's is, until its texels fit `--table-budget-mb`
    /// in `--table-format` (said in one line: a spacing wider than the narrowest lobe lets
    /// the spline ring below zero beside the blue lobes).
    pub fn env_spec(&self, coherence_um: f64) -> Result<TableSpec> {
        let mut spec = map_table_spec(
            self.table_texel,
            self.table_w_nodes,
            self.table_step_nm,
            coherence_um,
        )?;
        let budget = self.table_budget_mb.saturating_mul(1 << 20) as f64;
        let bytes = |t: f64| {
            let side = (4.0 / t).ceil() + 3.0; // nodes plus the splines' two ghosts
            side * side
                * crate::render::variant::table::packed_layers(spec.w_nodes) as f64
                * self.table_format.texel_bytes() as f64
        };
        let asked = spec.texel_uv;
        let smallest = bytes(4.0);
        if smallest > budget {
            return Err(Error::invalid(
                "table budget",
                format!(
                    "{} MB cannot hold the environment table even at 2×2 nodes ({:.1} MB)",
                    self.table_budget_mb,
                    smallest / 1e6
                ),
            ));
        }
        while bytes(spec.texel_uv) > budget {
            spec.texel_uv *= 1.1;
        }
        if spec.texel_uv > asked {
            crate::report::Report::warn(
                &crate::report::Stderr,
                &format!(
                    "environment table coarsened from texel {asked:.4} to {:.4} to fit {} MB in {}: wider than the narrowest lobe, its spline may ring below zero beside the blue lobes (the white furnace's Z rises)",
                    spec.texel_uv,
                    self.table_budget_mb,
                    self.table_format.name()
                ),
            );
        }
        Ok(spec)
    }
}

/// What [`draw_map`] drew.
pub struct EnvMapOutput {
    /// Linear-sRGB radiance, row-major from the top.
    pub rgb: Vec<[f32; 3]>,
    pub size: u32,
    pub gpu_ms: f64,
    pub table_line: String,
    pub samples: u32,
    /// The variant that drew it, as its report names it.
    pub variant: String,
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
    gpu: &crate::cli::gpu::GpuArgs,
    cache: &crate::cli::cache::CacheArgs,
) -> Result<EnvMapOutput> {
    let shading = material.shading();
    refuse_variant(gpu.variant)?;
    let (lighting, built) = lighting_for(hf, material, spec, cache)?;
    // A map's pixels are points: no footprint to read levels at.
    let variant = env_variant(
        dev,
        (gpu.variant, false, 1),
        (material, hf),
        &lighting,
        &gpu.table,
        cache,
    )?;
    let samples = args.env_samples.unwrap_or(DEFAULT_SAMPLES);
    let sun = (!args.no_sun).then(|| (crate::brdf::direction(sun_deg.0, sun_deg.1), 1.0));
    let req = EnvMapRequest {
        env,
        shading,
        samples,
        size,
        sun,
        seed: args.env_seed.unwrap_or(0),
        brdf: Some(&variant.brdf),
        per_dispatch: None,
    };
    let pic = render_env_brdf_map(dev, &lighting, &req)?;
    warn_dropped(pic.dropped);
    let inside = (0..size * size)
        .filter(|p| crate::render::env::map_direction(p % size, p / size, size).is_some());
    let short = inside
        .clone()
        .filter(|&p| pic.taken[p as usize] < samples)
        .count();
    if short > 0 && pic.dropped == 0 {
        let taken: u64 = inside.map(|p| u64::from(pic.taken[p as usize])).sum();
        crate::report::Report::warn(
            &crate::report::Stderr,
            &format!(
                "{short} pixel(s) took fewer than {samples} samples ({taken} in all): the driver ended the samples' loop early; each pixel is the mean of the samples it took"
            ),
        );
    }
    let table_line = lighting.report_line(!built);
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
        variant: variant.name.clone(),
    })
}

/// Says how many batches of samples the estimator left out for a NaN or an infinity (the
/// picture is the mean of the others), where any were.
fn warn_dropped(dropped: u64) {
    if dropped > 0 {
        crate::report::Report::warn(
            &crate::report::Stderr,
            &format!(
                "{dropped} batch(es) of samples held a NaN or an infinity and were left out: each pixel is the mean of its other batches"
            ),
        );
    }
}

/// What `render` hands [`run_env_scene`]: its flags that apply to an environment-lit
/// scene, and the material with its flags applied.
pub struct EnvSceneArgs<'a> {
    pub material: crate::material::Material,
    pub gpu: &'a crate::cli::gpu::GpuArgs,
    pub env: &'a EnvArgs,
    pub cache: &'a crate::cli::cache::CacheArgs,
    pub out: &'a std::path::Path,
}

/// A scene lit by an environment, disc lights or `--no-sun` (`render`'s flags for it in
/// `args`): the scene in radiance units ([`crate::render::env_scene`]), written as
/// `render` writes scenes (supersampled, exposed, tone-mapped for a PNG).
pub fn run_env_scene(args: &EnvSceneArgs<'_>, scene: &Scene, env: Option<&EnvMap>) -> Result<()> {
    crate::render::env_scene::fit_size(None, scene)?;
    refuse_variant(args.gpu.variant)?;
    let start = std::time::Instant::now();
    let material = args.material.clone();
    let (hf, _) = material.load_planned(
        &crate::brdf::truncation::Reach::ALL,
        crate::brdf::truncation::Precision::F32,
        &crate::report::Stderr,
    )?;
    let inputs = crate::render::SceneInputs::load(scene, true)?;
    for line in &inputs.mesh.repairs {
        crate::report::Report::warn(&crate::report::Stderr, line);
    }
    let t = &args.gpu.table;
    let spec = t.env_spec(material.coherence_um)?;
    let dev = crate::gpu::Device::new(crate::cli::gpu::validation_requested())?;
    let (fitted, note) = crate::render::env_scene::fit_size(Some(&dev), scene)?;
    if let Some(line) = note {
        crate::report::Report::note(&crate::report::Stderr, &line);
    }
    let scene = &fitted;
    let shading = material.shading();
    let (lighting, built) = lighting_for(&hf, &material, &spec, args.cache)?;
    let lights = crate::render::env_scene::scene_lights(scene, !args.env.no_sun, lighting.white);
    // Without a map the scene's own sky (its ambient) is the environment.
    let sky = match env {
        Some(_) => None,
        None => crate::render::env_scene::scene_sky(scene)?,
    };
    let env = env.or(sky.as_ref());
    // Without an environment or disc lights there is nothing to sample: the sun's
    // directions are point lights, evaluated in full once a pixel (`--shading compute`).
    let nothing_sampled = env.is_none() && lights.discs.is_empty();
    let kind = crate::render::env_brdf::scene_variant(args.gpu.variant, !nothing_sampled);
    let default = kind != args.gpu.variant.resolve();
    // Without point lights `volume` draws everything.
    let paired = default && !lights.points.is_empty();
    let mut variant = env_variant(
        &dev,
        (kind, paired, args.gpu.table.table_levels),
        (&material, &hf),
        &lighting,
        &args.gpu.table,
        args.cache,
    )?;
    if default {
        variant.name = format!(
            "{} (the default where light is sampled; its converged picture within ΔE2000 p99 {} of chebyshev-w's, which --variant chebyshev-w draws)",
            variant.name,
            crate::render::env_brdf::VOLUME_BIAS_P99
        );
    }
    let samples = match (nothing_sampled, args.env.env_samples) {
        (true, None) => 1,
        (_, n) => n.unwrap_or(crate::render::env_scene::DEFAULT_SAMPLES),
    };
    let noise = match nothing_sampled {
        true => 0.0,
        false => args
            .env
            .env_noise
            .unwrap_or(crate::render::env_scene::DEFAULT_NOISE)
            .max(0.0),
    };
    let frame = crate::render::env_scene::render_env_scene(
        &dev,
        &lighting,
        &crate::render::env_scene::EnvScene {
            scene,
            mesh: &inputs.mesh,
            texture: inputs.texture.as_ref(),
            env,
            lights: &lights,
            shading,
            samples,
            seed: args.env.env_seed.unwrap_or(0),
            noise: (noise > 0.0).then_some(noise),
            brdf: Some(&variant.brdf),
        },
    )?;
    warn_dropped(frame.dropped);
    let out = &scene.output;
    let rgb = match crate::image_io::output_format(args.out)? {
        crate::image_io::OutputFormat::Exr => {
            let (_, _, px) = crate::image_io::box_downsample(
                frame.width,
                frame.height,
                &frame.rgb,
                out.supersample.max(1),
            )?;
            px.into_iter()
                .map(|p| p.map(|c| c * out.exposure))
                .collect()
        }
        _ => out.resolve(&frame.rgb)?,
    };
    if rgb.iter().flatten().any(|c| !c.is_finite()) {
        return Err(Error::invalid(
            "render",
            format!(
                "a pixel is not a finite number; nothing written to {}",
                args.out.display()
            ),
        ));
    }
    let units = format!(
        "linear sRGB of a scene of radiance (× exposure {} / S = {:.0})",
        out.exposure, lighting.mirror_scale
    );
    crate::image_io::write_image(args.out, out.width, out.height, &rgb, 1.0, &units)?;
    println!("{}", lighting.report_line(!built));
    println!(
        "device: {}; scene {}×{} → {} in radiance units (× exposure {} / {:.0}) under {}, {} disc light(s), sun {}: variant {}: {:.0} samples per pixel on average, {} at most ({}), {} G-buffer pixels of {}² covered; G-buffer {:.0} ms (raster pipeline and readback), GPU {:.1} ms (dispatches), wall {:.2} s (the whole process)",
        dev.info.name,
        out.width,
        out.height,
        args.out.display(),
        out.exposure,
        lighting.mirror_scale,
        env.map_or("no environment".to_string(), |e| e.name.clone()),
        scene.disc_lights.len(),
        if args.env.no_sun { "off" } else { "on" },
        variant.name,
        frame.samples_mean,
        frame.samples_most,
        if noise > 0.0 {
            format!("up to {samples}, until the estimated noise is below ΔE2000 {noise}")
        } else {
            format!("{samples} everywhere")
        },
        frame.covered,
        out.supersample.max(1),
        frame.raster_ms,
        frame.gpu_ms,
        crate::report::process_wall_s().unwrap_or(start.elapsed().as_secs_f64())
    );
    let n = dev.validation_messages();
    if n > 0 {
        return Err(Error::Validation(n));
    }
    Ok(())
}

/// The variant the environment-lit stages evaluate for `--variant`: `chebyshev-w` (or
/// `default`) drawn from the environment table itself in `--table-format`; else `variant`
/// built on `dev` from `material` and its height field `hf` (already loaded) in radiance
/// units with the table options of `table` ([`crate::render::Renderer::env_brdf`]; a
/// variant that cannot be lit by an environment is refused there, before any build). A
/// scene's default where light is sampled comes as `volume` with `paired`: its point
/// lights are drawn by `chebyshev-w` ([`crate::render::env_brdf::default_pair`]).
/// `chebyshev-w` keeps `levels` levels for the point lights' footprints (1 for a map).
pub fn env_variant(
    dev: &std::sync::Arc<crate::gpu::Device>,
    (variant, paired, levels): (crate::render::variant::VariantKind, bool, usize),
    (material, hf): (&crate::material::Material, &crate::heightfield::HeightField),
    lighting: &EnvLighting,
    table: &crate::cli::gpu::TableArgs,
    cache: &crate::cli::cache::CacheArgs,
) -> Result<EnvVariant> {
    use crate::render::variant::VariantKind;
    if matches!(variant, VariantKind::Default | VariantKind::ChebyshevW) {
        let brdf = lighting.brdf_in(dev, &material.shading(), table.table_format, levels)?;
        return Ok(EnvVariant {
            brdf: std::sync::Arc::new(brdf),
            name: format!(
                "chebyshev-w (the environment table, {})",
                table.table_format.name()
            ),
        });
    }
    refuse_variant(variant)?;
    let mut renderer = crate::render::Renderer::on(std::sync::Arc::clone(dev))?;
    renderer.set_variant(variant);
    renderer.set_table_options(table.options());
    let dir = cache.dir();
    renderer.set_cache_dir(dir.clone());
    let prepared = material.prepare_anywhere(hf.clone(), dir.as_deref(), &crate::report::Stderr)?;
    // The stages' variant lives in the binding (it holds the variant), not in the renderer.
    let shading = material.shading();
    let mut brdf = renderer.env_brdf_owned(&prepared, lighting, &shading)?;
    if paired {
        brdf = crate::render::env_brdf::default_pair(
            dev,
            lighting,
            &shading,
            (table.table_format, levels),
            brdf,
        )?;
    }
    let name = brdf.report_name();
    Ok(EnvVariant {
        brdf: std::sync::Arc::new(brdf),
        name,
    })
}

/// The error of a variant that cannot be lit by an environment (a debug view), before any
/// table is built.
fn refuse_variant(variant: crate::render::variant::VariantKind) -> Result<()> {
    crate::render::env_brdf::env_spirv(variant.resolve(), crate::render::env_brdf::EnvStage::Map)
        .map(|_| ())
}

/// A variant bound for the environment-lit stages ([`env_variant`]).
pub struct EnvVariant {
    pub brdf: std::sync::Arc<crate::render::env_brdf::EnvBrdf>,
    /// What the variant's report calls it (`flss T=12 R=1 dλ=10`, a table's nodes).
    pub name: String,
}

/// The radiance table of `spec` and its density, through the cache unless `--no-cache`;
/// and whether it was built (not read from the cache).
fn lighting_for(
    hf: &crate::heightfield::HeightField,
    material: &crate::material::Material,
    spec: &TableSpec,
    cache: &crate::cli::cache::CacheArgs,
) -> Result<(EnvLighting, bool)> {
    let dir = cache.dir();
    let (l, cached) = EnvLighting::build_cached(
        hf,
        material.coherence_um,
        &material.shading(),
        spec,
        dir.as_deref(),
        &crate::report::Stderr,
    )?;
    Ok((l, !cached))
}
