//! PNG plots (plotters' bitmap backend): the profiler's error-versus-time plot, and the heat
//! maps with curves of the experiments (grating equation, stability matrix). Text is drawn
//! with the DejaVu Sans font shipped in `assets/fonts/` (Bitstream Vera licence beside it),
//! registered once, so plotting needs no system font library. Every plot has a title,
//! labelled axes with ticks, and a legend or colour bar for what its colours and marks mean.

use std::path::Path;
use std::sync::Once;

use image::ImageEncoder;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

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
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Point {
    pub label: String,
    /// GPU time (ms).
    pub time_ms: f64,
    /// Error (any positive metric).
    pub error: f64,
    /// The error's interval (a 95 % bootstrap interval), drawn as a vertical bar.
    pub error_range: Option<(f64, f64)>,
    /// The time's spread (p10–p90 of the frames), drawn as a horizontal bar.
    pub time_range: Option<(f64, f64)>,
}

impl Point {
    /// Whether the measurements cannot tell this point from `other`: both intervals
    /// overlap, the error's and the time's (a point without an interval is its value).
    pub fn indistinguishable(&self, other: &Point) -> bool {
        let overlap = |a: (f64, f64), b: (f64, f64)| a.0 <= b.1 && b.0 <= a.1;
        let e = |p: &Point| p.error_range.unwrap_or((p.error, p.error));
        let t = |p: &Point| p.time_range.unwrap_or((p.time_ms, p.time_ms));
        overlap(e(self), e(other)) && overlap(t(self), t(other))
    }
}

/// For each point, whether another point of `points` is indistinguishable from it.
pub fn indistinguishable(points: &[Point]) -> Vec<bool> {
    (0..points.len())
        .map(|i| (0..points.len()).any(|j| j != i && points[i].indistinguishable(&points[j])))
        .collect()
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

/// How a height-field source is named in a figure: `builtin:…` as given, a file by its name
/// alone, so no directory of the machine that drew the figure ends up in it.
pub fn source_name(source: &str) -> String {
    if source.starts_with("builtin:") {
        return source.to_string();
    }
    Path::new(source)
        .file_name()
        .map_or_else(|| source.to_string(), |n| n.to_string_lossy().into_owned())
}

/// A number as a tick label: no trailing `.0`, powers of ten beyond 10⁴ and below 10⁻³ as
/// `1e5`, `2e-4`.
pub fn format_tick(v: f64) -> String {
    let a = v.abs();
    let s = if a == 0.0 || !a.is_finite() {
        "0".to_string()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{v:.0e}")
    } else {
        let digits = (-(a.log10() + 1e-9).floor()).max(0.0) as usize;
        format!("{v:.digits$}")
    };
    s.replace('-', "−")
}

/// A log axis's tick label (the ticks are [`log_key_points`]).
fn log_tick(v: f64) -> String {
    if !(v.is_finite() && v > 0.0) {
        return String::new();
    }
    let digits = (-(v.log10() + 1e-9).floor()).max(0.0) as usize + 1;
    let s = format!("{v:.digits$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if (1e-3..1e5).contains(&v) {
        s
    } else {
        format_tick(v)
    }
}

/// The ticks of a log axis over `lo..hi`: 1, 2 and 5 times each power of ten inside it,
/// each once (a grid line and a label apiece, none crowding another); where that leaves
/// fewer than three (a span under a factor of about 2.5), 1.5, 3 and 7 times too.
pub fn log_key_points(lo: f64, hi: f64) -> Vec<f64> {
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0) {
        return Vec::new();
    }
    let within = |mantissas: &[f64]| -> Vec<f64> {
        let (k0, k1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
        let mut v: Vec<f64> = (k0..=k1)
            .flat_map(|k| mantissas.iter().map(move |m| m * 10f64.powi(k)))
            .filter(|v| (lo..=hi).contains(v))
            .collect();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    };
    let ticks = within(&[1.0, 2.0, 5.0]);
    if ticks.len() >= 3 {
        ticks
    } else {
        within(&[1.0, 1.5, 2.0, 3.0, 5.0, 7.0])
    }
}

/// A series of points drawn as one curve beside the Pareto front, outside it (its errors
/// are against another reference), in the order given, each point labelled.
#[derive(Debug, Clone, PartialEq)]
pub struct SideCurve {
    /// The legend's entry.
    pub label: String,
    pub points: Vec<Point>,
}

/// Writes a log–log plot of `error` against `time_ms`, the Pareto front joined by a line
/// and its points filled, every point labelled. Non-positive values are clamped to the
/// smallest positive one (log axes).
pub fn error_vs_time(path: &Path, title: &str, y_label: &str, points: &[Point]) -> Result<()> {
    error_vs_time_with(path, title, y_label, points, &[])
}

/// [`error_vs_time`] with `curves` drawn beside the front (green, then blue, then violet,
/// each joined in its order).
pub fn error_vs_time_with(
    path: &Path,
    title: &str,
    y_label: &str,
    points: &[Point],
    curves: &[SideCurve],
) -> Result<()> {
    register_font();
    let curves = coloured(curves);
    let curve_points = curves.iter().flat_map(|(c, _)| &c.points);
    let all: Vec<Point> = points.iter().chain(curve_points).cloned().collect();
    // Each curve's points in its colour, in the order of `all`.
    let curve_colours: Vec<RGBColor> = curves
        .iter()
        .flat_map(|&(c, colour)| std::iter::repeat_n(colour, c.points.len()))
        .collect();
    if all.is_empty() {
        return Err(Error::invalid("plot", "no points"));
    }
    let (t0, t1) = positive_range(&all, |p| p.time_ms);
    let (e0, e1) = positive_range(&all, |p| p.error);
    let clamp = |v: f64, lo: f64| if v.is_finite() && v > 0.0 { v } else { lo };
    let at_of = |p: &Point| (clamp(p.time_ms, t0), clamp(p.error, e0));
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
                (t0 / 2.0..t1 * 2.0)
                    .log_scale()
                    .with_key_points(log_key_points(t0 / 2.0, t1 * 2.0)),
                (e0 / 3.0..e1 * 3.0)
                    .log_scale()
                    .with_key_points(log_key_points(e0 / 3.0, e1 * 3.0)),
            )
            .map_err(plot_error)?;
        chart
            .configure_mesh()
            .x_desc("GPU time per frame (ms)")
            .y_desc(y_label)
            .x_label_formatter(&|v| log_tick(*v))
            .y_label_formatter(&|v| log_tick(*v))
            .label_style(("sans-serif", 15))
            .draw()
            .map_err(plot_error)?;
        let mut front: Vec<&Point> = pareto_front(points)
            .into_iter()
            .map(|i| &points[i])
            .collect();
        front.sort_by(|a, b| a.time_ms.total_cmp(&b.time_ms));
        if !front.is_empty() {
            chart
                .draw_series(LineSeries::new(
                    front.iter().map(|p| at_of(p)),
                    RED.stroke_width(2),
                ))
                .map_err(plot_error)?
                .label("Pareto front")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
        }
        for &(c, colour) in &curves {
            chart
                .draw_series(LineSeries::new(
                    c.points.iter().map(at_of),
                    colour.stroke_width(2),
                ))
                .map_err(plot_error)?
                .label(c.label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                });
        }
        // Each point's intervals: the error's (vertical) and the time's (horizontal).
        let grey = RGBColor(110, 110, 110);
        for p in &all {
            let (t, e) = at_of(p);
            let mut bars = Vec::new();
            if let Some((lo, hi)) = p.error_range {
                bars.push(vec![(t, clamp(lo, e0)), (t, clamp(hi, e0))]);
            }
            if let Some((lo, hi)) = p.time_range {
                bars.push(vec![(clamp(lo, t0), e), (clamp(hi, t0), e)]);
            }
            chart
                .draw_series(
                    bars.into_iter()
                        .map(|b| PathElement::new(b, grey.stroke_width(1))),
                )
                .map_err(plot_error)?;
        }
        // A point that another cannot be told from (both intervals overlap) gets a ring.
        let alike = indistinguishable(points);
        if alike.iter().any(|&a| a) {
            chart
                .draw_series(
                    points
                        .iter()
                        .zip(&alike)
                        .filter(|(_, &a)| a)
                        .map(|(p, _)| Circle::new(at_of(p), 9, grey.stroke_width(2))),
                )
                .map_err(plot_error)?
                .label("ring: not distinguishable from another point (both intervals overlap)")
                .legend(move |(x, y)| Circle::new((x + 10, y), 6, grey.stroke_width(2)));
        }
        let at: Vec<(f64, f64)> = all.iter().map(at_of).collect();
        for (k, &at) in at.iter().enumerate() {
            let style = if k >= points.len() {
                curve_colours[k - points.len()].filled()
            } else if front.iter().any(|f| std::ptr::eq(*f, &points[k])) {
                RED.filled()
            } else {
                BLUE.filled()
            };
            chart
                .draw_series(std::iter::once(Circle::new(at, 5, style)))
                .map_err(plot_error)?;
        }
        let marks: Vec<(i32, i32)> = at.iter().map(|a| chart.backend_coord(a)).collect();
        let (xr, yr) = chart.plotting_area().get_pixel_range();
        draw_labels(&root, &all, &marks, [xr.start, yr.start, xr.end, yr.end])?;
        // The legend goes to the lower left, fast and accurate: that corner holds points only
        // where one variant is about the fastest and the most accurate at once.
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerLeft)
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .label_font(("sans-serif", 15))
            .draw()
            .map_err(plot_error)?;
        root.present().map_err(plot_error)?;
    }
    write_png(path, &buf, width, height)
}

