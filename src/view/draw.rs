//! What the window draws: the passes (the mesh's and the BRDF map's beside it), kept up to
//! date with the background builds without blocking; the recording of a frame into an
//! acquired swapchain image and its submission; screenshots; and the GPU timing, for the
//! title and the run's totals. The window ([`super::app`]) owns the swapchain: it handles
//! the events, acquires an image, hands it to [`Draw`] and presents it.
//!
//! A picture that builds up over frames while nothing changes (an image accumulated frame
//! by frame) keeps its state here: [`Accumulation`] counts the frames drawn since the
//! picture last changed, and every change of view, pass or material resets it.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use ash::vk;

use super::env::EnvView;
use super::input::{tangent_frame_at_view, Controls};
use crate::gpu::frames::{FrameStart, Frames};
use crate::gpu::memory::Buffer;
use crate::gpu::swapchain::Swapchain;
use crate::gpu::Device;
use crate::material::PreparedMaterial;
use crate::mesh::Mesh;
use crate::render::{MapView, PassOptions, Readiness, Renderer, ScenePass, VariantKind};
use crate::scene::Scene;
use crate::{Error, Result};

/// Frames recorded while the GPU works on earlier ones.
const FRAMES_IN_FLIGHT: usize = 2;

/// The passes, the renderer that builds them and what a frame records. Field order is drop
/// order: the frames (with the passes retired into them) before the passes and the
/// environment's objects, those before the renderer.
pub(super) struct Draw {
    frames: Frames,
    pass: Option<ScenePass>,
    /// The BRDF map beside the mesh (while `controls.map`).
    map_pass: Option<ScenePass>,
    /// The environment-lit picture, drawn instead of the passes while an environment is on.
    env: EnvView,
    renderer: Renderer,
    /// The scene's mesh in world space: the map's tangent frame is read from it.
    mesh: Mesh,
    /// The material the controls ask for (the newest edit loaded).
    material: Arc<PreparedMaterial>,
    /// The material of the prepared variant the passes draw: `material` once its build
    /// has arrived.
    shown: Arc<PreparedMaterial>,
    /// While a build runs: the frames presented since it started.
    build: Option<u32>,
    /// The last request was answered `Building` and nothing changed since: the next frames
    /// do not ask again.
    waiting: bool,
    /// The passes are rebuilt at the next update (variant, switches, shaders, format).
    rebuild: bool,
    view_changed: bool,
    screenshots: Screenshots,
    timing: Timing,
    accumulation: Accumulation,
}

/// Where the passes draw in the target this frame.
pub(super) struct Views {
    mesh: vk::Rect2D,
    /// The BRDF map's square, when the map is drawn.
    map: Option<vk::Rect2D>,
}

/// A frame whose image is read back into a PNG once it is done.
pub(super) struct Shot {
    path: PathBuf,
    readback: Buffer,
}

/// Screenshots asked for with `P`: the next frame's image goes to
/// `diffract-view-{n}.png`.
#[derive(Default)]
struct Screenshots {
    next: Option<PathBuf>,
    taken: u32,
}

impl Screenshots {
    fn request(&mut self) {
        self.taken += 1;
        self.next = Some(PathBuf::from(format!("diffract-view-{}.png", self.taken)));
    }

    /// Where this frame's image goes: on the last frame of `--frames`, to `last_path`;
    /// otherwise where `P` asked.
    fn due(&mut self, last: bool, last_path: Option<&PathBuf>) -> Option<PathBuf> {
        if last {
            last_path.cloned()
        } else {
            self.next.take()
        }
    }
}

/// GPU and frame times: rolling numbers for the title and totals over the run.
struct Timing {
    title: TitleStats,
    totals: Totals,
}

/// Rolling numbers for the title, since `since`.
struct TitleStats {
    since: Instant,
    frames: u32,
    gpu_ms_sum: f64,
    gpu_samples: u32,
}

impl TitleStats {
    fn new() -> Self {
        Self {
            since: Instant::now(),
            frames: 0,
            gpu_ms_sum: 0.0,
            gpu_samples: 0,
        }
    }
}

