//! The `diffract render` command: arguments, the choice of variant, output files, the
//! one-line report and the one line of what was left out (stderr).

use std::path::PathBuf;

use crate::brdf::truncation::{Precision, Reach};
use crate::cli::cache::CacheArgs;
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
    /// Leave nothing out: every wavelength, every DFT texel of the band (to measure what
    /// leaving out saves). By default what the scene cannot need at the tolerance is left
    /// out and reported on one line.
    #[arg(long)]
    pub keep_all: bool,
    /// Say what was left out in detail (which wavelengths, the texel band, the terms).
    #[arg(long)]
    pub verbose: bool,
}

/// Runs `diffract render`: renders, writes the image(s), prints one line with the device,
/// GPU and wall time.
pub fn run(args: &RenderArgs) -> Result<()> {
    let scene = args.scene.load()?;
    crate::image_io::output_format(&args.out)?;
    render_args(args, &scene)?;
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
    let prepared = material.prepare_planned_deferred(heightfield, plan, cache_dir.as_deref())?;
    // Table variants show their own bar while they build; the draw after it is short.
    let spin = variant
        .is_spectral()
        .then(|| crate::progress::spinner("rendering"));

    let (frame, what) = if let Some(inputs) = &inputs {
        let frame = render_resolved(&mut renderer, &scene, inputs, &prepared, &args.out)?;
        (frame, "scene".to_string())
    } else {
        let frame = renderer.render_brdf_map(
            &prepared,
            args.theta_i.unwrap_or(crate::render::DEFAULT_MAP_THETA_I),
            args.phi_i.unwrap_or(0.0),
            args.size.unwrap_or(crate::render::DEFAULT_MAP_SIZE),
            args.lambda_nm,
        )?;
        write_map(args, &frame)?;
        let what = match args.lambda_nm {
            Some(l) => format!("BRDF map ρ at {l} nm"),
            None => "BRDF map (XYZ)".to_string(),
        };
        (frame, what)
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
    print_result(args, &scene, renderer.device_name(), &frame, &what);
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
    Ok(())
}

/// The render's lines on stdout: where the table was built (table variants), then the
/// device, what was drawn, the output, the variant, GPU and wall time, and the fetches a
/// pixel costs.
fn print_result(args: &RenderArgs, scene: &Scene, device: &str, frame: &Picture, what: &str) {
    let gpu = frame
        .gpu_ms
        .map_or("n/a".to_string(), |ms| format!("{ms:.2}"));
    let written = match (args.brdf_map && args.png).then(|| args.out.with_extension("png")) {
        Some(png) => format!("{} + {}", args.out.display(), png.display()),
        None => args.out.display().to_string(),
    };
    let v = &frame.variant;
    if let Some(built) = &v.table_build {
        println!(
            "table: {}, {built}, {:.1} MB",
            v.name,
            v.gpu_bytes as f64 / 1e6
        );
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
        "{}: {what} {}×{} → {written}: variant {}: GPU {gpu} ms, wall {:.1} ms (build {:.1} ms, {:.1} MB, {fetches})",
        device,
        frame.width,
        frame.height,
        v.name,
        frame.wall_ms,
        v.build_ms,
        v.gpu_bytes as f64 / 1e6,
    );
}

/// Writes a BRDF map: an EXR holds the raw channels (XYZ or ρ); a PNG shows XYZ as sRGB
/// (or ρ as grey). `--png` with an EXR output adds the PNG beside it.
fn write_map(args: &RenderArgs, frame: &Picture) -> Result<()> {
    let exposure = args.scene.exposure.unwrap_or(1.0);
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
    match crate::image_io::output_format(&args.out)? {
        crate::image_io::OutputFormat::Exr => {
            crate::image_io::write_exr(&args.out, frame.width, frame.height, &frame.rgb)?;
            if args.png {
                let png = args.out.with_extension("png");
                crate::image_io::write_png_srgb(
                    &png,
                    frame.width,
                    frame.height,
                    &viewable(),
                    exposure,
                )?;
            }
            Ok(())
        }
        _ => crate::image_io::write_image(
            &args.out,
            frame.width,
            frame.height,
            &viewable(),
            exposure,
        ),
    }
}

/// Renders `scene` as the output file holds it ([`Renderer::render_output`]: an EXR stays
/// linear, a PNG is tone-mapped) and writes `out`. The returned frame holds the written
/// pixels.
fn render_resolved(
    renderer: &mut Renderer,
    scene: &Scene,
    inputs: &SceneInputs,
    prepared: &crate::material::PreparedMaterial,
    out_path: &std::path::Path,
) -> Result<Picture> {
    let tone = !matches!(
        crate::image_io::output_format(out_path)?,
        crate::image_io::OutputFormat::Exr
    );
    let frame = renderer.render_output(scene, Some(inputs), prepared, tone)?;
    crate::image_io::write_image(out_path, frame.width, frame.height, &frame.rgb, 1.0)?;
    Ok(frame)
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
    args.gpu.table.check()?;
    let material = args.material.apply(scene.material.clone());
    material.validate()?;

    let mut outputs = vec![("output", args.out.clone())];
    if args.brdf_map && args.png {
        outputs.push(("--png image", png_sibling));
    }
    crate::guard::check_outputs(
        &crate::guard::scene_inputs(args.scene.scene.as_deref(), scene, &material.heightfield),
        &outputs,
    )?;
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
