//! Progress on stderr for steps that can take more than about a second. Bars and spinners
//! draw only when stderr is a terminal (indicatif's stderr target hides itself otherwise),
//! so scripts, tests and CI logs see no escape codes; results stay on stdout.

use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

/// A bar of `len` steps named `what` (`{pos}/{len}`, elapsed, ETA).
pub fn bar(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    if let Ok(style) =
        ProgressStyle::with_template("{msg} {bar:30} {pos}/{len} {elapsed} (eta {eta})")
    {
        bar.set_style(style);
    }
    bar.set_message(what.to_string());
    bar
}

/// A ticking spinner for a step whose length is not known in advance; it clears itself
/// when dropped, whether the step succeeded or failed.
pub struct Spinner(ProgressBar);

/// Starts a [`Spinner`] named `what`.
pub fn spinner(what: &str) -> Spinner {
    let bar = ProgressBar::new_spinner();
    if let Ok(style) = ProgressStyle::with_template("{spinner} {msg} {elapsed}") {
        bar.set_style(style);
    }
    bar.set_message(what.to_string());
    bar.enable_steady_tick(Duration::from_millis(120));
    Spinner(bar)
}

impl Drop for Spinner {
    fn drop(&mut self) {
        self.0.finish_and_clear();
    }
}
