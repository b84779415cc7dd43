//! The winit application: the window, its events and the swapchain. Each redraw acquires
//! a swapchain image, hands it to [`Draw`], which records the passes into it and submits,
//! and presents it. Replaced swapchains are retired through the frame layer's deferred
//! release: the frame path never waits for the device to be idle. Tables, DFT terms and
//! edited materials are built on worker threads
//! ([`Renderer::prepare_in_background`](crate::render::Renderer::prepare_in_background),
//! [`MaterialLoader`]): the window keeps drawing what it has (at start, a coarse table) and
//! the title shows the build's progress. Also the title, hot reload and the hidden `--at`
//! test hook. What an input means is [`super::input`]'s; what a frame draws,
//! [`super::draw`]'s.

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

use super::draw::Draw;
use super::input::{Controls, Effect, ViewState, HELP};
use super::material::MaterialLoader;
use super::reload::ShaderReload;
use super::ScriptAction;
use crate::brdf::truncation::{Precision, Reach};
use crate::gpu::swapchain::{Acquired, Presented, Recreated, Surface, Swapchain, Vsync};
use crate::gpu::{Device, Instance, StorageFormat};
use crate::material::PreparedMaterial;
use crate::render::{Renderer, TableOptions, VariantKind};
use crate::scene::Scene;
use crate::{Error, Result};

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
    /// The environments and how they light the scene.
    pub env: Option<(super::env::EnvSettings, Option<crate::light::env::EnvMap>)>,
    /// When the command started (the first frame's delay is measured from it).
    pub started: Instant,
}

