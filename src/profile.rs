//! Error-versus-time profiling of shader variants (MODEL §6–7): every row (a variant with
//! its numerical choices) renders the same BRDF map (and, optionally, a mesh view) on the
//! GPU, is timed with GPU timestamps (median of the frames after a warm-up frame that also
//! builds its tables), and is scored at sampled pixels against the f64 reference (direct
//! sum, 1 nm) and against the variant's own f64 model ([`CpuModel`]), which separates
//! approximation error from float32 and driver error.
//!
//! Metrics per row (MODEL §6): relative L2 of linear XYZ over the sampled pixels, max
//! |ΔY|, and CIEDE2000 (p50, p99, mean, max) of the colours after scaling so the brightest
//! reference sample has `Y = 1`; the relative L2 and ΔE p99 against the reference carry a
//! 95 % bootstrap interval over the scored pixels.
//!
//! Frames per row are either fixed ([`Frames::Fixed`], `--full`) or budgeted
//! ([`Frames::Budget`]): rows are measured cheapest first, each draws frames until its
//! median is known to the budget's precision or its share of the time left is spent, and
//! a row whose estimated cost exceeds the time left is reported as skipped with that
//! estimate.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};

use crate::brdf::{direction, reference};
use crate::cli::cache::CacheArgs;
use crate::cli::gpu::TableArgs;
use crate::cli::material::MaterialArgs;
use crate::colour::{delta_e2000, linear_srgb_to_xyz, xyz_to_lab, ColourTable};
use crate::gpu::StorageFormat;
use crate::material::{Material, PreparedMaterial};
use crate::render::variant::{CpuModel, Family, Preset};
use crate::render::Picture;
use crate::render::{map_direction, Renderer, TableOptions, VariantKind};
use crate::scene::Scene;
use crate::spectrum::Expansion;
use crate::{Error, Result};

/// One profiled configuration: a variant with its numerical choices (FLSS: the material's
/// expansion, `T`, `R`, `Δλ` and term storage; tables: their sampling options).
#[derive(Debug, Clone, PartialEq)]
pub struct Variant {
    pub name: String,
    pub kind: VariantKind,
    pub expansion: Expansion,
    pub terms: usize,
    pub window_radius: usize,
    pub lambda_step_nm: u32,
    pub storage: StorageFormat,
    pub table: TableOptions,
    /// Leave out what the map cannot need, as `render` does (wavelengths whose weight is
    /// under the tolerance, DFT texels outside the reached band); false: keep everything.
    pub leave_out: bool,
}

impl Variant {
    /// `base` with this variant's numerical choices (the DFT-term variants read them; the
    /// table variants read only the height field and coherence length).
    pub fn material(&self, base: &Material) -> Material {
        match self.kind.family() {
            Family::Terms => Material {
                expansion: self.expansion,
                terms: crate::material::Terms::Fixed(self.terms),
                window_radius: self.window_radius,
                lambda_step_nm: self.lambda_step_nm,
                ..base.clone()
            },
            Family::Table | Family::Debug => base.clone(),
        }
    }

    /// The row of `kind` for `preset`, with the profile's Taylor `terms` and `table` options.
    fn from_preset(kind: VariantKind, preset: &Preset, terms: usize, table: &TableOptions) -> Self {
        let table = TableOptions {
            step_nm: preset.table_step_nm.or(table.step_nm),
            format: preset.table_format.unwrap_or(table.format),
            ..*table
        };
        let name = if preset.label.is_empty() {
            kind.name().to_string()
        } else {
            preset.label.to_string()
        };
        match kind.family() {
            Family::Terms => Variant {
                name,
                kind,
                expansion: preset.expansion,
                terms: preset.terms(terms),
                window_radius: preset.window_radius,
                lambda_step_nm: preset.lambda_step_nm,
                storage: preset.storage,
                table,
                leave_out: preset.leave_out,
            },
            Family::Table | Family::Debug => Variant {
                name,
                kind,
                expansion: Expansion::Taylor,
                terms: 0,
                window_radius: 0,
                lambda_step_nm: table.step_nm.unwrap_or(TableOptions::DEFAULT_STEP_NM),
                storage: StorageFormat::Rg32f,
                table,
                leave_out: preset.leave_out,
            },
        }
    }
}

/// The rows of every registered variant of `family`, from the presets each declares.
fn rows_of(family: Family, terms: usize, table: &TableOptions) -> Vec<Variant> {
    VariantKind::ALL
        .into_iter()
        .filter(|k| k.family() == family)
        .flat_map(|k| {
            k.profile_presets()
                .iter()
                .map(move |p| Variant::from_preset(k, p, terms, table))
        })
        .collect()
}

/// The DFT-term set (flss, nmm, pq): the rows each variant declares, e.g. FLSS's thesis
/// setting (Taylor, R = 1), the default, larger R, Chebyshev, the compact storage formats,
/// and coarser and finer wavelength steps. `terms` is T of the Taylor rows; Chebyshev gets
/// about two thirds of it (it converges faster, README).
pub fn flss_variants(terms: usize) -> Vec<Variant> {
    rows_of(Family::Terms, terms, &TableOptions::default())
}

/// The pre-integrated set with `table` as the base options: each table variant at its
/// defaults, plus the extra rows each declares (`chebyshev-w` with its spectrum integrated
/// at 5 nm as FLSS samples it, `volume` in float16).
pub fn table_variants(table: &TableOptions) -> Vec<Variant> {
    rows_of(Family::Table, 0, table)
}

/// Every variant: [`flss_variants`] then [`table_variants`].
pub fn standard_variants(terms: usize) -> Vec<Variant> {
    let mut v = flss_variants(terms);
    v.extend(table_variants(&TableOptions::default()));
    v
}

/// Errors of one set of XYZ samples against another (MODEL §6).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorStats {
    /// `‖xyz − ref‖₂ / ‖ref‖₂` over all samples and channels.
    pub rel_l2: f64,
    /// Largest `|Y − Y_ref|`.
    pub max_abs_y: f64,
    /// Mean and largest CIEDE2000 after scaling by `1 / max Y_ref`.
    pub mean_de: f64,
    pub max_de: f64,
    /// Median and 99th percentile of the same CIEDE2000 values.
    pub p50_de: f64,
    pub p99_de: f64,
}

/// Compares `xyz` with `reference` sample by sample.
pub fn error_stats(xyz: &[[f64; 3]], reference: &[[f64; 3]]) -> ErrorStats {
    let y_max = reference.iter().map(|r| r[1]).fold(0.0, f64::max);
    let scale = if y_max > 0.0 { 1.0 / y_max } else { 1.0 };
    let (mut diff2, mut ref2, mut max_abs_y) = (0.0, 0.0, 0.0);
    let mut des = Vec::with_capacity(xyz.len());
    for (a, r) in xyz.iter().zip(reference) {
        for c in 0..3 {
            diff2 += (a[c] - r[c]).powi(2);
            ref2 += r[c] * r[c];
        }
        max_abs_y = f64::max(max_abs_y, (a[1] - r[1]).abs());
        let de = delta_e2000(
            xyz_to_lab(a.map(|v| (v * scale).max(0.0))),
            xyz_to_lab(r.map(|v| (v * scale).max(0.0))),
        );
        des.push(de);
    }
    let n = xyz.len().max(1) as f64;
    des.sort_by(f64::total_cmp);
    let pct = |p: f64| {
        if des.is_empty() {
            0.0
        } else {
            des[((p * (des.len() - 1) as f64).round() as usize).min(des.len() - 1)]
        }
    };
    ErrorStats {
        rel_l2: if ref2 > 0.0 {
            (diff2 / ref2).sqrt()
        } else {
            diff2.sqrt()
        },
        max_abs_y,
        mean_de: des.iter().sum::<f64>() / n,
        max_de: des.last().copied().unwrap_or(0.0),
        p50_de: pct(0.5),
        p99_de: pct(0.99),
    }
}

/// A 95 % interval of an error figure: the 2.5th and 97.5th percentiles of the figure
/// over bootstrap resamples of the scored pixels.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Interval {
    pub lo: f64,
    pub hi: f64,
}

impl Interval {
    /// Whether the two intervals share a value.
    pub fn overlaps(&self, other: &Interval) -> bool {
        self.lo <= other.hi && other.lo <= self.hi
    }
}