/// The side curves that have points, each with its colour: green, blue, violet, then again.
fn coloured(curves: &[SideCurve]) -> Vec<(&SideCurve, RGBColor)> {
    let palette = [
        RGBColor(0, 140, 60),
        RGBColor(30, 90, 200),
        RGBColor(140, 60, 170),
    ];
    curves
        .iter()
        .filter(|c| !c.points.is_empty())
        .zip(palette.into_iter().cycle())
        .collect()
}

/// The smallest positive and the largest finite value of `f` over `points` (a log axis's
/// range; 1e-9 where none is positive).
fn positive_range(points: &[Point], f: fn(&Point) -> f64) -> (f64, f64) {
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
}

/// The points' labels where they overlap neither another label nor a point; one moved
/// away from its point is joined to it by a thin grey line.
fn draw_labels(
    root: &DrawingArea<BitMapBackend<'_>, Shift>,
    points: &[Point],
    marks: &[(i32, i32)],
    area: [i32; 4],
) -> Result<()> {
    let font = ("sans-serif", 14).into_font();
    let style = TextStyle::from(font.clone());
    let sizes = points
        .iter()
        .map(|p| {
            root.estimate_text_size(&p.label, &style)
                .map_err(plot_error)
        })
        .collect::<Result<Vec<_>>>()?;
    let placed = place_labels(marks, &sizes, area);
    for ((p, &mark), (&corner, &size)) in points.iter().zip(marks).zip(placed.iter().zip(&sizes)) {
        if p.label.is_empty() {
            continue;
        }
        let near = nearest_on_box(mark, corner, size);
        let (dx, dy) = (near.0 - mark.0, near.1 - mark.1);
        if dx * dx + dy * dy > 12 * 12 {
            root.draw(&PathElement::new(vec![mark, near], RGBColor(140, 140, 140)))
                .map_err(plot_error)?;
        }
        root.draw(&Text::new(p.label.clone(), corner, font.clone()))
            .map_err(plot_error)?;
    }
    Ok(())
}

