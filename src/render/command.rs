//! The `diffract render` command: arguments, the choice of variant, output files, the
//! one-line report and the one line of what was left out (stderr).

use std::path::PathBuf;

use super::table_build::TableBuild;
use super::variant::{TableFormat, TableOptions, VariantKind};
use super::{Picture, Renderer, SceneInputs};
use crate::brdf::truncation::{Precision, Reach};
use crate::gpu::StorageFormat;
use crate::material::MaterialArgs;
use crate::scene::Scene;
use crate::{Error, Result};

/// Table options shared by `render`, `profile` and `view`.
#[derive(Debug, Clone, clap::Args)]
pub struct TableArgs {
    /// Table variants: node spacing in u and v (default: half the coherence lobe).
    #[arg(long)]
    pub table_texel: Option<f64>,
    /// Table variants: nodes along w (default: volume 32, chebyshev-w 16, dhillon 12).
    #[arg(long)]
    pub table_w_nodes: Option<usize>,
    /// Table variants: wavelength step of the offline spectral integral (nm).
    #[arg(long, default_value_t = TableOptions::default().step_nm)]
    pub table_step_nm: u32,
    /// Table variants: GPU memory budget (MB); the u/v spacing is coarsened to fit.
    #[arg(long, default_value_t = 512)]
    pub table_budget_mb: usize,
    /// Table variants: texel format (float16 halves the memory; on the default scene the
    /// picture moves by a ΔE2000 of 0.001).
    #[arg(long, value_enum, default_value_t = TableFormat::Rgba16f)]
    pub table_format: TableFormat,
    /// Table variants: where to build the table (auto: the device when it is a GPU, the
    /// CPU when Vulkan itself runs on the CPU, e.g. lavapipe).
    #[arg(long, value_enum, default_value_t = TableBuild::Auto)]
    pub table_build: TableBuild,
}

impl TableArgs {
    pub fn options(&self) -> TableOptions {
        TableOptions {
            texel_uv: self.table_texel,
            w_nodes: self.table_w_nodes,
            step_nm: self.table_step_nm,
            budget_bytes: self.table_budget_mb.saturating_mul(1 << 20),
            format: self.table_format,
            build: self.table_build,
        }
    }
}

/// `diffract render`: a scene (or a BRDF map) to an image.
#[derive(Debug, Clone, clap::Args)]
pub struct RenderArgs {
    /// Scene file (TOML); the embedded default scene when omitted.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Output image: .png (8-bit sRGB) or .exr (linear float).
    #[arg(short, long, default_value = "diffract.png")]
    pub out: PathBuf,
    /// Image width in pixels (overrides the scene).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels (overrides the scene).
    #[arg(long)]
    pub height: Option<u32>,
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
    /// Exposure (linear multiplier before the sRGB curve): overrides the scene's; for BRDF
    /// maps it scales the PNG only (the EXR keeps the raw values).
    #[arg(long)]
    pub exposure: Option<f32>,
    /// Shader variant (`diffract variants` lists them).
    #[arg(long, value_enum, default_value_t = VariantKind::Default)]
    pub variant: VariantKind,
    /// Storage format of the DFT terms on the GPU (flss).
    #[arg(long, value_enum, default_value_t = StorageFormat::Rg32f)]
    pub storage: StorageFormat,
    /// Evaluate the BRDF per vertex and interpolate the colour (thesis §1.5.1; flss, nmm,
    /// pq; scenes only: a BRDF map has no vertices).
    #[arg(long)]
    pub per_vertex: bool,
    #[command(flatten)]
    pub table: TableArgs,
    #[command(flatten)]
    pub material: MaterialArgs,
    /// Directory of the DFT term cache (default: $DIFFRACT_CACHE or ~/.cache/diffract).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Do not read or write the term cache.
    #[arg(long)]
    pub no_cache: bool,
    /// Leave nothing out: every wavelength, every DFT texel of the band (to measure what
    /// leaving out saves). By default what the scene cannot need at the tolerance is left
    /// out and reported on one line.
    #[arg(long)]
    pub keep_all: bool,
    /// Say what was left out in detail (which wavelengths, the texel band, the terms).
    #[arg(long)]
    pub verbose: bool,
}