/// The bootstrap intervals of a row's errors against the reference.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ErrorIntervals {
    pub rel_l2: Interval,
    pub p99_de: Interval,
}

/// Resamples in [`bootstrap`]: enough for the 2.5th and 97.5th percentiles to move by
/// less than the intervals' own width between runs.
const RESAMPLES: usize = 400;

/// 95 % intervals of `error_stats(xyz, reference)`'s relative L2 and ΔE p99 by the
/// bootstrap over pixels: [`RESAMPLES`] draws of as many pixels with replacement, from a
/// fixed seed (the same pixels give the same interval).
pub fn bootstrap(xyz: &[[f64; 3]], reference: &[[f64; 3]]) -> ErrorIntervals {
    let n = xyz.len().min(reference.len());
    if n == 0 {
        return ErrorIntervals::default();
    }
    // xorshift64*: a fixed, dependency-free stream of indices.
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as usize % n
    };
    let (mut l2, mut p99) = (Vec::with_capacity(RESAMPLES), Vec::with_capacity(RESAMPLES));
    let (mut a, mut r) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
    for _ in 0..RESAMPLES {
        for k in 0..n {
            let i = next();
            a[k] = xyz[i];
            r[k] = reference[i];
        }
        let e = error_stats(&a, &r);
        l2.push(e.rel_l2);
        p99.push(e.p99_de);
    }
    let interval = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        let at = |p: f64| v[((p * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)];
        Interval {
            lo: at(0.025),
            hi: at(0.975),
        }
    };
    ErrorIntervals {
        rel_l2: interval(l2),
        p99_de: interval(p99),
    }
}

/// The times of a row's timed frames (ms): GPU timestamps where the queue has them, else
/// wall time.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FrameTimes(pub Vec<f64>);

impl FrameTimes {
    /// The `p`-quantile (nearest rank); `None` without frames.
    pub fn quantile(&self, p: f64) -> Option<f64> {
        let mut v = self.0.clone();
        v.sort_by(f64::total_cmp);
        let last = v.len().checked_sub(1)?;
        Some(v[((p * last as f64).round() as usize).min(last)])
    }

    pub fn median(&self) -> Option<f64> {
        crate::render::median(self.0.clone())
    }

    /// The median's relative standard error, `1.2533·σ/(√n·median)` (the asymptotic
    /// efficiency of the median against the mean); `None` below 3 frames.
    pub fn relative_error(&self) -> Option<f64> {
        let n = self.0.len();
        if n < 3 {
            return None;
        }
        let mean = self.0.iter().sum::<f64>() / n as f64;
        let var = self.0.iter().map(|t| (t - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        let median = self.median()?;
        (median > 0.0).then(|| 1.2533 * var.sqrt() / ((n as f64).sqrt() * median))
    }
}

/// How many frames each row draws after its warm-up frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Frames {
    /// Exactly this many (`--full`, `--frames`).
    Fixed(usize),
    /// As many as the budget allows.
    Budget(Budget),
}

/// A time budget for the whole profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Budget {
    /// Wall time of the whole profile (s): references, builds, frames and scoring.
    pub total_s: f64,
    /// A row stops drawing once its median's relative standard error is below this.
    pub precision: f64,
    /// At most this many timed frames a row.
    pub max_frames: usize,
}

impl Budget {
    /// A minute on a 2-core lavapipe machine for the default field and map; 5 % precision.
    pub const DEFAULT_S: f64 = 60.0;

    pub fn seconds(total_s: f64) -> Self {
        Self {
            total_s,
            precision: 0.05,
            max_frames: 50,
        }
    }
}

/// One row of the profile.
#[derive(Debug, Clone, PartialEq)]
pub struct VariantReport {
    pub variant: Variant,
    /// Median GPU time of the map frames after the warm-up (ms); `None` without timestamps.
    pub gpu_ms: Option<f64>,
    /// The 10th and 90th percentiles of the same frames' times (GPU, else wall).
    pub spread_ms: Option<(f64, f64)>,
    /// Timed map frames after the warm-up.
    pub frames: usize,
    /// Wall time of the warm-up frame (ms): preparing the row (terms, table) and its draw.
    pub warm_up_ms: f64,
    /// Median wall time of a map frame after the warm-up (ms), upload and readback included.
    pub wall_ms: f64,
    /// Building and uploading the variant's resources (ms): table build or term upload.
    pub build_ms: f64,
    /// GPU memory of the variant's resources (bytes).
    pub gpu_bytes: usize,
    /// Texel fetches per pixel.
    pub fetches: usize,
    /// The variant's own description of its settings.
    pub detail: String,
    /// Median GPU time of the mesh view (ms), when profiled.
    pub mesh_gpu_ms: Option<f64>,
    /// Condition number of the representation's sum, where float32 rounding limits it.
    pub conditioning: Option<f64>,
    /// Table variants: the most negative `G` (any channel) of the interpolant over the map
    /// before the clamp to `G ≥ 0`, relative to the map's largest `G_Y` (0: none).
    pub overshoot: Option<f64>,
    /// The reference is dark: every scored sample is below what the variants may err by
    /// there (the tolerance times the gain `C`: `ρ/C` under the tolerance of a mirror's
    /// specular value), so ratios to it measure noise and the table says `reference dark`.
    pub reference_dark: bool,
    /// GPU against the f64 reference.
    pub vs_reference: ErrorStats,
    /// 95 % bootstrap intervals of `vs_reference` over the scored pixels.
    pub intervals: ErrorIntervals,
    /// GPU against the f64 model of the same variant (float32 and driver error only).
    pub vs_model: ErrorStats,
    /// With `--per-vertex`: the mesh view against the per-pixel reference variant's mesh
    /// render.
    pub mesh_vs_reference: Option<ErrorStats>,
    /// A per-vertex row (thesis §1.5.1): only its mesh columns are measured (a BRDF map has
    /// no vertices; its map columns repeat the per-pixel variant's).
    pub per_vertex: bool,
}

/// A row that was not measured, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Skipped {
    pub variant: Variant,
    /// Its estimated cost (s) where it did not fit the budget; `None` where it refused the
    /// material.
    pub estimated_s: Option<f64>,
    pub reason: String,
}

/// What a profile measured: the rows in the order asked for, and those it skipped.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ProfileRun {
    pub reports: Vec<VariantReport>,
    pub skipped: Vec<Skipped>,
    /// Wall time of the whole profile (s).
    pub wall_s: f64,
    /// Pixels scored: those asked for, or fewer where the budget's share of the reference
    /// ran out (the first ones picked, bright and spread in proportion).
    pub scored: usize,
}

/// What to profile.
#[derive(Debug, Clone)]
pub struct ProfileSetup {
    pub base: Material,
    pub variants: Vec<Variant>,
    pub theta_i_deg: f64,
    pub phi_i_deg: f64,
    /// BRDF map side in pixels.
    pub size: u32,
    /// Pixels scored, spread evenly over the disk (where errors in dark regions show).
    pub pixels: usize,
    /// Pixels scored among the brightest of the first measured row's map (where
    /// diffraction is).
    pub brightest: usize,
    /// Frames per row after a warm-up frame; the median is reported.
    pub frames: Frames,
    /// A mesh view timed per row (not scored), when given.
    pub mesh: Option<Scene>,
    /// Also evaluate the variants that have a per-vertex stage per vertex on the mesh view,
    /// and score every mesh view against a per-pixel render of it by
    /// [`VariantKind::REFERENCE`] at 1 nm.
    pub per_vertex: bool,
    pub cache_dir: Option<PathBuf>,
}

/// Scored pixels and the reference XYZ at each.
type Samples = (Vec<(u32, u32)>, Vec<[f64; 3]>);

/// The unwinding payload of a table build stopped because it would not fit the budget:
/// the build's estimated total (s).
struct OverBudget {
    projected_s: f64,
    steps: u64,
}

/// The renderer's report during a budgeted row: passes lines and bars on to stderr, and
/// stops a table build (see [`crate::report::Report::checkpoint`]) once the build, at the
/// pace of its steps so far, would end past `deadline`.
struct Deadline {
    start: Instant,
    deadline: Option<Instant>,
    steps: std::sync::atomic::AtomicU64,
    total: std::sync::atomic::AtomicU64,
}

