//! PNG plots for the experiments (grating equation, stability matrix): a heat map of a
//! grid of values with curves drawn over it. Drawn with plotters' bitmap backend into a
//! buffer and encoded with `image`. No text: plotters without a font backend panics on
//! text, so axes and scales are stated by the caller (README, markdown next to the PNG).

use std::path::Path;

use plotters::prelude::*;

use crate::{Error, Result};

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
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(&buf, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| Error::Image {
            path: path.to_path_buf(),
            msg: e.to_string(),
        })?;
    crate::fsutil::write_atomic(path, &png)
}

use image::ImageEncoder;

#[cfg(test)]
mod tests {
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
