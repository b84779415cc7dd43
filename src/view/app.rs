//! The winit application: window and controls. Each redraw asks the frame layer
//! ([`Frames`]) for the next frame in flight, acquires a swapchain image, records the
//! renderer's passes into it, submits and presents. Rebuilt passes and replaced swapchains
//! are retired through the layer's deferred release: the frame path never waits for the
//! device to be idle. Tables, DFT terms and edited materials are built on worker threads
//! ([`Renderer::prepare_in_background`], [`MaterialLoader`]): the window keeps drawing
//! what it has (at start, a coarse table) and the title shows the build's progress. Also the layout of the mesh beside its BRDF map, the title's
//! statistics, screenshots, hot reload and the hidden `--at` test hook. What an input means
//! is [`super::input`]'s.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ash::vk;
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, NamedKey};
use winit::raw_window_handle::{HasDisplayHandle, HasWindowHandle};
use winit::window::{Window, WindowId};

use super::input::{tangent_frame_at_view, Controls, Effect, ViewState, HELP};
use super::material::MaterialLoader;
use super::reload::ShaderReload;
use super::ScriptAction;
use crate::brdf::truncation::{Precision, Reach};
use crate::gpu::frames::Frames;
use crate::gpu::memory::Buffer;
use crate::gpu::swapchain::{Acquired, Presented, Recreated, Surface, Swapchain, Vsync};
use crate::gpu::{Device, Instance, StorageFormat};
use crate::material::PreparedMaterial;
use crate::mesh::Mesh;
use crate::render::{
    MapView, PassOptions, Readiness, Renderer, ScenePass, TableOptions, VariantKind,
};
use crate::scene::Scene;
use crate::{Error, Result};

/// Frames recorded while the GPU works on earlier ones.
const FRAMES_IN_FLIGHT: usize = 2;
/// Table variants are built for the view's `(u, v, w)` region widened by this, and rebuilt
/// only when the view leaves it.
const REGION_MARGIN: f64 = 0.25;

/// What `diffract view` was asked for (parsed arguments).
pub(super) struct Settings {
    pub variant: VariantKind,
    pub per_vertex: bool,
    pub storage: StorageFormat,
    pub table: TableOptions,
    pub cache_dir: Option<PathBuf>,
    pub watch: Option<PathBuf>,
    pub vsync: Vsync,
    pub frames: Option<u32>,
    pub screenshot: Option<PathBuf>,
    pub validation: bool,
    /// Test hook (`--at`): actions before the frame of the given index.
    pub script: Vec<(u32, ScriptAction)>,
    /// Start with the BRDF map beside the mesh.
    pub map: bool,
    pub map_exposure: f32,
    /// When the command started (the first frame's delay is measured from it).
    pub started: Instant,
}

/// Opens the display, prepares the material, runs the event loop.
pub(super) fn run(scene: Scene, settings: Settings) -> Result<()> {
    if std::env::var_os("DISPLAY").is_none_or(|d| d.is_empty()) {
        return Err(Error::NoPresentation(
            "no X display (DISPLAY is not set); run under X11, XWayland or Xvfb".into(),
        ));
    }
    let event_loop = EventLoop::new()
        .map_err(|e| Error::NoPresentation(format!("cannot open the display: {e}")))?;
    event_loop.set_control_flow(ControlFlow::Poll);
    // The DFT terms wait for a variant that reads them (`V` to flss, nmm or pq): the
    // table variants build from the height field.
    let (heightfield, plan) =
        scene
            .material
            .load_planned(&Reach::ALL, Precision::F32, &crate::report::Stderr)?;
    let loader = MaterialLoader::new(
        scene.material.clone(),
        settings.cache_dir.clone(),
        &heightfield,
    );
    let prepared = scene.material.prepare_planned_deferred(
        heightfield,
        plan,
        settings.cache_dir.as_deref(),
    )?;
    let mut app = App {
        scene,
        start: Some((Arc::new(prepared), loader)),
        settings,
        viewer: None,
        error: None,
    };
    event_loop
        .run_app(&mut app)
        .map_err(|e| Error::NoPresentation(format!("event loop: {e}")))?;
    let canary = app.viewer.as_ref().map(|v| v.renderer.canary());
    if let Some(v) = &app.viewer {
        v.print_totals();
    }
    // Dropping the viewer waits for the GPU and destroys everything; messages raised then
    // (objects left alive) still reach the canary.
    drop(app.viewer.take());
    if let Some(e) = app.error {
        return Err(e);
    }
    let messages = canary.map_or(0, |c| c.count());
    if messages > 0 {
        return Err(Error::Validation(messages));
    }
    Ok(())
}