impl Deadline {
    fn new(deadline: Option<Instant>) -> Self {
        Self {
            start: Instant::now(),
            deadline,
            steps: 0.into(),
            total: 0.into(),
        }
    }
}

impl crate::report::Report for Deadline {
    fn warn(&self, line: &str) {
        crate::report::Stderr.warn(line);
    }

    fn note(&self, line: &str) {
        crate::report::Stderr.note(line);
    }

    fn progress(&self, bar: ProgressBar) -> ProgressBar {
        use std::sync::atomic::Ordering;
        self.total
            .fetch_add(bar.length().unwrap_or(0), Ordering::Relaxed);
        bar
    }

    fn checkpoint(&self) {
        use std::sync::atomic::Ordering;
        let Some(deadline) = self.deadline else {
            return;
        };
        let done = self.steps.fetch_add(1, Ordering::Relaxed) + 1;
        let total = self.total.load(Ordering::Relaxed).max(done);
        let spent = self.start.elapsed().as_secs_f64();
        // A few steps first, so the pace is not one step's noise.
        if done < 4 {
            return;
        }
        let projected = spent * total as f64 / done as f64;
        let end = self.start + std::time::Duration::from_secs_f64(projected);
        if end > deadline {
            std::panic::resume_unwind(Box::new(OverBudget {
                projected_s: projected,
                steps: total,
            }));
        }
    }
}

/// What the rows measured so far say about the cost of the next ones.
#[derive(Debug, Clone, Copy)]
struct Pace {
    /// Map frame time per fetch and pixel (ms).
    ms_per_fetch: f64,
    /// Frame time that does not scale with fetches: draw set-up and readback (ms).
    frame_overhead_ms: f64,
    /// A warm-up's preparation beyond its frame (loading terms, pipelines) (ms).
    prepare_ms: f64,
    /// A table build's time per sampled `(w, λ)` plane, from a build this profile made or
    /// stopped (ms); `None` until then (a table may be in the cache: it is tried).
    table_ms_per_plane: Option<f64>,
}

impl Pace {
    /// Before any row: lavapipe's pace on 2 cores (FLSS at 5 nm, 128² map: 1.7 s a frame
    /// for 48 825 fetches a pixel), so a fast GPU is overestimated only until its first
    /// row is measured.
    const PRIOR: Pace = Pace {
        ms_per_fetch: 3e-6,
        frame_overhead_ms: 20.0,
        prepare_ms: 300.0,
        table_ms_per_plane: None,
    };

    /// A plane's build time assumed only to order the rows before any table was built.
    const PRIOR_TABLE_MS_PER_PLANE: f64 = 5.0;

    /// Estimated map frame time of `fetches` a pixel on a `size`² map (ms).
    fn frame_ms(&self, fetches: usize, size: u32) -> f64 {
        let pixels = std::f64::consts::FRAC_PI_4 * (size * size) as f64;
        self.frame_overhead_ms + self.ms_per_fetch * fetches as f64 * pixels
    }

    /// Learns from a measured row: `frame_ms` a frame for `fetches` a pixel, `warm_ms` for
    /// its warm-up (preparation included), `built_ms` of that spent building tables.
    fn learn(&mut self, fetches: usize, size: u32, frame_ms: f64, warm_ms: f64, built_ms: f64) {
        let pixels = std::f64::consts::FRAC_PI_4 * (size * size) as f64;
        if fetches >= 100 {
            self.ms_per_fetch = ((frame_ms - self.frame_overhead_ms).max(0.0)
                / (fetches as f64 * pixels))
                .max(1e-12);
        } else {
            self.frame_overhead_ms = frame_ms;
        }
        self.prepare_ms = (warm_ms - frame_ms - built_ms).max(0.0);
    }
}

/// Progress of a profile on stderr: a bar on a terminal, else one line per finished row
/// with the time left (a log shows it as it happens).
struct Progress {
    bar: Option<ProgressBar>,
    start: Instant,
    rows: usize,
    done: usize,
}

impl Progress {
    fn new(rows: usize) -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let b = ProgressBar::new(rows as u64);
            b.set_style(
                ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} {eta} left")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            b
        });
        Self {
            bar,
            start: Instant::now(),
            rows,
            done: 0,
        }
    }

    fn started(&self, name: &str) {
        if let Some(b) = &self.bar {
            b.set_message(format!("profile: {name}"));
        }
    }

    /// A row is done: `line` says how it went; `left_s` is the time the rest may take
    /// (the budget left, or the pace so far).
    fn finished(&mut self, line: &str, left_s: Option<f64>) {
        self.done += 1;
        match &self.bar {
            Some(b) => {
                b.suspend(|| eprintln!("profile: {line}"));
                b.inc(1);
            }
            None => {
                let left = left_s.unwrap_or_else(|| {
                    let per_row = self.start.elapsed().as_secs_f64() / self.done as f64;
                    per_row * (self.rows - self.done) as f64
                });
                eprintln!(
                    "profile: {line}; {}/{} rows, about {left:.0} s left",
                    self.done, self.rows
                );
            }
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

/// A profile in progress.
struct Run<'a> {
    setup: &'a ProfileSetup,
    start: Instant,
    pace: Pace,
    samples: Option<Samples>,
    table_1nm: ColourTable,
    /// The mesh view by the reference variant at 1 nm, for `--per-vertex`.
    mesh_reference: Option<Vec<[f64; 3]>>,
    progress: Progress,
    /// Per row of `setup.variants`: its report (and its per-vertex twin), or why not.
    done: Vec<Option<RowOutcome>>,
    /// The height field, loaded once for every row.
    heightfield: crate::heightfield::HeightField,
    /// Whether a row was measured (until then the pace is the prior's, and the first row
    /// is measured whatever its estimate).
    measured: bool,
}

/// Renders and scores every row. The reference (1 nm, direct sum) is computed once at the
/// sampled pixels, so its cost is `pixels × N² × 401` complex multiply-adds.
pub fn profile(renderer: &mut Renderer, setup: &ProfileSetup) -> Result<ProfileRun> {
    if setup.variants.is_empty() {
        return Err(Error::invalid("variants", "none to profile"));
    }
    if setup.pixels + setup.brightest == 0 || setup.frames == Frames::Fixed(0) {
        return Err(Error::invalid(
            "profile",
            "at least one scored pixel and one frame are needed",
        ));
    }
    let start = Instant::now();
    let heightfield = setup.base.load_heightfield(&crate::report::Stderr)?;
    let mut run = Run {
        setup,
        start,
        heightfield,
        measured: false,
        pace: Pace::PRIOR,
        samples: None,
        table_1nm: ColourTable::new(1)?,
        mesh_reference: None,
        progress: Progress::new(setup.variants.len()),
        done: vec![None; setup.variants.len()],
    };
    renderer.set_keep_models(true);
    renderer.set_cache_dir(setup.cache_dir.clone());
    let result = run.rows(renderer);
    renderer.set_keep_models(false);
    renderer.set_leave_out(false);
    renderer.set_report(std::sync::Arc::new(crate::report::Stderr));
    result?;
    let mut out = ProfileRun::default();
    for row in run.done.into_iter().flatten() {
        match row {
            RowOutcome::Measured(reports) => out.reports.extend(reports),
            RowOutcome::Skipped(skipped) => out.skipped.push(skipped),
        }
    }
    out.wall_s = run.start.elapsed().as_secs_f64();
    out.scored = run.samples.as_ref().map_or(0, |s| s.0.len());
    Ok(out)
}

impl Run<'_> {
    /// The mesh reference, then every row, cheapest first when budgeted.
    fn rows(&mut self, renderer: &mut Renderer) -> Result<()> {
        if self.progress.bar.is_none() {
            let how = match self.setup.frames {
                Frames::Fixed(n) => format!("{n} frames a row"),
                Frames::Budget(b) => format!("a budget of {:.0} s", b.total_s),
            };
            eprintln!(
                "profile: {} rows, {how}; a line as each row finishes",
                self.setup.variants.len()
            );
        }
        if let (Some(scene), true) = (&self.setup.mesh, self.setup.per_vertex) {
            self.progress.started("mesh reference (per pixel, 1 nm)");
            self.mesh_reference = Some(mesh_reference(renderer, self.setup, scene)?);
        }
        for i in self.order() {
            let row = &self.setup.variants[i];
            self.progress.started(&row.name);
            let outcome = self.row(renderer, i)?;
            let line = match &outcome {
                RowOutcome::Measured(reports) => row_line(&reports[0]),
                RowOutcome::Skipped(s) => skipped_line(s),
            };
            self.done[i] = Some(outcome);
            let left = self.budget().map(|b| self.left_s(&b));
            self.progress.finished(&line, left);
        }
        Ok(())
    }

    fn budget(&self) -> Option<Budget> {
        match self.setup.frames {
            Frames::Budget(b) => Some(b),
            Frames::Fixed(_) => None,
        }
    }

    /// Budget left (s).
    fn left_s(&self, budget: &Budget) -> f64 {
        (budget.total_s - self.start.elapsed().as_secs_f64()).max(0.0)
    }

    /// The order rows are measured in: as given, or, with a budget, by estimated cost
    /// (cheapest first, so a tight budget measures as many rows as it can).
    fn order(&self) -> Vec<usize> {
        let mut order: Vec<usize> = (0..self.setup.variants.len()).collect();
        if self.budget().is_some() {
            // Tables by their planes at an assumed pace: fewer planes are tried first.
            let cost: Vec<f64> = self
                .setup
                .variants
                .iter()
                .map(|v| {
                    let (ms, planes) = self.estimate(v);
                    ms + planes as f64 * Pace::PRIOR_TABLE_MS_PER_PLANE
                })
                .collect();
            order.sort_by(|&a, &b| cost[a].total_cmp(&cost[b]));
        }
        order
    }

    /// Estimated cost of a row's warm-up and one timed frame (ms), with its table's build
    /// once a build's pace is known; and the `(w, λ)` planes its table samples.
    fn estimate(&self, row: &Variant) -> (f64, usize) {
        let material = row.material(&self.setup.base);
        let (lo, hi) = self.heightfield.range();
        let wi = direction(self.setup.theta_i_deg, self.setup.phi_i_deg);
        let inputs = crate::render::variant::FetchInputs {
            terms: row.terms,
            material: &material,
            table: &row.table,
            region: crate::render::variant::map_region(wi),
            h_range_um: hi - lo,
            leave_out: row.leave_out,
            heightfield: None,
        };
        let fetches = row.kind.fetches(&inputs);
        let step = row
            .table
            .step_nm
            .unwrap_or(TableOptions::DEFAULT_STEP_NM)
            .max(1);
        let planes = match row.kind.footprint(&inputs) {
            Some(Ok(f)) => f.planes * (400 / step as usize + 1),
            _ => 0,
        };
        let build = planes as f64 * self.pace.table_ms_per_plane.unwrap_or(0.0);
        (
            self.pace.prepare_ms + 2.0 * self.pace.frame_ms(fetches, self.setup.size) + build,
            planes,
        )
    }

    fn estimate_ms(&self, row: &Variant) -> f64 {
        self.estimate(row).0
    }
}