/// Opens the display, prepares the material, runs the event loop.
pub(super) fn run(scene: Scene, mut settings: Settings) -> Result<()> {
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
    let env = settings.env.take();
    let mut app = App {
        scene,
        start: Some((Arc::new(prepared), loader, env)),
        settings,
        viewer: None,
        error: None,
    };
    event_loop
        .run_app(&mut app)
        .map_err(|e| Error::NoPresentation(format!("event loop: {e}")))?;
    let canary = app.viewer.as_ref().map(|v| v.draw.renderer().canary());
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

type EnvStart = (super::env::EnvSettings, Option<crate::light::env::EnvMap>);

struct App {
    scene: Scene,
    /// The material, its loader and the environments, until the viewer takes them.
    start: Option<(Arc<PreparedMaterial>, MaterialLoader, Option<EnvStart>)>,
    settings: Settings,
    viewer: Option<Viewer>,
    error: Option<Error>,
}

/// The time between frames while a table builds and the view is still
/// ([`Viewer::next_frame_at`]).
const BUILDING_FRAME_INTERVAL: Duration = Duration::from_millis(1000);

/// How often a still view looks whether its build has sent what the next frame installs.
const BUILD_WATCH_INTERVAL: Duration = Duration::from_millis(20);

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        let Some((prepared, loader, env)) = self.start.take() else {
            return;
        };
        let Some((env_settings, first_map)) = env else {
            self.error = Some(Error::invalid("view", "no environment settings"));
            event_loop.exit();
            return;
        };
        let env = super::env::EnvView::new(env_settings, first_map);
        match Viewer::new(
            event_loop,
            &self.scene,
            &self.settings,
            prepared,
            loader,
            env,
        ) {
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
        if !matches!(event, WindowEvent::RedrawRequested) {
            v.touched = true;
        }
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
            WindowEvent::KeyboardInput { event, .. } => {
                v.controls.key_released(&event.logical_key);
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

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        let Some(v) = &self.viewer else { return };
        match v.next_frame_at() {
            Some(at) if Instant::now() < at => {
                // Awake often enough to see a build's arrival (a flag, no drawing).
                let soon = Instant::now() + BUILD_WATCH_INTERVAL;
                event_loop.set_control_flow(ControlFlow::WaitUntil(at.min(soon)));
            }
            _ => {
                event_loop.set_control_flow(ControlFlow::Poll);
                v.window.request_redraw();
            }
        }
    }
}

/// Everything that lives while the window is open. Field order is drop order: what is drawn
/// (the frames with the passes and swapchains retired into them, the passes, the renderer)
/// and the swapchain before the surface, the surface before the window.
struct Viewer {
    draw: Draw,
    swapchain: Option<Swapchain>,
    surface: Surface,
    reload: Option<ShaderReload>,
    controls: Controls,
    /// Loads edited materials on a worker thread.
    loader: MaterialLoader,
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
    /// When the last frame was presented, and whether an input event came since.
    last_presented: Instant,
    touched: bool,
    needs_recreate: bool,
    last_reload_check: Instant,
    window: Arc<Window>,
}

impl Viewer {
    fn new(
        event_loop: &ActiveEventLoop,
        scene: &Scene,
        settings: &Settings,
        prepared: Arc<PreparedMaterial>,
        loader: MaterialLoader,
        env: super::env::EnvView,
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
        let mut renderer = Renderer::on(dev)?;
        renderer.set_variant(settings.variant);
        renderer.set_per_vertex(settings.per_vertex);
        renderer.set_storage_format(settings.storage);
        renderer.set_table_options(settings.table);
        renderer.set_cache_dir(settings.cache_dir.clone());
        renderer.set_region_margin(REGION_MARGIN);
        renderer.set_leave_out(true);
        let mut controls = Controls::new(ViewState::from_scene(scene), settings.variant);
        controls.per_vertex = settings.per_vertex;
        controls.map = settings.map;
        controls.state.map_exposure = settings.map_exposure;
        let mut viewer = Viewer {
            draw: Draw::new(renderer, mesh, prepared, env)?,
            swapchain: None,
            surface,
            reload: None,
            controls,
            loader,
            script: settings.script.clone(),
            fake_minimised: 0,
            minimised: false,
            frames_done: 0,
            presented: 0,
            opened: settings.started,
            last_presented: Instant::now(),
            touched: false,
            needs_recreate: false,
            last_reload_check: Instant::now(),
            window,
        };
        if let Some(dir) = &settings.watch {
            let mut reload = ShaderReload::new(dir)?;
            // The watched sources may differ from the built-in SPIR-V: start from them.
            match reload.compile_all() {
                Ok(spirv) => viewer.draw.set_shader_overrides(spirv.clone()),
                Err(msg) => eprintln!("{msg}\nshader reload: keeping the built-in shaders"),
            }
            println!("watching {} for shader edits", dir.display());
            viewer.reload = Some(reload);
        }
        viewer.recreate_swapchain(settings.vsync)?;
        // The first frame starts the variant's build (a coarse table first).
        Ok(viewer)
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
                        self.draw.request_rebuild();
                    }
                    self.draw.retire_after_present(old);
                    true
                }
            },
            None => match Swapchain::new(self.draw.dev(), &self.surface, want, vsync)? {
                Some(sc) => {
                    self.swapchain = Some(sc);
                    self.draw.request_rebuild();
                    true
                }
                None => false,
            },
        };
        if ok {
            self.needs_recreate = false;
            self.draw.view_changed();
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

    /// A swapchain to draw into, recreated when due. `Ok(false)`: none (minimised).
    fn ensure_swapchain(&mut self, vsync: Vsync) -> Result<bool> {
        if self.needs_recreate && !self.recreate_swapchain(vsync)? {
            // Minimised: nothing to draw; do not spin the event loop at full speed.
            std::thread::sleep(Duration::from_millis(16));
            return Ok(false);
        }
        if self.swapchain.is_none() && !self.recreate_swapchain(vsync)? {
            return Ok(false);
        }
        Ok(true)
    }

    /// Hands an edited material that finished loading to the passes; a failed load takes
    /// the controls back to the material shown.
    fn take_loaded_material(&mut self) {
        match self.loader.poll() {
            None => {}
            Some(Ok(material)) => {
                let (lo, hi) = material.heightfield.range();
                println!(
                    "material loaded: {} (peak-to-valley {:.4} µm, coherence length {:.2} µm)",
                    material.material.heightfield,
                    hi - lo,
                    material.material.coherence_um
                );
                self.draw.want_material(material);
            }
            Some(Err(e)) => {
                eprintln!("error: {e} (keeping the material shown)");
                self.controls.material = self.loader.current();
            }
        }
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
                    self.draw.set_shader_overrides(spirv.clone());
                }
                Err(msg) => {
                    eprintln!("{msg}\nshader reload failed: keeping the last good pipeline")
                }
            },
            Err(e) => eprintln!("shader reload: {e}"),
        }
    }

    /// Draws one frame: the passes brought up to date, an image acquired, drawn into and
    /// presented. `Ok(true)` when `--frames` are done.
    fn frame(&mut self, scene: &Scene, settings: &Settings) -> Result<bool> {
        self.poll_reload();
        if !self.ensure_swapchain(settings.vsync)? {
            return Ok(false);
        }
        self.take_loaded_material();
        self.draw
            .update_passes(scene, &mut self.controls, self.swapchain.as_ref())?;
        if let Some(sc) = &self.swapchain {
            self.draw.update_env(scene, &self.controls, sc);
        }
        let settled = !(self.draw.settling() || self.loader.loading());
        if !self.draw.has_pass() {
            // Nothing to draw before the first build arrives; the title says how far it is.
            self.update_title(false);
            std::thread::sleep(Duration::from_millis(5));
            return Ok(false);
        }
        let Some(sc) = &self.swapchain else {
            return Ok(false);
        };
        let views = self.draw.set_views(scene, &self.controls, sc.extent);
        let frame = self.draw.begin()?;
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
        let shot = self.draw.screenshot_due(last, settings.screenshot.as_ref());
        let shot = self
            .draw
            .record_and_submit(&frame, sc, index, &views, shot)?;
        match sc.present(index)? {
            Presented::Ok => {}
            Presented::Suboptimal | Presented::OutOfDate => self.needs_recreate = true,
        }
        if let Some(shot) = shot {
            self.draw.save_screenshot(sc, shot)?;
        }
        self.count_presented(settled);
        self.update_title(true);
        Ok(last)
    }

    /// When the next frame is due; `None`: at once. While a table builds and the view is
    /// still (no input since the last frame, no environment-lit picture accumulating, the
    /// build not waiting for a frame with its coarse stand-in), a frame would show the same
    /// picture with a new percentage in the title: frames then come
    /// [`BUILDING_FRAME_INTERVAL`] apart, and a CPU device gives the build its cores. Any
    /// input draws at once.
    fn next_frame_at(&self) -> Option<Instant> {
        let still = self.draw.building()
            && !self.draw.build_waits_for_a_frame()
            && !self.draw.env_drawing()
            && !self.touched
            && self.presented > 0;
        still.then(|| self.last_presented + BUILDING_FRAME_INTERVAL)
    }

    /// A frame was presented (`settled`: while nothing was building or loading).
    fn count_presented(&mut self, settled: bool) {
        self.last_presented = Instant::now();
        self.touched = false;
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
        self.draw.presented();
    }

    /// One line on the frames over the run and one on frame pacing.
    fn print_totals(&self) {
        self.draw
            .print_totals(self.frames_done, self.swapchain.as_ref());
    }

    /// The title, twice a second: the variant, GPU time and frame rate, and while a build
    /// runs how far it is. `presented`: this call follows a presented frame.
    fn update_title(&mut self, presented: bool) {
        let loading = self.loader.loading();
        if let Some(title) = self.draw.title(presented, self.controls.variant, loading) {
            self.window.set_title(&title);
        }
    }

    /// Acts on what an input changed.
    fn apply(&mut self, effect: Effect, event_loop: &ActiveEventLoop) {
        match effect {
            Effect::None => {}
            Effect::View => self.draw.view_changed(),
            Effect::Rebuild(what) => {
                println!("{what}");
                self.draw.set_variant(self.controls.variant);
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
                self.draw.map_toggled(self.controls.map);
            }
            Effect::Env => println!("{}", self.draw.next_env()),
            Effect::Help => println!("{HELP}"),
            Effect::Screenshot => self.draw.request_screenshot(),
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
}

impl Drop for Viewer {
    fn drop(&mut self) {
        // Teardown, not the frame path: the swapchain's present operations have no fence,
        // so one idle wait covers them before the fields (frames with their release lists,
        // passes, swapchain, surface) are destroyed.
        let _ = self.draw.dev().wait_idle();
    }
}
