//! `diffract view`: the desktop viewer. A winit window, a Vulkan surface and swapchain
//! (`gpu::swapchain`), two frames in flight, live camera/light/exposure/variant controls
//! ([`input`]) and GLSL hot reload ([`reload`]). Frames are the renderer's
//! [`ScenePass`](crate::render::ScenePass) recorded into swapchain images: the same code as
//! `diffract render`, so a screenshot matches the offscreen render of the same camera.
//!
//! No physics here and no Vulkan beyond frame pacing: the pass and the swapchain own their
//! objects.

mod app;
pub mod input;
pub mod reload;

use std::path::PathBuf;

use crate::gpu::swapchain::Vsync;
use crate::gpu::StorageFormat;
use crate::material::MaterialArgs;
use crate::render::{TableArgs, VariantKind};
use crate::scene::Scene;
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
    /// Scene file (TOML); the embedded default scene when omitted.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Window width in pixels (default: the scene's image width).
    #[arg(long)]
    pub width: Option<u32>,
    /// Window height in pixels (default: the scene's image height).
    #[arg(long)]
    pub height: Option<u32>,
    /// Initial exposure (overrides the scene).
    #[arg(long, allow_negative_numbers = true)]
    pub exposure: Option<f32>,
    /// Initial shader variant (V cycles through them).
    #[arg(long, value_enum, default_value_t = VariantKind::Default)]
    pub variant: VariantKind,
    /// Storage format of the DFT terms on the GPU (flss).
    #[arg(long, value_enum, default_value_t = StorageFormat::Rg32f)]
    pub storage: StorageFormat,
    /// Evaluate the BRDF per vertex and interpolate the colour (thesis §1.5.1; flss, nmm,
    /// pq; V then cycles through those).
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
    let map_exposure = args.map_exposure.unwrap_or(input::DEFAULT_MAP_EXPOSURE);
    if !(map_exposure.is_finite() && map_exposure > 0.0) {
        return Err(Error::invalid(
            "map exposure",
            format!("{map_exposure}; must be finite and > 0"),
        ));
    }
    if let Some(w) = args.width {
        scene.output.width = w;
    }
    if let Some(h) = args.height {
        scene.output.height = h;
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
    if args.frames == Some(0) {
        return Err(Error::invalid("frames", "0; expected at least 1"));
    }
    let script = args
        .at
        .iter()
        .map(|a| parse_at(a))
        .collect::<Result<Vec<_>>>()?;
    crate::render::check_per_vertex(args.per_vertex, false, args.variant)?;
    scene.material = args.material.apply(scene.material.clone());
    let settings = app::Settings {
        variant: args.variant.resolve(),
        per_vertex: args.per_vertex,
        storage: args.storage,
        table: args.table.options(),
        cache_dir: crate::cachedir::resolve(args.no_cache, args.cache_dir.as_deref()),
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
        validation: crate::render::validation_requested(),
        script,
        map: args.map,
        map_exposure,
    };
    app::run(scene, settings)
}

/// `diffract view`: the screenshot must be a PNG that can be written and is none of the
/// files the scene reads.
pub fn view_args(args: &ViewArgs, scene: &crate::scene::Scene) -> Result<()> {
    crate::render::table_args(&args.table)?;
    if let Some(p) = &args.screenshot {
        if p.extension().and_then(|e| e.to_str()) != Some("png") {
            return Err(Error::invalid(
                "screenshot",
                format!("{}: must be a .png file", p.display()),
            ));
        }
        let material = args.material.apply(scene.material.clone());
        crate::guard::check_outputs(
            &crate::guard::scene_inputs(args.scene.as_deref(), scene, &material.heightfield),
            &[("--screenshot", p.clone())],
        )?;
    }
    Ok(())
}