/// The line a finished row gets on stderr.
fn row_line(r: &VariantReport) -> String {
    let spread = r
        .spread_ms
        .map_or(String::new(), |(a, b)| format!(" (p10–p90 {a:.2}–{b:.2})"));
    format!(
        "{}: warm-up {:.1} s, {} frames, median {} ms{spread}, rel L2 {:.2e} [{:.2e}, {:.2e}]",
        r.variant.name,
        r.warm_up_ms / 1e3,
        r.frames,
        ms(r.gpu_ms.or(Some(r.wall_ms))),
        r.vs_reference.rel_l2,
        r.intervals.rel_l2.lo,
        r.intervals.rel_l2.hi
    )
}

/// The line a skipped row gets on stderr.
fn skipped_line(s: &Skipped) -> String {
    format!("{}: skipped, {}", s.variant.name, s.reason)
}

/// The mesh view of `scene` by [`VariantKind::REFERENCE`] per pixel at 1 nm, keeping
/// everything (on the map it matches the f64 direct sum to 9e-5 rel L2, README).
fn mesh_reference(
    renderer: &mut Renderer,
    setup: &ProfileSetup,
    scene: &Scene,
) -> Result<Vec<[f64; 3]>> {
    let kind = VariantKind::REFERENCE;
    let reference = Variant {
        name: "mesh reference".into(),
        kind,
        expansion: Expansion::Taylor,
        terms: setup
            .variants
            .iter()
            .map(|v| v.terms)
            .max()
            .unwrap_or(30)
            .max(1),
        window_radius: 2,
        lambda_step_nm: 1,
        storage: StorageFormat::Rg32f,
        table: TableOptions::default(),
        leave_out: false,
    };
    renderer.set_leave_out(false);
    let prepared = reference
        .material(&setup.base)
        .prepare(setup.cache_dir.as_deref(), &crate::report::Stderr)?;
    renderer.set_variant(kind);
    renderer.set_storage_format(StorageFormat::Rg32f);
    renderer.set_per_vertex(false);
    let f = renderer.render_scene(scene, &prepared)?;
    Ok(f.rgb.iter().map(|c| c.map(f64::from)).collect())
}

/// What a row's scoring found.
struct Scores {
    vs_reference: ErrorStats,
    intervals: ErrorIntervals,
    vs_model: ErrorStats,
    reference_dark: bool,
    conditioning: Option<f64>,
    overshoot: Option<f64>,
}

/// A row's timed frames.
struct Timed {
    times: FrameTimes,
    wall: Vec<f64>,
    last: Picture,
}

/// How a row ended: its report (and its per-vertex twin), or why it was skipped.
#[derive(Clone)]
enum RowOutcome {
    Measured(Vec<VariantReport>),
    Skipped(Skipped),
}

