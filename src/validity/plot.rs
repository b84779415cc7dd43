//! The validity map as a PNG: the scalar model's worst order-ratio error over the angle of
//! the light (y) and the wavelength (x), on a logarithmic colour scale from 1 % to 10×, with
//! the 10 % and 25 % verdict lines marked on the colour bar.

use std::path::Path;

use image::ImageEncoder;
use plotters::prelude::*;

use super::Map;
use crate::{Error, Result};

/// Colour-scale limits (relative error): below and above them the colours saturate.
const SCALE: (f64, f64) = (0.01, 10.0);

fn plot_error(e: impl std::fmt::Display) -> Error {
    Error::invalid("plot", e.to_string())
}

/// The colour of relative error `e` (grey where there is none).
fn colour(e: f64) -> RGBColor {
    if !e.is_finite() {
        return RGBColor(150, 150, 150);
    }
    let t = (e.max(SCALE.0).log10() - SCALE.0.log10()) / (SCALE.1.log10() - SCALE.0.log10());
    let (r, g, b) = crate::plot::ramp(t);
    RGBColor(r, g, b)
}

/// Writes `map` as a labelled heat map to `path` (PNG, written atomically).
pub fn write_map(path: &Path, map: &Map, title: &str) -> Result<()> {
    crate::plot::register_font();
    let (nt, nl) = (map.thetas_deg.len(), map.lambdas_nm.len());
    if nt == 0 || nl == 0 {
        return Err(Error::invalid("plot", "empty validity map"));
    }
    let half = |v: &[f64]| {
        if v.len() > 1 {
            0.5 * (v[1] - v[0])
        } else {
            1.0
        }
    };
    let (dl, dt) = (half(&map.lambdas_nm), half(&map.thetas_deg));
    let x = (map.lambdas_nm[0] - dl, map.lambdas_nm[nl - 1] + dl);
    let y = (map.thetas_deg[0] - dt, map.thetas_deg[nt - 1] + dt);
    let (width, height) = (900u32, 600u32);
    let mut buf = vec![0u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_error)?;
        let (main, bar) = root.split_horizontally(width - 150);
        let mut chart = ChartBuilder::on(&main)
            .caption(title, ("sans-serif", 18))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(x.0..x.1, y.0..y.1)
            .map_err(plot_error)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("wavelength λ (nm)")
            .y_desc("light θi (°)")
            .x_labels(8)
            .y_labels(10)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style(("sans-serif", 13))
            .draw()
            .map_err(plot_error)?;
        chart
            .draw_series(map.error.iter().enumerate().flat_map(|(i, row)| {
                row.iter().enumerate().map(move |(j, &e)| {
                    let (l, t) = (map.lambdas_nm[j], map.thetas_deg[i]);
                    Rectangle::new([(l - dl, t - dt), (l + dl, t + dt)], colour(e).filled())
                })
            }))
            .map_err(plot_error)?;
        let mut scale = ChartBuilder::on(&bar)
            .margin_top(45)
            .margin_bottom(60)
            .margin_right(55)
            .y_label_area_size(0)
            .right_y_label_area_size(60)
            .caption("ratio error", ("sans-serif", 13))
            .build_cartesian_2d(0.0..1.0, (SCALE.0..SCALE.1).log_scale())
            .map_err(plot_error)?;
        scale
            .configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_label_formatter(&|v| format!("{:.0} %", 100.0 * v))
            .y_labels(4)
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(plot_error)?;
        let steps = 200;
        let ratio = SCALE.1 / SCALE.0;
        scale
            .draw_series((0..steps).map(|k| {
                let e0 = SCALE.0 * ratio.powf(k as f64 / steps as f64);
                let e1 = SCALE.0 * ratio.powf((k + 1) as f64 / steps as f64);
                Rectangle::new([(0.0, e0), (1.0, e1)], colour(e0).filled())
            }))
            .map_err(plot_error)?;
        for (e, label) in [(0.10, "10 %"), (0.25, "25 %")] {
            scale
                .draw_series(std::iter::once(PathElement::new(
                    vec![(0.0, e), (1.0, e)],
                    WHITE.stroke_width(2),
                )))
                .map_err(plot_error)?;
            scale
                .draw_series(std::iter::once(Text::new(
                    label,
                    (0.08, e * 1.12),
                    ("sans-serif", 12).into_font().color(&WHITE),
                )))
                .map_err(plot_error)?;
        }
        root.present().map_err(plot_error)?;
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