/// Top-left corners (pixels) for labels of `sizes` beside the marks at `marks`, inside
/// `area` (`[x0, y0, x1, y1]`): each label takes the first of its candidate places, nearest
/// first, that overlaps no label already placed and no mark (a disc of 6 pixels); where
/// none is free, the candidate with the least overlap. Labels are placed in order of their
/// marks from left to right, so a crowded cluster fans out from its left.
pub fn place_labels(marks: &[(i32, i32)], sizes: &[(u32, u32)], area: [i32; 4]) -> Vec<(i32, i32)> {
    const MARK: i32 = 6;
    const GAP: i32 = 4;
    let overlap = |a: [i32; 4], b: [i32; 4]| -> i64 {
        let w = (a[2].min(b[2]) - a[0].max(b[0])).max(0) as i64;
        let h = (a[3].min(b[3]) - a[1].max(b[1])).max(0) as i64;
        w * h
    };
    let mut order: Vec<usize> = (0..marks.len()).collect();
    order.sort_by_key(|&i| (marks[i].0, marks[i].1));
    let mut boxes: Vec<[i32; 4]> = Vec::with_capacity(marks.len());
    let mut corners = vec![(0, 0); marks.len()];
    for i in order {
        let (mx, my) = marks[i];
        let (w, h) = (sizes[i].0 as i32, sizes[i].1 as i32);
        let mut candidates = vec![
            (mx + 8, my - h - 2),
            (mx + 8, my + 2),
            (mx - w - 8, my - h - 2),
            (mx - w - 8, my + 2),
            (mx - w / 2, my - h - 8),
            (mx - w / 2, my + 8),
        ];
        // Farther out: stacked above and below, then to the sides.
        for k in 1..=8 {
            let step = k * (h + GAP);
            candidates.push((mx + 8, my - h - 2 - step));
            candidates.push((mx + 8, my + 2 + step));
            candidates.push((mx - w - 8, my - h - 2 - step));
            candidates.push((mx - w - 8, my + 2 + step));
        }
        let cost = |&(x, y): &(i32, i32)| -> i64 {
            let b = [x, y, x + w, y + h];
            let outside = (area[0] - b[0]).max(0)
                + (b[2] - area[2]).max(0)
                + (area[1] - b[1]).max(0)
                + (b[3] - area[3]).max(0);
            let padded = [
                b[0] - GAP / 2,
                b[1] - GAP / 2,
                b[2] + GAP / 2,
                b[3] + GAP / 2,
            ];
            let labels: i64 = boxes.iter().map(|&o| overlap(padded, o)).sum();
            let dots: i64 = marks
                .iter()
                .map(|&(x, y)| overlap(b, [x - MARK, y - MARK, x + MARK, y + MARK]))
                .sum();
            labels + dots + 1000 * outside as i64
        };
        let best = candidates
            .iter()
            .find(|c| cost(c) == 0)
            .or_else(|| candidates.iter().min_by_key(|c| cost(c)))
            .copied()
            .unwrap_or((mx + 8, my - h - 2));
        boxes.push([best.0, best.1, best.0 + w, best.1 + h]);
        corners[i] = best;
    }
    corners
}

/// The point of the box at `corner` with `size` nearest to `p`.
fn nearest_on_box(p: (i32, i32), corner: (i32, i32), size: (u32, u32)) -> (i32, i32) {
    (
        p.0.clamp(corner.0, corner.0 + size.0 as i32),
        p.1.clamp(corner.1, corner.1 + size.1 as i32),
    )
}

/// Labels along one axis of a heat map, in data coordinates.
#[derive(Debug, Clone, Default)]
pub struct Axis {
    /// The axis title, drawn outermost.
    pub label: String,
    /// Tick marks and their labels at data positions.
    pub ticks: Vec<(f64, String)>,
    /// Rows of group labels beyond the ticks, innermost first: each a span `(from, to)` of
    /// data coordinates and its label, drawn beside a bracket over the span.
    pub groups: Vec<Vec<(f64, f64, String)>>,
    /// Data positions of white lines drawn across the map (e.g. between groups).
    pub rules: Vec<f64>,
}

/// A heat map with its title, axes and colour bar: `values[row][col]`, row 0 at the bottom
/// (`y.0`), column 0 at `x.0`.
pub struct HeatMap<'a> {
    pub title: String,
    pub values: &'a [Vec<f64>],
    /// Data range of the columns (`x.0`, `x.1`) and rows (`y.0`, `y.1`), cell edges.
    pub x: (f64, f64),
    pub y: (f64, f64),
    pub x_axis: Axis,
    pub y_axis: Axis,
    /// Colour by `log10` (values ≤ 0 and non-finite values are drawn grey).
    pub log: bool,
    /// Title of the colour bar (its scale is the coloured quantity: `log10` of the values
    /// when `log`).
    pub scale_label: String,
    /// Limits of the colour scale (in its units: `log10` when `log`); values beyond take
    /// the end colour and the bar's end label reads `≤`/`≥`. `None`: the data's extent.
    pub scale_limits: (Option<f64>, Option<f64>),
    /// Values marked across the colour bar (scale units) with their labels.
    pub scale_marks: Vec<(f64, String)>,
    /// Legend entry for the grey cells, where they mean something (e.g. "refused").
    pub missing_label: Option<String>,
    /// Overlays, listed in a legend.
    pub curves: Vec<Curve>,
    /// Image size in pixels.
    pub size: (u32, u32),
}

/// An overlay in data coordinates; `NaN` points split a line.
pub struct Curve {
    pub points: Vec<(f64, f64)>,
    pub colour: (u8, u8, u8),
    /// Legend text.
    pub label: String,
    /// Draw each point as a dot (outlined in black) instead of joining them.
    pub markers: bool,
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

/// Grey of cells without a value.
const MISSING: RGBColor = RGBColor(150, 150, 150);
const TICK: i32 = 5;

fn text(size: u32) -> TextStyle<'static> {
    TextStyle::from(("sans-serif", size).into_font()).color(&BLACK)
}

/// A round step (1, 2 or 5 × 10ⁿ) giving about `count` ticks over `span`.
pub fn nice_step(span: f64, count: usize) -> f64 {
    let raw = (span / count.max(1) as f64).abs();
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let mag = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw * (1.0 - 1e-9))
        .unwrap_or(10.0 * mag)
}

/// Ticks at the multiples of `step` in `[lo, hi]`, labelled with the digits the step needs
/// and `unit` appended.
pub fn ticks_every(lo: f64, hi: f64, step: f64, unit: &str) -> Vec<(f64, String)> {
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    (first..=last)
        .map(|k| {
            let v = k as f64 * step;
            let s = format!("{:.*}", decimals, if v == 0.0 { 0.0 } else { v });
            (v, format!("{}{unit}", s.replace('-', "−")))
        })
        .collect()
}