/// Over the whole run, after the first frame.
#[derive(Default)]
struct Totals {
    /// When the first frame was presented.
    first: Option<Instant>,
    /// Frames presented after the first.
    frames: u32,
    gpu_ms_sum: f64,
    gpu_samples: u32,
}

impl Timing {
    /// One frame's GPU time, into the title's numbers and the totals.
    fn add_gpu(&mut self, ms: f64) {
        self.title.gpu_ms_sum += ms;
        self.title.gpu_samples += 1;
        self.totals.gpu_ms_sum += ms;
        self.totals.gpu_samples += 1;
    }

    /// A frame was presented.
    fn presented(&mut self) {
        match self.totals.first {
            None => self.totals.first = Some(Instant::now()),
            Some(_) => self.totals.frames += 1,
        }
    }
}

/// Frames drawn since the picture last changed: what a picture accumulated over frames
/// weighs its next frame by, and where it starts again.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub(super) struct Accumulation {
    frames: u32,
}

impl Accumulation {
    /// The picture changed: accumulation starts again.
    fn reset(&mut self) {
        self.frames = 0;
    }

    /// A frame was drawn over the same picture.
    fn advance(&mut self) {
        self.frames = self.frames.saturating_add(1);
    }

    /// Frames drawn since the last reset (0: the next frame is the first of its picture).
    #[cfg_attr(not(test), expect(dead_code, reason = "read by an accumulating pass"))]
    pub fn frames(&self) -> u32 {
        self.frames
    }
}

impl Draw {
    /// Draws with `renderer` (set up for the window); `prepared` is the material shown first.
    pub fn new(
        renderer: Renderer,
        mesh: Mesh,
        prepared: Arc<PreparedMaterial>,
        env: EnvView,
    ) -> Result<Self> {
        let frames = Frames::new(renderer.device(), "viewer frame", FRAMES_IN_FLIGHT, true)?;
        Ok(Self {
            frames,
            pass: None,
            map_pass: None,
            renderer,
            mesh,
            shown: Arc::clone(&prepared),
            material: prepared,
            build: None,
            waiting: false,
            rebuild: true,
            view_changed: false,
            screenshots: Screenshots::default(),
            timing: Timing {
                title: TitleStats::new(),
                totals: Totals::default(),
            },
            accumulation: Accumulation::default(),
            env,
        })
    }

    pub fn dev(&self) -> &Arc<Device> {
        self.renderer.device()
    }

    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// Whether there is something to draw: a pass (not before the first build arrives) or
    /// the environment-lit picture.
    pub fn has_pass(&self) -> bool {
        self.pass.is_some() || self.env.drawing()
    }

    /// Whether a variant build runs in the background.
    pub fn building(&self) -> bool {
        self.renderer.building()
    }

    /// Whether a background build waits for the next frame: to go on after its stand-in,
    /// or to have what it sent installed.
    pub fn build_waits_for_a_frame(&self) -> bool {
        self.renderer.build_waits_for_a_frame()
    }

    /// Whether the frames draw the environment-lit picture (which accumulates frame by
    /// frame).
    pub fn env_drawing(&self) -> bool {
        self.env.drawing()
    }

    /// What changes the picture without a new pass: the camera, the light, the exposure,
    /// the window's size.
    pub fn view_changed(&mut self) {
        self.view_changed = true;
        self.accumulation.reset();
        self.env.reset(&mut self.frames);
    }

    /// The passes are rebuilt at the next update (a new swapchain format).
    pub fn request_rebuild(&mut self) {
        self.rebuild = true;
        self.waiting = false;
        self.env.reset(&mut self.frames);
    }

    /// `E`: the next environment. The line to print.
    pub fn next_env(&mut self) -> String {
        self.accumulation.reset();
        self.env.cycle(&mut self.frames)
    }

    /// Whether what the frame shows is still changing: while the environment-lit picture
    /// draws, its preparation and accumulation; otherwise a variant build.
    pub fn settling(&self) -> bool {
        if self.env.drawing() {
            self.env.busy()
        } else {
            self.building() || self.env.busy()
        }
    }