impl Run<'_> {
    /// Measures row `i`: its warm-up (which prepares it), its timed frames, its scores and
    /// its mesh views; or says why it was skipped.
    fn row(&mut self, renderer: &mut Renderer, i: usize) -> Result<RowOutcome> {
        let setup = self.setup;
        let row = &setup.variants[i];
        let skipped = |estimated_s, reason| Skipped {
            variant: row.clone(),
            estimated_s,
            reason,
        };
        let row_start = Instant::now();
        let (deadline, frames_end) = match self.budget() {
            None => (None, None),
            Some(b) => {
                // Greedy: cheapest first, each row while its estimate fits what is left.
                let allowance = self.left_s(&b);
                let est = self.estimate_ms(row) / 1e3;
                if est > allowance && self.measured {
                    let why = format!(
                        "estimated {est:.1} s, over the {allowance:.1} s left of the budget"
                    );
                    return Ok(RowOutcome::Skipped(skipped(Some(est), why)));
                }
                let rows_left = self.done.iter().filter(|d| d.is_none()).count().max(1);
                let fair = self.left_s(&b) / rows_left as f64;
                let at = |s: f64| row_start + std::time::Duration::from_secs_f64(s);
                (Some(at(allowance)), Some(at(fair.min(allowance))))
            }
        };
        let material = row.material(&setup.base);
        // The terms are computed (or read from the cache) only if the row's variant reads
        // them: a table variant builds from the height field.
        let plan = material.plan_loaded(
            &self.heightfield,
            &crate::brdf::truncation::Reach::ALL,
            crate::brdf::truncation::Precision::F32,
            &crate::report::Stderr,
        )?;
        let prepared = material.prepare_planned_deferred(
            self.heightfield.clone(),
            plan,
            setup.cache_dir.as_deref(),
        )?;
        renderer.set_variant(row.kind);
        renderer.set_storage_format(row.storage);
        renderer.set_table_options(row.table);
        renderer.set_leave_out(row.leave_out);
        let warm = match self.warm_up(renderer, &prepared, deadline) {
            Ok(f) => f,
            Err(Warm::Refused(e)) => {
                return Ok(RowOutcome::Skipped(skipped(None, format!("refused: {e}"))))
            }
            Err(Warm::OverBudget(over)) => {
                let est = over.projected_s;
                self.pace.table_ms_per_plane = Some(1e3 * est / over.steps.max(1) as f64);
                let why = format!(
                    "its table build would take about {est:.0} s, over the time left of the budget (a table built once, by a larger --budget-s or --full, is read from the cache after)"
                );
                return Ok(RowOutcome::Skipped(skipped(Some(est), why)));
            }
            Err(Warm::Failed(e)) => return Err(e),
        };
        let warm_ms = row_start.elapsed().as_secs_f64() * 1e3;
        let timed = self.timed_frames(renderer, &prepared, frames_end)?;
        let built_ms = match &warm.variant.table_build {
            Some(b) if !b.contains("cache") => warm.variant.build_ms,
            _ => 0.0,
        };
        let planes = self.estimate(row).1;
        if built_ms > 0.0 && planes > 0 {
            self.pace.table_ms_per_plane = Some(built_ms / planes as f64);
        }
        let frame_ms = crate::render::median(timed.wall.clone()).unwrap_or(warm.wall_ms);
        self.pace.learn(
            warm.variant.fetches,
            setup.size,
            frame_ms,
            warm_ms,
            built_ms,
        );
        self.measured = true;
        let scores = self.score(renderer, &prepared, &material, &timed.last)?;
        self.reports(renderer, row, &prepared, timed, scores)
            .map(|mut reports| {
                for r in &mut reports {
                    r.warm_up_ms = warm_ms;
                }
                RowOutcome::Measured(reports)
            })
    }

    /// The warm-up frame, which builds (or uploads) the row's resources; with a deadline,
    /// a table build that would end past it is stopped.
    fn warm_up(
        &self,
        renderer: &mut Renderer,
        prepared: &PreparedMaterial,
        deadline: Option<Instant>,
    ) -> std::result::Result<Picture, Warm> {
        renderer.set_report(std::sync::Arc::new(Deadline::new(deadline)));
        let drawn = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            draw_map(renderer, prepared, self.setup)
        }));
        renderer.set_report(std::sync::Arc::new(crate::report::Stderr));
        match drawn {
            Ok(Ok(f)) => Ok(f),
            // A row that refuses this material (nmm without a dominant period).
            Ok(Err(e @ Error::Invalid { .. })) => Err(Warm::Refused(e)),
            Ok(Err(e)) => Err(Warm::Failed(e)),
            Err(payload) => match payload.downcast::<OverBudget>() {
                Ok(over) => Err(Warm::OverBudget(*over)),
                Err(payload) => std::panic::resume_unwind(payload),
            },
        }
    }

    /// The timed frames: a fixed count, or, with a budget, until the median is known to
    /// the budget's precision or the next frame would end past `end`.
    fn timed_frames(
        &self,
        renderer: &mut Renderer,
        prepared: &PreparedMaterial,
        end: Option<Instant>,
    ) -> Result<Timed> {
        let mut times = FrameTimes::default();
        let mut wall: Vec<f64> = Vec::new();
        let mut last = None;
        loop {
            let n = wall.len();
            let more = match (self.setup.frames, end) {
                (Frames::Fixed(k), _) => n < k,
                (Frames::Budget(b), Some(end)) => {
                    let next = std::time::Duration::from_secs_f64(
                        wall.last().copied().unwrap_or(0.0) / 1e3,
                    );
                    n == 0
                        || (n < b.max_frames
                            && times.relative_error().is_none_or(|e| e > b.precision)
                            && Instant::now() + next <= end)
                }
                (Frames::Budget(_), None) => n == 0,
            };
            if !more {
                break;
            }
            let f = draw_map(renderer, prepared, self.setup)?;
            times.0.push(f.gpu_ms.unwrap_or(f.wall_ms));
            wall.push(f.wall_ms);
            last = Some(f);
        }
        let last = last.ok_or_else(|| Error::invalid("profile", "no timed frame"))?;
        Ok(Timed { times, wall, last })
    }
}

/// How a warm-up ended without a frame.
enum Warm {
    Refused(Error),
    OverBudget(OverBudget),
    Failed(Error),
}

/// The row's BRDF map.
fn draw_map(
    renderer: &mut Renderer,
    prepared: &PreparedMaterial,
    setup: &ProfileSetup,
) -> Result<Picture> {
    renderer.render_brdf_map(
        prepared,
        setup.theta_i_deg,
        setup.phi_i_deg,
        setup.size,
        None,
    )
}

impl Run<'_> {
    /// The scored pixels and their reference XYZ, fixed by the first measured row's map.
    fn samples(&mut self, prepared: &PreparedMaterial, frame: &Picture) -> Samples {
        if let Some(s) = &self.samples {
            return s.clone();
        }
        let setup = self.setup;
        let mut pixels = pick_pixels(&frame.rgb, setup.size, setup.brightest, setup.pixels);
        // With a budget the reference takes at most its share of it: pixels in the order
        // picked (any prefix holds bright and spread ones, spread over the disk), at least
        // REFERENCE_MIN_PIXELS.
        let limit = self
            .budget()
            .map(|b| self.start + std::time::Duration::from_secs_f64(REFERENCE_SHARE * b.total_s));
        let bar = crate::progress::bar(pixels.len() as u64, "f64 reference at 1 nm");
        let started = Instant::now();
        let mut refs: Vec<[f64; 3]> = Vec::with_capacity(pixels.len());
        for chunk in pixels.chunks(4) {
            if let Some(limit) = limit {
                let per_pixel = started.elapsed().as_secs_f64() / refs.len().max(1) as f64;
                let next = std::time::Duration::from_secs_f64(per_pixel * chunk.len() as f64);
                if refs.len() >= REFERENCE_MIN_PIXELS && Instant::now() + next > limit {
                    break;
                }
            }
            let wrs: Vec<[f64; 3]> = chunk.iter().map(|p| wr_of(setup, p)).collect();
            refs.extend(reference::xyz_many(
                &prepared.heightfield,
                prepared.material.coherence_um,
                &prepared.shading,
                &self.table_1nm,
                direction(setup.theta_i_deg, setup.phi_i_deg),
                &wrs,
                &|| bar.inc(1),
            ));
        }
        bar.finish_and_clear();
        let asked = pixels.len();
        pixels.truncate(refs.len());
        if self.progress.bar.is_none() || pixels.len() < asked {
            eprintln!(
                "profile: f64 reference at 1 nm at {} of {asked} pixels: {:.1} s",
                pixels.len(),
                started.elapsed().as_secs_f64()
            );
        }
        self.samples = Some((pixels, refs));
        self.samples.clone().unwrap_or_default()
    }

    /// The map's errors against the reference and against the row's own CPU model, and
    /// what its table says about itself.
    fn score(
        &mut self,
        renderer: &Renderer,
        prepared: &PreparedMaterial,
        material: &Material,
        frame: &Picture,
    ) -> Result<Scores> {
        let setup = self.setup;
        let (pixels, refs) = self.samples(prepared, frame);
        let gpu_xyz: Vec<[f64; 3]> = pixels
            .iter()
            .map(|&(i, j)| frame.at(i, j).map(f64::from))
            .collect();
        let wi = direction(setup.theta_i_deg, setup.phi_i_deg);
        // ωi as uploaded (float32), so the model sees what the shader saw.
        let wi32 = wi.map(|c| c as f32 as f64);
        let model: &dyn CpuModel = renderer.model().ok_or_else(|| {
            Error::invalid(
                "profile",
                format!("{} has no CPU model to score against", frame.variant.name),
            )
        })?;
        let colour = kept_colour(renderer, prepared);
        let modelled: Vec<[f64; 3]> = pixels
            .iter()
            .map(|p| model.xyz(prepared, &colour, wi32, wr_of(setup, p)))
            .collect::<Result<_>>()?;
        // Dark: every reference sample lies under the error the variants promise there,
        // the tolerance on ρ/C (relative to a mirror's specular value) times the gain C.
        let reference_dark = pixels.iter().zip(&refs).all(|(p, r)| {
            let c = crate::brdf::gain(wi, wr_of(setup, p), &prepared.shading);
            c <= 0.0 || r[1] < material.tolerance * c
        });
        let table = model.table();
        Ok(Scores {
            vs_reference: error_stats(&gpu_xyz, &refs),
            intervals: bootstrap(&gpu_xyz, &refs),
            vs_model: error_stats(&gpu_xyz, &modelled),
            reference_dark,
            conditioning: table.and_then(|t| t.conditioning()),
            overshoot: table.map(|t| overshoot(t, setup, wi32)),
        })
    }
}