struct App {
    scene: Scene,
    /// The material and its loader, until the viewer takes them.
    start: Option<(Arc<PreparedMaterial>, MaterialLoader)>,
    settings: Settings,
    viewer: Option<Viewer>,
    error: Option<Error>,
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        let Some((prepared, loader)) = self.start.take() else {
            return;
        };
        match Viewer::new(event_loop, &self.scene, &self.settings, prepared, loader) {
            Ok(v) => {
                println!("{HELP}");
                self.viewer = Some(v);
            }
            Err(e) => {
                self.error = Some(e);
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(v) = &mut self.viewer else { return };
        let result = match event {
            WindowEvent::CloseRequested => {
                event_loop.exit();
                Ok(())
            }
            WindowEvent::Resized(size) => {
                // The hook's resize recreates at once; X's event for it then changes nothing
                // (an out-of-date swapchain of the same size is caught by acquire/present).
                let current = v.swapchain.as_ref().map(|sc| sc.extent);
                if current.is_none_or(|e| (e.width, e.height) != (size.width, size.height)) {
                    v.needs_recreate = true;
                }
                Ok(())
            }
            WindowEvent::RedrawRequested => {
                v.run_script(event_loop);
                v.frame(&self.scene, &self.settings).map(|done| {
                    if done {
                        event_loop.exit();
                    }
                })
            }
            WindowEvent::ModifiersChanged(m) => {
                v.controls.modifiers(m.state());
                Ok(())
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                let effect = v.controls.key(&event.logical_key);
                v.apply(effect, event_loop);
                Ok(())
            }
            WindowEvent::MouseInput { state, button, .. } => {
                v.controls.button(button, state == ElementState::Pressed);
                Ok(())
            }
            WindowEvent::CursorMoved { position, .. } => {
                let effect = v.controls.cursor_moved(position.x, position.y);
                v.apply(effect, event_loop);
                Ok(())
            }
            WindowEvent::CursorLeft { .. } => {
                v.controls.cursor_left();
                Ok(())
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let effect = v.controls.wheel(delta);
                v.apply(effect, event_loop);
                Ok(())
            }
            _ => Ok(()),
        };
        if let Err(e) = result {
            self.error = Some(e);
            event_loop.exit();
        }
    }

    fn about_to_wait(&mut self, _event_loop: &ActiveEventLoop) {
        if let Some(v) = &self.viewer {
            v.window.request_redraw();
        }
    }
}

/// Everything that lives while the window is open. Field order is drop order: the frames
/// (with the passes and swapchains retired into them), the pass and the swapchain before the
/// surface, the surface before the window.
struct Viewer {
    frames: Frames,
    pass: Option<ScenePass>,
    /// The BRDF map beside the mesh (while `controls.map`).
    map_pass: Option<ScenePass>,
    swapchain: Option<Swapchain>,
    renderer: Renderer,
    surface: Surface,
    reload: Option<ShaderReload>,
    controls: Controls,
    /// The scene's mesh in world space: the map's tangent frame is read from it.
    mesh: Mesh,
    /// The material the controls ask for (the newest edit loaded).
    material: Arc<PreparedMaterial>,
    /// The material of the prepared variant the passes draw: `material` once its build
    /// has arrived.
    shown: Arc<PreparedMaterial>,
    /// Loads edited materials on a worker thread.
    loader: MaterialLoader,
    /// While a build runs: the frames presented since it started.
    build: Option<u32>,
    /// The last request was answered `Building` and nothing changed since: the next frames
    /// do not ask again.
    waiting: bool,
    /// `--at` actions not yet run, by settled frame index.
    script: Vec<(u32, ScriptAction)>,
    /// `--at N:minimise=K`: the window counts as zero-sized for K more redraws.
    fake_minimised: u32,
    /// The last recreation saw a zero extent (printed once).
    minimised: bool,
    /// Settled frames: presented while nothing was building or loading. `--frames` and the
    /// `--at` indices count these, so a screenshot shows the finished table.
    frames_done: u32,
    /// Every frame presented.
    presented: u32,
    /// When the command started.
    opened: Instant,
    needs_recreate: bool,
    view_changed: bool,
    rebuild: bool,
    screenshot_next: Option<PathBuf>,
    screenshots_taken: u32,
    stats: TitleStats,
    /// Over the whole run, after the first frame: frames, GPU ms summed, GPU samples.
    totals: (Option<Instant>, u32, f64, u32),
    last_reload_check: Instant,
    window: Arc<Window>,
}

/// Rolling numbers for the title.
struct TitleStats {
    since: Instant,
    frames: u32,
    gpu_ms_sum: f64,
    gpu_samples: u32,
}

impl TitleStats {
    /// One frame's GPU time, into the title's numbers and the run's `totals`.
    fn add_gpu(&mut self, ms: f64, totals: &mut (Option<Instant>, u32, f64, u32)) {
        self.gpu_ms_sum += ms;
        self.gpu_samples += 1;
        totals.2 += ms;
        totals.3 += 1;
    }
}

impl Viewer {
    fn new(
        event_loop: &ActiveEventLoop,
        scene: &Scene,
        settings: &Settings,
        prepared: Arc<PreparedMaterial>,
        loader: MaterialLoader,
    ) -> Result<Self> {
        let mesh = scene.mesh.load()?;
        for line in &mesh.repairs {
            crate::report::Report::warn(&crate::report::Stderr, line);
        }
        let out = &scene.output;
        let attrs = Window::default_attributes()
            .with_title("diffract")
            .with_inner_size(PhysicalSize::new(out.width, out.height));
        let window = Arc::new(
            event_loop
                .create_window(attrs)
                .map_err(|e| Error::NoPresentation(format!("cannot create a window: {e}")))?,
        );
        let display = window
            .display_handle()
            .map_err(|e| Error::NoPresentation(format!("no display handle: {e}")))?
            .as_raw();
        let handle = window
            .window_handle()
            .map_err(|e| Error::NoPresentation(format!("no window handle: {e}")))?
            .as_raw();
        let instance = Instance::with_surface_extensions(settings.validation, display)?;
        // SAFETY: the handles belong to `window`, which the Viewer keeps (as its last field)
        // until after the surface is destroyed.
        let surface = unsafe { Surface::new(&instance, display, handle)? };
        let dev = Device::on_surface(instance, &surface)?;
        let mut renderer = Renderer::on(dev.clone())?;
        renderer.set_variant(settings.variant);
        renderer.set_per_vertex(settings.per_vertex);
        renderer.set_storage_format(settings.storage);
        renderer.set_table_options(settings.table);
        renderer.set_cache_dir(settings.cache_dir.clone());
        renderer.set_region_margin(REGION_MARGIN);
        renderer.set_leave_out(true);
        let frames = Frames::new(&dev, "viewer frame", FRAMES_IN_FLIGHT, true)?;
        let mut controls = Controls::new(ViewState::from_scene(scene), settings.variant);
        controls.per_vertex = settings.per_vertex;
        controls.map = settings.map;
        controls.state.map_exposure = settings.map_exposure;
        let mut viewer = Viewer {
            frames,
            pass: None,
            map_pass: None,
            swapchain: None,
            renderer,
            surface,
            reload: None,
            controls,
            mesh,
            shown: Arc::clone(&prepared),
            material: prepared,
            loader,
            build: None,
            waiting: false,
            script: settings.script.clone(),
            fake_minimised: 0,
            minimised: false,
            frames_done: 0,
            presented: 0,
            opened: settings.started,
            needs_recreate: false,
            view_changed: false,
            rebuild: true,
            screenshot_next: None,
            screenshots_taken: 0,
            stats: TitleStats {
                since: Instant::now(),
                frames: 0,
                gpu_ms_sum: 0.0,
                gpu_samples: 0,
            },
            totals: (None, 0, 0.0, 0),
            last_reload_check: Instant::now(),
            window,
        };
        if let Some(dir) = &settings.watch {
            let mut reload = ShaderReload::new(dir)?;
            // The watched sources may differ from the built-in SPIR-V: start from them.
            match reload.compile_all() {
                Ok(spirv) => viewer.renderer.set_shader_overrides(spirv.clone()),
                Err(msg) => eprintln!("{msg}\nshader reload: keeping the built-in shaders"),
            }
            println!("watching {} for shader edits", dir.display());
            viewer.reload = Some(reload);
        }
        viewer.recreate_swapchain(settings.vsync)?;
        // The first frame starts the variant's build (a coarse table first).
        Ok(viewer)
    }

