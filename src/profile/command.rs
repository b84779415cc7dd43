//! The `diffract profile` command: its flags, their checks before any work, and the run
//! from the flags to the table on stdout and the CSV and plot files.

use std::path::PathBuf;

use super::budget::{Budget, Frames};
use super::output::{format_csv, format_table, write_plot};
use super::plan::{
    flss_variants, table_variants, EnvProfile, ProfileSetup, Variant, DEFAULT_ENV_PIXELS,
    DEFAULT_ENV_SPP,
};
use super::run::profile_with_env;
use crate::cli::cache::CacheArgs;
use crate::cli::gpu::TableArgs;
use crate::cli::material::MaterialArgs;
use crate::material::Material;
use crate::render::variant::VariantKind;
use crate::render::{map_direction, Renderer};
use crate::scene::Scene;
use crate::{Error, Result};

/// `diffract profile` options.
#[derive(Debug, Clone, clap::Args)]
pub struct ProfileArgs {
    #[command(flatten)]
    pub material: MaterialArgs,
    /// Taylor terms T of the FLSS variants (Chebyshev gets ⌈2T/3⌉).
    #[arg(long = "variant-terms", default_value_t = 30)]
    pub variant_terms: usize,
    /// Profile only these (comma-separated names from the table; default: all; `env`: the
    /// environment rows of --env alone).
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// Polar angle of the light (degrees).
    #[arg(long, default_value_t = 60.0)]
    pub theta_i: f64,
    /// Azimuth of the light (degrees).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub phi_i: f64,
    /// Wall-time budget of the whole profile in seconds: the default variant's row first,
    /// then the rest cheapest first; each draws frames until its median is known to 5 % or
    /// its share is spent, and a row that does not fit is reported as skipped with its
    /// estimated cost.
    #[arg(long, default_value_t = Budget::DEFAULT_S, conflicts_with = "full")]
    pub budget_s: f64,
    /// The exhaustive set: no budget, a 128² map, 1024 + 64 scored pixels, 5 frames per
    /// row, a 128² mesh view (each still overridden by its own flag).
    #[arg(long)]
    pub full: bool,
    /// BRDF map side in pixels [default: 65, or 128 with --full].
    #[arg(long)]
    pub size: Option<u32>,
    /// Pixels scored against the reference, spread over the map (each costs N²·401
    /// complex multiply-adds) [default: 16, or 1024 with --full].
    #[arg(long)]
    pub pixels: Option<usize>,
    /// Pixels scored among the brightest of the map [default: 8, or 64 with --full].
    #[arg(long)]
    pub brightest: Option<usize>,
    /// Frames per row after the warm-up, instead of the budget's count (the median is
    /// reported) [default with --full: 5].
    #[arg(long)]
    pub frames: Option<usize>,
    /// Side of the mesh view (the default scene) timed per row; 0: none [default: none,
    /// or 128 with --full].
    #[arg(long)]
    pub mesh_size: Option<u32>,
    /// Mesh view: quads along each side of a scale of the default scene's `scaly-snake`
    /// (its resolution; 6 by default).
    #[arg(long)]
    pub mesh_quads: Option<u32>,
    /// Also evaluate flss, nmm and pq per vertex on the mesh view (thesis §1.5.1), and score
    /// every mesh view against a per-pixel FLSS 1 nm render of it.
    #[arg(long)]
    pub per_vertex: bool,
    /// Also write the table as CSV.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Also write a PNG plot of error against GPU time (log–log, Pareto front marked).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Also profile the environment-lit BRDF map under SOURCE (an equirectangular .hdr or
    /// .exr, builtin:sky, builtin:studio, builtin:white) at each of --env-spp, lit by the
    /// environment alone, against the f64 quadrature of the environment. `--only env`:
    /// these rows alone.
    #[arg(long, value_name = "SOURCE")]
    pub env: Option<String>,
    /// The environment's radiance scale [default: 1].
    #[arg(long)]
    pub env_intensity: Option<f64>,
    /// The environment's rotation about +Y in degrees [default: 0].
    #[arg(long, allow_negative_numbers = true)]
    pub env_rotate_deg: Option<f64>,
    /// Samples per pixel of the environment rows, comma-separated [default: 1,4,16,64,256].
    #[arg(long, value_delimiter = ',', value_name = "N,...")]
    pub env_spp: Vec<u32>,
    /// Pixels of the environment rows scored against the f64 quadrature, spread over the
    /// map's disk [default: 8].
    #[arg(long)]
    pub env_pixels: Option<usize>,
    /// Also score whole pictures: the default scene (or --picture-scene) at --picture-size,
    /// drawn by each table variant's rows (or the rows --only names) at each --picture-aa
    /// mode, against the same scene drawn by the default variant at
    /// --picture-reference-ss² samples a pixel: relative L2, CIEDE2000 and ꟻLIP with the
    /// GPU time of each (on with --full).
    #[arg(long)]
    pub picture: bool,
    /// The scene of the picture rows (TOML) [default: the embedded default scene].
    #[arg(long, value_name = "S.toml")]
    pub picture_scene: Option<PathBuf>,
    /// Side of the picture rows' pictures [default: 128, the size CI renders at].
    #[arg(long)]
    pub picture_size: Option<u32>,
    /// Anti-aliasing modes of the picture rows, samples a pixel per side [default: 1,2,3,4;
    /// the default scene takes 3].
    #[arg(long, value_delimiter = ',', value_name = "N,...")]
    pub picture_aa: Vec<u32>,
    /// Samples a pixel per side of the picture rows' reference [default: 16].
    #[arg(long)]
    pub picture_reference_ss: Option<u32>,
    /// Write each picture row's ꟻLIP error map (magma) and picture, and the reference, as
    /// PNG into this directory.
    #[arg(long, value_name = "DIR")]
    pub picture_maps: Option<PathBuf>,
    #[command(flatten)]
    pub table: TableArgs,
    #[command(flatten)]
    pub cache: CacheArgs,
}