/// `ωr` of map pixel `(i, j)`.
fn wr_of(setup: &ProfileSetup, &(i, j): &(u32, u32)) -> [f64; 3] {
    map_direction(i, j, setup.size).unwrap_or([0.0, 0.0, 1.0])
}

/// The material's colour table with the wavelengths the row left out at weight 0 (its
/// model integrates the kept ones only).
fn kept_colour(renderer: &Renderer, prepared: &PreparedMaterial) -> ColourTable {
    let mut c = prepared.colour.clone();
    if let Some(w) = renderer.left_out().and_then(|l| l.wavelengths) {
        if w.place == "per pixel" {
            for (l, wt) in c.lambdas_nm.iter().zip(c.weights.iter_mut()) {
                if !w.kept_nm.iter().any(|k| (k - l).abs() < 1e-9) {
                    *wt = [0.0; 3];
                }
            }
        }
    }
    c
}

/// The most negative `G` of `table`'s interpolant over the map before the clamp, relative
/// to the map's largest `G_Y`.
fn overshoot(table: &dyn crate::brdf::table::GTable, setup: &ProfileSetup, wi32: [f64; 3]) -> f64 {
    let (mut lowest, mut peak) = (0.0f64, 0.0f64);
    for k in 0..setup.size * setup.size {
        let Some(wr) = map_direction(k % setup.size, k / setup.size, setup.size) else {
            continue;
        };
        if let Some(g) = table.g_unclamped(crate::brdf::uvw(wi32, wr)) {
            peak = peak.max(g[1]);
            lowest = g.iter().fold(lowest, |m, x| m.min(*x));
        }
    }
    if peak > 0.0 {
        lowest / peak
    } else {
        0.0
    }
}

impl Run<'_> {
    /// The mesh view of the row's prepared variant: its median GPU time and last picture.
    fn mesh_view(
        &self,
        renderer: &mut Renderer,
        prepared: &PreparedMaterial,
        per_vertex: bool,
        frames: usize,
    ) -> Result<Option<(f64, Vec<[f32; 3]>)>> {
        let Some(scene) = &self.setup.mesh else {
            return Ok(None);
        };
        renderer.set_per_vertex(per_vertex);
        let mut last = renderer.render_scene(scene, prepared)?;
        let mut t = Vec::new();
        for _ in 0..frames.max(1) {
            last = renderer.render_scene(scene, prepared)?;
            t.extend(last.gpu_ms);
        }
        renderer.set_per_vertex(false);
        Ok(crate::render::median(t).map(|ms| (ms, last.rgb)))
    }

    /// A mesh view against the reference variant's mesh render (with `--per-vertex`).
    fn mesh_error(&self, rgb: &[[f32; 3]]) -> Option<ErrorStats> {
        let reference = self.mesh_reference.as_ref()?;
        let xyz: Vec<[f64; 3]> = rgb
            .iter()
            .map(|c| linear_srgb_to_xyz(c.map(f64::from)))
            .collect();
        let refs: Vec<[f64; 3]> = reference.iter().map(|c| linear_srgb_to_xyz(*c)).collect();
        Some(error_stats(&xyz, &refs))
    }

    /// The row's report, after its per-vertex twin's where it has one.
    fn reports(
        &self,
        renderer: &mut Renderer,
        row: &Variant,
        prepared: &PreparedMaterial,
        timed: Timed,
        scores: Scores,
    ) -> Result<Vec<VariantReport>> {
        let frames = timed.wall.len();
        let mesh = self.mesh_view(renderer, prepared, false, frames)?;
        let v = &timed.last.variant;
        let report = VariantReport {
            variant: row.clone(),
            gpu_ms: timed.last.gpu_ms.and_then(|_| timed.times.median()),
            spread_ms: timed.times.quantile(0.1).zip(timed.times.quantile(0.9)),
            frames,
            warm_up_ms: 0.0,
            wall_ms: crate::render::median(timed.wall).unwrap_or(timed.last.wall_ms),
            build_ms: v.build_ms,
            gpu_bytes: v.gpu_bytes,
            fetches: v.fetches,
            detail: match &v.table_build {
                Some(built) => format!("{}, table {built}", v.name),
                None => v.name.clone(),
            },
            mesh_gpu_ms: mesh.as_ref().map(|m| m.0),
            conditioning: scores.conditioning,
            overshoot: scores.overshoot,
            reference_dark: scores.reference_dark,
            vs_reference: scores.vs_reference,
            intervals: scores.intervals,
            vs_model: scores.vs_model,
            mesh_vs_reference: mesh.as_ref().and_then(|m| self.mesh_error(&m.1)),
            per_vertex: false,
        };
        let mut out = vec![report];
        if self.setup.per_vertex && row.kind.per_vertex_file().is_some() {
            if let Some((ms, rgb)) = self.mesh_view(renderer, prepared, true, frames)? {
                let r = &out[0];
                out.push(VariantReport {
                    variant: Variant {
                        name: format!("{} per-vertex", row.name),
                        ..row.clone()
                    },
                    gpu_ms: None,
                    spread_ms: None,
                    wall_ms: 0.0,
                    detail: format!("{} per-vertex", v.name),
                    mesh_gpu_ms: Some(ms),
                    conditioning: None,
                    overshoot: None,
                    mesh_vs_reference: self.mesh_error(&rgb),
                    per_vertex: true,
                    ..r.clone()
                });
            }
        }
        Ok(out)
    }
}

/// Share of the budget the reference may take, and the fewest pixels it scores.
const REFERENCE_SHARE: f64 = 0.4;
const REFERENCE_MIN_PIXELS: usize = 8;

/// Pixels to score: the `bright` brightest of `map` and `spread` more spread evenly over the
/// rest of the disk, each at most once; in an order whose every prefix holds bright and
/// spread pixels in proportion, the spread ones spread over the disk.
fn pick_pixels(map: &[[f32; 3]], size: u32, bright: usize, spread: usize) -> Vec<(u32, u32)> {
    let mut inside: Vec<(u32, u32, f32)> = (0..size * size)
        .filter_map(|k| {
            let (i, j) = (k % size, k / size);
            map_direction(i, j, size).map(|_| (i, j, map[k as usize][1]))
        })
        .collect();
    inside.sort_by(|a, b| b.2.total_cmp(&a.2));
    let bright = bright.min(inside.len());
    let brightest: Vec<(u32, u32)> = inside[..bright].iter().map(|p| (p.0, p.1)).collect();
    let rest = &inside[bright..];
    let spread = spread.min(rest.len());
    let mut order: Vec<(u32, u32)> = rest.iter().map(|p| (p.0, p.1)).collect();
    order.sort_unstable_by_key(|&(i, j)| (j, i));
    // Strided picks, visited in bit-reversed order: a prefix samples the whole disk.
    let bits = usize::BITS - spread.max(1).leading_zeros();
    let spread: Vec<(u32, u32)> = (0..1usize << bits)
        .map(|s| s.reverse_bits() >> (usize::BITS - bits))
        .filter(|&s| s < spread)
        .map(|s| order[s * order.len() / spread])
        .collect();
    let (nb, n) = (brightest.len(), brightest.len() + spread.len());
    let (mut b, mut s) = (
        brightest.into_iter().peekable(),
        spread.into_iter().peekable(),
    );
    let mut picked = Vec::with_capacity(n);
    let mut taken_bright = 0;
    for k in 0..n {
        let from_bright = match (b.peek().is_some(), s.peek().is_some()) {
            (true, true) => taken_bright * n < (k + 1) * nb,
            (bright_left, _) => bright_left,
        };
        if from_bright {
            picked.extend(b.next());
            taken_bright += 1;
        } else {
            picked.extend(s.next());
        }
    }
    picked
}

#[cfg(test)]
mod pick_tests {
    use super::*;

