//! The `diffract render` command: arguments, the choice of variant, output files, the
//! one-line report and the one line of what was left out (stderr).

use std::path::PathBuf;

use crate::brdf::truncation::{Precision, Reach};
use crate::cli::cache::CacheArgs;
use crate::cli::env::EnvArgs;
use crate::cli::gpu::{validation_requested, GpuArgs};
use crate::cli::material::MaterialArgs;
use crate::cli::scene::SceneArgs;
use crate::render::variant::VariantKind;
use crate::render::{Picture, Renderer, SceneInputs};
use crate::scene::Scene;
use crate::{Error, Result};

/// `diffract render`: a scene (or a BRDF map) to an image.
#[derive(Debug, Clone, clap::Args)]
pub struct RenderArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Output image: .png (8-bit sRGB) or .exr (linear float).
    #[arg(short, long, default_value = "diffract.png")]
    pub out: PathBuf,
    /// Render a BRDF map (hemisphere of view directions) instead of the scene.
    #[arg(long)]
    pub brdf_map: bool,
    /// BRDF map: polar angle of the light from the normal (degrees) [default: 30].
    #[arg(long)]
    pub theta_i: Option<f64>,
    /// BRDF map: azimuth of the light from +x, the height-field columns (degrees) [default: 0].
    #[arg(long, allow_negative_numbers = true)]
    pub phi_i: Option<f64>,
    /// BRDF map side in pixels [default: 256].
    #[arg(long)]
    pub size: Option<u32>,
    /// BRDF map: the spectral reflectance at this wavelength (nm) instead of XYZ colour.
    #[arg(long)]
    pub lambda_nm: Option<f64>,
    /// BRDF map: also write an sRGB PNG beside the EXR output.
    #[arg(long)]
    pub png: bool,
    #[command(flatten)]
    pub gpu: GpuArgs,
    #[command(flatten)]
    pub material: MaterialArgs,
    #[command(flatten)]
    pub cache: CacheArgs,
    #[command(flatten)]
    pub env: EnvArgs,
    /// Leave nothing out: every wavelength, every DFT texel of the band (to measure what
    /// leaving out saves). By default what the scene cannot need at the tolerance is left
    /// out and reported on one line.
    #[arg(long)]
    pub keep_all: bool,
    /// Say what was left out in detail (which wavelengths, the texel band, the terms).
    #[arg(long)]
    pub verbose: bool,
    /// Draw the picture N more times after the first and report the median GPU time of
    /// those N draws: the first draw of a pipeline also pays for one-time work in the
    /// driver (on lavapipe, about twice the time of a later draw of a small map). 0: one draw.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub repeat: u32,
    /// How a scene's pixels are shaded: `fragment`, the thesis's raster pass (the sun's
    /// disc pre-filtered into the table, the ambient sky in closed form), or `compute`,
    /// the G-buffer and the compute stages of environment light (the sun's directions as
    /// point lights, the ambient sky sampled); both draw radiance, the same picture, to
    /// measure one against the other. A scene lit by an environment or disc lights, or
    /// with `--no-sun`, is always `compute`.
    #[arg(long, value_enum, default_value_t = Shading::Fragment)]
    pub shading: Shading,
}

/// How `render` shades a scene's pixels (`--shading`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Shading {
    Fragment,
    Compute,
}

/// A scene shaded by the compute stages (lit by an environment, disc lights or `--no-sun`,
/// or `--shading compute`): `render`'s flags that apply handed to
/// [`crate::cli::env::run_env_scene`], those that do not refused.
fn run_compute_scene(
    args: &RenderArgs,
    scene: &Scene,
    env: Option<&crate::light::env::EnvMap>,
) -> Result<()> {
    crate::guard::refuse_flags(
        &[
            ("--per-vertex", args.gpu.per_vertex),
            ("--repeat", args.repeat > 0),
        ],
        "a scene lit by an environment, disc lights or --no-sun (its pixels are integrated by compute stages, once)",
    )?;
    let run = crate::cli::env::EnvSceneArgs {
        material: args.material.apply(scene.material.clone()),
        gpu: &args.gpu,
        env: &args.env,
        cache: &args.cache,
        out: &args.out,
    };
    crate::cli::env::run_env_scene(&run, scene, env)
}

