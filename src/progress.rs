//! Progress on stderr for steps that can take more than about a second. Bars and spinners
//! draw only when stderr is a terminal (indicatif's stderr target hides itself otherwise),
//! so scripts, tests and CI logs see no escape codes; results stay on stdout.

use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

/// A bar of `len` steps named `what` (`{pos}/{len}`, elapsed, the time left).
pub fn bar(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    if let Ok(style) = style("{msg} {bar:30} {pos}/{len} {elapsed} ({left} left)") {
        bar.set_style(style);
    }
    bar.set_message(what.to_string());
    bar
}

/// A bar's style from `template`, in which `{left}` is the time left at the mean pace of
/// the steps since the bar started (`…` before a second has passed or a step has ended).
/// indicatif's own `{eta}` follows a moving average that starts from nothing: in a
/// build's first seconds it says `0s` or hours.
pub fn style(template: &str) -> Result<ProgressStyle, indicatif::style::TemplateError> {
    Ok(ProgressStyle::with_template(template)?.with_key("left", time_left))
}

/// The `{left}` key of [`style`].
fn time_left(state: &indicatif::ProgressState, out: &mut dyn std::fmt::Write) {
    let (pos, len) = (state.pos(), state.len().unwrap_or(0));
    let elapsed = state.elapsed().as_secs_f64();
    let _ = match left_s(pos, len, elapsed) {
        Some(s) => write!(
            out,
            "{}",
            indicatif::HumanDuration(Duration::from_secs_f64(s))
        ),
        None => write!(out, "…"),
    };
}

/// Seconds left after `pos` of `len` steps in `elapsed` s, at their mean pace; `None`
/// before a second has passed or a step has ended.
fn left_s(pos: u64, len: u64, elapsed: f64) -> Option<f64> {
    (pos > 0 && elapsed >= 1.0).then(|| elapsed * len.saturating_sub(pos) as f64 / pos as f64)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_time_left_is_the_mean_pace_and_says_nothing_before_it_knows() {
        assert_eq!(left_s(0, 100, 5.0), None, "no step ended");
        assert_eq!(left_s(10, 100, 0.5), None, "under a second");
        assert_eq!(left_s(25, 100, 10.0), Some(30.0));
        assert_eq!(left_s(100, 100, 10.0), Some(0.0));
    }
}