    #[test]
    fn every_prefix_of_the_picked_pixels_mixes_bright_and_spread_ones() {
        let size = 33;
        let map: Vec<[f32; 3]> = (0..size * size).map(|k| [0.0, k as f32, 0.0]).collect();
        let picked = pick_pixels(&map, size as u32, 8, 16);
        assert_eq!(picked.len(), 24);
        let mut unique = picked.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), 24, "each pixel once");
        // The brightest are the last rows of this map (its Y grows with the index).
        let bright = |p: &(u32, u32)| p.1 >= 28;
        let first: Vec<_> = picked[..6].to_vec();
        assert!(first.iter().any(bright) && first.iter().any(|p| !bright(p)));
        // The spread ones among the first six lie in both halves of the disk.
        let spread: Vec<_> = first.iter().filter(|p| !bright(p)).collect();
        assert!(spread.iter().any(|p| p.1 < 16) && spread.iter().any(|p| p.1 >= 16));
    }
}

fn ms(v: Option<f64>) -> String {
    v.map_or("n/a".into(), |g| format!("{g:.2}"))
}

/// The table's first line: the device, the map, the pixels and how frames were counted.
fn header(device: &str, setup: &ProfileSetup, run: &ProfileRun) -> String {
    let mesh = setup.mesh.as_ref().map_or(String::new(), |s| {
        format!("; mesh view {}×{}", s.output.width, s.output.height)
    });
    let frames = match setup.frames {
        Frames::Fixed(n) => format!("GPU ms = median of {n} frames after a warm-up"),
        Frames::Budget(b) => format!(
            "budget {:.0} s ({:.0} s spent): each row draws frames after a warm-up until its median's standard error is under {:.0} % or its share of the budget is spent; GPU ms = their median, p10–p90 their spread",
            b.total_s,
            run.wall_s,
            100.0 * b.precision
        ),
    };
    let asked = setup.brightest + setup.pixels;
    let scored = if run.scored < asked {
        format!(
            "{} of {asked} scored pixels (the reference's share of the budget ran out; {} brightest + {} spread asked)",
            run.scored, setup.brightest, setup.pixels
        )
    } else {
        format!(
            "{asked} scored pixels ({} brightest + {} spread)",
            setup.brightest, setup.pixels
        )
    };
    format!(
        "device: {device}; BRDF map {}² at θi = {}°, φi = {}°{mesh}; {scored}, errors against the reference with 95 % bootstrap intervals over them; {frames}; reference: f64 direct sum at 1 nm\n\n",
        setup.size,
        setup.theta_i_deg,
        setup.phi_i_deg,
    )
}

/// One row of the Markdown table (`mesh_cols`: the per-vertex columns, or empty).
fn table_row(r: &VariantReport, mesh_cols: &str) -> String {
    if r.per_vertex {
        return format!(
            "| {} | — | — | — | — | — | — | {} | — | — | — | — | — | — |{mesh_cols}\n",
            r.variant.name,
            ms(r.mesh_gpu_ms)
        );
    }
    let e = &r.vs_reference;
    let i = &r.intervals;
    let errors = if r.reference_dark {
        format!("reference dark | {:.2e} | — | — | —", e.max_abs_y)
    } else {
        format!(
            "{:.2e} ({:.2e}–{:.2e}) | {:.2e} | {:.3} | {:.3} ({:.3}–{:.3}) | {:.3}",
            e.rel_l2,
            i.rel_l2.lo,
            i.rel_l2.hi,
            e.max_abs_y,
            e.p50_de,
            e.p99_de,
            i.p99_de.lo,
            i.p99_de.hi,
            e.max_de
        )
    };
    let spread = r
        .spread_ms
        .map_or("—".to_string(), |(a, b)| format!("{a:.2}–{b:.2}"));
    format!(
        "| {} | {} | {:.0} | {:.1} | {} | {} | {spread} | {} | {errors} | {:.2e} |{mesh_cols}\n",
        r.variant.name,
        r.fetches,
        r.build_ms,
        r.gpu_bytes as f64 / 1e6,
        r.frames,
        ms(r.gpu_ms),
        ms(r.mesh_gpu_ms),
        r.vs_model.rel_l2
    )
}