/// Most draws `--repeat` asks for.
pub const MAX_REPEAT: u32 = 1000;

/// Runs `diffract render`: renders, writes the image(s), prints one line with the device,
/// GPU and wall time.
pub fn run(args: &RenderArgs) -> Result<()> {
    let scene = args.scene.load()?;
    crate::image_io::output_format(&args.out)?;
    render_args(args, &scene)?;
    let env = args.env.load(args.brdf_map, &scene)?;
    match env {
        Some(env) if args.brdf_map => return run_env_map(args, &scene, &env),
        env if !args.brdf_map
            && (args.env.lights_scene(env.as_ref(), &scene)
                || args.shading == Shading::Compute) =>
        {
            return run_compute_scene(args, &scene, env.as_ref());
        }
        _ => {}
    }
    // `default` means the best variant that can draw the request: one wavelength needs
    // flss (the table variants integrate the spectrum offline). Explicit choices stand.
    let spectral_default = args.gpu.variant == VariantKind::Default && args.lambda_nm.is_some();
    let variant = if spectral_default {
        VariantKind::Flss
    } else {
        args.gpu.variant
    };
    args.gpu.check_per_vertex(args.brdf_map, variant)?;
    if args.lambda_nm.is_some() {
        variant.check_output(crate::render::OutputMode::MapSpectral)?;
    }
    // Every file the user gave is read and checked before the device opens (a bad OBJ
    // or PNG must not wait for Vulkan, nor be hidden by a missing driver); the slow parts
    // (the term precompute, the table build) come after it, so a machine without Vulkan
    // fails first. The terms are computed only if the variant reads them: a table variant
    // builds from the height field.
    let material = args.material.apply(scene.material.clone());
    let (heightfield, plan) =
        material.load_planned(&Reach::ALL, Precision::F32, &crate::report::Stderr)?;
    let inputs = if args.brdf_map {
        None
    } else {
        Some(SceneInputs::load(&scene, true)?)
    };
    for line in inputs.iter().flat_map(|i| &i.mesh.repairs) {
        crate::report::Report::warn(&crate::report::Stderr, line);
    }
    if spectral_default {
        eprintln!(
            "note: one wavelength (--lambda-nm) is drawn by flss; the default {} integrates the spectrum offline",
            VariantKind::DEFAULT
        );
    }
    let mut renderer = Renderer::new(validation_requested())?;
    renderer.set_storage_format(args.gpu.storage);
    renderer.set_variant(variant);
    renderer.set_per_vertex(args.gpu.per_vertex);
    renderer.set_table_options(args.gpu.table.options());
    renderer.set_leave_out(!args.keep_all);
    let cache_dir = args.cache.dir();
    renderer.set_cache_dir(cache_dir.clone());
    let model_check = start_model_check(args, &material, &heightfield, cache_dir.clone());
    let prepared = material.prepare_planned_deferred(heightfield, plan, cache_dir.as_deref())?;
    // Table variants show their own bar while they build; the draw after it is short.
    let spin = variant
        .is_spectral()
        .then(|| crate::progress::spinner("rendering"));

    // A scene is written as its output file holds it: an EXR stays linear, a PNG is
    // tone-mapped (Renderer::render_output).
    let tone = !matches!(
        crate::image_io::output_format(&args.out)?,
        crate::image_io::OutputFormat::Exr
    );
    let draw = |renderer: &mut Renderer| match &inputs {
        Some(inputs) => renderer.render_output(&scene, Some(inputs), &prepared, tone),
        None => renderer.render_brdf_map(
            &prepared,
            args.theta_i.unwrap_or(crate::render::DEFAULT_MAP_THETA_I),
            args.phi_i.unwrap_or(0.0),
            args.size.unwrap_or(crate::render::DEFAULT_MAP_SIZE),
            args.lambda_nm,
        ),
    };
    let mut frame = draw(&mut renderer)?;
    let mut repeated = Vec::new();
    for _ in 0..args.repeat {
        repeated.extend(draw(&mut renderer)?.gpu_ms);
    }
    let timing = Timing::of(frame.gpu_ms, repeated);
    frame.gpu_ms = timing.gpu_ms;
    all_finite(&frame, &args.out)?;
    let mut chosen_exposure = None;
    let what = if inputs.is_some() {
        let what = scene_units(&scene, &prepared);
        let units = format!("linear sRGB of a {what}");
        let (w, h) = (frame.width, frame.height);
        crate::image_io::write_image(&args.out, w, h, &frame.rgb, 1.0, &units)?;
        what
    } else {
        if let Some(Exposure::Auto(e)) = write_map(args, &frame)? {
            chosen_exposure = Some(e);
        }
        match args.lambda_nm {
            Some(l) => format!("BRDF map ρ at {l} nm (relative reflectance)"),
            None => "BRDF map (XYZ of the relative reflectance ρ)".to_string(),
        }
    };
    drop(spin);
    let left = renderer.left_out();
    let report = crate::leave_out::Report {
        left: left.as_ref(),
        variant: &frame.variant.name,
        plan: &prepared.plan,
        features: vec![
            ("Fresnel", prepared.shading.fresnel),
            ("shadowing", prepared.shading.shadowing),
            (
                "texture blending",
                !args.brdf_map && scene.texture.is_some(),
            ),
        ],
        gpu_bytes: frame.variant.gpu_bytes,
        keep_all: args.keep_all,
    };
    // The model check may add a tenth of the render to it, no more; it ends before the
    // result line, so that its wall time covers the whole process.
    let render_s = crate::report::process_wall_s().unwrap_or(frame.wall_ms * 1e-3);
    let model_check = model_check.finish(std::time::Duration::from_secs_f64(0.1 * render_s));
    print_result(args, &scene, renderer.device_name(), &frame, &what, &timing);
    let n = renderer.validation_messages();
    if n > 0 {
        return Err(Error::Validation(n));
    }
    // After the checks: a failed render ends on its one error line.
    eprintln!("{}", report.line());
    if args.verbose {
        for line in report.details() {
            eprintln!("{line}");
        }
    }
    if let Some(e) = chosen_exposure {
        eprintln!(
            "exposure of the PNG: {} (the 99.9th percentile of the lit pixels' luminance at half of white; --exposure sets it)",
            crate::plot::format_tick(f64::from(e))
        );
    }
    eprintln!("{model_check}");
    Ok(())
}

