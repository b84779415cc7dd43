//! Where library code sends what a person should see while it works: warnings, notes and
//! progress bars. The library never prints these itself; the command that owns the work
//! hands a [`Report`] down (the renderer holds one, [`crate::render::Renderer::set_report`]).
//! The command line uses [`Stderr`]; tests use [`Collect`] to read what was said.

use std::sync::Mutex;

use indicatif::{ProgressBar, ProgressDrawTarget};

/// The receiver of a piece of work's warnings, notes and progress.
pub trait Report: Send + Sync {
    /// A warning: the work goes on, but a person should know (`warning: ` is added).
    fn warn(&self, line: &str);
    /// A line of information (a cache hit, what was reused).
    fn note(&self, line: &str);
    /// Shows `bar` (already sized, named and styled by the caller) while the work advances;
    /// the caller increments and finishes it.
    fn progress(&self, bar: ProgressBar) -> ProgressBar;
    /// Long work (a table build) calls this between its steps. A report whose owner no
    /// longer wants the result (a viewer closing while a table builds) stops the work here
    /// by unwinding with [`std::panic::resume_unwind`], which runs no panic hook; the
    /// owner catches it where it started the work. Does nothing by default.
    fn checkpoint(&self) {}
}

/// The command line's report: lines on stderr, bars on stderr while it is a terminal.
#[derive(Debug, Clone, Copy, Default)]
pub struct Stderr;

impl Report for Stderr {
    fn warn(&self, line: &str) {
        eprintln!("warning: {line}");
    }

    fn note(&self, line: &str) {
        eprintln!("{line}");
    }

    fn progress(&self, bar: ProgressBar) -> ProgressBar {
        bar
    }
}

/// A report that keeps every line (for tests and for callers that show them elsewhere);
/// its bars draw nothing.
#[derive(Debug, Default)]
pub struct Collect {
    warnings: Mutex<Vec<String>>,
    notes: Mutex<Vec<String>>,
    bars: Mutex<Vec<String>>,
}

impl Collect {
    /// The warnings so far, without the `warning: ` prefix.
    pub fn warnings(&self) -> Vec<String> {
        self.warnings.lock().map(|w| w.clone()).unwrap_or_default()
    }

    /// The notes so far.
    pub fn notes(&self) -> Vec<String> {
        self.notes.lock().map(|n| n.clone()).unwrap_or_default()
    }

    /// The names (messages) of the progress bars shown so far.
    pub fn bars(&self) -> Vec<String> {
        self.bars.lock().map(|b| b.clone()).unwrap_or_default()
    }
}

impl Report for Collect {
    fn warn(&self, line: &str) {
        if let Ok(mut w) = self.warnings.lock() {
            w.push(line.to_string());
        }
    }

    fn note(&self, line: &str) {
        if let Ok(mut n) = self.notes.lock() {
            n.push(line.to_string());
        }
    }

    fn progress(&self, bar: ProgressBar) -> ProgressBar {
        if let Ok(mut b) = self.bars.lock() {
            b.push(bar.message());
        }
        bar.set_draw_target(ProgressDrawTarget::hidden());
        bar
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn collect_keeps_lines_and_hides_bars() {
        let c = Collect::default();
        c.warn("w1");
        c.note("n1");
        let bar = c.progress(ProgressBar::new(3).with_message("table"));
        bar.inc(3);
        assert!(bar.is_hidden());
        assert_eq!(c.warnings(), ["w1"]);
        assert_eq!(c.notes(), ["n1"]);
        assert_eq!(c.bars(), ["table"]);
    }
}
