//! What a profile says on stderr while it runs: a bar on a terminal, else a line per
//! finished row with the time left.

use std::io::IsTerminal;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};

use super::output::{ms, Skipped, VariantReport};

/// Progress of a profile on stderr: a bar on a terminal, else one line per finished row
/// with the time left (a log shows it as it happens).
pub(super) struct Progress {
    pub(super) bar: Option<ProgressBar>,
    start: Instant,
    rows: usize,
    done: usize,
}

impl Progress {
    pub(super) fn new(rows: usize) -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let b = ProgressBar::new(rows as u64);
            b.set_style(
                crate::progress::style("{msg} [{bar:30}] {pos}/{len} {left} left")
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

    pub(super) fn started(&self, name: &str) {
        if let Some(b) = &self.bar {
            b.set_message(format!("profile: {name}"));
        }
    }

    /// A row is done: `line` says how it went; `left_s` is the time the rest may take
    /// (the budget left, or the pace so far).
    pub(super) fn finished(&mut self, line: &str, left_s: Option<f64>) {
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

/// The line a finished row gets on stderr.
pub(super) fn row_line(r: &VariantReport) -> String {
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
pub(super) fn skipped_line(s: &Skipped) -> String {
    format!("{}: skipped, {}", s.variant.name, s.reason)
}
