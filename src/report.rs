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

/// A message as a person reads it: a number of more than 24 digits (1e300 printed in full
/// by `{}`; no integer of 64 bits or time stamp is that long) becomes scientific notation
/// with four significant digits. Digits that touch letters (a hexadecimal key) stay as
/// they are. Every `error:` and `warning:` line the binary prints passes through here.
pub fn readable(msg: &str) -> String {
    let mut out = String::with_capacity(msg.len());
    let b = msg.as_bytes();
    let mut i = 0;
    while i < b.len() {
        let start = i;
        while i < b.len() && (b[i].is_ascii_digit() || (b[i] == b'.' && i > start)) {
            i += 1;
        }
        let run = &msg[start..i];
        let digits = run.bytes().filter(u8::is_ascii_digit).count();
        let touches = |c: Option<char>| c.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_');
        let before = msg[..start].chars().next_back();
        let after = msg[i..].chars().next();
        if digits > 24 && !touches(before) && !after.is_some_and(|c| c.is_ascii_alphabetic()) {
            let run = run.trim_end_matches('.');
            match run.parse::<f64>() {
                Ok(v) => out.push_str(&format!("{v:.3e}")),
                Err(_) => out.push_str(run),
            }
            out.push_str(&msg[start + run.len()..i]);
        } else if i > start {
            out.push_str(run);
        }
        if i < b.len() && i == start {
            let c = msg[i..].chars().next().unwrap_or(' ');
            out.push(c);
            i += c.len_utf8();
        }
    }
    out
}

/// The command line's report: lines on stderr, bars on stderr while it is a terminal.
///
/// Notes can be held back while a command checks its inputs ([`hold_notes`]): a refused
/// command then prints its one `error:` line and nothing else, since the notes of a check
/// that failed ([`discard_notes`]) are never shown. They are printed, in order, when the
/// work begins ([`work_begins`]: the device opens, a progress bar starts) or when the
/// command ends well. Warnings are never held.
#[derive(Debug, Clone, Copy, Default)]
pub struct Stderr;

/// When the process started its work (set by the binary first thing, [`start_clock`]).
static START: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();

/// Starts the process clock that [`process_wall_s`] reads; later calls change nothing.
pub fn start_clock() {
    START.get_or_init(std::time::Instant::now);
}

/// Seconds since [`start_clock`]: the wall time a command reports covers the whole process
/// (parsing, loading, building, drawing, writing), not just its draw. It first waits for
/// the cache files still being written behind the work ([`crate::cache::finish_writes`]),
/// so the figure covers them too.
pub fn process_wall_s() -> Option<f64> {
    let start = START.get()?;
    crate::cache::finish_writes(&Stderr);
    Some(start.elapsed().as_secs_f64())
}

/// Notes waiting for the work to begin; `None` while notes print at once.
static HELD: Mutex<Option<Vec<String>>> = Mutex::new(None);

/// Holds [`Stderr`]'s notes back from now until [`work_begins`] or [`discard_notes`].
pub fn hold_notes() {
    if let Ok(mut h) = HELD.lock() {
        h.get_or_insert_with(Vec::new);
    }
}

/// The checks are over: prints the held notes and lets later ones through at once.
pub fn work_begins() {
    let lines = HELD.lock().ok().and_then(|mut h| h.take());
    for line in lines.into_iter().flatten() {
        eprintln!("{line}");
    }
}

/// A check failed: the held notes are dropped (the command prints only its error).
pub fn discard_notes() {
    if let Ok(mut h) = HELD.lock() {
        *h = None;
    }
}

impl Report for Stderr {
    fn warn(&self, line: &str) {
        eprintln!("warning: {}", readable(line));
    }

    fn note(&self, line: &str) {
        if let Ok(mut h) = HELD.lock() {
            if let Some(held) = h.as_mut() {
                held.push(line.to_string());
                return;
            }
        }
        eprintln!("{line}");
    }

    fn progress(&self, bar: ProgressBar) -> ProgressBar {
        work_begins();
        if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
            tick_lines(&bar);
        }
        bar
    }
}

/// Longest silence of a long step when stderr is not a terminal (a log, a pipe, CI).
pub const PROGRESS_PERIOD: std::time::Duration = std::time::Duration::from_secs(10);

/// [`PROGRESS_PERIOD`], or `DIFFRACT_PROGRESS_SECS` (0.1 to 3600 seconds) where that is set.
pub fn progress_period() -> std::time::Duration {
    std::env::var("DIFFRACT_PROGRESS_SECS")
        .ok()
        .and_then(|v| v.trim().parse::<f64>().ok())
        .filter(|s| (0.1..=3600.0).contains(s))
        .map_or(PROGRESS_PERIOD, std::time::Duration::from_secs_f64)
}

/// Off a terminal a bar draws nothing: a thread prints its state as a line every
/// [`PROGRESS_PERIOD`] until the work finishes or drops the bar.
fn tick_lines(bar: &ProgressBar) {
    let weak = bar.downgrade();
    let start = std::time::Instant::now();
    let period = progress_period();
    std::thread::spawn(move || {
        let step = std::time::Duration::from_millis(200);
        let mut last = std::time::Instant::now();
        loop {
            std::thread::sleep(step);
            let Some(bar) = weak.upgrade() else { return };
            // A bar at its end whose owner keeps it (without finishing it) is done too.
            if bar.is_finished() || bar.length().is_some_and(|l| l > 0 && bar.position() >= l) {
                return;
            }
            if last.elapsed() >= period {
                last = std::time::Instant::now();
                let (pos, len) = (bar.position(), bar.length().unwrap_or(0));
                let done = if len > 0 {
                    format!("{pos}/{len} ({:.0} %)", 100.0 * pos as f64 / len as f64)
                } else {
                    format!("{pos}")
                };
                let elapsed = start.elapsed().as_secs_f64();
                let left = if pos > 0 && len > pos {
                    let s = elapsed * (len - pos) as f64 / pos as f64;
                    format!(", about {s:.0} s left")
                } else {
                    String::new()
                };
                eprintln!("{}: {done} after {elapsed:.0} s{left}", bar.message());
            }
        }
    });
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

    #[test]
    fn long_numbers_read_as_scientific_notation() {
        let huge = format!("theta-i {}°; expected 0° to 90°", 1e300);
        assert_eq!(readable(&huge), "theta-i 1.000e300°; expected 0° to 90°");
        let tiny = format!("dH {} µm", 1.234_567_890_123_456_7e-30);
        assert_eq!(readable(&tiny), "dH 1.235e-30 µm");
        let same = "12 of 2026-11-27: 1.5 µm, 3.25e-3, 18446744073709551615 bytes";
        assert_eq!(readable(same), same);
        let key = "key 0123456789012345678901234567abcdef ok";
        assert_eq!(readable(key), key);
        assert_eq!(readable("é 1000000000000000000000000000."), "é 1.000e27.");
    }

    #[test]
    fn held_notes_wait_for_the_work_and_go_with_a_refusal() {
        hold_notes();
        Stderr.note("kept");
        assert_eq!(
            HELD.lock().unwrap().as_deref(),
            Some(&["kept".to_string()][..])
        );
        discard_notes();
        assert!(HELD.lock().unwrap().is_none());
        hold_notes();
        Stderr.note("shown");
        work_begins();
        assert!(HELD.lock().unwrap().is_none());
    }
}
