//! PNG plots (plotters' bitmap backend): the profiler's error-versus-time plot, and the heat
//! maps with curves of the experiments (grating equation, stability matrix). Text is drawn
//! with the DejaVu Sans font shipped in `assets/fonts/` (Bitstream Vera licence beside it),
//! registered once, so plotting needs no system font library; the heat maps draw none.

use std::path::Path;
use std::sync::Once;

use image::ImageEncoder;
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
    let (width, height) = (1000u32, 700u32);
    let mut buf = vec![0u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
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
    }
    write_png(path, &buf, width, height)
}

/// A grid of values: `values[row][col]`, row 0 at the bottom (`y0`), column 0 at `x0`.
pub struct Heat<'a> {
    pub values: &'a [Vec<f64>],
    /// Data range of the columns (`x0`, `x1`) and rows (`y0`, `y1`), cell edges.
    pub x: (f64, f64),
    pub y: (f64, f64),
    /// Colour by `log10` (values ≤ 0 and non-finite values are drawn grey).
    pub log: bool,
}

/// A polyline in data coordinates; `NaN` points split it.
pub struct Curve {
    pub points: Vec<(f64, f64)>,
    pub colour: (u8, u8, u8),
}

/// A dark-to-bright ramp (black, blue, magenta, orange, pale yellow) for `t ∈ [0, 1]`.
pub fn ramp(t: f64) -> (u8, u8, u8) {
    const STOPS: [(f64, [f64; 3]); 5] = [
        (0.0, [0.0, 0.0, 0.02]),
        (0.25, [0.15, 0.05, 0.55]),
        (0.5, [0.7, 0.1, 0.55]),
        (0.75, [0.98, 0.5, 0.1]),
        (1.0, [0.99, 0.99, 0.75]),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let i = STOPS.iter().position(|s| s.0 >= t).unwrap_or(4).max(1);
    let (t0, c0) = STOPS[i - 1];
    let (t1, c1) = STOPS[i];
    let f = (t - t0) / (t1 - t0);
    let c = |k: usize| ((c0[k] + f * (c1[k] - c0[k])) * 255.0).round() as u8;
    (c(0), c(1), c(2))
}

/// Writes `heat` with `curves` over it as a `width × height` RGB PNG.
pub fn write_heat_map(
    path: &Path,
    heat: &Heat,
    curves: &[Curve],
    width: u32,
    height: u32,
) -> Result<()> {
    let rows = heat.values.len();
    let cols = heat.values.first().map_or(0, Vec::len);
    if rows == 0 || cols == 0 || heat.values.iter().any(|r| r.len() != cols) {
        return Err(Error::invalid("plot", "empty or ragged grid"));
    }
    let map = |v: f64| if heat.log { v.log10() } else { v };
    let finite: Vec<f64> = heat
        .values
        .iter()
        .flatten()
        .filter(|v| v.is_finite() && (!heat.log || **v > 0.0))
        .map(|&v| map(v))
        .collect();
    let lo = finite.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = finite.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut buf = vec![0u8; (width * height * 3) as usize];
    let draw_err = |e: String| Error::invalid("plot", e);
    {
        let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(e.to_string()))?;
        let mut chart = ChartBuilder::on(&root)
            .margin(8)
            .build_cartesian_2d(heat.x.0..heat.x.1, heat.y.0..heat.y.1)
            .map_err(|e| draw_err(e.to_string()))?;
        let dx = (heat.x.1 - heat.x.0) / cols as f64;
        let dy = (heat.y.1 - heat.y.0) / rows as f64;
        let cells = heat.values.iter().enumerate().flat_map(|(r, row)| {
            row.iter().enumerate().map(move |(c, &v)| {
                let colour = if v.is_finite() && (!heat.log || v > 0.0) {
                    let (r, g, b) = ramp((map(v) - lo) / span);
                    RGBColor(r, g, b)
                } else {
                    RGBColor(128, 128, 128)
                };
                let x = heat.x.0 + c as f64 * dx;
                let y = heat.y.0 + r as f64 * dy;
                Rectangle::new([(x, y), (x + dx, y + dy)], colour.filled())
            })
        });
        chart
            .draw_series(cells)
            .map_err(|e| draw_err(e.to_string()))?;
        for curve in curves {
            let (r, g, b) = curve.colour;
            let style = RGBColor(r, g, b).stroke_width(2);
            for piece in curve
                .points
                .split(|p| !(p.0.is_finite() && p.1.is_finite()))
            {
                if piece.len() > 1 {
                    chart
                        .draw_series(LineSeries::new(piece.iter().copied(), style))
                        .map_err(|e| draw_err(e.to_string()))?;
                }
            }
        }
        root.present().map_err(|e| draw_err(e.to_string()))?;
    }
    write_png(path, &buf, width, height)
}

/// Encodes an RGB8 buffer as PNG and writes it atomically.
fn write_png(path: &Path, rgb: &[u8], width: u32, height: u32) -> Result<()> {
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| Error::Image {
            path: path.to_path_buf(),
            msg: e.to_string(),
        })?;
    crate::fsutil::write_atomic(path, &png)
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

#[cfg(test)]
mod heat_tests {
    use super::*;

    #[test]
    fn ramp_runs_dark_to_bright() {
        let lum = |c: (u8, u8, u8)| c.0 as u32 + c.1 as u32 + c.2 as u32;
        let l: Vec<u32> = (0..=10).map(|i| lum(ramp(i as f64 / 10.0))).collect();
        assert!(l.windows(2).all(|w| w[1] >= w[0]), "{l:?}");
        assert_eq!(ramp(f64::NAN), ramp(0.0));
    }

    #[test]
    fn writes_a_png_of_the_requested_size() {
        let dir = std::env::temp_dir().join(format!("diffract-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("h.png");
        let values = vec![vec![1.0, 10.0, 100.0], vec![0.0, f64::NAN, 1e3]];
        write_heat_map(
            &p,
            &Heat {
                values: &values,
                x: (0.0, 3.0),
                y: (0.0, 2.0),
                log: true,
            },
            &[Curve {
                points: vec![
                    (0.0, 0.0),
                    (1.0, 1.0),
                    (f64::NAN, 0.0),
                    (2.0, 1.0),
                    (3.0, 2.0),
                ],
                colour: (0, 255, 0),
            }],
            60,
            40,
        )
        .unwrap();
        let img = image::open(&p).unwrap();
        assert_eq!((img.width(), img.height()), (60, 40));
        std::fs::remove_dir_all(&dir).ok();
    }
}