    /// Brings the environment-lit picture up to date for the controls' view in a target of
    /// `extent` (see [`EnvView::update`]). A failure is printed and the environment is
    /// switched off (the sun-lit passes draw).
    pub fn update_env(&mut self, scene: &Scene, controls: &Controls, sc: &Swapchain) {
        if self.env.on() && !sc.uploadable() {
            eprintln!("error: the window's images cannot be copied into (environment off)");
            self.env.switch_off(&mut self.frames);
            return;
        }
        let extent = sc.extent;
        let (mesh_rect, map_rect) = layout(extent, controls.map);
        let map = map_rect.map(|r| (r, self.map_wi(controls)));
        let dev = Arc::clone(self.renderer.device());
        let result = self.env.update(
            &dev,
            &mut self.frames,
            &self.material,
            scene,
            &controls.state,
            &self.mesh,
            extent,
            (mesh_rect, map),
            (self.renderer.variant(), self.renderer.table_options()),
        );
        if let Err(e) = result {
            eprintln!("error: {e} (environment off)");
            self.env.switch_off(&mut self.frames);
        }
    }

    /// Draws `kind` from the next update on.
    pub fn set_variant(&mut self, kind: VariantKind) {
        self.renderer.set_variant(kind);
        self.request_rebuild();
    }

    /// Recompiled shaders: the passes are rebuilt with them.
    pub fn set_shader_overrides(&mut self, spirv: std::collections::HashMap<String, Vec<u8>>) {
        self.renderer.set_shader_overrides(spirv);
        self.request_rebuild();
    }

    /// The BRDF map was switched on or off.
    pub fn map_toggled(&mut self, on: bool) {
        self.waiting = false;
        if !on {
            // Frames in flight may still read the map's objects.
            if let Some(old) = self.map_pass.take() {
                self.frames.retire(old);
            }
        }
        self.view_changed();
    }

    /// An edited material has loaded: the passes move to it once its variant is built.
    pub fn want_material(&mut self, material: PreparedMaterial) {
        self.material = Arc::new(material);
        self.waiting = false;
    }