    fn dev(&self) -> &Arc<Device> {
        self.renderer.device()
    }

    /// (Re)creates the swapchain for the window's size; the old one is retired until the
    /// frames that used it are done. `Ok(false)`: minimised, skip frames.
    fn recreate_swapchain(&mut self, vsync: Vsync) -> Result<bool> {
        let size = self.window.inner_size();
        let mut want = vk::Extent2D {
            width: size.width,
            height: size.height,
        };
        if self.fake_minimised > 0 {
            self.fake_minimised -= 1;
            want = vk::Extent2D::default();
        }
        if want.width == 0 || want.height == 0 {
            if !self.minimised {
                println!("window minimised (zero extent): frames skipped");
                self.minimised = true;
            }
            return Ok(false);
        }
        let old = self.swapchain.as_ref().map(|sc| sc.extent);
        let ok = match &mut self.swapchain {
            Some(sc) => match sc.recreate(&self.surface, want, vsync)? {
                Recreated::Minimised => false,
                Recreated::Replaced(old) => {
                    // A new format means a new render pass: the pipelines are rebuilt.
                    if old.format != sc.format {
                        self.rebuild = true;
                        self.waiting = false;
                    }
                    self.frames.retire_after_present(old);
                    true
                }
            },
            None => match Swapchain::new(self.dev(), &self.surface, want, vsync)? {
                Some(sc) => {
                    self.swapchain = Some(sc);
                    self.rebuild = true;
                    self.waiting = false;
                    true
                }
                None => false,
            },
        };
        if ok {
            self.needs_recreate = false;
            self.view_changed = true;
            self.minimised = false;
            if let (Some(old), Some(sc)) = (old, &self.swapchain) {
                println!(
                    "swapchain recreated: {}×{} → {}×{}",
                    old.width, old.height, sc.extent.width, sc.extent.height
                );
            }
        }
        Ok(ok)
    }