/// The counts a profile runs with, once `--full` and the explicit flags are applied.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Counts {
    pub size: u32,
    pub pixels: usize,
    pub brightest: usize,
    pub frames: Frames,
    pub mesh_size: u32,
}

impl ProfileArgs {
    /// The counts: the budgeted defaults, `--full`'s exhaustive ones, or the flags given.
    pub fn counts(&self) -> Counts {
        let full = self.full;
        let frames = match (self.frames, full) {
            (Some(n), _) => Frames::Fixed(n),
            (None, true) => Frames::Fixed(5),
            (None, false) => Frames::Budget(Budget::seconds(self.budget_s)),
        };
        Counts {
            size: self.size.unwrap_or(if full { 128 } else { 65 }),
            pixels: self.pixels.unwrap_or(if full { 1024 } else { 16 }),
            brightest: self.brightest.unwrap_or(if full { 64 } else { 8 }),
            frames,
            mesh_size: self.mesh_size.unwrap_or(if full { 128 } else { 0 }),
        }
    }
}

/// Runs `diffract profile`.
pub fn run(args: &ProfileArgs) -> Result<()> {
    profile_args(args)?;
    let counts = args.counts();
    let variants = selected_rows(args)?;
    let base = args.material.apply(Material::default());
    let env = env_profile(args, &base)?;
    let picture = picture_setup(args)?;
    // The picture's scene brings its own material (the default scene's grown Elaphe skin);
    // the material flags given override it, as they override the maps' default material.
    let picture_material = picture
        .as_ref()
        .map(|p| args.material.apply(p.scene.material.clone()));
    // The user's numbers and height fields are checked before the device opens (each
    // variant loads the field again when it prepares; that is cheap next to its terms).
    for m in std::iter::once(&base).chain(&picture_material) {
        m.validate()?;
        m.load_heightfield(&crate::report::Stderr)?;
    }
    let mut renderer = Renderer::new(crate::cli::gpu::validation_requested())?;
    let mesh = (counts.mesh_size > 0).then(|| {
        let mut s = Scene::default_scene();
        s.output.width = counts.mesh_size;
        s.output.height = counts.mesh_size;
        if args.mesh_quads.is_some() {
            s.mesh.scale_quads = args.mesh_quads;
        }
        s
    });
    let setup = ProfileSetup {
        base,
        variants,
        theta_i_deg: args.theta_i,
        phi_i_deg: args.phi_i,
        size: counts.size,
        pixels: counts.pixels,
        brightest: counts.brightest,
        frames: counts.frames,
        mesh,
        per_vertex: args.per_vertex,
        cache_dir: args.cache.dir(),
    };
    let mut run = profile_with_env(&mut renderer, &setup, env.as_ref())?;
    print!("{}", format_table(renderer.device_name(), &setup, &run));
    if let (Some(p), Some(material)) = (&picture, &picture_material) {
        let rows = picture_rows(args)?;
        let frames = match counts.frames {
            Frames::Fixed(n) => n,
            Frames::Budget(_) => 3,
        };
        let cache = setup.cache_dir.as_deref();
        let done = super::picture::run(&mut renderer, p, &rows, material, frames, cache)?;
        print!("{}", done.table());
        run.picture = Some(done);
    }
    if let Some(path) = &args.csv {
        crate::fsutil::write_atomic(path, format_csv(&run).as_bytes())?;
    }
    if let Some(path) = &args.plot {
        write_plot(path, &setup, &run, renderer.device_name())?;
    }
    let n = renderer.validation_messages();
    if n > 0 {
        return Err(Error::Validation(n));
    }
    // Every error above is against the model's own reference; this one is the model's own.
    eprintln!(
        "{}",
        crate::validity::expected_error_line(
            &setup.base,
            &[setup.theta_i_deg],
            setup.cache_dir.as_deref()
        )
    );
    Ok(())
}