    /// A replaced swapchain, destroyed once the frames that used it have been presented.
    pub fn retire_after_present<T: 'static>(&mut self, old: T) {
        self.frames.retire_after_present(old);
    }

    /// `P`: the next frame is saved.
    pub fn request_screenshot(&mut self) {
        self.screenshots.request();
    }

    /// Takes what the background build finished and brings the passes up to date without
    /// blocking: when the prepared variant serves the view, the wanted material and the
    /// map, the passes that need it are rebuilt now (pipelines only); otherwise a background
    /// build starts (or goes on, or replaces one that the request superseded) and the old
    /// passes draw until it arrives.
    pub fn update_passes(
        &mut self,
        scene: &Scene,
        controls: &mut Controls,
        sc: Option<&Swapchain>,
    ) -> Result<()> {
        self.take_arrived_build()?;
        let material_changed = !Arc::ptr_eq(&self.shown, &self.material);
        let map_missing = controls.map && self.map_pass.is_none();
        let due = self.rebuild
            || self.view_changed
            || material_changed
            || map_missing
            || self.pass.is_none();
        if !due || (self.waiting && !self.view_changed) {
            return Ok(());
        }
        self.view_changed = false;
        match self.request_variant(scene, controls, sc)? {
            None => {}
            Some(Readiness::Building) => self.building_noted(controls.variant),
            Some(Readiness::Ready) => {
                self.shown = Arc::clone(&self.material);
                if self.rebuild || material_changed || self.pass.is_none() {
                    self.rebuild_pass(scene, controls, sc)?;
                } else if map_missing {
                    let prepared = Arc::clone(&self.shown);
                    self.build_map(scene, controls, sc, &prepared);
                }
            }
        }
        Ok(())
    }

    /// Installs a background build that arrived: the passes are rebuilt from it.
    fn take_arrived_build(&mut self) -> Result<()> {
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
        Ok(())
    }

    /// Asks the renderer for the variant the view, the wanted material and the map need.
    /// `None`: the request failed and the passes shown stay.
    fn request_variant(
        &mut self,
        scene: &Scene,
        controls: &Controls,
        sc: Option<&Swapchain>,
    ) -> Result<Option<Readiness>> {
        let view = controls.state.apply(scene);
        let map_wi = controls.map.then(|| self.map_wi(controls));
        let coarse_first = self.pass.is_none();
        let aspect = sc.map_or(1.0, |sc| mesh_aspect(sc.extent, controls.map));
        let cancelled = self.renderer.builds_cancelled();
        let readiness = self.renderer.prepare_in_background(
            &view,
            aspect,
            &self.material,
            map_wi,
            coarse_first,
        );
        if self.renderer.builds_cancelled() > cancelled {
            println!("superseded build cancelled");
            self.build = None;
        }
        match readiness {
            Ok(r) => Ok(Some(r)),
            Err(e) if self.pass.is_some() => {
                self.keep_shown(&e);
                Ok(None)
            }
            Err(e) => Err(e),
        }
    }

    /// A background build runs for `variant`: said once, when it starts.
    fn building_noted(&mut self, variant: VariantKind) {
        self.waiting = true;
        if self.build.is_some() {
            return;
        }
        let coarse = self
            .renderer
            .background_progress()
            .is_some_and(|p| p.coarse);
        println!(
            "building {} in the background{}",
            variant.name(),
            if coarse {
                " (a coarse table first)"
            } else {
                ""
            }
        );
        self.build = Some(0);
    }

    /// A failed build or request: the passes and material shown stay, and nothing is asked
    /// again until something changes.
    fn keep_shown(&mut self, e: &Error) {
        eprintln!("error: {e} (keeping the previous pass)");
        self.material = Arc::clone(&self.shown);
        self.rebuild = false;
    }

    /// Rebuilds the passes for the prepared variant (variant, switches, shaders, a table
    /// that arrived). The old pass is kept when the new one fails (e.g. a reloaded shader
    /// that does not link).
    fn rebuild_pass(
        &mut self,
        scene: &Scene,
        controls: &mut Controls,
        sc: Option<&Swapchain>,
    ) -> Result<()> {
        let prepared = Arc::clone(&self.shown);
        // The map first: its table also serves the mesh beside it.
        if controls.map {
            self.build_map(scene, controls, sc, &prepared);
        }
        let Some(sc) = sc else {
            return Ok(());
        };
        let aspect = mesh_aspect(sc.extent, controls.map);
        let state = &controls.state;
        let view = state.apply(scene);
        let options = PassOptions {
            fresnel: state.fresnel,
            shadowing: state.shadowing,
            texture_blending: state.texture,
        };
        let start = Instant::now();
        let built = self
            .renderer
            .scene_pass(&view, &prepared, options, sc.render_pass(), aspect);
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
                self.accumulation.reset();
            }
            Err(e) if self.pass.is_some() => {
                eprintln!("error: {e} (keeping the previous pipeline)");
            }
            Err(e) => return Err(e),
        }
        self.rebuild = false;
        Ok(())
    }

    /// Builds the BRDF map's pass for the current light. A failure is printed: the previous
    /// map pass stays, or without one the map is switched off.
    fn build_map(
        &mut self,
        scene: &Scene,
        controls: &mut Controls,
        sc: Option<&Swapchain>,
        prepared: &PreparedMaterial,
    ) {
        let Some(sc) = sc else {
            return;
        };
        let side = layout(sc.extent, true).1.map_or(1, |r| r.extent.width);
        let (theta, phi) = self.map_angles(controls);
        let state = &controls.state;
        let view = state.apply(scene);
        let options = PassOptions {
            fresnel: state.fresnel,
            shadowing: state.shadowing,
            texture_blending: false,
        };
        let start = Instant::now();
        let map = MapView {
            wi: crate::brdf::direction(theta, phi),
            size: side,
            exposure: state.map_exposure,
        };
        let built =
            self.renderer
                .brdf_map_pass(prepared, map, options, Some(&view), sc.render_pass());
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
                self.accumulation.reset();
            }
            Err(e) if self.map_pass.is_some() => {
                eprintln!("error: BRDF map: {e} (keeping the previous map pipeline)");
            }
            Err(e) => {
                eprintln!("error: BRDF map: {e} (map off)");
                controls.map = false;
            }
        }
    }

    /// The map's light `ωi`: the light in the tangent frame of the surface at the centre of
    /// the view ([`tangent_frame_at_view`]), as `render_brdf_map` computes it from
    /// `(θi, φi)`.
    fn map_wi(&self, controls: &Controls) -> [f64; 3] {
        let (theta, phi) = self.map_angles(controls);
        crate::brdf::direction(theta, phi)
    }

    fn map_angles(&self, controls: &Controls) -> (f64, f64) {
        let state = &controls.state;
        let frame = tangent_frame_at_view(&self.mesh, &state.camera).unwrap_or([
            glam::Vec3::X,
            glam::Vec3::Y,
            glam::Vec3::Z,
        ]);
        state.map_light_angles(frame)
    }

    /// Points the passes at the controls' view for a target of `extent`: the mesh's camera,
    /// light and exposure, and the map's light. Says where each pass draws.
    pub fn set_views(&mut self, scene: &Scene, controls: &Controls, extent: vk::Extent2D) -> Views {
        let (mesh_rect, map_rect) = layout(extent, controls.map);
        let aspect = mesh_aspect(extent, controls.map);
        let map_wi = controls.map.then(|| self.map_wi(controls));
        let state = &controls.state;
        let view = state.apply(scene);
        if let Some(pass) = &mut self.pass {
            pass.set_view(&view.camera, &view.light, aspect, state.exposure);
        }
        let map = match (&mut self.map_pass, map_wi, map_rect) {
            (Some(m), Some(wi), Some(rect)) if controls.map => {
                m.set_map(wi.map(|c| c as f32), rect.extent.width, state.map_exposure);
                Some(rect)
            }
            _ => None,
        };
        Views {
            mesh: mesh_rect,
            map,
        }
    }

    /// Begins the next frame in flight (waiting for the GPU only if it is that far behind).
    pub fn begin(&mut self) -> Result<FrameStart> {
        let frame = self.frames.begin()?;
        if let Some(ms) = frame.previous_gpu_ms {
            self.timing.add_gpu(ms);
            self.env.frame_gpu_ms(ms, FRAMES_IN_FLIGHT);
        }
        Ok(frame)
    }

    /// Where this frame's image is saved, if anywhere (see [`Screenshots::due`]).
    pub fn screenshot_due(&mut self, last: bool, last_path: Option<&PathBuf>) -> Option<PathBuf> {
        self.screenshots.due(last, last_path)
    }

    /// Records the passes into swapchain image `index` at `views` (and, for a screenshot
    /// to `shot`, the image's copy into a readback buffer) and submits the frame: it waits
    /// for the image to be acquired and signals the image's present semaphore.
    pub fn record_and_submit(
        &mut self,
        frame: &FrameStart,
        sc: &Swapchain,
        index: u32,
        views: &Views,
        shot: Option<PathBuf>,
    ) -> Result<Option<Shot>> {
        let readback = match &shot {
            Some(_) => Some(sc.readback_buffer()?),
            None => None,
        };
        if self.env.drawing() {
            let dev = Arc::clone(self.renderer.device());
            self.env.record(&dev, frame.cb, sc, index)?;
        } else {
            let Some(pass) = &self.pass else {
                return Err(Error::invalid("viewer frame", "no pass to draw"));
            };
            let target = sc.target(index);
            match (&self.map_pass, views.map) {
                (Some(map), Some(map_rect)) => ScenePass::record_views(
                    frame.cb,
                    &target,
                    &[(pass, views.mesh), (map, map_rect)],
                ),
                _ => pass.record(frame.cb, &target),
            }
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
        Ok(shot
            .zip(readback)
            .map(|(path, readback)| Shot { path, readback }))
    }

    /// Saves a presented frame's image: waits for this frame only (its fence), not for the
    /// device.
    pub fn save_screenshot(&mut self, sc: &Swapchain, shot: Shot) -> Result<()> {
        if let Some(ms) = self.frames.wait()? {
            self.timing.add_gpu(ms);
        }
        save_screenshot(sc, &shot.readback, &shot.path)?;
        println!("screenshot → {}", shot.path.display());
        Ok(())
    }

    /// A frame was presented: the build's and the run's counts, and the accumulation.
    pub fn presented(&mut self) {
        if let Some(n) = &mut self.build {
            *n += 1;
        }
        self.timing.presented();
        self.accumulation.advance();
    }

    /// The window's title, twice a second (`None` in between): the variant, GPU time and
    /// frame rate, and while a build runs how far it is. `presented`: this call follows a
    /// presented frame; `variant`: the name to show before a pass exists; `loading`: an
    /// edited material loads.
    pub fn title(
        &mut self,
        presented: bool,
        variant: VariantKind,
        loading: bool,
    ) -> Option<String> {
        let stats = &mut self.timing.title;
        if presented {
            stats.frames += 1;
        }
        let elapsed = stats.since.elapsed().as_secs_f64();
        if elapsed < 0.5 {
            return None;
        }
        let fps = stats.frames as f64 / elapsed;
        let gpu = if stats.gpu_samples > 0 {
            format!("{:.2} ms", stats.gpu_ms_sum / stats.gpu_samples as f64)
        } else {
            "n/a".into()
        };
        *stats = TitleStats::new();
        let name = self
            .pass
            .as_ref()
            .map_or(variant.name().to_string(), |p| p.stats().name.clone());
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
            None if loading => " — loading the material".to_string(),
            None => String::new(),
        };
        let env = self
            .env
            .title()
            .map_or(String::new(), |t| format!(" — {t}"));
        Some(format!(
            "diffract — {name}{env}{building} — GPU {gpu} — {fps:.1} fps"
        ))
    }

    /// One line: frames presented, frame time and GPU time over the run (the first frame,
    /// which includes the pipeline build, excluded from the frame time); and one on frame
    /// pacing.
    pub fn print_totals(&self, frames_done: u32, sc: Option<&Swapchain>) {
        let totals = &self.timing.totals;
        let Some(start) = totals.first else {
            return;
        };
        let wall = start.elapsed().as_secs_f64() * 1e3;
        let frame_ms = if totals.frames > 0 {
            format!("{:.2} ms/frame", wall / totals.frames as f64)
        } else {
            "n/a".into()
        };
        let gpu = if totals.gpu_samples > 0 {
            format!("{:.2} ms", totals.gpu_ms_sum / totals.gpu_samples as f64)
        } else {
            "n/a".into()
        };
        let (w, h) = sc.map_or((0, 0), |s| (s.extent.width, s.extent.height));
        println!(
            "{}: {} frames presented ({w}×{h}, {:?}): {frame_ms}, GPU {gpu} per frame",
            self.renderer.device_name(),
            frames_done,
            sc.map_or(vk::PresentModeKHR::FIFO, |s| s.present_mode),
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

/// Writes the read-back swapchain texels (already sRGB-encoded) to a PNG, through a
/// temporary file and a rename like every output.
fn save_screenshot(sc: &Swapchain, buf: &Buffer, path: &std::path::Path) -> Result<()> {
    let rgb = sc.texels_to_rgb8(buf.mapped()?);
    let bytes: Vec<u8> = rgb.into_iter().flatten().collect();
    crate::image_io::write_png_rgb8(path, sc.extent.width, sc.extent.height, bytes)
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

    #[test]
    fn accumulation_counts_frames_since_the_last_change() {
        let mut a = Accumulation::default();
        assert_eq!(a.frames(), 0);
        a.advance();
        a.advance();
        assert_eq!(a.frames(), 2);
        a.reset();
        assert_eq!(a.frames(), 0);
    }

    #[test]
    fn a_screenshot_is_taken_once_where_asked() {
        let mut s = Screenshots::default();
        assert_eq!(s.due(false, None), None);
        s.request();
        s.request();
        assert_eq!(
            s.due(false, None),
            Some(PathBuf::from("diffract-view-2.png"))
        );
        assert_eq!(s.due(false, None), None);
        // The last frame of --frames goes where --screenshot says, or nowhere.
        let last = PathBuf::from("last.png");
        s.request();
        assert_eq!(s.due(true, Some(&last)), Some(last.clone()));
        assert_eq!(s.due(true, None), None);
        assert_eq!(
            s.due(false, None),
            Some(PathBuf::from("diffract-view-3.png"))
        );
    }
}