    /// Rebuilds the passes for the prepared variant (variant, switches, shaders, a table
    /// that arrived). The old pass is kept when the new one fails (e.g. a reloaded shader
    /// that does not link).
    fn rebuild_pass(&mut self, scene: &Scene) -> Result<()> {
        let prepared = Arc::clone(&self.shown);
        // The map first: its table also serves the mesh beside it.
        if self.controls.map {
            self.build_map(scene, &prepared);
        }
        let Some(sc) = &self.swapchain else {
            return Ok(());
        };
        let aspect = mesh_aspect(sc.extent, self.controls.map);
        let render_pass = sc.render_pass();
        let state = &self.controls.state;
        let view = state.apply(scene);
        let options = PassOptions {
            fresnel: state.fresnel,
            shadowing: state.shadowing,
            texture_blending: state.texture,
        };
        let start = Instant::now();
        let built = self
            .renderer
            .scene_pass(&view, &prepared, options, render_pass, aspect);
        match built {
            Ok(mut pass) => {
                pass.set_view(&view.camera, &view.light, aspect, state.exposure);
                let s = pass.stats();
                println!(
                    "variant {}: pass built in {:.0} ms ({:.1} MB)",
                    s.name,
                    start.elapsed().as_secs_f64() * 1e3,
                    s.gpu_bytes as f64 / 1e6
                );
                // Frames in flight may still draw with the old pass.
                if let Some(old) = self.pass.replace(pass) {
                    self.frames.retire(old);
                }
            }
            Err(e) if self.pass.is_some() => {
                eprintln!("error: {e} (keeping the previous pipeline)");
            }
            Err(e) => return Err(e),
        }
        self.rebuild = false;
        Ok(())
    }