/// The drawing area of a plot's bitmap.
type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;
/// A chart over `f64 × f64` on a plot's bitmap.
type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A heat map's colour scale: the range the ramp spans (in log10 where the map is
/// logarithmic) and the colour bar's tick labels, which say where the range cuts the data
/// off.
struct ColourScale {
    log: bool,
    lo: f64,
    hi: f64,
    ticks: Vec<(f64, String)>,
}

impl ColourScale {
    fn of(map: &HeatMap) -> Self {
        let mut s = ColourScale {
            log: map.log,
            lo: 0.0,
            hi: 1.0,
            ticks: Vec::new(),
        };
        let finite: Vec<f64> = map
            .values
            .iter()
            .flatten()
            .filter(|v| s.shown(**v))
            .map(|&v| s.scale(v))
            .collect();
        let (mut lo, mut hi) = finite
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        if !(lo.is_finite() && hi.is_finite()) {
            (lo, hi) = (0.0, 1.0);
        }
        let (data_lo, data_hi) = (lo, hi);
        if let Some(min) = map.scale_limits.0 {
            lo = min;
            hi = hi.max(min);
        }
        if let Some(max) = map.scale_limits.1 {
            hi = max;
            lo = lo.min(max);
        }
        if hi <= lo {
            (lo, hi) = (lo - 0.5, hi + 0.5);
        }
        let bar_step = nice_step(hi - lo, 6);
        let mut ticks = ticks_every(lo, hi, bar_step, "");
        // Say where the scale cuts the data off.
        for (end, cut, sign) in [(lo, data_lo < lo, "≤ "), (hi, data_hi > hi, "≥ ")] {
            if cut {
                let near = |t: &(f64, String)| (t.0 - end).abs() < 1e-6 * bar_step;
                match ticks.iter_mut().find(|t| near(t)) {
                    Some(t) => t.1 = format!("{sign}{}", t.1),
                    None => ticks.push((end, format!("{sign}{}", format_tick(end)))),
                }
            }
        }
        s.lo = lo;
        s.hi = hi;
        s.ticks = ticks;
        s
    }

    fn span(&self) -> f64 {
        self.hi - self.lo
    }

    /// Whether a value has a colour (finite, and positive on a log scale).
    fn shown(&self, v: f64) -> bool {
        v.is_finite() && (!self.log || v > 0.0)
    }

    fn scale(&self, v: f64) -> f64 {
        if self.log {
            v.log10()
        } else {
            v
        }
    }

    /// The cell colour of a value: the ramp, or grey where it has none.
    fn colour(&self, v: f64) -> RGBColor {
        if self.shown(v) {
            let (r, g, b) = ramp((self.scale(v) - self.lo) / self.span());
            RGBColor(r, g, b)
        } else {
            MISSING
        }
    }
}

/// The text styles of a heat map and the margins around its cells (pixels).
struct Margins {
    title: TextStyle<'static>,
    desc: TextStyle<'static>,
    tick: TextStyle<'static>,
    group: TextStyle<'static>,
    /// Height of a line of tick labels.
    line_h: i32,
    top: i32,
    bottom: i32,
    left: i32,
    right: i32,
    /// Widest `y` tick label, and widest label of each level of `y` groups.
    y_tick_w: i32,
    y_group_w: Vec<i32>,
    bar_w: i32,
}

impl Margins {
    /// Measures the labels: the title's font shrinks (to 12 px at least) until it fits the
    /// width; the margins hold the ticks, groups, descriptions and the colour bar.
    fn measure(root: &Area, map: &HeatMap, scale: &ColourScale) -> Result<Self> {
        let (desc, tick, group) = (text(15), text(13), text(13));
        let size_of = |s: &str, style: &TextStyle| {
            root.estimate_text_size(s, style)
                .map(|(w, h)| (w as i32, h as i32))
                .map_err(plot_error)
        };
        let mut title = text(20);
        for px in (12..=20).rev() {
            title = text(px);
            if size_of(&map.title, &title)?.0 <= map.size.0 as i32 - 20 {
                break;
            }
        }
        let widest = |labels: &[&str], style: &TextStyle| -> Result<i32> {
            let mut w = 0;
            for s in labels {
                w = w.max(size_of(s, style)?.0);
            }
            Ok(w)
        };
        let line_h = size_of("Ag", &tick)?.1;
        let desc_h = size_of("Ag", &desc)?.1;
        let top = 12 + size_of(&map.title, &title)?.1 + 14;
        let y_tick_w = widest(
            &map.y_axis
                .ticks
                .iter()
                .map(|t| t.1.as_str())
                .collect::<Vec<_>>(),
            &tick,
        )?;
        let y_group_w: Vec<i32> = map
            .y_axis
            .groups
            .iter()
            .map(|level| {
                widest(
                    &level.iter().map(|g| g.2.as_str()).collect::<Vec<_>>(),
                    &group,
                )
            })
            .collect::<Result<_>>()?;
        let left =
            10 + desc_h + 10 + y_group_w.iter().map(|w| w + 16).sum::<i32>() + y_tick_w + TICK + 6;
        let bottom =
            TICK + 4 + line_h + map.x_axis.groups.len() as i32 * (line_h + 12) + 10 + desc_h + 10;
        let bar_label_w = widest(
            &scale
                .ticks
                .iter()
                .map(|t| t.1.as_str())
                .chain(map.missing_label.as_deref())
                .chain(map.scale_marks.iter().map(|m| m.1.as_str()))
                .collect::<Vec<_>>(),
            &tick,
        )?;
        let bar_w = 22;
        let right = 26 + bar_w + TICK + 4 + bar_label_w + 12 + desc_h + 10;
        Ok(Self {
            title,
            desc,
            tick,
            group,
            line_h,
            top,
            bottom,
            left,
            right,
            y_tick_w,
            y_group_w,
            bar_w,
        })
    }
}

/// Rows and columns of the grid; an empty or ragged grid is an error.
fn grid_size(map: &HeatMap) -> Result<(usize, usize)> {
    let rows = map.values.len();
    let cols = map.values.first().map_or(0, Vec::len);
    if rows == 0 || cols == 0 || map.values.iter().any(|r| r.len() != cols) {
        return Err(Error::invalid("plot", "empty or ragged grid"));
    }
    Ok((rows, cols))
}

