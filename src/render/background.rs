//! Variant builds off the caller's thread, for the viewer: the event loop keeps presenting
//! frames with what it has while a table (or a variant's DFT terms) is built on a worker.
//! [`Renderer::prepare_in_background`] starts a build (a coarse stand-in first when asked,
//! then the real one), [`Renderer::poll_background`] installs what finished, and
//! [`Renderer::background_progress`] says how far the build is, for the window title.
//!
//! The worker uploads through the device's own one-shot submissions, which take the queue's
//! lock only to submit: frames of the event loop go on meanwhile.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressDrawTarget};

use super::variant::{DrawSetup, PreparedVariant, TableOptions};
use super::{region, OutputMode, PreparedKey, Renderer};
use crate::brdf::table::{DiscKernel, Region, TableSpec};
use crate::gpu::StorageFormat;
use crate::material::PreparedMaterial;
use crate::report::Report;
use crate::scene::Scene;
use crate::{Error, Result};

/// How much coarser than the real table the stand-in is in `(u, v)`.
const COARSE_TEXEL_FACTOR: f64 = 4.0;
/// Wavelength step of the stand-in's spectral integral (nm).
const COARSE_STEP_NM: u32 = 20;
/// `w` nodes of the stand-in.
const COARSE_W_NODES: usize = 6;

/// A variant's settings, owned: what [`DrawSetup`] borrows.
#[derive(Clone)]
pub(super) struct BuildOptions {
    pub region: Region,
    pub output: OutputMode,
    pub storage: StorageFormat,
    pub table: TableOptions,
    pub keep_model: bool,
    pub cache_dir: Option<PathBuf>,
    pub leave_out: bool,
    pub disc: Option<DiscKernel>,
}

impl BuildOptions {
    pub fn setup<'a>(
        &'a self,
        prepared: &'a PreparedMaterial,
        report: &'a dyn Report,
    ) -> DrawSetup<'a> {
        DrawSetup {
            prepared,
            region: self.region,
            output: self.output,
            storage: self.storage,
            table: &self.table,
            keep_model: self.keep_model,
            cache_dir: self.cache_dir.as_deref(),
            leave_out: self.leave_out,
            disc: self.disc,
            report,
        }
    }

    /// A table a few times coarser in every direction, built in a fraction of the time:
    /// what the window shows while the real table builds. Not cached.
    fn coarse(&self, material: &crate::material::Material) -> BuildOptions {
        let texel = self
            .table
            .texel_uv
            .unwrap_or_else(|| TableSpec::default_texel(material.coherence_um));
        BuildOptions {
            table: TableOptions {
                texel_uv: Some(texel * COARSE_TEXEL_FACTOR),
                w_nodes: Some(COARSE_W_NODES),
                step_nm: Some(
                    self.table
                        .step_nm
                        .map_or(COARSE_STEP_NM, |s| s.max(COARSE_STEP_NM)),
                ),
                ..self.table
            },
            cache_dir: None,
            keep_model: false,
            ..self.clone()
        }
    }
}

/// The progress of a background build: the worker's bar, hidden, read by the title; and
/// its cancellation.
struct Progress {
    inner: Arc<dyn Report>,
    bar: Mutex<Option<ProgressBar>>,
    cancel: AtomicBool,
    /// The worker sent a stage (or stopped) that no poll has taken yet.
    news: AtomicBool,
}

/// The unwinding payload of a cancelled build.
struct Cancelled;

impl Report for Progress {
    fn warn(&self, line: &str) {
        self.inner.warn(line);
    }

    fn note(&self, line: &str) {
        self.inner.note(line);
    }

    fn progress(&self, bar: ProgressBar) -> ProgressBar {
        bar.set_draw_target(ProgressDrawTarget::hidden());
        if let Ok(mut b) = self.bar.lock() {
            *b = Some(bar.clone());
        }
        bar
    }

    fn checkpoint(&self) {
        if self.cancel.load(Ordering::Relaxed) {
            std::panic::resume_unwind(Box::new(Cancelled));
        }
    }
}

/// What a worker sends: the stand-in, then the real build.
enum Stage {
    Coarse(Result<Box<dyn PreparedVariant>>),
    Final(Result<Box<dyn PreparedVariant>>),
}

/// A build running on a worker thread.
pub(super) struct Background {
    key: PreparedKey,
    material: Arc<PreparedMaterial>,
    rx: Receiver<Stage>,
    /// Lets the worker go on after the stand-in (sent at the poll after it arrived).
    go: Option<mpsc::Sender<()>>,
    /// The stand-in was installed at the last poll.
    released: bool,
    progress: Arc<Progress>,
    started: Instant,
    coarse: bool,
    handle: Option<JoinHandle<()>>,
}