    /// Takes what the workers finished (an edited material, a variant build) and brings the
    /// passes up to date without blocking: when the prepared variant serves the view, the
    /// wanted material and the map, the passes that need it are rebuilt now (pipelines
    /// only); otherwise a background build starts (or goes on) and the old passes draw
    /// until it arrives.
    fn update_passes(&mut self, scene: &Scene) -> Result<()> {
        match self.loader.poll() {
            None => {}
            Some(Ok(material)) => {
                println!(
                    "material loaded: {} (peak-to-valley {:.4} µm, coherence length {:.2} µm)",
                    material.material.heightfield,
                    {
                        let (lo, hi) = material.heightfield.range();
                        hi - lo
                    },
                    material.material.coherence_um
                );
                self.material = Arc::new(material);
                self.waiting = false;
            }
            Some(Err(e)) => {
                eprintln!("error: {e} (keeping the material shown)");
                self.controls.material = self.loader.current();
            }
        }
        match self.renderer.poll_background() {
            Ok(None) => {}
            Ok(Some(arrived)) => {
                let frames = self.build.unwrap_or(0);
                println!(
                    "{} ready in {:.0} ms; {frames} frames presented meanwhile",
                    if arrived.coarse {
                        "coarse table"
                    } else {
                        "build"
                    },
                    arrived.ms
                );
                if !arrived.coarse {
                    self.build = None;
                }
                self.shown = arrived.material;
                self.rebuild = true;
                self.waiting = false;
            }
            Err(e) => {
                self.build = None;
                if self.pass.is_none() {
                    return Err(e);
                }
                self.keep_shown(&e);
            }
        }
        let material_changed = !Arc::ptr_eq(&self.shown, &self.material);
        let map_missing = self.controls.map && self.map_pass.is_none();
        let due = self.rebuild
            || self.view_changed
            || material_changed
            || map_missing
            || self.pass.is_none();
        if !due || (self.waiting && !self.view_changed) {
            return Ok(());
        }
        self.view_changed = false;
        let view = self.controls.state.apply(scene);
        let map_wi = self.controls.map.then(|| self.map_wi());
        let coarse_first = self.pass.is_none();
        let aspect = self
            .swapchain
            .as_ref()
            .map_or(1.0, |sc| mesh_aspect(sc.extent, self.controls.map));
        let readiness = match self.renderer.prepare_in_background(
            &view,
            aspect,
            &self.material,
            map_wi,
            coarse_first,
        ) {
            Ok(r) => r,
            Err(e) if self.pass.is_some() => {
                self.keep_shown(&e);
                return Ok(());
            }
            Err(e) => return Err(e),
        };
        match readiness {
            Readiness::Building => {
                self.waiting = true;
                if self.build.is_none() {
                    let coarse = self
                        .renderer
                        .background_progress()
                        .is_some_and(|p| p.coarse);
                    println!(
                        "building {} in the background{}",
                        self.controls.variant.name(),
                        if coarse {
                            " (a coarse table first)"
                        } else {
                            ""
                        }
                    );
                    self.build = Some(0);
                }
            }
            Readiness::Ready => {
                self.shown = Arc::clone(&self.material);
                if self.rebuild || material_changed || self.pass.is_none() {
                    self.rebuild_pass(scene)?;
                } else if map_missing {
                    let prepared = Arc::clone(&self.shown);
                    self.build_map(scene, &prepared);
                }
            }
        }
        Ok(())
    }

    /// A failed build or request: the passes and material shown stay, and nothing is asked
    /// again until something changes.
    fn keep_shown(&mut self, e: &Error) {
        eprintln!("error: {e} (keeping the previous pass)");
        self.material = Arc::clone(&self.shown);
        self.rebuild = false;
    }

    /// Polls the watched glsl directory (twice a second); a successful compile rebuilds the
    /// pass with the new SPIR-V, an error is printed and the current pipeline stays.
    fn poll_reload(&mut self) {
        if self.last_reload_check.elapsed() < Duration::from_millis(500) {
            return;
        }
        self.last_reload_check = Instant::now();
        let Some(reload) = &mut self.reload else {
            return;
        };
        match reload.changed() {
            Ok(false) => {}
            Ok(true) => match reload.compile_all() {
                Ok(spirv) => {
                    println!("shaders recompiled");
                    self.renderer.set_shader_overrides(spirv.clone());
                    self.rebuild = true;
                    self.waiting = false;
                }
                Err(msg) => {
                    eprintln!("{msg}\nshader reload failed: keeping the last good pipeline")
                }
            },
            Err(e) => eprintln!("shader reload: {e}"),
        }
    }

