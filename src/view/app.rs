//! The winit application: window, Vulkan objects of presentation, frame pacing (two frames
//! in flight, each with its command buffer, fence, acquire semaphore and timestamp pair),
//! input handling, the title's statistics, screenshots and hot reload.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ash::vk;
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key, ModifiersState, NamedKey};
use winit::raw_window_handle::{HasDisplayHandle, HasWindowHandle};
use winit::window::{Window, WindowId};

use super::input::{ViewState, HELP};
use super::reload::ShaderReload;
use crate::gpu::memory::Buffer;
use crate::gpu::swapchain::{Surface, Swapchain, Vsync};
use crate::gpu::timer::GpuTimer;
use crate::gpu::{Device, Instance, StorageFormat};
use crate::material::PreparedMaterial;
use crate::render::{PassOptions, Renderer, ScenePass, TableOptions, VariantKind};
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
    let prepared = scene.material.prepare(settings.cache_dir.as_deref())?;
    let mut app = App {
        scene,
        prepared,
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
    prepared: PreparedMaterial,
    settings: Settings,
    viewer: Option<Viewer>,
    error: Option<Error>,
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.viewer.is_some() {
            return;
        }
        match Viewer::new(event_loop, &self.scene, &self.settings, &self.prepared) {
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
            WindowEvent::Resized(_) => {
                v.needs_recreate = true;
                Ok(())
            }
            WindowEvent::RedrawRequested => v
                .frame(&self.scene, &self.prepared, &self.settings)
                .map(|done| {
                    if done {
                        event_loop.exit();
                    }
                }),
            WindowEvent::ModifiersChanged(m) => {
                v.modifiers = m.state();
                Ok(())
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                v.key(&event.logical_key, event_loop)
            }
            WindowEvent::MouseInput { state, button, .. } => {
                let down = state == ElementState::Pressed;
                match button {
                    MouseButton::Left => v.buttons[0] = down,
                    MouseButton::Right => v.buttons[1] = down,
                    MouseButton::Middle => v.buttons[2] = down,
                    _ => {}
                }
                Ok(())
            }
            WindowEvent::CursorMoved { position, .. } => {
                let p = (position.x as f32, position.y as f32);
                if let Some(last) = v.cursor {
                    v.drag(p.0 - last.0, p.1 - last.1);
                }
                v.cursor = Some(p);
                Ok(())
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let steps = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                v.state.zoom(0.9f32.powf(steps));
                v.view_changed = true;
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

/// One frame in flight.
struct FrameSlot {
    cb: vk::CommandBuffer,
    /// Signalled when the frame's submission completed (created signalled).
    fence: vk::Fence,
    acquired: vk::Semaphore,
    timer: Option<GpuTimer>,
    /// Whether the timer holds a submitted frame's timestamps.
    timed: bool,
}

/// Everything that lives while the window is open. Field order is drop order: the pass and
/// the swapchain before the renderer's device, the surface before the window.
struct Viewer {
    slots: Vec<FrameSlot>,
    pool: vk::CommandPool,
    pass: Option<ScenePass>,
    swapchain: Option<Swapchain>,
    renderer: Renderer,
    surface: Surface,
    reload: Option<ShaderReload>,
    state: ViewState,
    variant: VariantKind,
    current: usize,
    frames_done: u32,
    needs_recreate: bool,
    view_changed: bool,
    rebuild: bool,
    screenshot_next: Option<PathBuf>,
    screenshots_taken: u32,
    buttons: [bool; 3],
    modifiers: ModifiersState,
    cursor: Option<(f32, f32)>,
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

impl Viewer {
    fn new(
        event_loop: &ActiveEventLoop,
        scene: &Scene,
        settings: &Settings,
        prepared: &PreparedMaterial,
    ) -> Result<Self> {
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

        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(dev.queue_family())
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: live device, valid family index.
        let pool = unsafe { dev.raw().create_command_pool(&pool_info, None) }
            .map_err(Error::vk("vkCreateCommandPool"))?;
        dev.set_name(pool, "viewer command pool");
        let mut viewer = Viewer {
            slots: Vec::new(),
            pool,
            pass: None,
            swapchain: None,
            renderer,
            surface,
            reload: None,
            state: ViewState::from_scene(scene),
            variant: settings.variant,
            current: 0,
            frames_done: 0,
            needs_recreate: false,
            view_changed: false,
            rebuild: true,
            screenshot_next: None,
            screenshots_taken: 0,
            buttons: [false; 3],
            modifiers: ModifiersState::empty(),
            cursor: None,
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
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(FRAMES_IN_FLIGHT as u32);
        // SAFETY: the pool belongs to this device and is used only by this thread.
        let cbs = unsafe { dev.raw().allocate_command_buffers(&alloc) }
            .map_err(Error::vk("vkAllocateCommandBuffers"))?;
        for (i, cb) in cbs.into_iter().enumerate() {
            dev.set_name(cb, &format!("frame {i}"));
            let fence_info = vk::FenceCreateInfo::default().flags(vk::FenceCreateFlags::SIGNALED);
            // SAFETY: live device.
            let fence = unsafe { dev.raw().create_fence(&fence_info, None) }
                .map_err(Error::vk("vkCreateFence"))?;
            dev.set_name(fence, &format!("frame {i} done"));
            // SAFETY: live device.
            let acquired = unsafe {
                dev.raw()
                    .create_semaphore(&vk::SemaphoreCreateInfo::default(), None)
            };
            let acquired = match acquired {
                Ok(s) => s,
                Err(e) => {
                    // SAFETY: the fence was never submitted.
                    unsafe { dev.raw().destroy_fence(fence, None) };
                    return Err(Error::vk("vkCreateSemaphore")(e));
                }
            };
            dev.set_name(acquired, &format!("frame {i} image acquired"));
            let timer = GpuTimer::new(&dev, &format!("frame {i} timestamps"));
            viewer.slots.push(FrameSlot {
                cb,
                fence,
                acquired,
                timer: None,
                timed: false,
            });
            viewer.slots[i].timer = timer?;
        }
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
        viewer.rebuild_pass(scene, prepared)?;
        Ok(viewer)
    }

    fn dev(&self) -> &Arc<Device> {
        self.renderer.device()
    }

    fn wait_idle(&self) {
        let _q = self.dev().queue_lock();
        // SAFETY: live device; the queue is externally synchronised by the lock. A failure
        // (device lost) surfaces at the next submission.
        let _ = unsafe { self.dev().raw().device_wait_idle() };
    }

    /// (Re)creates the swapchain for the window's size. `Ok(false)`: minimised, skip frames.
    fn recreate_swapchain(&mut self, vsync: Vsync) -> Result<bool> {
        self.wait_idle();
        let size = self.window.inner_size();
        let want = vk::Extent2D {
            width: size.width,
            height: size.height,
        };
        if want.width == 0 || want.height == 0 {
            return Ok(false);
        }
        let ok = match &mut self.swapchain {
            Some(sc) => {
                let format = sc.format;
                let ok = sc.recreate(&self.surface, want, vsync)?;
                if sc.format != format {
                    self.rebuild = true;
                }
                ok
            }
            None => match Swapchain::new(self.dev(), &self.surface, want, vsync)? {
                Some(sc) => {
                    self.swapchain = Some(sc);
                    self.rebuild = true;
                    true
                }
                None => false,
            },
        };
        if ok {
            self.needs_recreate = false;
            self.view_changed = true;
        }
        Ok(ok)
    }

    /// Rebuilds the pass (variant, switches, shaders or a table that no longer covers the
    /// view). The old pass is kept when the new one fails (e.g. a reloaded shader that does
    /// not link).
    fn rebuild_pass(&mut self, scene: &Scene, prepared: &PreparedMaterial) -> Result<()> {
        let Some(sc) = &self.swapchain else {
            return Ok(());
        };
        let aspect = sc.extent.width as f32 / sc.extent.height as f32;
        let render_pass = sc.render_pass;
        let view = self.state.apply(scene);
        let options = PassOptions {
            fresnel: self.state.fresnel,
            shadowing: self.state.shadowing,
            texture_blending: self.state.texture,
        };
        self.wait_idle();
        let start = Instant::now();
        let built = self
            .renderer
            .scene_pass(&view, prepared, options, render_pass, aspect);
        match built {
            Ok(mut pass) => {
                pass.set_view(
                    &view.camera,
                    view.light.direction,
                    aspect,
                    self.state.exposure,
                );
                let s = pass.stats();
                println!(
                    "variant {}: pass built in {:.0} ms (table build {:.0} ms, {:.1} MB)",
                    s.name,
                    start.elapsed().as_secs_f64() * 1e3,
                    s.build_ms,
                    s.gpu_bytes as f64 / 1e6
                );
                self.pass = Some(pass);
            }
            Err(e) if self.pass.is_some() => {
                eprintln!("error: {e} (keeping the previous pipeline)");
            }
            Err(e) => return Err(e),
        }
        self.rebuild = false;
        self.view_changed = false;
        Ok(())
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
                }
                Err(msg) => {
                    eprintln!("{msg}\nshader reload failed: keeping the last good pipeline")
                }
            },
            Err(e) => eprintln!("shader reload: {e}"),
        }
    }

    /// Draws one frame. `Ok(true)` when `--frames` are done.
    fn frame(
        &mut self,
        scene: &Scene,
        prepared: &PreparedMaterial,
        settings: &Settings,
    ) -> Result<bool> {
        self.poll_reload();
        if self.needs_recreate && !self.recreate_swapchain(settings.vsync)? {
            // Minimised: nothing to draw; do not spin the event loop at full speed.
            std::thread::sleep(Duration::from_millis(16));
            return Ok(false);
        }
        if self.swapchain.is_none() && !self.recreate_swapchain(settings.vsync)? {
            return Ok(false);
        }
        let Some(sc) = &self.swapchain else {
            return Ok(false);
        };
        let aspect = sc.extent.width as f32 / sc.extent.height as f32;
        if self.view_changed && !self.rebuild && self.renderer.variant() != VariantKind::Flss {
            // Table variants: rebuild only when the view left the table's region.
            if !self.renderer.covers_view(&self.state.apply(scene))? {
                self.rebuild = true;
            }
        }
        if self.rebuild || self.pass.is_none() {
            self.rebuild_pass(scene, prepared)?;
        }
        let view = self.state.apply(scene);
        let Some(pass) = &mut self.pass else {
            return Ok(false);
        };
        pass.set_view(
            &view.camera,
            view.light.direction,
            aspect,
            self.state.exposure,
        );
        self.view_changed = false;

        let dev = self.renderer.device().clone();
        let raw = dev.raw();
        let slot = &mut self.slots[self.current];
        // SAFETY: the fence belongs to this device.
        unsafe { raw.wait_for_fences(&[slot.fence], true, u64::MAX) }
            .map_err(Error::vk("vkWaitForFences"))?;
        if slot.timed {
            if let Some(t) = &slot.timer {
                let ms = t.elapsed_ms()?;
                self.stats.gpu_ms_sum += ms;
                self.stats.gpu_samples += 1;
                self.totals.2 += ms;
                self.totals.3 += 1;
            }
        }
        let sc = self.swapchain.as_ref().expect("checked above");
        let index = match sc.acquire(slot.acquired) {
            Ok((i, _suboptimal)) => i,
            Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => {
                self.needs_recreate = true;
                return Ok(false);
            }
            Err(e) => return Err(Error::vk("vkAcquireNextImageKHR")(e)),
        };
        // SAFETY: the fence is signalled (waited above) and not in use by a pending submit.
        unsafe { raw.reset_fences(&[slot.fence]) }.map_err(Error::vk("vkResetFences"))?;
        let last = settings.frames.is_some_and(|n| self.frames_done + 1 >= n);
        let shot = if last {
            settings.screenshot.clone()
        } else {
            self.screenshot_next.take()
        };
        let readback = match &shot {
            Some(_) => Some(sc.readback_buffer()?),
            None => None,
        };
        // SAFETY: the previous submission of cb completed (its fence was waited on); the
        // pool was created with RESET_COMMAND_BUFFER.
        unsafe {
            raw.reset_command_buffer(slot.cb, vk::CommandBufferResetFlags::empty())
                .map_err(Error::vk("vkResetCommandBuffer"))?;
            raw.begin_command_buffer(
                slot.cb,
                &vk::CommandBufferBeginInfo::default()
                    .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
            )
            .map_err(Error::vk("vkBeginCommandBuffer"))?;
        }
        if let Some(t) = &slot.timer {
            t.record_start(slot.cb);
        }
        let pass = self.pass.as_ref().expect("built above");
        pass.record(slot.cb, &sc.frame_target(index));
        if let Some(t) = &slot.timer {
            t.record_end(slot.cb);
        }
        if let Some(buf) = &readback {
            sc.record_copy(slot.cb, index, buf);
        }
        // SAFETY: cb is recording.
        unsafe { raw.end_command_buffer(slot.cb) }.map_err(Error::vk("vkEndCommandBuffer"))?;
        let waits = [slot.acquired];
        let stages = [vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT];
        let cbs = [slot.cb];
        let signals = [sc.render_done[index as usize]];
        let submit = [vk::SubmitInfo::default()
            .wait_semaphores(&waits)
            .wait_dst_stage_mask(&stages)
            .command_buffers(&cbs)
            .signal_semaphores(&signals)];
        {
            let _q = dev.queue_lock();
            // SAFETY: cb is executable; the acquire semaphore has a pending signal from
            // vkAcquireNextImageKHR; the fence is unsignalled; the queue is locked.
            unsafe { raw.queue_submit(dev.queue(), &submit, slot.fence) }
                .map_err(Error::vk("vkQueueSubmit"))?;
        }
        slot.timed = true;
        match sc.present(index) {
            Ok(false) => {}
            Ok(true) | Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => self.needs_recreate = true,
            Err(e) => return Err(Error::vk("vkQueuePresentKHR")(e)),
        }
        if let (Some(path), Some(buf)) = (&shot, &readback) {
            // SAFETY: the fence belongs to this device; the submission above signals it.
            unsafe { raw.wait_for_fences(&[slot.fence], true, u64::MAX) }
                .map_err(Error::vk("vkWaitForFences"))?;
            save_screenshot(sc, buf, path)?;
            println!("screenshot → {}", path.display());
        }
        drop(readback);
        self.current = (self.current + 1) % FRAMES_IN_FLIGHT;
        self.frames_done += 1;
        match self.totals.0 {
            None => self.totals.0 = Some(Instant::now()),
            Some(_) => self.totals.1 += 1,
        }
        self.update_title();
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
    }

    fn update_title(&mut self) {
        self.stats.frames += 1;
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
            .map_or(self.variant.name().to_string(), |p| p.stats().name.clone());
        self.window
            .set_title(&format!("diffract — {name} — GPU {gpu} — {fps:.1} fps"));
        self.stats = TitleStats {
            since: Instant::now(),
            frames: 0,
            gpu_ms_sum: 0.0,
            gpu_samples: 0,
        };
    }

    /// A mouse move of `(dx, dy)` pixels with the current buttons.
    fn drag(&mut self, dx: f32, dy: f32) {
        let k = 0.01;
        let pan = self.buttons[2] || (self.buttons[0] && self.modifiers.shift_key());
        if pan {
            self.state.pan(dx * 0.002, dy * 0.002);
        } else if self.buttons[0] {
            self.state.orbit(dx * k, dy * k);
        } else if self.buttons[1] {
            self.state.turn_light(dx * k, dy * k);
        } else {
            return;
        }
        self.view_changed = true;
    }

    fn key(&mut self, key: &Key, event_loop: &ActiveEventLoop) -> Result<()> {
        let step = 3f32.to_radians();
        match key {
            Key::Named(NamedKey::Escape) => event_loop.exit(),
            Key::Named(NamedKey::ArrowLeft) => self.state.turn_light(-step, 0.0),
            Key::Named(NamedKey::ArrowRight) => self.state.turn_light(step, 0.0),
            Key::Named(NamedKey::ArrowUp) => self.state.turn_light(0.0, -step),
            Key::Named(NamedKey::ArrowDown) => self.state.turn_light(0.0, step),
            Key::Character(c) => match c.to_lowercase().as_str() {
                "q" => event_loop.exit(),
                "+" | "=" => self.state.exposure *= 1.25,
                "-" => self.state.exposure /= 1.25,
                "h" => println!("{HELP}"),
                "v" => {
                    let per_vertex = self.renderer.per_vertex();
                    let all: Vec<VariantKind> = VariantKind::ALL
                        .into_iter()
                        .filter(|k| {
                            !per_vertex || crate::render::variant::per_vertex_file(*k).is_some()
                        })
                        .collect();
                    let i = all.iter().position(|k| *k == self.variant).unwrap_or(0);
                    self.variant = all[(i + 1) % all.len()];
                    self.renderer.set_variant(self.variant);
                    println!("variant → {}", self.variant.name());
                    self.rebuild = true;
                }
                "f" => {
                    self.state.fresnel = !self.state.fresnel;
                    println!("Fresnel {}", on_off(self.state.fresnel));
                    self.rebuild = true;
                }
                "s" => {
                    self.state.shadowing = !self.state.shadowing;
                    println!("shadowing {}", on_off(self.state.shadowing));
                    self.rebuild = true;
                }
                "t" => {
                    self.state.texture = !self.state.texture;
                    println!("texture blending {}", on_off(self.state.texture));
                    self.rebuild = true;
                }
                "p" => {
                    self.screenshots_taken += 1;
                    self.screenshot_next = Some(PathBuf::from(format!(
                        "diffract-view-{}.png",
                        self.screenshots_taken
                    )));
                }
                _ => return Ok(()),
            },
            _ => return Ok(()),
        }
        self.view_changed = true;
        Ok(())
    }
}

fn on_off(b: bool) -> &'static str {
    if b {
        "on"
    } else {
        "off"
    }
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
        self.wait_idle();
        let raw = self.renderer.device().raw();
        // SAFETY: the device is idle, so no submission uses the slots' objects; the command
        // buffers are freed with their pool.
        unsafe {
            for s in &self.slots {
                raw.destroy_fence(s.fence, None);
                raw.destroy_semaphore(s.acquired, None);
            }
            raw.destroy_command_pool(self.pool, None);
        }
        // Timers, pass and swapchain drop next (fields), then the device, the surface and
        // the window.
        for s in &mut self.slots {
            s.timer = None;
        }
    }
}