/// The environment rows `--env` asks for, the map loaded and checked (render's flags and
/// checks: one error line for a bad map, before any device work).
fn env_profile(args: &ProfileArgs, base: &Material) -> Result<Option<EnvProfile>> {
    let env_args = crate::cli::env::EnvArgs {
        env: args.env.clone(),
        env_samples: None,
        env_noise: None,
        env_seed: None,
        env_intensity: args.env_intensity,
        env_rotate_deg: args.env_rotate_deg,
        no_sun: false,
    };
    let Some(map) = env_args.load(true, &Scene::default())? else {
        return Ok(None);
    };
    let t = &args.table;
    let spec = t.env_spec(base.coherence_um)?;
    let samples = ascending(&args.env_spp, &DEFAULT_ENV_SPP);
    Ok(Some(EnvProfile {
        map,
        samples,
        spec,
        pixels: args.env_pixels.unwrap_or(DEFAULT_ENV_PIXELS),
        variants: env_variants(args)?,
    }))
}

/// The values a list flag gave, or `default` without any: ascending, each once.
fn ascending(given: &[u32], default: &[u32]) -> Vec<u32> {
    let mut v = if given.is_empty() { default } else { given }.to_vec();
    v.sort_unstable();
    v.dedup();
    v
}

/// The picture rows' set-up, when `--picture` (or `--full`, or any `--picture-*` flag)
/// asks for them: the scene loaded and sized, the modes and the reference checked, the
/// error maps' directory made, before any device work.
fn picture_setup(args: &ProfileArgs) -> Result<Option<super::picture::PictureSetup>> {
    use super::picture::{DEFAULT_AA, DEFAULT_SIZE, REFERENCE_SS};
    let asked = args.picture
        || args.full
        || args.picture_scene.is_some()
        || args.picture_size.is_some()
        || !args.picture_aa.is_empty()
        || args.picture_reference_ss.is_some()
        || args.picture_maps.is_some();
    if !asked {
        return Ok(None);
    }
    let mut scene = match &args.picture_scene {
        Some(p) => Scene::load(p)?,
        None => Scene::default_scene(),
    };
    let size = args.picture_size.unwrap_or(DEFAULT_SIZE);
    if !(1..=1024).contains(&size) {
        return Err(Error::invalid(
            "picture-size",
            format!("{size}; expected 1..=1024 pixels"),
        ));
    }
    scene.output.width = size;
    scene.output.height = size;
    let aa = ascending(&args.picture_aa, &DEFAULT_AA);
    let reference_ss = args.picture_reference_ss.unwrap_or(REFERENCE_SS);
    if aa.iter().any(|&n| !(1..=8).contains(&n)) {
        return Err(Error::invalid(
            "picture-aa",
            format!("{aa:?}; each mode is 1..=8 samples a pixel per side"),
        ));
    }
    let most = aa.last().copied().unwrap_or(1);
    if !(2..=32).contains(&reference_ss) || reference_ss <= most {
        return Err(Error::invalid(
            "picture-reference-ss",
            format!("{reference_ss}; expected 2..=32 and more than the largest mode ({most})"),
        ));
    }
    if u64::from(size) * u64::from(reference_ss) > 8192 {
        return Err(Error::invalid(
            "picture-reference-ss",
            format!(
                "{size} pixels × {reference_ss} samples a side is a {}² picture; at most 8192²",
                size * reference_ss
            ),
        ));
    }
    if let Some(dir) = &args.picture_maps {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::invalid("picture-maps", format!("{}: {e}", dir.display())))?;
    }
    let label = match &args.picture_scene {
        Some(p) => format!("the scene {}", p.display()),
        None => "the default scene".to_string(),
    };
    Ok(Some(super::picture::PictureSetup {
        label,
        scene,
        aa,
        reference_ss,
        error_maps: args.picture_maps.clone(),
    }))
}