    /// Draws one frame. `Ok(true)` when `--frames` are done.
    fn frame(&mut self, scene: &Scene, settings: &Settings) -> Result<bool> {
        self.poll_reload();
        if self.needs_recreate && !self.recreate_swapchain(settings.vsync)? {
            // Minimised: nothing to draw; do not spin the event loop at full speed.
            std::thread::sleep(Duration::from_millis(16));
            return Ok(false);
        }
        if self.swapchain.is_none() && !self.recreate_swapchain(settings.vsync)? {
            return Ok(false);
        }
        self.update_passes(scene)?;
        let settled = !(self.renderer.building() || self.loader.loading());
        if self.pass.is_none() {
            // Nothing to draw before the first build arrives; the title says how far it is.
            self.update_title(false);
            std::thread::sleep(Duration::from_millis(5));
            return Ok(false);
        }
        let Some(sc) = &self.swapchain else {
            return Ok(false);
        };
        let (mesh_rect, map_rect) = layout(sc.extent, self.controls.map);
        let aspect = mesh_aspect(sc.extent, self.controls.map);
        let map_wi = self.controls.map.then(|| self.map_wi());
        let state = &self.controls.state;
        let view = state.apply(scene);
        let Some(pass) = &mut self.pass else {
            return Ok(false);
        };
        pass.set_view(&view.camera, &view.light, aspect, state.exposure);
        let pass = &*pass;
        let map = match (&mut self.map_pass, map_wi, map_rect) {
            (Some(m), Some(wi), Some(rect)) if self.controls.map => {
                m.set_map(wi.map(|c| c as f32), rect.extent.width, state.map_exposure);
                Some((&*m, rect))
            }
            _ => None,
        };
        let frame = self.frames.begin()?;
        if let Some(ms) = frame.previous_gpu_ms {
            self.stats.add_gpu(ms, &mut self.totals);
        }
        let sc = self.swapchain.as_ref().expect("checked above");
        let index = match sc.acquire(frame.image_acquired)? {
            Acquired::Image { index, suboptimal } => {
                // Drawn and presented all the same; the swapchain is replaced afterwards.
                self.needs_recreate |= suboptimal;
                index
            }
            Acquired::OutOfDate => {
                // The frame begun above is begun again next time.
                self.needs_recreate = true;
                return Ok(false);
            }
        };
        let last = settled && settings.frames.is_some_and(|n| self.frames_done + 1 >= n);
        let shot = if last {
            settings.screenshot.clone()
        } else {
            self.screenshot_next.take()
        };
        let readback = match &shot {
            Some(_) => Some(sc.readback_buffer()?),
            None => None,
        };
        let target = sc.target(index);
        match map {
            Some((map, map_rect)) => {
                ScenePass::record_views(frame.cb, &target, &[(pass, mesh_rect), (map, map_rect)])
            }
            None => pass.record(frame.cb, &target),
        }
        self.frames.end_timing();
        if let Some(buf) = &readback {
            sc.record_copy(frame.cb, index, buf);
        }
        self.frames.submit(
            &[(
                frame.image_acquired,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
            )],
            &[sc.render_done(index)],
        )?;
        match sc.present(index)? {
            Presented::Ok => {}
            Presented::Suboptimal | Presented::OutOfDate => self.needs_recreate = true,
        }
        if let (Some(path), Some(buf)) = (&shot, &readback) {
            // Waits for this frame only (its fence), not for the device.
            if let Some(ms) = self.frames.wait()? {
                self.stats.add_gpu(ms, &mut self.totals);
            }
            save_screenshot(sc, buf, path)?;
            println!("screenshot → {}", path.display());
        }
        // Only made for a screenshot, whose frame was waited for above.
        drop(readback);
        if self.presented == 0 {
            println!(
                "first frame presented {:.0} ms after start",
                self.opened.elapsed().as_secs_f64() * 1e3
            );
        }
        self.presented += 1;
        if settled {
            self.frames_done += 1;
        }
        if let Some(n) = &mut self.build {
            *n += 1;
        }
        match self.totals.0 {
            None => self.totals.0 = Some(Instant::now()),
            Some(_) => self.totals.1 += 1,
        }
        self.update_title(true);
        Ok(last)
    }

    /// One line: frames presented, frame time and GPU time over the run (the first frame,
    /// which includes the pipeline build, excluded from the frame time).
    fn print_totals(&self) {
        let (Some(start), frames, gpu_sum, gpu_n) = self.totals else {
            return;
        };
        let wall = start.elapsed().as_secs_f64() * 1e3;
        let frame_ms = if frames > 0 {
            format!("{:.2} ms/frame", wall / frames as f64)
        } else {
            "n/a".into()
        };
        let gpu = if gpu_n > 0 {
            format!("{:.2} ms", gpu_sum / gpu_n as f64)
        } else {
            "n/a".into()
        };
        let (w, h) = self
            .swapchain
            .as_ref()
            .map_or((0, 0), |s| (s.extent.width, s.extent.height));
        println!(
            "{}: {} frames presented ({w}×{h}, {:?}): {frame_ms}, GPU {gpu} per frame",
            self.renderer.device_name(),
            self.frames_done,
            self.swapchain
                .as_ref()
                .map_or(vk::PresentModeKHR::FIFO, |s| s.present_mode),
        );
        // Counted by the device: the frame path (rebuilds, resizes included) makes none.
        println!(
            "frame pacing: {} frames in flight, {} submitted, {} objects retired, {} device idle waits",
            self.frames.count(),
            self.frames.submitted(),
            self.frames.retired_total(),
            self.dev().idle_waits()
        );
    }