impl Drop for Background {
    fn drop(&mut self) {
        // Stopped at its next step; what it made so far is destroyed as it unwinds, before
        // the renderer's own objects and the device.
        self.progress.cancel.store(true, Ordering::Relaxed);
        // A worker waiting after its stand-in sees the channel close and stops.
        self.go = None;
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// A background build that finished and was installed.
#[derive(Debug)]
pub struct Arrived {
    /// The material it was built for: passes built now must use it.
    pub material: Arc<PreparedMaterial>,
    /// A coarse stand-in: the real build goes on.
    pub coarse: bool,
    /// Since the build started (ms).
    pub ms: f64,
}

/// How far a background build is.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildProgress {
    /// The bar's name (e.g. `chebyshev-w table`); the variant's name before the bar starts.
    pub what: String,
    /// `(done, total)` steps of the bar, when it has started.
    pub steps: Option<(u64, u64)>,
    /// The coarse stand-in is being built (else the real one).
    pub coarse: bool,
    /// Since the build started (s).
    pub seconds: f64,
}

/// The answer of [`Renderer::prepare_in_background`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Readiness {
    /// The prepared variant serves the view: passes built now are immediate.
    Ready,
    /// A build runs (started now or before); [`Renderer::poll_background`] says when it
    /// arrives.
    Building,
}