/// Refuses `--per-vertex` where it cannot apply: on a BRDF map (no vertices) and for a
/// variant without a per-vertex stage. Checked before the device is opened.
pub fn check_per_vertex(per_vertex: bool, brdf_map: bool, variant: VariantKind) -> Result<()> {
    if !per_vertex {
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

/// Whether to enable Vulkan validation: always in debug builds, or with
/// `DIFFRACT_VALIDATION=1`.
pub fn validation_requested() -> bool {
    cfg!(debug_assertions) || std::env::var("DIFFRACT_VALIDATION").is_ok_and(|v| v == "1")
}

/// Runs `diffract render`: renders, writes the image(s), prints one line with the device,
/// GPU and wall time.
pub fn run(args: &RenderArgs) -> Result<()> {
    let mut scene = match &args.scene {
        Some(p) => Scene::load(p)?,
        None => Scene::default_scene(),
    };
    if let Some(e) = args.exposure {
        if !(e.is_finite() && e > 0.0) {
            return Err(Error::invalid(
                "exposure",
                format!("{e}; must be finite and > 0"),
            ));
        }
        scene.output.exposure = e;
    }
    crate::image_io::output_format(&args.out)?;
    render_args(args, &scene)?;
    // `default` means the best variant that can draw the request: one wavelength needs
    // flss (the table variants integrate the spectrum offline). Explicit choices stand.
    let spectral_default = args.variant == VariantKind::Default && args.lambda_nm.is_some();
    let variant = if spectral_default {
        VariantKind::Flss
    } else {
        args.variant
    };
    check_per_vertex(args.per_vertex, args.brdf_map, variant)?;
    if args.lambda_nm.is_some() {
        variant.check_output(super::OutputMode::MapSpectral)?;
    }
    if let Some(w) = args.width {
        scene.output.width = w;
    }
    if let Some(h) = args.height {
        scene.output.height = h;
    }
    // Every file the user gave is read and checked before the device opens (a bad OBJ
    // or PNG must not wait for Vulkan, nor be hidden by a missing driver); the slow parts
    // (the term precompute, the table build) come after it, so a machine without Vulkan
    // fails first. The terms are computed only if the variant reads them: a table variant
    // builds from the height field.
    let material = args.material.apply(scene.material.clone());
    let (heightfield, plan) = material.load_planned(&Reach::ALL, Precision::F32)?;
    let inputs = if args.brdf_map {
        None
    } else {
        Some(SceneInputs::load(&scene, true)?)
    };
    if spectral_default {
        eprintln!(
            "note: one wavelength (--lambda-nm) is drawn by flss; the default {} integrates the spectrum offline",
            VariantKind::DEFAULT
        );
    }
    let mut renderer = Renderer::new(validation_requested())?;
    renderer.set_storage_format(args.storage);
    renderer.set_variant(variant);
    renderer.set_per_vertex(args.per_vertex);
    renderer.set_table_options(args.table.options());
    renderer.set_leave_out(!args.keep_all);
    let cache_dir = crate::cachedir::resolve(args.no_cache, args.cache_dir.as_deref());
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
            args.theta_i.unwrap_or(super::DEFAULT_MAP_THETA_I),
            args.phi_i.unwrap_or(0.0),
            args.size.unwrap_or(super::DEFAULT_MAP_SIZE),
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
        renderer.device_name(),
        frame.width,
        frame.height,
        v.name,
        frame.wall_ms,
        v.build_ms,
        v.gpu_bytes as f64 / 1e6,
    );
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

/// Writes a BRDF map: an EXR holds the raw channels (XYZ or ρ); a PNG shows XYZ as sRGB
/// (or ρ as grey). `--png` with an EXR output adds the PNG beside it.
fn write_map(args: &RenderArgs, frame: &Picture) -> Result<()> {
    let exposure = args.exposure.unwrap_or(1.0);
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
                ("--width", args.width.is_some()),
                ("--height", args.height.is_some()),
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
            ("width", args.width.unwrap_or(scene.output.width)),
            ("height", args.height.unwrap_or(scene.output.height)),
        ] {
            if !(1..=8192).contains(&v) {
                return Err(Error::invalid(
                    "image size",
                    format!("{what} {v}; expected 1..=8192"),
                ));
            }
        }
    }
    table_args(&args.table)?;
    let material = args.material.apply(scene.material.clone());
    material.validate()?;

    let mut outputs = vec![("output", args.out.clone())];
    if args.brdf_map && args.png {
        outputs.push(("--png image", png_sibling));
    }
    crate::guard::check_outputs(
        &crate::guard::scene_inputs(args.scene.as_deref(), scene, &material.heightfield),
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

/// The table variants' options (`--table-*`), checked the same way by every command that
/// takes them, whichever variant is drawn: a spacing above zero, a `w` node count the
/// table supports, a wavelength step that divides the visible range, a budget of at least
/// 1 MB.
pub fn table_args(t: &TableArgs) -> Result<()> {
    use crate::brdf::table::MAX_NODES_W;
    if let Some(texel) = t.table_texel {
        crate::guard::positive("table texel", texel, "")?;
    }
    if let Some(n) = t.table_w_nodes {
        if !(2..=MAX_NODES_W).contains(&n) {
            return Err(Error::invalid(
                "table w nodes",
                format!("{n}; expected 2..={MAX_NODES_W}"),
            ));
        }
    }
    crate::colour::ColourTable::new(t.table_step_nm)?;
    if t.table_budget_mb == 0 {
        return Err(Error::invalid(
            "table budget",
            "0 MB; expected at least 1 MB",
        ));
    }
    Ok(())
}