    /// The title, twice a second: the variant, GPU time and frame rate, and while a build
    /// runs how far it is. `presented`: this call follows a presented frame.
    fn update_title(&mut self, presented: bool) {
        if presented {
            self.stats.frames += 1;
        }
        let elapsed = self.stats.since.elapsed().as_secs_f64();
        if elapsed < 0.5 {
            return;
        }
        let fps = self.stats.frames as f64 / elapsed;
        let gpu = if self.stats.gpu_samples > 0 {
            format!(
                "{:.2} ms",
                self.stats.gpu_ms_sum / self.stats.gpu_samples as f64
            )
        } else {
            "n/a".into()
        };
        let name = self
            .pass
            .as_ref()
            .map_or(self.controls.variant.name().to_string(), |p| {
                p.stats().name.clone()
            });
        let building = match self.renderer.background_progress() {
            Some(p) => {
                let pct = p
                    .steps
                    .filter(|&(_, total)| total > 0)
                    .map_or(String::new(), |(done, total)| {
                        format!(" {:.0}%", 100.0 * done as f64 / total as f64)
                    });
                let coarse = if p.coarse { " (coarse)" } else { "" };
                format!(" — building {}{coarse}{pct}, {:.0} s", p.what, p.seconds)
            }
            None if self.loader.loading() => " — loading the material".to_string(),
            None => String::new(),
        };
        self.window.set_title(&format!(
            "diffract — {name}{building} — GPU {gpu} — {fps:.1} fps"
        ));
        self.stats = TitleStats {
            since: Instant::now(),
            frames: 0,
            gpu_ms_sum: 0.0,
            gpu_samples: 0,
        };
    }

    /// Acts on what an input changed.
    fn apply(&mut self, effect: Effect, event_loop: &ActiveEventLoop) {
        match effect {
            Effect::None => {}
            Effect::View => self.view_changed = true,
            Effect::Rebuild(what) => {
                println!("{what}");
                self.renderer.set_variant(self.controls.variant);
                self.rebuild = true;
                self.waiting = false;
            }
            Effect::Material(what) => {
                println!("{what}");
                if let Err(e) = self.loader.want(self.controls.material) {
                    eprintln!("error: {e}");
                    self.controls.material = self.loader.current();
                }
            }
            Effect::Map => {
                println!("BRDF map {}", if self.controls.map { "on" } else { "off" });
                self.waiting = false;
                if !self.controls.map {
                    // Frames in flight may still read the map's objects.
                    if let Some(old) = self.map_pass.take() {
                        self.frames.retire(old);
                    }
                }
                self.view_changed = true;
            }
            Effect::Help => println!("{HELP}"),
            Effect::Screenshot => {
                self.screenshots_taken += 1;
                self.screenshot_next = Some(PathBuf::from(format!(
                    "diffract-view-{}.png",
                    self.screenshots_taken
                )));
            }
            Effect::Quit => event_loop.exit(),
        }
    }

    /// Runs the `--at` actions due before the next frame: keys go through the same
    /// [`Controls`] as real ones.
    fn run_script(&mut self, event_loop: &ActiveEventLoop) {
        let now = self.frames_done;
        let due: Vec<ScriptAction> = self
            .script
            .iter()
            .filter(|(at, _)| *at == now)
            .map(|(_, a)| a.clone())
            .collect();
        self.script.retain(|(at, _)| *at != now);
        for action in due {
            match action {
                ScriptAction::Key(name) => {
                    let key = match name.as_str() {
                        "left" => Key::Named(NamedKey::ArrowLeft),
                        "right" => Key::Named(NamedKey::ArrowRight),
                        "up" => Key::Named(NamedKey::ArrowUp),
                        "down" => Key::Named(NamedKey::ArrowDown),
                        "esc" => Key::Named(NamedKey::Escape),
                        c => Key::Character(c.into()),
                    };
                    let effect = self.controls.key(&key);
                    self.apply(effect, event_loop);
                }
                ScriptAction::Resize(w, h) => {
                    println!("requesting a {w}×{h} window");
                    // X11 answers with a Resized event (None here); where the size applies
                    // at once, the recreation is due all the same.
                    let _ = self.window.request_inner_size(PhysicalSize::new(w, h));
                    self.needs_recreate = true;
                }
                ScriptAction::Minimise(frames) => {
                    self.fake_minimised = frames;
                    self.needs_recreate = true;
                }
            }
        }
    }

    /// The map's light `ωi`: the light in the tangent frame of the surface at the centre of
    /// the view ([`tangent_frame_at_view`]), as `render_brdf_map` computes it from
    /// `(θi, φi)`.
    fn map_wi(&self) -> [f64; 3] {
        let (theta, phi) = self.map_angles();
        crate::brdf::direction(theta, phi)
    }

    fn map_angles(&self) -> (f64, f64) {
        let state = &self.controls.state;
        let frame = tangent_frame_at_view(&self.mesh, &state.camera).unwrap_or([
            glam::Vec3::X,
            glam::Vec3::Y,
            glam::Vec3::Z,
        ]);
        state.map_light_angles(frame)
    }