impl Renderer {
    /// Makes the prepared variant serve `scene`'s view at `aspect` (and, with `map_wi`, a
    /// BRDF map beside it under that light) for `material`, without blocking: `Ready` when
    /// it already does; otherwise a build starts on a worker thread (`coarse_first`: a
    /// coarse table first, for a window with nothing to show yet) and `Building` is
    /// returned. Without the map, a table variant holds the sun's disc pre-filtered, as
    /// `render`'s does (a footprint within 20 % of the view's still serves). A build
    /// already running goes on; a new one starts once it has arrived and if it is still
    /// needed then. Only for a renderer with a covering margin (the viewer).
    pub fn prepare_in_background(
        &mut self,
        scene: &Scene,
        aspect: f32,
        material: &Arc<PreparedMaterial>,
        map_wi: Option<[f64; 3]>,
        coarse_first: bool,
    ) -> Result<Readiness> {
        let mesh = self.scene_mesh(scene)?;
        let disc = if map_wi.is_none() && !self.per_vertex && self.variant.is_table() {
            region::scene_disc(scene, &mesh, aspect)
        } else {
            None
        };
        // The mesh alone: the triangles in the camera's frame (as its pass asks); beside the
        // map, every lit one (as the map's pass asks).
        let in_frame = map_wi.is_none().then_some(aspect);
        let mut need = region::scene_region(scene, &mesh, in_frame, disc.is_some())
            .unwrap_or_else(region::unlit);
        let mut output = OutputMode::Mesh;
        if let Some(wi) = map_wi {
            self.variant.check_output(OutputMode::MapDisplay)?;
            need = need.union(&Region::brdf_map(wi.map(|c| c as f32 as f64)).widened(1e-5));
            output = OutputMode::MapDisplay;
        }
        let wanted = self.wanted_variant(material, need, output, disc)?;
        // A build for another material or other settings is superseded: stopped now, not
        // run to its end before the wanted one starts. One for another region of the same
        // variant goes on (the view may come back to it).
        if self
            .background
            .as_ref()
            .is_some_and(|bg| !wanted.served_by(&bg.key) && !wanted.same_but_region(&bg.key))
        {
            self.cancel_background();
        }
        if self
            .prepared
            .as_ref()
            .is_some_and(|(k, _)| wanted.served_by(k))
        {
            return Ok(Readiness::Ready);
        }
        if self.background.is_some() {
            return Ok(Readiness::Building);
        }
        let (key, region) = (wanted.key, wanted.region);
        let options = self.build_options(region, output, disc, key.table);
        let coarse =
            (coarse_first && self.variant.is_table()).then(|| options.coarse(&material.material));
        let coarse_building = coarse.is_some();
        let progress = Arc::new(Progress {
            inner: Arc::clone(&self.report),
            bar: Mutex::new(None),
            cancel: AtomicBool::new(false),
            news: AtomicBool::new(false),
        });
        let (tx, rx) = mpsc::channel();
        // After the stand-in, the worker waits for the next poll (the first frame with it
        // has been drawn by then): on a CPU device the frame and the build share the cores.
        let (go_tx, go_rx) = mpsc::channel::<()>();
        let variant = self.variant.implementation();
        let dev = Arc::clone(&self.dev);
        let worker_material = Arc::clone(material);
        let report = Arc::clone(&progress);
        let handle = std::thread::Builder::new()
            .name("variant build".into())
            .spawn(move || {
                let m = &*worker_material;
                let work = || {
                    if let Some(c) = coarse {
                        let built = variant.prepare(&dev, &c.setup(m, &*report));
                        let sent = tx.send(Stage::Coarse(built));
                        report.news.store(true, Ordering::Relaxed);
                        if sent.is_err() || go_rx.recv().is_err() {
                            return;
                        }
                        if let Ok(mut b) = report.bar.lock() {
                            *b = None;
                        }
                    }
                    let built = variant.prepare(&dev, &options.setup(m, &*report));
                    let _ = tx.send(Stage::Final(built));
                };
                let ended = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work));
                report.news.store(true, Ordering::Relaxed);
                if let Err(payload) = ended {
                    if !payload.is::<Cancelled>() {
                        std::panic::resume_unwind(payload);
                    }
                }
            })
            .map_err(|e| Error::invalid("background build", format!("no worker thread: {e}")))?;
        self.background = Some(Background {
            key,
            material: Arc::clone(material),
            rx,
            go: Some(go_tx),
            released: false,
            progress,
            started: Instant::now(),
            coarse: coarse_building,
            handle: Some(handle),
        });
        Ok(Readiness::Building)
    }

    /// Stops the running background build: its worker stops at its next step and is joined
    /// once it has (at a later poll, or when the renderer goes), so the caller never waits
    /// for it.
    fn cancel_background(&mut self) {
        if let Some(mut bg) = self.background.take() {
            bg.progress.cancel.store(true, Ordering::Relaxed);
            // A worker waiting after its stand-in sees the channel close and stops.
            bg.go = None;
            self.cancelled.push(bg);
            self.builds_cancelled += 1;
        }
    }

    /// Background builds stopped because a later request superseded them.
    pub fn builds_cancelled(&self) -> u64 {
        self.builds_cancelled
    }

    /// Installs what a background build finished, if anything: the prepared variant it
    /// replaces is dropped here (passes built from it keep their own references). A coarse
    /// stand-in is held under the real build's key, so passes built now use it until the
    /// real one arrives. A failed build is an error (the previous variant stays).
    pub fn poll_background(&mut self) -> Result<Option<Arrived>> {
        // Cancelled workers that have stopped are joined (at once: they have ended).
        self.cancelled
            .retain(|bg| bg.handle.as_ref().is_some_and(|h| !h.is_finished()));
        let Some(bg) = &mut self.background else {
            return Ok(None);
        };
        if bg.released {
            bg.released = false;
            if let Some(go) = bg.go.take() {
                let _ = go.send(());
            }
        }
        bg.progress.news.store(false, Ordering::Relaxed);
        let (built, coarse) = match bg.rx.try_recv() {
            Ok(Stage::Coarse(b)) => (b, true),
            Ok(Stage::Final(b)) => (b, false),
            Err(TryRecvError::Empty) => return Ok(None),
            Err(TryRecvError::Disconnected) => {
                self.background = None;
                return Err(Error::invalid("background build", "its worker stopped"));
            }
        };
        let ms = bg.started.elapsed().as_secs_f64() * 1e3;
        let key = bg.key.clone();
        let material = Arc::clone(&bg.material);
        if coarse {
            bg.coarse = false;
            bg.released = true;
        } else {
            self.background = None;
        }
        let built = built?;
        self.map = None;
        self.prepared = Some((key, Arc::from(built)));
        Ok(Some(Arrived {
            material,
            coarse,
            ms,
        }))
    }

    /// The running background build's progress (`None` when none runs).
    pub fn background_progress(&self) -> Option<BuildProgress> {
        let bg = self.background.as_ref()?;
        let bar = bg.progress.bar.lock().ok().and_then(|b| b.clone());
        Some(BuildProgress {
            what: bar
                .as_ref()
                .map_or_else(|| bg.key.kind.name().to_string(), |b| b.message()),
            steps: bar.map(|b| (b.position(), b.length().unwrap_or(0))),
            coarse: bg.coarse,
            seconds: bg.started.elapsed().as_secs_f64(),
        })
    }

    /// Whether a background build is running.
    pub fn building(&self) -> bool {
        self.background.is_some()
    }

    /// Whether the running build waits for the next poll: its coarse stand-in arrived
    /// (and the real build starts once a frame has been drawn with it), or it sent what no
    /// poll has taken yet.
    pub fn build_waits_for_a_frame(&self) -> bool {
        self.background
            .as_ref()
            .is_some_and(|b| b.released || b.progress.news.load(Ordering::Relaxed))
    }
}
