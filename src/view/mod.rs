//! `diffract view`: the desktop viewer. A winit window, a Vulkan surface and swapchain
//! (`gpu::swapchain`), two frames in flight, live camera/light/exposure/variant controls
//! ([`input`]) and GLSL hot reload ([`reload`]). Frames are the renderer's
//! [`ScenePass`](crate::render::ScenePass) recorded into swapchain images: the same code as
//! `diffract render`, so a screenshot matches the offscreen render of the same camera.
//!
//! Under an environment map (`env.rs`) the frames are the environment-lit picture of
//! `diffract render --env`, accumulated over frames by the same compute estimator.
//!
//! No physics here and no Vulkan beyond frame pacing and the environment's resolve: the
//! passes, the kernels and the swapchain own their objects.

mod app;
mod draw;
mod env;
pub mod input;
mod material;
pub mod reload;

use std::path::PathBuf;

use crate::cli::cache::CacheArgs;
use crate::cli::env::EnvArgs;
use crate::cli::gpu::GpuArgs;
use crate::cli::material::MaterialArgs;
use crate::cli::scene::SceneArgs;
use crate::gpu::swapchain::Vsync;
use crate::{Error, Result};

/// `on` / `off` for `--vsync`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OnOff {
    On,
    Off,
}

/// `diffract view`: the scene in a window.
#[derive(Debug, Clone, clap::Args)]
pub struct ViewArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub gpu: GpuArgs,
    #[command(flatten)]
    pub material: MaterialArgs,
    #[command(flatten)]
    pub cache: CacheArgs,
    #[command(flatten)]
    pub env: EnvArgs,
    /// Recompile glsl/* when it changes and rebuild the pipeline (a compile error keeps the
    /// last good one).
    #[arg(long)]
    pub watch: bool,
    /// The GLSL directory --watch reads (default: the glsl/ of the source tree).
    #[arg(long)]
    pub glsl_dir: Option<PathBuf>,
    /// on: FIFO (wait for the display); off: MAILBOX or IMMEDIATE where available.
    #[arg(long, value_enum, default_value_t = OnOff::On)]
    pub vsync: OnOff,
    /// Render this many frames through the swapchain, then exit (tests, CI).
    #[arg(long)]
    pub frames: Option<u32>,
    /// With --frames: save the last frame (the swapchain image) to this PNG.
    #[arg(long, requires = "frames")]
    pub screenshot: Option<PathBuf>,
    /// Start with the BRDF map beside the mesh (B toggles it).
    #[arg(long)]
    pub map: bool,
    /// Exposure of the BRDF map ([ and ] change it) [default: 30].
    #[arg(long, allow_negative_numbers = true)]
    pub map_exposure: Option<f32>,
    /// Test hook: before frame N, press a key (`N:b`, `N:left`, ...), request a window size
    /// (`N:resize=WxH`) or treat the window as minimised for K redraws (`N:minimise=K`).
    #[arg(long = "at", value_name = "N:ACTION", hide = true)]
    pub at: Vec<String>,
}

/// One `--at` action (a test hook: tests drive the controls and the window through it).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ScriptAction {
    /// A key press as [`input::Controls::key`] sees it: one character, or `left`, `right`,
    /// `up`, `down`, `esc`.
    Key(String),
    /// Ask the window system for this inner size.
    Resize(u32, u32),
    /// The window counts as zero-sized for this many redraws (what a minimised window
    /// reports; Xvfb has no window manager to minimise it).
    Minimise(u32),
}

/// Parses `N:ACTION` of `--at`.
pub fn parse_at(s: &str) -> Result<(u32, ScriptAction)> {
    let bad = |why: &str| Error::invalid("--at", format!("'{s}': {why}"));
    let (n, action) = s.split_once(':').ok_or_else(|| bad("expected N:ACTION"))?;
    let n: u32 = n.parse().map_err(|_| bad("N must be a frame index"))?;
    let action = if let Some(size) = action.strip_prefix("resize=") {
        let (w, h) = size
            .split_once('x')
            .ok_or_else(|| bad("expected resize=WxH"))?;
        let (w, h): (u32, u32) = match (w.parse(), h.parse()) {
            (Ok(w), Ok(h)) if (1..=8192).contains(&w) && (1..=8192).contains(&h) => (w, h),
            _ => return Err(bad("W and H must be 1..=8192")),
        };
        ScriptAction::Resize(w, h)
    } else if let Some(k) = action.strip_prefix("minimise=") {
        match k.parse() {
            Ok(k) if (1..=1000).contains(&k) => ScriptAction::Minimise(k),
            _ => return Err(bad("minimise=K needs K in 1..=1000")),
        }
    } else if action.chars().count() == 1
        || ["left", "right", "up", "down", "esc"].contains(&action)
    {
        ScriptAction::Key(action.to_string())
    } else {
        return Err(bad("unknown action"));
    };
    Ok((n, action))
}