    /// Builds the BRDF map's pass for the current light. A failure is printed: the previous
    /// map pass stays, or without one the map is switched off.
    fn build_map(&mut self, scene: &Scene, prepared: &PreparedMaterial) {
        let Some(sc) = &self.swapchain else {
            return;
        };
        let render_pass = sc.render_pass();
        let side = layout(sc.extent, true).1.map_or(1, |r| r.extent.width);
        let (theta, phi) = self.map_angles();
        let wi = crate::brdf::direction(theta, phi);
        let state = &self.controls.state;
        let view = state.apply(scene);
        let options = PassOptions {
            fresnel: state.fresnel,
            shadowing: state.shadowing,
            texture_blending: false,
        };
        let exposure = state.map_exposure;
        let start = Instant::now();
        let map = MapView {
            wi,
            size: side,
            exposure,
        };
        let built = self
            .renderer
            .brdf_map_pass(prepared, map, options, Some(&view), render_pass);
        match built {
            Ok(pass) => {
                println!(
                    "BRDF map: θi = {theta:.6}°, φi = {phi:.6}° ({}, built in {:.0} ms)",
                    pass.stats().name,
                    start.elapsed().as_secs_f64() * 1e3
                );
                if let Some(old) = self.map_pass.replace(pass) {
                    self.frames.retire(old);
                }
            }
            Err(e) if self.map_pass.is_some() => {
                eprintln!("error: BRDF map: {e} (keeping the previous map pipeline)");
            }
            Err(e) => {
                eprintln!("error: BRDF map: {e} (map off)");
                self.controls.map = false;
            }
        }
    }
}

/// Where the mesh and the BRDF map go in a target of `extent`: without the map the mesh
/// fills it; with it the map is the square of side `min(width/2, height)` at the top left
/// (the map shader reads `gl_FragCoord` from the target's origin) and the mesh the rest.
fn layout(extent: vk::Extent2D, map: bool) -> (vk::Rect2D, Option<vk::Rect2D>) {
    let whole = vk::Rect2D {
        offset: vk::Offset2D::default(),
        extent,
    };
    let side = (extent.width / 2).min(extent.height);
    if !map || side == 0 {
        return (whole, None);
    }
    let mesh = vk::Rect2D {
        offset: vk::Offset2D {
            x: side as i32,
            y: 0,
        },
        extent: vk::Extent2D {
            width: extent.width - side,
            height: extent.height,
        },
    };
    let map = vk::Rect2D {
        offset: vk::Offset2D::default(),
        extent: vk::Extent2D {
            width: side,
            height: side,
        },
    };
    (mesh, Some(map))
}

/// Width over height of the mesh's part of a target of `extent`.
fn mesh_aspect(extent: vk::Extent2D, map: bool) -> f32 {
    let mesh = layout(extent, map).0.extent;
    mesh.width as f32 / mesh.height.max(1) as f32
}

/// Writes the read-back swapchain texels (already sRGB-encoded) to a PNG.
fn save_screenshot(sc: &Swapchain, buf: &Buffer, path: &std::path::Path) -> Result<()> {
    let rgb = sc.texels_to_rgb8(buf.mapped()?);
    let bytes: Vec<u8> = rgb.into_iter().flatten().collect();
    image::save_buffer(
        path,
        &bytes,
        sc.extent.width,
        sc.extent.height,
        image::ExtendedColorType::Rgb8,
    )
    .map_err(|e| Error::Image {
        path: path.to_path_buf(),
        msg: e.to_string(),
    })
}

impl Drop for Viewer {
    fn drop(&mut self) {
        // Teardown, not the frame path: the swapchain's present operations have no fence,
        // so one idle wait covers them before the fields (frames with their release lists,
        // passes, swapchain, surface) are destroyed.
        let _ = self.dev().wait_idle();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn extent(width: u32, height: u32) -> vk::Extent2D {
        vk::Extent2D { width, height }
    }

    #[test]
    fn map_takes_the_left_square_and_the_mesh_the_rest() {
        let (mesh, map) = layout(extent(128, 64), true);
        let map = map.expect("a map");
        assert_eq!((map.offset.x, map.offset.y), (0, 0));
        assert_eq!(map.extent, extent(64, 64));
        assert_eq!((mesh.offset.x, mesh.offset.y), (64, 0));
        assert_eq!(mesh.extent, extent(64, 64));
        // Tall window: the map's side is half the width, top-aligned.
        let (mesh, map) = layout(extent(100, 300), true);
        assert_eq!(map.expect("a map").extent, extent(50, 50));
        assert_eq!(mesh.extent, extent(50, 300));
        // Map off, or no room for it: the mesh fills the target.
        for (e, on) in [(extent(128, 64), false), (extent(1, 64), true)] {
            let (mesh, map) = layout(e, on);
            assert!(map.is_none());
            assert_eq!(mesh.extent, e);
        }
    }
}