/// The rows drawn as whole pictures: those `--only` names (less the debug views), else
/// every table variant's (a DFT-term variant evaluates thousands of terms a pixel: at a
/// picture's size and supersampling, minutes on a CPU device; `--only` adds it).
fn picture_rows(args: &ProfileArgs) -> Result<Vec<Variant>> {
    let rows = selected_rows(args)?;
    let named = args.only.iter().any(|n| n != "env");
    Ok(rows
        .into_iter()
        .filter(|v| match v.kind.family() {
            crate::render::variant::Family::Table => true,
            crate::render::variant::Family::Terms => named,
            crate::render::variant::Family::Debug => false,
        })
        .collect())
}

/// The variants the environment rows draw: every one that can be lit by an environment
/// without `--only`; with it, those it names that can (the default variant alone when it
/// names only `env`); the default variant first.
fn env_variants(args: &ProfileArgs) -> Result<Vec<VariantKind>> {
    let candidates: Vec<VariantKind> = if args.only.is_empty() {
        VariantKind::ALL.to_vec()
    } else {
        selected_rows(args)?
            .iter()
            .map(|v| v.kind.resolve())
            .collect()
    };
    let mut kinds = crate::render::env_brdf::lightable(&candidates);
    if kinds.is_empty() {
        kinds.push(VariantKind::DEFAULT);
    }
    Ok(kinds)
}

/// The rows of every registered variant, or those `--only` names (`env` names the
/// environment rows, which `--env` adds whatever `--only` says).
fn selected_rows(args: &ProfileArgs) -> Result<Vec<Variant>> {
    let mut variants = flss_variants(args.variant_terms);
    variants.extend(table_variants(&args.table.options()));
    let only: Vec<&String> = args.only.iter().filter(|n| *n != "env").collect();
    if args.only.is_empty() {
        return Ok(variants);
    }
    if only.is_empty() {
        return Ok(Vec::new());
    }
    for name in only {
        if !variants.iter().any(|v| &v.name == name) {
            let names: Vec<&str> = variants.iter().map(|v| v.name.as_str()).collect();
            return Err(Error::invalid(
                "only",
                format!(
                    "'{name}' is not a profiled variant; expected one of: {}",
                    names.join(", ")
                ),
            ));
        }
    }
    variants.retain(|v| args.only.contains(&v.name));
    Ok(variants)
}