/// Writes `map` as an RGB PNG: the title on top, the cells with the overlays and their
/// legend, ticks and group labels on both axes, and a colour bar with its scale on the right.
pub fn write_heat_map(path: &Path, map: &HeatMap) -> Result<()> {
    register_font();
    let (rows, cols) = grid_size(map)?;
    let (width, height) = map.size;
    if width < 200 || height < 150 {
        return Err(Error::invalid(
            "plot",
            format!("{width}×{height} is too small for a labelled heat map (200×150 at least)"),
        ));
    }
    let scale = ColourScale::of(map);
    let mut buf = vec![0u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_error)?;
        let m = Margins::measure(&root, map, &scale)?;
        let (w, h) = (width as i32, height as i32);
        if m.left + m.right + cols as i32 > w || m.top + m.bottom + rows as i32 > h {
            return Err(Error::invalid(
                "plot",
                format!("{width}×{height} leaves no room for the {cols}×{rows} cells"),
            ));
        }
        root.draw_text(
            &map.title,
            &m.title.pos(Pos::new(HPos::Center, VPos::Top)),
            (w / 2, 12),
        )
        .map_err(plot_error)?;
        let mut chart = ChartBuilder::on(&root)
            .margin_top(m.top)
            .margin_bottom(m.bottom)
            .margin_left(m.left)
            .margin_right(m.right)
            .build_cartesian_2d(map.x.0..map.x.1, map.y.0..map.y.1)
            .map_err(plot_error)?;
        draw_cells(&mut chart, map, &scale)?;
        draw_rules(&mut chart, map)?;
        draw_curves(&mut chart, map)?;
        draw_axes(&root, &chart, map, &m)?;
        draw_colour_bar(&root, &chart, map, &scale, &m)?;
        root.present().map_err(plot_error)?;
    }
    write_png(path, &buf, width, height)
}

/// One rectangle a cell, coloured by the scale.
fn draw_cells(chart: &mut Chart, map: &HeatMap, scale: &ColourScale) -> Result<()> {
    let rows = map.values.len();
    let cols = map.values.first().map_or(0, Vec::len);
    let dx = (map.x.1 - map.x.0) / cols as f64;
    let dy = (map.y.1 - map.y.0) / rows as f64;
    let cells = map.values.iter().enumerate().flat_map(|(r, row)| {
        row.iter().enumerate().map(move |(c, &v)| {
            let x = map.x.0 + c as f64 * dx;
            let y = map.y.0 + r as f64 * dy;
            Rectangle::new([(x, y), (x + dx, y + dy)], scale.colour(v).filled())
        })
    });
    chart.draw_series(cells).map_err(plot_error)?;
    Ok(())
}

/// White rules across the cells between groups.
fn draw_rules(chart: &mut Chart, map: &HeatMap) -> Result<()> {
    let rule = WHITE.stroke_width(2);
    for &x in &map.x_axis.rules {
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(x, map.y.0), (x, map.y.1)],
                rule,
            )))
            .map_err(plot_error)?;
    }
    for &y in &map.y_axis.rules {
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(map.x.0, y), (map.x.1, y)],
                rule,
            )))
            .map_err(plot_error)?;
    }
    Ok(())
}

/// The overlaid curves (lines broken at non-finite points, or markers) and their legend.
fn draw_curves<'a, 'b: 'a>(chart: &mut Chart<'a, 'b>, map: &HeatMap) -> Result<()> {
    for curve in &map.curves {
        let (r, g, b) = curve.colour;
        let colour = RGBColor(r, g, b);
        if curve.markers {
            let points: Vec<(f64, f64)> = curve
                .points
                .iter()
                .copied()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .collect();
            chart
                .draw_series(points.iter().map(|&p| Circle::new(p, 5, BLACK.filled())))
                .map_err(plot_error)?;
            let anno = chart
                .draw_series(points.iter().map(|&p| Circle::new(p, 3, colour.filled())))
                .map_err(plot_error)?;
            if !points.is_empty() && !curve.label.is_empty() {
                anno.label(curve.label.clone()).legend(move |(x, y)| {
                    EmptyElement::at((x + 10, y))
                        + Circle::new((0, 0), 5, BLACK.filled())
                        + Circle::new((0, 0), 3, colour.filled())
                });
            }
        } else {
            let mut labelled = curve.label.is_empty();
            for piece in curve
                .points
                .split(|p| !(p.0.is_finite() && p.1.is_finite()))
                .filter(|piece| piece.len() > 1)
            {
                let anno = chart
                    .draw_series(LineSeries::new(
                        piece.iter().copied(),
                        colour.stroke_width(2),
                    ))
                    .map_err(plot_error)?;
                if !labelled {
                    labelled = true;
                    anno.label(curve.label.clone()).legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                    });
                }
            }
        }
    }
    if map.curves.iter().any(|c| !c.label.is_empty()) {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .border_style(BLACK)
            .background_style(WHITE.mix(0.85))
            .label_font(text(14))
            .draw()
            .map_err(plot_error)?;
    }
    Ok(())
}

/// A one-pixel black line on the bitmap.
fn ink_line(root: &Area, a: (i32, i32), b: (i32, i32)) -> Result<()> {
    root.draw(&PathElement::new(vec![a, b], BLACK.stroke_width(1)))
        .map_err(plot_error)
}

