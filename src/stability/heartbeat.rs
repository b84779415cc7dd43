//! Progress of `diffract stability` on stderr as plain lines (a log or a pipe gets them as
//! a terminal does): the command's own lines, and a line naming the step under way
//! whenever [`PERIOD`] passes without one, so a long cell, the device setup or the
//! lighting cases never leave the log silent.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Longest time between two progress lines.
pub const PERIOD: Duration = Duration::from_secs(10);

struct State {
    step: String,
    last_line: Instant,
}

/// Prints a line for the step under way when [`PERIOD`] passes without one; stops when
/// dropped.
pub struct Heartbeat {
    start: Instant,
    state: Arc<Mutex<State>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Heartbeat {
    /// Starts the clock of the run at `start`.
    pub fn start(start: Instant) -> Self {
        let state = Arc::new(Mutex::new(State {
            step: "starting".into(),
            last_line: Instant::now(),
        }));
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (state, stop) = (Arc::clone(&state), Arc::clone(&stop));
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(200));
                    let Ok(mut s) = state.lock() else { return };
                    if s.last_line.elapsed() >= PERIOD {
                        eprintln!(
                            "stability: {}, {:.0} s so far",
                            s.step,
                            start.elapsed().as_secs_f64()
                        );
                        s.last_line = Instant::now();
                    }
                }
            })
        };
        Self {
            start,
            state,
            stop,
            thread: Some(thread),
        }
    }

    /// Names the step now under way (in the next heartbeat line).
    pub fn step(&self, step: impl Into<String>) {
        if let Ok(mut s) = self.state.lock() {
            s.step = step.into();
        }
    }

    /// Prints a progress line now (the heartbeat waits another [`PERIOD`]).
    pub fn line(&self, line: &str) {
        if let Ok(mut s) = self.state.lock() {
            eprintln!("{line}");
            s.last_line = Instant::now();
        }
    }

    /// Seconds since the run started.
    pub fn elapsed_s(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }
}

impl Drop for Heartbeat {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