/// How far the scalar model is from Maxwell's equations for this material: at the map's
/// light angle, or over the angles a scene's surface sees the light at. It runs beside the
/// render and is cached per material.
fn start_model_check(
    args: &RenderArgs,
    material: &crate::material::Material,
    heightfield: &crate::heightfield::HeightField,
    cache_dir: Option<std::path::PathBuf>,
) -> crate::validity::ModelCheck {
    let thetas = if args.brdf_map {
        vec![args.theta_i.unwrap_or(crate::render::DEFAULT_MAP_THETA_I)]
    } else {
        vec![0.0, 30.0, 60.0]
    };
    crate::validity::ModelCheck::start(material.clone(), heightfield.clone(), thetas, cache_dir)
}

/// `render --brdf-map --env SOURCE`: the environment-lit BRDF map (linear-sRGB radiance ×
/// the exposure; the sun at `--theta-i`/`--phi-i` unless `--no-sun`).
fn run_env_map(args: &RenderArgs, scene: &Scene, env: &crate::light::env::EnvMap) -> Result<()> {
    if args.lambda_nm.is_some() {
        return Err(Error::invalid(
            "arguments",
            "--lambda-nm draws one wavelength; an environment-lit map integrates the spectrum",
        ));
    }
    let material = args.material.apply(scene.material.clone());
    let (hf, _) = material.load_planned(&Reach::ALL, Precision::F32, &crate::report::Stderr)?;
    let t = &args.gpu.table;
    let spec = t.env_spec(material.coherence_um)?;
    let start = std::time::Instant::now();
    let dev = crate::gpu::Device::new(validation_requested())?;
    let size = args.size.unwrap_or(crate::render::DEFAULT_MAP_SIZE);
    let sun = (
        args.theta_i.unwrap_or(crate::render::DEFAULT_MAP_THETA_I),
        args.phi_i.unwrap_or(0.0),
    );
    let out = crate::cli::env::draw_map(
        &dev,
        &hf,
        &material,
        &spec,
        env,
        &args.env,
        size,
        sun,
        &args.gpu,
        &args.cache,
    )?;
    if out.rgb.iter().flatten().any(|c| !c.is_finite()) {
        return Err(Error::invalid(
            "render",
            format!(
                "a pixel is not a finite number; nothing written to {}",
                args.out.display()
            ),
        ));
    }
    let exposure = args.scene.exposure.unwrap_or(1.0);
    let units = "linear sRGB of the radiance an environment-lit BRDF map reflects";
    match crate::image_io::output_format(&args.out)? {
        crate::image_io::OutputFormat::Exr => {
            crate::image_io::write_exr(&args.out, size, size, &out.rgb, units)?;
            if args.png {
                let png = args.out.with_extension("png");
                crate::image_io::write_png_srgb(&png, size, size, &out.rgb, exposure)?;
            }
        }
        _ => crate::image_io::write_image(&args.out, size, size, &out.rgb, exposure, units)?,
    }
    println!("{}", out.table_line);
    println!(
        "device: {}; environment-lit BRDF map (linear-sRGB radiance) {size}×{size} under {}, variant {}, {} samples per pixel, sun {} → {}; GPU {:.1} ms (dispatches), wall {:.2} s (the whole process)",
        dev.info.name,
        env.name,
        out.variant,
        out.samples,
        if args.env.no_sun { "off" } else { "on" },
        args.out.display(),
        out.gpu_ms,
        crate::report::process_wall_s().unwrap_or(start.elapsed().as_secs_f64())
    );
    let n = dev.validation_messages();
    if n > 0 {
        return Err(Error::Validation(n));
    }
    Ok(())
}