/// Formats a profile as a Markdown table, then its notes: skipped rows, dark references,
/// conditioning and overshoot.
pub fn format_table(device: &str, setup: &ProfileSetup, run: &ProfileRun) -> String {
    let reports = &run.reports;
    let mut s = header(device, setup, run);
    let mesh_scored = reports.iter().any(|r| r.mesh_vs_reference.is_some());
    if mesh_scored {
        s.push_str("Per-vertex rows (thesis §1.5.1) measure the mesh view only: `mesh GPU ms` evaluated per vertex, and the last two columns, the mesh view against a per-pixel render of it by the reference variant at 1 nm (rel L2 of XYZ, ΔE2000 p99). A BRDF map has no vertices: their map columns are `—`.\n\n");
    }
    s.push_str("| variant | fetches/px | build ms | GPU MB | frames | GPU ms | p10–p90 ms | mesh GPU ms | rel L2 vs ref (95 %) | max ΔY vs ref | ΔE p50 | ΔE p99 (95 %) | max ΔE | rel L2 vs f64 model |");
    s.push_str(if mesh_scored {
        " mesh rel L2 vs 1 nm | mesh ΔE p99 |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    } else {
        "\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    });
    for r in reports {
        let mesh_cols = if mesh_scored {
            r.mesh_vs_reference.map_or(" — | — |".to_string(), |m| {
                format!(" {:.2e} | {:.3} |", m.rel_l2, m.p99_de)
            })
        } else {
            String::new()
        };
        s.push_str(&table_row(r, &mesh_cols));
    }
    s.push_str(&notes(run));
    s
}

/// The notes under the table.
fn notes(run: &ProfileRun) -> String {
    let reports = &run.reports;
    let mut s = String::new();
    for k in &run.skipped {
        s.push_str(&format!("\nskipped: {}: {}\n", k.variant.name, k.reason));
    }
    if reports.iter().any(|r| r.reference_dark) {
        s.push_str("\nreference dark: every reference sample is below the tolerance times its gain C (ρ/C under the tolerance of a mirror's specular value), the error every variant is allowed there; relative errors and ΔE of a dark map measure noise, so only max ΔY is shown.\n");
    }
    for r in reports {
        if let Some(k) = r.conditioning {
            s.push_str(&format!(
                "\n{}: condition number of its sum {k:.2e}; × float32's 6e-8 ≈ {:.1e} relative error expected\n",
                r.variant.name,
                k * 6e-8
            ));
        }
    }
    let over: Vec<String> = reports
        .iter()
        .filter_map(|r| Some(format!("{} {:.1e}", r.variant.name, r.overshoot?)))
        .collect();
    if !over.is_empty() {
        s.push_str(&format!(
            "\novershoot (most negative G of the interpolant over the map before the clamp to G ≥ 0, relative to the peak G_Y): {}\n",
            over.join(", ")
        ));
    }
    s
}

/// The CSV of a profile: a line per measured row with every figure of the table and the
/// intervals; a skipped row has its name, its settings, `skipped`, the reason and its
/// estimated cost only.
pub fn format_csv(run: &ProfileRun) -> String {
    let mut csv = String::from("variant,expansion,terms,window_radius,lambda_step_nm,storage,gpu_ms,wall_ms,rel_l2_ref,max_abs_y_ref,mean_de_ref,max_de_ref,rel_l2_model,kind,detail,fetches,build_ms,gpu_bytes,mesh_gpu_ms,p50_de_ref,p99_de_ref,p99_de_model,conditioning,per_vertex,mesh_rel_l2_ref,mesh_p99_de_ref,overshoot,reference_dark,leave_out,frames,gpu_ms_p10,gpu_ms_p90,rel_l2_ref_lo,rel_l2_ref_hi,p99_de_ref_lo,p99_de_ref_hi,skipped,estimated_s\n");
    let opt = |v: Option<f64>| v.map_or(String::new(), |g| g.to_string());
    let settings = |v: &Variant| {
        format!(
            "{},{},{},{},{},{:?}",
            v.name, v.expansion, v.terms, v.window_radius, v.lambda_step_nm, v.storage
        )
    };
    for r in &run.reports {
        let v = &r.variant;
        let (e, m, i) = (&r.vs_reference, &r.vs_model, &r.intervals);
        let columns = [
            opt(r.gpu_ms),
            r.wall_ms.to_string(),
            e.rel_l2.to_string(),
            e.max_abs_y.to_string(),
            e.mean_de.to_string(),
            e.max_de.to_string(),
            m.rel_l2.to_string(),
            v.kind.to_string(),
            r.detail.replace(',', ";"),
            r.fetches.to_string(),
            r.build_ms.to_string(),
            r.gpu_bytes.to_string(),
            opt(r.mesh_gpu_ms),
            e.p50_de.to_string(),
            e.p99_de.to_string(),
            m.p99_de.to_string(),
            opt(r.conditioning),
            r.per_vertex.to_string(),
            opt(r.mesh_vs_reference.map(|m| m.rel_l2)),
            opt(r.mesh_vs_reference.map(|m| m.p99_de)),
            opt(r.overshoot),
            r.reference_dark.to_string(),
            v.leave_out.to_string(),
            r.frames.to_string(),
            opt(r.spread_ms.map(|s| s.0)),
            opt(r.spread_ms.map(|s| s.1)),
            i.rel_l2.lo.to_string(),
            i.rel_l2.hi.to_string(),
            i.p99_de.lo.to_string(),
            i.p99_de.hi.to_string(),
            "false".to_string(),
            String::new(),
        ];
        csv.push_str(&format!("{},{}\n", settings(v), columns.join(",")));
    }
    for k in &run.skipped {
        let mut columns = vec![String::new(); 32];
        columns[7] = k.variant.kind.to_string();
        columns[8] = k.reason.replace(',', ";");
        columns[22] = k.variant.leave_out.to_string();
        columns[30] = "true".to_string();
        columns[31] = opt(k.estimated_s);
        csv.push_str(&format!("{},{}\n", settings(&k.variant), columns.join(",")));
    }
    csv
}

/// `diffract profile` options.
#[derive(Debug, Clone, clap::Args)]
pub struct ProfileArgs {
    #[command(flatten)]
    pub material: MaterialArgs,
    /// Taylor terms T of the FLSS variants (Chebyshev gets ⌈2T/3⌉).
    #[arg(long = "variant-terms", default_value_t = 30)]
    pub variant_terms: usize,
    /// Profile only these (comma-separated names from the table; default: all).
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// Polar angle of the light (degrees).
    #[arg(long, default_value_t = 60.0)]
    pub theta_i: f64,
    /// Azimuth of the light (degrees).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub phi_i: f64,
    /// Wall-time budget of the whole profile in seconds: rows are measured cheapest first,
    /// each draws frames until its median is known to 5 % or its share is spent, and a row
    /// that does not fit is reported as skipped with its estimated cost.
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
    // The user's numbers and height field are checked before the device opens (each
    // variant loads the field again when it prepares; that is cheap next to its terms).
    base.validate()?;
    base.load_heightfield(&crate::report::Stderr)?;
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
    let run = profile(&mut renderer, &setup)?;
    print!("{}", format_table(renderer.device_name(), &setup, &run));
    if let Some(path) = &args.csv {
        crate::fsutil::write_atomic(path, format_csv(&run).as_bytes())?;
    }
    if let Some(path) = &args.plot {
        write_plot(path, &setup, &run.reports, renderer.device_name())?;
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

/// The rows of every registered variant, or those `--only` names.
fn selected_rows(args: &ProfileArgs) -> Result<Vec<Variant>> {
    let mut variants = flss_variants(args.variant_terms);
    variants.extend(table_variants(&args.table.options()));
    if args.only.is_empty() {
        return Ok(variants);
    }
    for name in &args.only {
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

/// The Pareto plot of error against GPU time: the map rows, and the per-vertex rows with
/// their per-pixel twins on the mesh view.
fn write_plot(
    path: &std::path::Path,
    setup: &ProfileSetup,
    reports: &[VariantReport],
    device: &str,
) -> Result<()> {
    // A dark reference's relative errors are noise: such rows are not plotted, and a map
    // that is dark for every row gives no plot at all.
    if reports.iter().all(|r| r.reference_dark) {
        return Err(Error::invalid(
            "plot",
            format!(
                "the reference map is dark (every sample below the tolerance), so its relative errors are noise and {} is not written; lobes narrower than a pixel are missed by a small map: try a larger or odd --size (an odd map's middle row lies in the plane of incidence)",
                path.display()
            ),
        ));
    }
    let mut points: Vec<crate::plot::Point> = reports
        .iter()
        .filter(|r| !r.reference_dark)
        .filter_map(|r| {
            r.gpu_ms.map(|t| crate::plot::Point {
                label: r.variant.name.clone(),
                time_ms: t,
                error: r.vs_reference.rel_l2,
            })
        })
        .collect();
    points.extend(reports.iter().filter_map(|r| {
        let e = r.mesh_vs_reference?;
        let per_vertex_twin = r.per_vertex
            || reports
                .iter()
                .any(|o| o.variant.name == format!("{} per-vertex", r.variant.name));
        (per_vertex_twin && e.rel_l2 > 0.0).then(|| crate::plot::Point {
            label: format!("{} (mesh)", r.variant.name),
            time_ms: r.mesh_gpu_ms.unwrap_or(f64::NAN),
            error: e.rel_l2,
        })
    }));
    crate::plot::error_vs_time(
        path,
        &format!(
            "diffract profile: {} at θi = {}°, {}² map, {device}",
            crate::plot::source_name(&setup.base.heightfield),
            setup.theta_i_deg,
            setup.size,
        ),
        "relative L2 error of XYZ vs the f64 reference at 1 nm",
        &points,
    )
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
    crate::guard::positive("budget-s", args.budget_s, " s")?;
    check_counts(&c, args)?;
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
    crate::guard::check_outputs(
        &crate::guard::heightfield_inputs(&material.heightfield),
        &outputs,
    )
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_samples_have_zero_error_and_differences_show() {
        let r = vec![[0.2, 0.3, 0.1], [0.01, 0.02, 0.03]];
        let e = error_stats(&r, &r);
        assert_eq!((e.rel_l2, e.max_abs_y, e.max_de), (0.0, 0.0, 0.0));
        let a = vec![[0.2, 0.33, 0.1], [0.01, 0.02, 0.03]];
        let e = error_stats(&a, &r);
        assert!((e.max_abs_y - 0.03).abs() < 1e-12);
        assert!(e.rel_l2 > 0.05 && e.rel_l2 < 0.1, "{}", e.rel_l2);
        assert!(e.max_de > 1.0);
    }

    #[test]
    fn bootstrap_intervals_hold_the_figure_and_narrow_with_more_pixels() {
        // Errors of 1 % to 9 % of a varying signal: the interval holds the figure itself
        // and shrinks as the pixels it resamples grow in number.
        let sample = |n: usize| -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
            let r: Vec<[f64; 3]> = (0..n)
                .map(|k| [0.2 + 0.1 * ((k * 7) % 11) as f64 / 11.0; 3])
                .collect();
            let a = r
                .iter()
                .enumerate()
                .map(|(k, v)| v.map(|x| x * (1.0 + 0.01 * (1 + (k * 5) % 9) as f64)))
                .collect();
            (a, r)
        };
        let (a, r) = sample(32);
        let e = error_stats(&a, &r);
        let i = bootstrap(&a, &r);
        assert!(
            i.rel_l2.lo <= e.rel_l2 && e.rel_l2 <= i.rel_l2.hi,
            "{i:?} {e:?}"
        );
        assert!(i.rel_l2.lo < i.rel_l2.hi);
        assert_eq!(bootstrap(&a, &r), i, "a fixed seed");
        let (a4, r4) = sample(512);
        let wide = bootstrap(&a, &r).rel_l2;
        let narrow = bootstrap(&a4, &r4).rel_l2;
        assert!(
            narrow.hi - narrow.lo < 0.5 * (wide.hi - wide.lo),
            "{wide:?} {narrow:?}"
        );
    }

    #[test]
    fn frame_statistics() {
        let t = FrameTimes(vec![10.0, 12.0, 11.0, 30.0, 9.0]);
        assert_eq!(t.median(), Some(11.0));
        assert_eq!(t.quantile(0.0), Some(9.0));
        assert_eq!(t.quantile(1.0), Some(30.0));
        assert!(FrameTimes(vec![5.0, 5.0]).relative_error().is_none());
        assert_eq!(FrameTimes(vec![5.0; 4]).relative_error(), Some(0.0));
        assert!(t.relative_error().unwrap() > 0.3);
    }
}