/// The frame around the cells, the ticks and group labels of both axes and the axis
/// descriptions, in pixels.
fn draw_axes(root: &Area, chart: &Chart, map: &HeatMap, m: &Margins) -> Result<()> {
    let (x0, y0) = chart.backend_coord(&(map.x.0, map.y.0));
    let (x1, y1) = chart.backend_coord(&(map.x.1, map.y.1));
    let px = |x: f64| chart.backend_coord(&(x, map.y.0)).0;
    let py = |y: f64| chart.backend_coord(&(map.x.0, y)).1;
    let line = |a, b| ink_line(root, a, b);
    root.draw(&Rectangle::new([(x0, y1), (x1, y0)], BLACK.stroke_width(1)))
        .map_err(plot_error)?;
    for (x, label) in &map.x_axis.ticks {
        let p = px(*x);
        line((p, y0), (p, y0 + TICK))?;
        root.draw_text(
            label,
            &m.tick.pos(Pos::new(HPos::Center, VPos::Top)),
            (p, y0 + TICK + 3),
        )
        .map_err(plot_error)?;
    }
    for (level, spans) in map.x_axis.groups.iter().enumerate() {
        let y = y0 + TICK + 4 + m.line_h + 6 + level as i32 * (m.line_h + 12);
        for (a, b, label) in spans {
            let (a, b) = (px(*a) + 3, px(*b) - 3);
            line((a, y - 4), (a, y))?;
            line((a, y), (b, y))?;
            line((b, y - 4), (b, y))?;
            root.draw_text(
                label,
                &m.group.pos(Pos::new(HPos::Center, VPos::Top)),
                ((a + b) / 2, y + 2),
            )
            .map_err(plot_error)?;
        }
    }
    for (y, label) in &map.y_axis.ticks {
        let p = py(*y);
        line((x0 - TICK, p), (x0, p))?;
        root.draw_text(
            label,
            &m.tick.pos(Pos::new(HPos::Right, VPos::Center)),
            (x0 - TICK - 3, p),
        )
        .map_err(plot_error)?;
    }
    let mut x = x0 - TICK - 6 - m.y_tick_w - 6;
    for (spans, gw) in map.y_axis.groups.iter().zip(&m.y_group_w) {
        for (a, b, label) in spans {
            let (a, b) = (py(*a) - 3, py(*b) + 3);
            line((x + 4, a), (x, a))?;
            line((x, a), (x, b))?;
            line((x + 4, b), (x, b))?;
            root.draw_text(
                label,
                &m.group.pos(Pos::new(HPos::Right, VPos::Center)),
                (x - 5, (a + b) / 2),
            )
            .map_err(plot_error)?;
        }
        x -= gw + 16;
    }
    root.draw_text(
        &map.x_axis.label,
        &m.desc.pos(Pos::new(HPos::Center, VPos::Bottom)),
        ((x0 + x1) / 2, map.size.1 as i32 - 10),
    )
    .map_err(plot_error)?;
    root.draw_text(
        &map.y_axis.label,
        &m.desc
            .transform(FontTransform::Rotate270)
            .pos(Pos::new(HPos::Center, VPos::Top)),
        (10, (y0 + y1) / 2),
    )
    .map_err(plot_error)
}