/// Runs `diffract view` until the window closes (or `--frames` are done).
pub fn run(args: &ViewArgs) -> Result<()> {
    let started = std::time::Instant::now();
    let mut scene = args.scene.load()?;
    let map_exposure = args.map_exposure.unwrap_or(input::DEFAULT_MAP_EXPOSURE);
    if !(map_exposure.is_finite() && map_exposure > 0.0) {
        return Err(Error::invalid(
            "map exposure",
            format!("{map_exposure}; must be finite and > 0"),
        ));
    }
    for (what, v) in [
        ("width", scene.output.width),
        ("height", scene.output.height),
    ] {
        if !(1..=8192).contains(&v) {
            return Err(Error::invalid(
                "window size",
                format!("{what} {v}; expected 1..=8192"),
            ));
        }
    }
    view_args(args, &scene)?;
    let env = env_settings(args, &scene)?;
    if args.frames == Some(0) {
        return Err(Error::invalid("frames", "0; expected at least 1"));
    }
    let script = args
        .at
        .iter()
        .map(|a| parse_at(a))
        .collect::<Result<Vec<_>>>()?;
    args.gpu.check_per_vertex(false, args.gpu.variant)?;
    scene.material = args.material.apply(scene.material.clone());
    let settings = app::Settings {
        variant: args.gpu.variant.resolve(),
        per_vertex: args.gpu.per_vertex,
        storage: args.gpu.storage,
        table: args.gpu.table.options(),
        cache_dir: args.cache.dir(),
        watch: args.watch.then(|| {
            args.glsl_dir
                .clone()
                .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("glsl"))
        }),
        vsync: match args.vsync {
            OnOff::On => Vsync::On,
            OnOff::Off => Vsync::Off,
        },
        frames: args.frames,
        screenshot: args.screenshot.clone(),
        validation: crate::cli::gpu::validation_requested(),
        script,
        map: args.map,
        map_exposure,
        env: Some(env),
        started,
    };
    app::run(scene, settings)
}

/// The environments `E` cycles through (none, the built-in maps, `--env`'s or the scene's
/// file) and how they light the scene, checked as `render` checks them; and the map shown
/// first, loaded.
fn env_settings(
    args: &ViewArgs,
    scene: &crate::scene::Scene,
) -> Result<(env::EnvSettings, Option<crate::light::env::EnvMap>)> {
    use crate::light::env::EnvSource;
    if args.env.env_noise.is_some() {
        return Err(crate::Error::invalid(
            "env noise",
            "--env-noise applies to render's scenes; the viewer accumulates every pixel to --env-samples",
        ));
    }
    if args.env.env_seed.is_some() {
        return Err(crate::Error::invalid(
            "env seed",
            "--env-seed applies to render; the viewer accumulates one sequence of samples",
        ));
    }
    let source = match (&args.env.env, &scene.environment) {
        (Some(s), _) => Some(EnvSource::parse(s)?),
        (None, Some(e)) => Some(e.source()?),
        (None, None) => None,
    };
    let first_map = match source {
        Some(_) => args.env.load(false, scene)?,
        None => {
            // Without a map the flags still apply to the maps `E` shows: checked as
            // `render` checks them, on the smallest one.
            let mut probe = args.env.clone();
            probe.env = Some("builtin:white".into());
            probe.load(false, scene)?;
            None
        }
    };
    let mut entries = vec![
        None,
        Some(EnvSource::Sky),
        Some(EnvSource::Studio),
        Some(EnvSource::White),
    ];
    let first = match &source {
        None => 0,
        Some(s) => match entries.iter().position(|e| e.as_ref() == Some(s)) {
            Some(i) => i,
            None => {
                entries.push(Some(s.clone()));
                entries.len() - 1
            }
        },
    };
    let spec_env = scene.environment.as_ref();
    let material = args.material.apply(scene.material.clone());
    let t = &args.gpu.table;
    let spec = t.env_spec(material.coherence_um)?;
    let texture = match &scene.texture {
        Some(t) => Some(t.load()?),
        None => None,
    };
    let settings = env::EnvSettings {
        entries,
        first,
        intensity: args
            .env
            .env_intensity
            .unwrap_or_else(|| spec_env.map_or(1.0, |e| e.intensity)),
        rotate_deg: args
            .env
            .env_rotate_deg
            .unwrap_or_else(|| spec_env.map_or(0.0, |e| e.rotate_deg)),
        samples: args
            .env
            .env_samples
            .unwrap_or(crate::render::env::DEFAULT_SAMPLES),
        sun: !args.env.no_sun,
        lit_without_map: args.env.lights_scene(None, scene),
        spec,
        cache_dir: args.cache.dir(),
        texture,
    };
    Ok((settings, first_map))
}

/// `diffract view`: every file the scene reads is a regular file, and the screenshot must be
/// a PNG that can be written and is none of them.
pub fn view_args(args: &ViewArgs, scene: &crate::scene::Scene) -> Result<()> {
    args.gpu.table.check()?;
    let mut outputs = Vec::new();
    if let Some(p) = &args.screenshot {
        if p.extension().and_then(|e| e.to_str()) != Some("png") {
            return Err(Error::invalid(
                "screenshot",
                format!("{}: must be a .png file", p.display()),
            ));
        }
        outputs.push(("--screenshot", p.clone()));
    }
    let material = args.material.apply(scene.material.clone());
    crate::guard::check_outputs(
        &crate::guard::scene_inputs(
            args.scene.scene.as_deref(),
            scene,
            &material.heightfield,
            args.env.env.as_deref(),
        ),
        &outputs,
    )
}