/// What a scene's picture holds, for its report line: radiance over the scale `S` that
/// every picture of a scene shares, times the exposure.
fn scene_units(scene: &Scene, prepared: &crate::material::PreparedMaterial) -> String {
    let m = &prepared.material;
    let s = crate::brdf::table::Response::radiance(m.coherence_um, &prepared.shading).scale();
    format!(
        "scene of radiance (× exposure {} / S = {s:.0})",
        scene.output.exposure
    )
}

/// The render's lines on stdout: where the table was built (table variants), then the
/// device, what was drawn, the output, the variant, GPU and wall time, and the fetches a
/// pixel costs; for a supersampled scene, its expected aliasing error.
fn print_result(
    args: &RenderArgs,
    scene: &Scene,
    device: &str,
    frame: &Picture,
    what: &str,
    timing: &Timing,
) {
    let gpu = frame
        .gpu_ms
        .map_or("n/a".to_string(), |ms| format!("{ms:.2}"));
    let gpu = match (timing.repeats, timing.first_ms) {
        (0, _) => gpu,
        (n, Some(first)) => format!("{gpu} (median of {n} draws after the first, {first:.2})"),
        (n, None) => format!("{gpu} ({n} more draws)"),
    };
    let written = match (args.brdf_map && args.png).then(|| args.out.with_extension("png")) {
        Some(png) => format!("{} + {}", args.out.display(), png.display()),
        None => args.out.display().to_string(),
    };
    let v = &frame.variant;
    if let Some(built) = &v.table_build {
        let line = crate::render::table_build::TableLine {
            label: "table",
            holds: v.name.clone(),
            origin: built.to_string(),
            bytes: v.gpu_bytes,
            bytes_of: None,
            extra: None,
        };
        println!("{line}");
    }
    // A scene's pixel evaluates the variant once per direction over the light's disc (once
    // when the disc is pre-filtered into the table), for each of its supersample²
    // samples; a BRDF map once.
    let fetches = if args.brdf_map {
        format!("{} fetches/pixel", v.fetches)
    } else {
        let ss = (scene.output.supersample.max(1) as usize).pow(2);
        let (disc, why) = if v.disc_prefiltered {
            (1, "1 evaluation (disc pre-filtered)".to_string())
        } else {
            let n = scene.light.disk_samples().len().max(1);
            (n, format!("{n} disc directions"))
        };
        format!(
            "{} fetches/pixel = {} × {why} × {ss} samples",
            v.fetches * disc * ss,
            v.fetches
        )
    };
    println!(
        "{}: {what} {}×{} → {written}: variant {}: GPU {gpu} ms, render {:.1} ms (build {:.1} ms, {:.1} MB, {fetches}){}",
        device,
        frame.width,
        frame.height,
        v.name,
        frame.wall_ms,
        v.build_ms,
        v.gpu_bytes as f64 / 1e6,
        crate::report::process_wall_s()
            .map_or(String::new(), |s| format!(", wall {s:.2} s (the whole process)")),
    );
    if let Some(e) = frame.aliasing {
        let ss = scene.output.supersample;
        println!(
            "aliasing: expected rel-L2 {e:.2} from the converged picture (the standard error of each pixel's {ss}×{ss} samples; profile --picture measures it)"
        );
    }
}

