//! PNG plots (plotters' bitmap backend). Text is drawn with the DejaVu Sans font shipped in
//! `assets/fonts/` (Bitstream Vera licence beside it), registered once, so plotting needs
//! no system font library.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;

use crate::{Error, Result};

const FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");

/// Registers the shipped font as `sans-serif` (idempotent).
pub fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The font is compiled in and known good; a failure would only lose the labels.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

/// One point of an error-versus-time plot.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    pub label: String,
    /// GPU time (ms).
    pub time_ms: f64,
    /// Error (any positive metric).
    pub error: f64,
}

/// Indices of the Pareto front: points no other point beats in both time and error.
pub fn pareto_front(points: &[Point]) -> Vec<usize> {
    (0..points.len())
        .filter(|&i| {
            let p = &points[i];
            !points.iter().enumerate().any(|(j, q)| {
                j != i
                    && q.time_ms <= p.time_ms
                    && q.error <= p.error
                    && (q.time_ms < p.time_ms || q.error < p.error)
            })
        })
        .collect()
}

fn plot_error(e: impl std::fmt::Display) -> Error {
    Error::invalid("plot", e.to_string())
}

/// Writes a log–log plot of `error` against `time_ms`, the Pareto front joined by a line
/// and its points filled, every point labelled. Non-positive values are clamped to the
/// smallest positive one (log axes).
pub fn error_vs_time(path: &Path, title: &str, y_label: &str, points: &[Point]) -> Result<()> {
    register_font();
    if points.is_empty() {
        return Err(Error::invalid("plot", "no points"));
    }
    let positive = |f: fn(&Point) -> f64| {
        let min = points
            .iter()
            .map(f)
            .filter(|v| v.is_finite() && *v > 0.0)
            .fold(f64::INFINITY, f64::min);
        let min = if min.is_finite() { min } else { 1e-9 };
        let max = points
            .iter()
            .map(f)
            .filter(|v| v.is_finite())
            .fold(min, f64::max);
        (min, max)
    };
    let (t0, t1) = positive(|p| p.time_ms);
    let (e0, e1) = positive(|p| p.error);
    let clamp = |v: f64, lo: f64| if v.is_finite() && v > 0.0 { v } else { lo };
    let root = BitMapBackend::new(path, (1000, 700)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_error)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(
            (t0 / 2.0..t1 * 2.0).log_scale(),
            (e0 / 3.0..e1 * 3.0).log_scale(),
        )
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .x_desc("GPU time per frame (ms)")
        .y_desc(y_label)
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(plot_error)?;
    let mut front: Vec<&Point> = pareto_front(points)
        .into_iter()
        .map(|i| &points[i])
        .collect();
    front.sort_by(|a, b| a.time_ms.total_cmp(&b.time_ms));
    chart
        .draw_series(LineSeries::new(
            front
                .iter()
                .map(|p| (clamp(p.time_ms, t0), clamp(p.error, e0))),
            RED.stroke_width(2),
        ))
        .map_err(plot_error)?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
    for p in points {
        let on_front = front.iter().any(|f| std::ptr::eq(*f, p));
        let at = (clamp(p.time_ms, t0), clamp(p.error, e0));
        let style = if on_front {
            RED.filled()
        } else {
            BLUE.filled()
        };
        chart
            .draw_series(std::iter::once(Circle::new(at, 5, style)))
            .map_err(plot_error)?;
        chart
            .draw_series(std::iter::once(Text::new(
                p.label.clone(),
                at,
                ("sans-serif", 14).into_font(),
            )))
            .map_err(plot_error)?;
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .label_font(("sans-serif", 15))
        .draw()
        .map_err(plot_error)?;
    root.present().map_err(plot_error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_only_unbeaten_points() {
        let p = |t, e| Point {
            label: String::new(),
            time_ms: t,
            error: e,
        };
        let pts = [
            p(1.0, 1.0),
            p(2.0, 0.5),
            p(3.0, 0.7),
            p(0.5, 2.0),
            p(2.0, 0.5),
        ];
        let mut f = pareto_front(&pts);
        f.sort_unstable();
        // (3, 0.7) is beaten by (2, 0.5); the duplicate (2, 0.5) points beat neither other.
        assert_eq!(f, vec![0, 1, 3, 4]);
    }
}
