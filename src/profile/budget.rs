//! Time: the frames a row draws (fixed or by a budget), their statistics, the deadline
//! that stops a table build the budget cannot afford, and the pace that estimates the cost
//! of the rows still to measure.

use std::time::Instant;

use indicatif::ProgressBar;

use crate::budget::{Cost, Keeper};

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

impl Frames {
    /// Whether a row that has drawn the frames in `times`, the last taking `last_wall_ms`,
    /// draws another: a fixed count until it is reached; with a budget, the first frame
    /// always, then until the median is known to the budget's precision, the row has its
    /// most frames, or another frame like the last would pass `end` (no `end`: the first
    /// frame only).
    pub fn more(
        &self,
        times: &FrameTimes,
        last_wall_ms: Option<f64>,
        end: Option<Instant>,
    ) -> bool {
        let n = times.0.len();
        match (*self, end) {
            (Frames::Fixed(k), _) => n < k,
            (Frames::Budget(b), Some(end)) => {
                let next = std::time::Duration::from_secs_f64(last_wall_ms.unwrap_or(0.0) / 1e3);
                n == 0
                    || (n < b.max_frames
                        && times.relative_error().is_none_or(|e| e > b.precision)
                        && Instant::now() + next <= end)
            }
            (Frames::Budget(_), None) => n == 0,
        }
    }
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

/// The unwinding payload of a table build stopped because it would not fit the budget:
/// the build's estimated total (s).
pub(super) struct OverBudget {
    pub(super) projected_s: f64,
    pub(super) steps: u64,
}

/// The renderer's report during a budgeted row: passes lines and bars on to stderr, and
/// stops a table build (see [`crate::report::Report::checkpoint`]) once the build, at the
/// pace of its steps so far, would end past `deadline`.
pub(super) struct Deadline {
    start: Instant,
    deadline: Option<Instant>,
    steps: std::sync::atomic::AtomicU64,
    total: std::sync::atomic::AtomicU64,
    /// When the build's first step ended: the pace is taken from the steps after it, so
    /// what comes once before them (the terms, a device's pipelines, the first upload)
    /// is not multiplied by the number of steps.
    first_step: std::sync::OnceLock<Instant>,
}

impl Deadline {
    pub(super) fn new(deadline: Option<Instant>) -> Self {
        Self {
            start: Instant::now(),
            deadline,
            steps: 0.into(),
            total: 0.into(),
            first_step: std::sync::OnceLock::new(),
        }
    }

    /// The build's projected total (s) after `done` of `total` steps: the time to its
    /// first step, then the pace of the steps since.
    fn projected_s(&self, done: u64, total: u64) -> f64 {
        let first = *self.first_step.get_or_init(Instant::now);
        let before = first.duration_since(self.start).as_secs_f64();
        project(before, first.elapsed().as_secs_f64(), done, total)
    }
}

/// A build's total (s) from the time to its first step (`before`), the time since
/// (`since_first`) and the steps done of `total`: the first step's cost once, the pace
/// of the later steps for the rest.
fn project(before: f64, since_first: f64, done: u64, total: u64) -> f64 {
    if done < 2 {
        return before;
    }
    before + since_first / (done - 1) as f64 * (total.max(done) - 1) as f64
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
        // Shown as the command line shows every bar (lines every 10 s off a terminal).
        crate::report::Stderr.progress(bar)
    }

    fn checkpoint(&self) {
        use std::sync::atomic::Ordering;
        let Some(deadline) = self.deadline else {
            return;
        };
        let done = self.steps.fetch_add(1, Ordering::Relaxed) + 1;
        let total = self.total.load(Ordering::Relaxed).max(done);
        let projected = self.projected_s(done, total);
        // A few steps first, so the pace is not one step's noise.
        if done < 4 {
            return;
        }
        let end = self.start + std::time::Duration::from_secs_f64(projected);
        if end > deadline {
            std::panic::resume_unwind(Box::new(OverBudget {
                projected_s: projected,
                steps: total,
            }));
        }
    }
}

/// The kinds of a profile row's cost that its budget keeper ([`crate::budget::Keeper`])
/// learns from the rows measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum RowCost {
    /// A map frame: a fixed part (draw set-up and readback) and a part per fetch and pixel
    /// ([`RowCost::frame_units`]).
    Frame,
    /// A warm-up's preparation beyond its frame and its table build (loading terms,
    /// pipelines).
    Prepare,
    /// A table build, per sampled `(w, λ)` plane: from a build this profile made or
    /// stopped (none until then: a table may be in the cache, so it is tried).
    TablePlanes,
}

impl RowCost {
    /// A plane's build time assumed only to order the rows before any table was built.
    pub(super) const PRIOR_TABLE_MS_PER_PLANE: f64 = 5.0;

    /// The keeper of a profile's budget (`None`: no budget), with lavapipe's pace on 2
    /// cores as its prior (FLSS at 5 nm, 128² map: 1.7 s a frame for 48 825 fetches a
    /// pixel; 0.3 s of preparation), so a fast GPU is overestimated only until its first
    /// row is measured.
    pub(super) fn keeper(start: Instant, total_s: Option<f64>) -> Keeper<RowCost> {
        let mut k = Keeper::new(start, total_s);
        k.prior(
            &RowCost::Frame,
            Cost {
                fixed_s: 0.020,
                per_unit_s: 3e-9,
            },
        );
        k.prior(
            &RowCost::Prepare,
            Cost {
                fixed_s: 0.3,
                per_unit_s: 0.0,
            },
        );
        k
    }

    /// The units of a map frame of `fetches` a pixel on a `size`² map: fetches times the
    /// pixels of its disc.
    pub(super) fn frame_units(fetches: usize, size: u32) -> f64 {
        std::f64::consts::FRAC_PI_4 * f64::from(size) * f64::from(size) * fetches as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_build_is_projected_from_the_pace_after_its_first_step() {
        // 2 s of pipelines and terms before the first step, then 10 steps in 0.1 s: the
        // total is 2 s plus the pace of the steps, not the first 2 s times the steps.
        let p = project(2.0, 0.1, 11, 1001);
        assert!((p - 12.0).abs() < 1e-9, "{p}");
        // At a steady pace the projection is the plain rate.
        assert!((project(0.5, 4.5, 10, 100) - 50.0).abs() < 1e-9);
        assert_eq!(project(3.0, 0.0, 1, 100), 3.0);
    }

    #[test]
    fn a_row_draws_its_frames_until_the_count_the_precision_or_the_deadline() {
        let none = FrameTimes::default();
        let two = FrameTimes(vec![1.0, 1.0]);
        assert!(Frames::Fixed(2).more(&none, None, None));
        assert!(!Frames::Fixed(2).more(&two, Some(1.0), None));
        let b = Frames::Budget(Budget::seconds(60.0));
        // Without a deadline the first frame only; with one, the first always.
        assert!(b.more(&none, None, None) && !b.more(&two, Some(1.0), None));
        let past = Instant::now();
        assert!(b.more(&none, None, Some(past)));
        let later = Instant::now() + std::time::Duration::from_secs(60);
        assert!(
            b.more(&two, Some(1.0), Some(later)),
            "fewer than 3 frames: no precision yet"
        );
        assert!(
            !b.more(&two, Some(120e3), Some(later)),
            "the next frame would pass the end"
        );
        let steady = FrameTimes(vec![1.0; 5]);
        assert!(
            !b.more(&steady, Some(1.0), Some(later)),
            "the median is known"
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