/// Writes a BRDF map: an EXR holds the raw channels (XYZ or ρ); a PNG shows XYZ as sRGB
/// (or ρ as grey). `--png` with an EXR output adds the PNG beside it.
fn write_map(args: &RenderArgs, frame: &Picture) -> Result<Option<Exposure>> {
    let exposure = match args.scene.exposure {
        Some(e) => Exposure::Given(e),
        None => Exposure::Auto(auto_exposure(frame, args.lambda_nm.is_none())),
    };
    let shown = exposure;
    let exposure = exposure.value();
    let viewable = || -> Vec<[f32; 3]> {
        if args.lambda_nm.is_some() {
            frame.rgb.clone()
        } else {
            frame
                .rgb
                .iter()
                .map(|p| crate::colour::xyz_to_linear_srgb(p.map(|c| c as f64)).map(|c| c as f32))
                .collect()
        }
    };
    // The EXR holds the map as drawn: XYZ (in R, G, B) or one wavelength's ρ.
    let units = match args.lambda_nm {
        Some(l) => format!("relative reflectance ρ at {l} nm (MODEL §2) in R, G and B"),
        None => "CIE X, Y, Z (in R, G, B) of the relative reflectance ρ (MODEL §2)".to_string(),
    };
    match crate::image_io::output_format(&args.out)? {
        crate::image_io::OutputFormat::Exr => {
            crate::image_io::write_exr(&args.out, frame.width, frame.height, &frame.rgb, &units)?;
            if args.png {
                let png = args.out.with_extension("png");
                crate::image_io::write_png_srgb(
                    &png,
                    frame.width,
                    frame.height,
                    &viewable(),
                    exposure,
                )?;
                return Ok(Some(shown));
            }
            Ok(None)
        }
        _ => crate::image_io::write_image(
            &args.out,
            frame.width,
            frame.height,
            &viewable(),
            exposure,
            "linear sRGB of the relative reflectance ρ (MODEL §2)",
        )
        .map(|()| Some(shown)),
    }
}

/// The exposure of a BRDF map's PNG: the one asked for, or one chosen from the map.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Exposure {
    Given(f32),
    Auto(f32),
}

impl Exposure {
    fn value(self) -> f32 {
        match self {
            Exposure::Given(e) | Exposure::Auto(e) => e,
        }
    }
}