/// The colour bar right of the cells: the ramp, its ticks, the marks on the scale (a mark's
/// label wins over a tick label it would overlap), its description and the swatch of the
/// cells without a value.
fn draw_colour_bar(
    root: &Area,
    chart: &Chart,
    map: &HeatMap,
    scale: &ColourScale,
    m: &Margins,
) -> Result<()> {
    let (_, y0) = chart.backend_coord(&(map.x.0, map.y.0));
    let (x1, y1) = chart.backend_coord(&(map.x.1, map.y.1));
    let w = map.size.0 as i32;
    let (lo, hi, span) = (scale.lo, scale.hi, scale.span());
    let line = |a, b| ink_line(root, a, b);
    let ink = BLACK.stroke_width(1);
    let bx0 = x1 + 26;
    let bx1 = bx0 + m.bar_w;
    let mut bar = ChartBuilder::on(root)
        .margin_top(m.top)
        .margin_bottom(m.bottom)
        .margin_left(bx0)
        .margin_right(w - bx1)
        .build_cartesian_2d(0.0..1.0, lo..hi)
        .map_err(plot_error)?;
    const STEPS: usize = 128;
    bar.draw_series((0..STEPS).map(|i| {
        let (r, g, b) = ramp((i as f64 + 0.5) / STEPS as f64);
        let v = |k: usize| lo + span * k as f64 / STEPS as f64;
        Rectangle::new([(0.0, v(i)), (1.0, v(i + 1))], RGBColor(r, g, b).filled())
    }))
    .map_err(plot_error)?;
    root.draw(&Rectangle::new([(bx0, y1), (bx1, y0)], ink))
        .map_err(plot_error)?;
    let marks: Vec<(i32, &String)> = map
        .scale_marks
        .iter()
        .filter(|mk| mk.0 >= lo && mk.0 <= hi)
        .map(|(v, label)| (bar.backend_coord(&(1.0, *v)).1, label))
        .collect();
    for (v, label) in &scale.ticks {
        let p = bar.backend_coord(&(1.0, *v)).1;
        line((bx1, p), (bx1 + TICK, p))?;
        if marks.iter().all(|mk| (mk.0 - p).abs() >= m.line_h) {
            root.draw_text(
                label,
                &m.tick.pos(Pos::new(HPos::Left, VPos::Center)),
                (bx1 + TICK + 4, p),
            )
            .map_err(plot_error)?;
        }
    }
    for (p, label) in marks {
        root.draw(&Rectangle::new(
            [(bx0 - 4, p - 1), (bx1 + TICK, p + 1)],
            BLACK.filled(),
        ))
        .map_err(plot_error)?;
        root.draw_text(
            label,
            &m.tick.pos(Pos::new(HPos::Left, VPos::Center)),
            (bx1 + TICK + 4, p),
        )
        .map_err(plot_error)?;
    }
    root.draw_text(
        &map.scale_label,
        &m.desc
            .transform(FontTransform::Rotate90)
            .pos(Pos::new(HPos::Center, VPos::Top)),
        (w - 10, (y0 + y1) / 2),
    )
    .map_err(plot_error)?;
    if let Some(label) = &map.missing_label {
        let y = y0 + TICK + 6;
        root.draw(&Rectangle::new(
            [(bx0, y), (bx1, y + m.line_h)],
            MISSING.filled(),
        ))
        .map_err(plot_error)?;
        root.draw(&Rectangle::new([(bx0, y), (bx1, y + m.line_h)], ink))
            .map_err(plot_error)?;
        root.draw_text(
            label,
            &m.tick.pos(Pos::new(HPos::Left, VPos::Center)),
            (bx1 + TICK + 4, y + m.line_h / 2),
        )
        .map_err(plot_error)?;
    }
    Ok(())
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
    fn points_whose_intervals_both_overlap_are_not_distinguishable() {
        let p = |t: f64, e: f64, dt: f64, de: f64| Point {
            label: String::new(),
            time_ms: t,
            error: e,
            error_range: Some((e - de, e + de)),
            time_range: Some((t - dt, t + dt)),
        };
        let a = p(10.0, 1e-3, 1.0, 2e-4);
        // Overlapping in both: alike.
        assert!(a.indistinguishable(&p(10.5, 1.1e-3, 1.0, 2e-4)));
        // Apart in error, or apart in time: told apart.
        assert!(!a.indistinguishable(&p(10.5, 2e-3, 1.0, 2e-4)));
        assert!(!a.indistinguishable(&p(20.0, 1.1e-3, 1.0, 2e-4)));
        // Without intervals a point is its value.
        let bare = Point {
            label: String::new(),
            time_ms: 10.0,
            error: 1e-3,
            ..Default::default()
        };
        assert!(a.indistinguishable(&bare));
        assert_eq!(
            indistinguishable(&[
                a.clone(),
                p(10.5, 1.1e-3, 1.0, 2e-4),
                p(50.0, 5e-2, 1.0, 1e-3)
            ]),
            vec![true, true, false]
        );
    }

    #[test]
    fn log_axes_get_one_tick_per_value_and_enough_of_them() {
        assert_eq!(
            log_key_points(0.003, 0.6),
            vec![0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5]
        );
        let narrow = log_key_points(40.0, 100.0);
        assert!(narrow.len() >= 3, "{narrow:?}");
        let labels: Vec<String> = log_key_points(0.003, 0.6)
            .iter()
            .map(|v| log_tick(*v))
            .collect();
        assert_eq!(
            labels,
            ["0.005", "0.01", "0.02", "0.05", "0.1", "0.2", "0.5"]
        );
        let mut unique = labels.clone();
        unique.dedup();
        assert_eq!(unique, labels, "a label printed twice");
        assert_eq!(log_tick(1.5), "1.5");
        assert_eq!(log_tick(200.0), "200");
        assert_eq!(log_tick(2e-5), format_tick(2e-5));
    }

    #[test]
    fn pareto_front_keeps_only_unbeaten_points() {
        let p = |t, e| Point {
            error_range: None,
            time_range: None,
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

    #[test]
    fn labels_of_a_crowded_cluster_do_not_overlap() {
        // Five marks within a few pixels of each other (as equal timings give), two apart.
        let marks = [
            (500, 300),
            (503, 301),
            (506, 300),
            (509, 302),
            (700, 300),
            (200, 100),
            (502, 299),
        ];
        let sizes = [
            (120, 14),
            (150, 14),
            (90, 14),
            (130, 14),
            (80, 14),
            (60, 14),
            (100, 14),
        ];
        let area = [100, 50, 950, 650];
        let corners = place_labels(&marks, &sizes, area);
        let boxes: Vec<[i32; 4]> = corners
            .iter()
            .zip(&sizes)
            .map(|(&(x, y), &(w, h))| [x, y, x + w as i32, y + h as i32])
            .collect();
        for (i, a) in boxes.iter().enumerate() {
            assert!(
                a[0] >= area[0] && a[1] >= area[1] && a[2] <= area[2] && a[3] <= area[3],
                "{a:?} outside"
            );
            for b in &boxes[i + 1..] {
                let apart = a[2] <= b[0] || b[2] <= a[0] || a[3] <= b[1] || b[3] <= a[1];
                assert!(apart, "labels {a:?} and {b:?} overlap");
            }
            for &(x, y) in &marks {
                let clear = a[2] <= x - 6 || x + 6 <= a[0] || a[3] <= y - 6 || y + 6 <= a[1];
                assert!(clear, "label {a:?} covers the mark at ({x}, {y})");
            }
        }
        // A lone mark keeps its label next to it: up and to the right.
        assert_eq!(corners[5], (208, 100 - 14 - 2));
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

    /// `name` in a directory of its own: the tests run in parallel and each removes its
    /// directory.
    fn scratch(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("diffract-plot-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    /// Pixels of `img` inside `x0..x1 × y0..y1` dark enough to be text or lines.
    fn ink(img: &image::RgbImage, (x0, x1): (u32, u32), (y0, y1): (u32, u32)) -> usize {
        (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let p = img.get_pixel(x, y).0;
                p.iter().map(|&c| c as u32).sum::<u32>() < 3 * 100
            })
            .count()
    }

    /// A 3 × 4 map with every kind of label, or none.
    fn sample(labelled: bool) -> image::RgbImage {
        let values = vec![
            vec![1.0, 10.0, 100.0],
            vec![0.0, f64::NAN, 1e3],
            vec![2.0, 20.0, 200.0],
            vec![5.0, 50.0, 500.0],
        ];
        let text = |s: &str| {
            if labelled {
                s.to_string()
            } else {
                String::new()
            }
        };
        let axis = |n: usize, unit: &str| crate::plot::Axis {
            label: text("axis"),
            ticks: if labelled {
                (0..n)
                    .map(|i| (i as f64 + 0.5, format!("{i}{unit}")))
                    .collect()
            } else {
                Vec::new()
            },
            groups: if labelled {
                vec![vec![
                    (0.0, 2.0, "first".into()),
                    (2.0, n as f64, "rest".into()),
                ]]
            } else {
                Vec::new()
            },
            rules: vec![2.0],
        };
        let p = scratch(if labelled { "labelled.png" } else { "bare.png" });
        write_heat_map(
            &p,
            &HeatMap {
                title: text("A heat map"),
                values: &values,
                x: (0.0, 3.0),
                y: (0.0, 4.0),
                x_axis: axis(3, " nm"),
                y_axis: axis(4, "°"),
                log: true,
                scale_label: text("log10 value"),
                scale_limits: (None, Some(2.5)),
                scale_marks: vec![(1.0, text("mark"))],
                missing_label: labelled.then(|| "refused".to_string()),
                curves: vec![
                    Curve {
                        points: vec![(0.0, 0.0), (1.0, 1.0), (f64::NAN, 0.0), (2.0, 1.0)],
                        colour: (0, 255, 0),
                        label: text("line"),
                        markers: false,
                    },
                    Curve {
                        points: vec![(0.5, 3.5), (2.5, 0.5)],
                        colour: (255, 255, 255),
                        label: text("dots"),
                        markers: true,
                    },
                ],
                size: (480, 360),
            },
        )
        .unwrap();
        image::open(&p).unwrap().to_rgb8()
    }

    #[test]
    fn heat_map_has_title_axes_labels_and_colour_bar() {
        let img = sample(true);
        assert_eq!(img.dimensions(), (480, 360));
        let bare = sample(false);
        // Bands outside the cells: the title on top, the y labels on the left, the x labels
        // at the bottom, the colour bar's title at the right edge.
        let bands = [
            ("title", (0, 480), (0, 28)),
            ("y labels", (0, 36), (40, 300)),
            ("x labels", (60, 380), (330, 360)),
            ("scale title", (455, 480), (40, 300)),
        ];
        for (name, x, y) in bands {
            let (with, without) = (ink(&img, x, y), ink(&bare, x, y));
            println!("{name}: {with} ink pixels labelled, {without} bare");
            assert!(with > 40, "{name}: {with} ink pixels");
            assert_eq!(without, 0, "{name}: the bare map drew text there");
        }
        // The colour bar runs from the ramp's dark end to its bright end.
        let bar: Vec<_> = (0..360)
            .flat_map(|y| (360..440).map(move |x| (x, y)))
            .map(|(x, y)| img.get_pixel(x, y).0)
            .collect();
        assert!(bar
            .iter()
            .any(|p| *p == [253, 252, 191] || p[0] > 240 && p[2] > 150));
        assert!(bar.iter().any(|p| p[2] > 100 && p[0] < 60 && p[1] < 30));
        // Grey cells for the missing values, and the legend's swatch.
        let grey = img.pixels().filter(|p| p.0 == [150, 150, 150]).count();
        assert!(grey > 100, "{grey} grey pixels");
        for name in ["labelled.png", "bare.png"] {
            std::fs::remove_dir_all(scratch(name).parent().unwrap()).ok();
        }
    }

    #[test]
    fn heat_map_refuses_bad_grids_and_tiny_images() {
        let p = scratch("bad.png");
        let map = |values: &[Vec<f64>], size| {
            write_heat_map(
                &p,
                &HeatMap {
                    title: String::new(),
                    values,
                    x: (0.0, 1.0),
                    y: (0.0, 1.0),
                    x_axis: Axis::default(),
                    y_axis: Axis::default(),
                    log: false,
                    scale_label: String::new(),
                    scale_limits: (None, None),
                    scale_marks: Vec::new(),
                    missing_label: None,
                    curves: Vec::new(),
                    size,
                },
            )
        };
        assert!(map(&[], (400, 300)).is_err());
        assert!(map(&[vec![1.0, 2.0], vec![1.0]], (400, 300)).is_err());
        assert!(map(&[vec![1.0]], (100, 80)).is_err());
        assert!(map(&[vec![1.0]], (400, 300)).is_ok());
    }

    #[test]
    fn error_plot_has_labelled_axes() {
        let p = scratch("error.png");
        let point = |label: &str, t, e| Point {
            error_range: None,
            time_range: None,
            label: label.into(),
            time_ms: t,
            error: e,
        };
        error_vs_time(
            &p,
            "title",
            "error",
            &[
                point("a", 3.0, 0.1),
                point("b", 30.0, 0.01),
                point("c", 3000.0, 0.2),
            ],
        )
        .unwrap();
        let img = image::open(&p).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (1000, 700));
        assert!(ink(&img, (0, 1000), (0, 40)) > 50, "title");
        assert!(ink(&img, (0, 95), (80, 620)) > 50, "y ticks and label");
        assert!(ink(&img, (100, 1000), (640, 700)) > 50, "x ticks and label");
    }

    #[test]
    fn a_side_curve_is_drawn_in_green_beside_the_front() {
        let p = scratch("curve.png");
        let point = |label: &str, t, e| Point {
            error_range: None,
            time_range: None,
            label: label.into(),
            time_ms: t,
            error: e,
        };
        let green = |img: &image::RgbImage| {
            img.pixels()
                .filter(|q| q[1] > 100 && q[0] < 60 && q[2] < 100)
                .count()
        };
        let front = [point("a", 3.0, 0.1), point("b", 30.0, 0.01)];
        error_vs_time(&p, "title", "error", &front).unwrap();
        assert_eq!(green(&image::open(&p).unwrap().to_rgb8()), 0);
        let curve = SideCurve {
            label: "by samples".into(),
            points: vec![
                point("1", 1.0, 1.0),
                point("16", 10.0, 0.3),
                point("256", 200.0, 0.05),
            ],
        };
        error_vs_time_with(&p, "title", "error", &front, std::slice::from_ref(&curve)).unwrap();
        assert!(
            green(&image::open(&p).unwrap().to_rgb8()) > 500,
            "the curve"
        );
        // The curve alone is a plot too.
        error_vs_time_with(&p, "title", "error", &[], std::slice::from_ref(&curve)).unwrap();
        assert!(error_vs_time_with(&p, "title", "error", &[], &[]).is_err());
    }

    #[test]
    fn tick_labels_and_source_names() {
        assert_eq!(source_name("/work/main/assets/elaphe.png"), "elaphe.png");
        assert_eq!(source_name("builtin:elaphe-grown"), "builtin:elaphe-grown");
        assert_eq!(format_tick(2000.0), "2000");
        assert_eq!(format_tick(0.05), "0.05");
        assert_eq!(format_tick(1e-4), "1e−4");
        assert_eq!(log_tick(300.0), "300");
        assert_eq!(log_tick(500.0), "500");
        assert_eq!(nice_step(300.0, 8), 50.0);
        assert_eq!(nice_step(13.7, 6), 5.0);
        let t = ticks_every(-90.0, 90.0, 30.0, "°");
        assert_eq!(t.len(), 7);
        assert_eq!(t[0].1, "−90°");
        assert_eq!(t[3].1, "0°");
        let t = ticks_every(-15.7, -2.1, 2.0, "");
        assert_eq!(t.first().unwrap().1, "−14");
        assert_eq!(t.last().unwrap().1, "−4");
    }
}