/// `diffract profile`: map size, angles, scored pixels (no more than the map's disk holds),
/// repeats, the budget, the material's numbers and the output paths.
pub fn profile_args(args: &ProfileArgs) -> Result<()> {
    use crate::render::MAX_MAP_SIZE;
    let c = args.counts();
    if !(1..=MAX_MAP_SIZE).contains(&c.size) {
        return Err(Error::invalid(
            "BRDF map size",
            format!("{}; expected 1..={MAX_MAP_SIZE} pixels", c.size),
        ));
    }
    crate::guard::in_range("theta-i", args.theta_i, 0.0..=90.0, "°")?;
    crate::guard::finite("phi-i", args.phi_i)?;
    crate::guard::budget_s(args.budget_s)?;
    check_counts(&c, args)?;
    check_env(&c, args)?;
    args.table.check()?;
    if args.variant_terms > 64 {
        return Err(Error::invalid(
            "variant-terms",
            format!("{}; at most 64 terms are supported", args.variant_terms),
        ));
    }
    let material = args.material.apply(crate::material::Material::default());
    material.validate()?;
    for p in args.csv.iter().chain(&args.plot) {
        if p.file_name().is_none() {
            return Err(Error::invalid(
                "output",
                format!("{} is not a file", p.display()),
            ));
        }
    }
    let outputs: Vec<(&str, PathBuf)> = [("--csv", &args.csv), ("--plot", &args.plot)]
        .into_iter()
        .filter_map(|(flag, out)| out.clone().map(|o| (flag, o)))
        .collect();
    let mut inputs = crate::guard::heightfield_inputs(&material.heightfield);
    inputs.extend(crate::guard::env_input(args.env.as_deref()));
    crate::guard::check_outputs(&inputs, &outputs)
}

/// Scored pixels (no more than the map's disk holds), frames, the mesh view and its quads.
fn check_counts(c: &Counts, args: &ProfileArgs) -> Result<()> {
    let inside = (0..c.size)
        .flat_map(|j| (0..c.size).map(move |i| (i, j)))
        .filter(|&(i, j)| map_direction(i, j, c.size).is_some())
        .count();
    let scored = c.pixels.saturating_add(c.brightest);
    if scored == 0 || scored > inside {
        return Err(Error::invalid(
            "pixels",
            format!(
                "{} spread + {} brightest; a {}² map has {inside} pixels inside its disk to score (at least 1)",
                c.pixels, c.brightest, c.size
            ),
        ));
    }
    if let Frames::Fixed(n) = c.frames {
        if !(1..=1000).contains(&n) {
            return Err(Error::invalid("frames", format!("{n}; expected 1..=1000")));
        }
    }
    if c.mesh_size > 8192 {
        return Err(Error::invalid(
            "mesh-size",
            format!("{}; expected 0 (none) ..=8192", c.mesh_size),
        ));
    }
    if args.per_vertex && c.mesh_size == 0 {
        return Err(Error::invalid(
            "per-vertex",
            "needs the mesh view (--mesh-size > 0): a BRDF map has no vertices",
        ));
    }
    if let Some(q) = args.mesh_quads {
        if !(1..=32).contains(&q) || c.mesh_size == 0 {
            return Err(Error::invalid(
                "mesh-quads",
                format!("{q}; expected 1..=32 with a mesh view (--mesh-size > 0)"),
            ));
        }
    }
    Ok(())
}

/// The environment rows' flags: each needs `--env` (as `--only env` does); samples per
/// pixel within what a map draws; scored pixels within the map's disk.
fn check_env(c: &Counts, args: &ProfileArgs) -> Result<()> {
    let asks = !args.env_spp.is_empty()
        || args.env_pixels.is_some()
        || args.only.iter().any(|n| n == "env");
    if args.env.is_none() && asks {
        return Err(Error::invalid(
            "env",
            "--env-spp, --env-pixels and --only env need an environment (--env SOURCE)",
        ));
    }
    use crate::render::env::MAX_SAMPLES;
    if let Some(&n) = args
        .env_spp
        .iter()
        .find(|&&n| !(1..=MAX_SAMPLES).contains(&n))
    {
        return Err(Error::invalid(
            "env-spp",
            format!("{n}; expected 1 to {MAX_SAMPLES} samples per pixel"),
        ));
    }
    if let Some(n) = args.env_pixels {
        let inside = (0..c.size * c.size)
            .filter(|k| map_direction(k % c.size, k / c.size, c.size).is_some())
            .count();
        if !(1..=inside).contains(&n) {
            return Err(Error::invalid(
                "env-pixels",
                format!(
                    "{n}; a {}² map has {inside} pixels inside its disk to score (at least 1)",
                    c.size
                ),
            ));
        }
    }
    Ok(())
}