/// A BRDF map's values span decades (the specular peak, its orders, their tails), so no
/// fixed exposure shows them: the one that puts the 99.9th percentile of the lit pixels'
/// luminance (Y of XYZ, or ρ) at half of white, within the exposures `--exposure` takes
/// (1 for a dark map). The brightest orders then show, the specular peak clips.
fn auto_exposure(frame: &Picture, xyz: bool) -> f32 {
    let mut lit: Vec<f32> = frame
        .rgb
        .iter()
        .map(|p| if xyz { p[1] } else { p[0] })
        .filter(|y| y.is_finite() && *y > 0.0)
        .collect();
    if lit.is_empty() {
        return 1.0;
    }
    let k = ((lit.len() - 1) as f64 * 0.999).round() as usize;
    let (_, y, _) = lit.select_nth_unstable_by(k, f32::total_cmp);
    let (lo, hi) = (crate::scene::MIN_EXPOSURE, crate::scene::MAX_EXPOSURE);
    (0.5 / *y).clamp(lo, hi)
}

/// No variant's numbers are written unchecked: a pixel that is not a finite number is a
/// fault of the draw, and then nothing is written to `out`.
fn all_finite(frame: &Picture, out: &std::path::Path) -> Result<()> {
    let bad = frame
        .rgb
        .iter()
        .filter(|p| !p.iter().all(|c| c.is_finite()))
        .count();
    if bad == 0 {
        return Ok(());
    }
    Err(Error::invalid(
        "render",
        format!(
            "{bad} of {} pixels drawn by {} are not finite numbers; {} was not written",
            frame.rgb.len(),
            frame.variant.name,
            out.display()
        ),
    ))
}

/// The GPU time `render` reports: the first draw's, or with `--repeat N` the median of the
/// N draws after it.
#[derive(Debug, Clone, PartialEq)]
pub struct Timing {
    /// The time reported (ms).
    pub gpu_ms: Option<f64>,
    /// The first draw's time (ms), when it is not the one reported.
    pub first_ms: Option<f64>,
    /// Draws after the first.
    pub repeats: usize,
}

impl Timing {
    /// From the first draw's GPU time and those of the draws after it (no timestamps: none).
    pub fn of(first: Option<f64>, repeated: Vec<f64>) -> Self {
        let repeats = repeated.len();
        match crate::render::median(repeated) {
            None => Self {
                gpu_ms: first,
                first_ms: None,
                repeats: 0,
            },
            Some(median) => Self {
                gpu_ms: Some(median),
                first_ms: first,
                repeats,
            },
        }
    }
}

