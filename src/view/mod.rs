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
    #[arg(long)]
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
    if let Some(p) = &args.screenshot {
        if p.extension().and_then(|e| e.to_str()) != Some("png") {
            return Err(Error::invalid(
                "screenshot",
                format!("{}: must be a .png file", p.display()),
            ));
        }
    }
    if args.frames == Some(0) {
        return Err(Error::invalid("frames", "0; expected at least 1"));
    }
    crate::render::check_per_vertex(args.per_vertex, false, args.variant)?;
    scene.material = args.material.apply(scene.material.clone());
    let settings = app::Settings {
        variant: args.variant.resolve(),
        per_vertex: args.per_vertex,
        storage: args.storage,
        table: args.table.options(),
        cache_dir: if args.no_cache {
            None
        } else {
            args.cache_dir
                .clone()
                .or_else(crate::material::default_cache_dir)
        },
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
    };
    app::run(scene, settings)
}