/// Everything `diffract render` can check before the device and the precompute: flags that
/// belong to the other mode, sizes and angles, the material's numbers, the output paths,
/// outputs that would replace an input, and the size of the mesh file.
pub fn render_args(args: &RenderArgs, scene: &crate::scene::Scene) -> Result<()> {
    use crate::render::MAX_MAP_SIZE;
    let png_sibling = args.out.with_extension("png");
    let exr_out = matches!(
        crate::image_io::output_format(&args.out)?,
        crate::image_io::OutputFormat::Exr
    );
    if args.brdf_map {
        crate::guard::refuse_flags(
            &[
                ("--width", args.scene.width.is_some()),
                ("--height", args.scene.height.is_some()),
                ("--shading compute", args.shading == Shading::Compute),
            ],
            "a scene render (without --brdf-map)",
        )?;
        if let Some(s) = args.size {
            if !(1..=MAX_MAP_SIZE).contains(&s) {
                return Err(Error::invalid(
                    "BRDF map size",
                    format!("{s}; expected 1..={MAX_MAP_SIZE} pixels"),
                ));
            }
        }
        if let Some(t) = args.theta_i {
            crate::guard::in_range("theta-i", t, 0.0..=90.0, "°")?;
        }
        if let Some(p) = args.phi_i {
            crate::guard::finite("phi-i", p)?;
        }
        if let Some(l) = args.lambda_nm {
            let (lo, hi) = (
                crate::colour::LAMBDA_MIN_NM as f64,
                crate::colour::LAMBDA_MAX_NM as f64,
            );
            crate::guard::in_range("wavelength", l, lo..=hi, " nm")?;
        }
        if args.png && !exr_out {
            return Err(Error::invalid(
                "arguments",
                "--png adds a PNG beside an .exr output; this output is already a PNG",
            ));
        }
    } else {
        crate::guard::refuse_flags(
            &[
                ("--size", args.size.is_some()),
                ("--theta-i", args.theta_i.is_some()),
                ("--phi-i", args.phi_i.is_some()),
                ("--lambda-nm", args.lambda_nm.is_some()),
                ("--png", args.png),
            ],
            "--brdf-map",
        )?;
        for (what, v) in [
            ("width", args.scene.width.unwrap_or(scene.output.width)),
            ("height", args.scene.height.unwrap_or(scene.output.height)),
        ] {
            if !(1..=8192).contains(&v) {
                return Err(Error::invalid(
                    "image size",
                    format!("{what} {v}; expected 1..=8192"),
                ));
            }
        }
    }
    if args.repeat > MAX_REPEAT {
        return Err(Error::invalid(
            "repeat",
            format!("{}; expected 0..={MAX_REPEAT} draws", args.repeat),
        ));
    }
    args.gpu.table.check()?;
    let material = args.material.apply(scene.material.clone());
    material.validate()?;

    let mut outputs = vec![("output", args.out.clone())];
    if args.brdf_map && args.png {
        outputs.push(("--png image", png_sibling));
    }
    let inputs = crate::guard::scene_inputs(
        args.scene.scene.as_deref(),
        scene,
        &material.heightfield,
        args.env.env.as_deref(),
    );
    crate::guard::check_outputs(&inputs, &outputs)?;
    if !args.brdf_map {
        if let Some(m) = &scene.mesh.path {
            crate::fsutil::check_input_file(m, "mesh", crate::fsutil::MAX_OBJ_BYTES)?;
        }
        if let Some(t) = scene.texture.as_ref().filter(|t| !t.is_builtin()) {
            crate::fsutil::check_input_file(&t.path, "texture", crate::fsutil::MAX_PNG_BYTES)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{all_finite, Timing};
    use crate::render::Picture;

    #[test]
    fn a_picture_with_a_non_finite_pixel_is_refused_before_writing() {
        let mut frame = Picture {
            width: 2,
            height: 1,
            rgb: vec![[0.5, 0.25, 0.0]; 2],
            gpu_ms: None,
            wall_ms: 0.0,
            variant: Default::default(),
            aliasing: None,
        };
        let out = std::path::Path::new("x.png");
        assert!(all_finite(&frame, out).is_ok());
        frame.rgb[1][2] = f32::NAN;
        let e = all_finite(&frame, out).unwrap_err().to_string();
        assert!(
            e.contains("1 of 2 pixels") && e.contains("x.png was not written"),
            "{e}"
        );
        frame.rgb[0][0] = f32::INFINITY;
        assert!(all_finite(&frame, out)
            .unwrap_err()
            .to_string()
            .contains("2 of 2"));
    }

    #[test]
    fn repeated_draws_report_their_median_and_the_first_beside_it() {
        let one = Timing::of(Some(9.0), vec![]);
        assert_eq!(
            (one.gpu_ms, one.first_ms, one.repeats),
            (Some(9.0), None, 0)
        );
        let odd = Timing::of(Some(30.0), vec![5.0, 3.0, 4.0]);
        assert_eq!(
            (odd.gpu_ms, odd.first_ms, odd.repeats),
            (Some(4.0), Some(30.0), 3)
        );
        let even = Timing::of(Some(30.0), vec![5.0, 3.0, 4.0, 8.0]);
        assert_eq!(even.gpu_ms, Some(4.5));
        // No timestamps on the queue: nothing to report, whatever was drawn.
        let none = Timing::of(None, vec![]);
        assert_eq!(none.gpu_ms, None);
    }
}
