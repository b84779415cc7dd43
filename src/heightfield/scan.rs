//! Scanning-probe files as Gwyddion saves them: `.gsf` (one channel, [`super::gsf`]) and
//! `.gwy` (a container of channels, [`super::gwy`]). Both carry their physical sizes and SI
//! units; this module turns a channel into a [`HeightField`] in µm: picks the channel,
//! converts the units, checks that the pixels are square and that every height is finite.
//! Levelling is [`super::level`]'s work.

use std::path::Path;

use super::{HeightField, MAX_SIDE};
use crate::{Error, Result};

/// Largest scan file read (bytes): four channels of a 4096² scan in f64 (512 MiB) and
/// a megabyte of metadata. A `.gwy` is read whole; the chosen channel is decoded from it.
pub const MAX_SCAN_BYTES: u64 = 4 * (MAX_SIDE * MAX_SIDE * 8) as u64 + (1 << 20);

/// What a reader knows about one channel before its data are decoded.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelInfo {
    /// The channel's title (`Title` in a `.gsf`, `/N/data/title` in a `.gwy`); may be empty.
    pub title: String,
    /// Samples along x (columns) and y (rows).
    pub nx: usize,
    pub ny: usize,
    /// Physical extent along x and y, in `xy_unit`.
    pub x_real: f64,
    pub y_real: f64,
    /// Lateral unit as written in the file (`m`, `µm`, …; empty when the file has none).
    pub xy_unit: String,
    /// Value unit as written in the file (`m` for a height, `V`, `deg`, …).
    pub z_unit: String,
}

/// One channel of a scan, decoded, in the file's units.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    pub info: ChannelInfo,
    /// Row-major values in `info.z_unit`; the first row is the first scan line.
    pub data: Vec<f64>,
}

/// The metres in one `unit`, when `unit` is a length: `m` with an SI prefix (`pm`, `nm`,
/// `µm`/`um`, `mm`, `cm`, `km`, …) or the ångström (`Å`, `Ang`). `None` for anything
/// else (`V`, `deg`, `m^2`, an empty unit).
pub fn metres_per_unit(unit: &str) -> Option<f64> {
    let u = unit.trim();
    // Not a bare "A": that is the ampere of a current channel.
    if matches!(u, "\u{c5}" | "\u{212b}" | "Ang" | "ang" | "angstrom") {
        return Some(1e-10);
    }
    let prefix = u.strip_suffix('m')?;
    let factor = match prefix {
        "" => 1.0,
        "k" => 1e3,
        "c" => 1e-2,
        "d" => 1e-1,
        "m" => 1e-3,
        "µ" | "μ" | "u" | "micro" => 1e-6,
        "n" => 1e-9,
        "p" => 1e-12,
        "f" => 1e-15,
        _ => return None,
    };
    Some(factor)
}

/// Whether a channel's title names a topography channel.
fn title_says_height(title: &str) -> bool {
    let t = title.trim().to_ascii_lowercase();
    let words = [
        "height",
        "topography",
        "topo",
        "zsensor",
        "z sensor",
        "z-sensor",
    ];
    t == "z" || t.starts_with("z ") || words.iter().any(|w| t.contains(w))
}

/// One line listing the channels: `0 "Height" (m), 1 "Phase" (deg)`.
pub fn list_channels(infos: &[ChannelInfo]) -> String {
    infos
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let unit = if c.z_unit.is_empty() {
                "no unit"
            } else {
                &c.z_unit
            };
            format!("{i} \"{}\" ({unit}, {}×{})", c.title, c.nx, c.ny)
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The index of the channel to use: `want` as an index or a title (exact, then
/// case-insensitive), or by default the first channel whose value unit is a length and
/// whose title says it is a height, else the first whose unit is a length. An error names
/// the channels.
pub fn choose_channel(path: &Path, infos: &[ChannelInfo], want: Option<&str>) -> Result<usize> {
    if infos.is_empty() {
        return Err(Error::parse(
            path,
            "no image channel (GwyDataField) in the file",
        ));
    }
    if let Some(w) = want {
        let w = w.trim();
        if let Ok(i) = w.parse::<usize>() {
            if i < infos.len() {
                return Ok(i);
            }
        }
        let found = infos
            .iter()
            .position(|c| c.title == w)
            .or_else(|| infos.iter().position(|c| c.title.eq_ignore_ascii_case(w)));
        return found.ok_or_else(|| {
            Error::parse(
                path,
                format!(
                    "no channel {w:?}; the channels are: {}",
                    list_channels(infos)
                ),
            )
        });
    }
    let length = |c: &ChannelInfo| metres_per_unit(&c.z_unit).is_some();
    infos
        .iter()
        .position(|c| length(c) && title_says_height(&c.title))
        .or_else(|| infos.iter().position(length))
        .ok_or_else(|| {
            Error::parse(
                path,
                format!(
                    "no height channel (a length unit such as m or nm); choose one with \
                     --channel NAME|INDEX (and give --hmax-um for a channel without a length \
                     unit); the channels are: {}",
                    list_channels(infos)
                ),
            )
        })
}

/// Checks a channel's declared size against the limits and against the bytes that hold
/// its data (`available`, with `bytes_per_sample` each), before anything is allocated.
pub fn check_declared_size(
    path: &Path,
    nx: i64,
    ny: i64,
    bytes_per_sample: u64,
    available: u64,
) -> Result<(usize, usize)> {
    if nx <= 0 || ny <= 0 {
        return Err(Error::parse(
            path,
            format!("declared size {nx}×{ny} is empty; a scan needs at least 1×1 samples"),
        ));
    }
    if nx > MAX_SIDE as i64 || ny > MAX_SIDE as i64 {
        return Err(Error::parse(
            path,
            format!("declared size {nx}×{ny} exceeds the limit of {MAX_SIDE} samples a side"),
        ));
    }
    let need = nx as u64 * ny as u64 * bytes_per_sample;
    if need > available {
        return Err(Error::parse(
            path,
            format!(
                "declared size {nx}×{ny} needs {need} bytes of data but the file holds \
                 {available} (truncated?)"
            ),
        ));
    }
    Ok((nx as usize, ny as usize))
}

/// The height field of a decoded channel, in µm. `dh_um` and `h_max_um` override the
/// file: the pixel size, and the peak-to-valley height the values are scaled to (for a
/// channel whose unit is not a length, or to correct a calibration). Pixels must be square
/// within 0.5 % (the renderer has one `dH`).
pub fn to_heightfield(
    path: &Path,
    ch: &Channel,
    dh_um: Option<f64>,
    h_max_um: Option<f64>,
) -> Result<HeightField> {
    let info = &ch.info;
    if let Some(i) = ch.data.iter().position(|v| !v.is_finite()) {
        return Err(Error::parse(
            path,
            format!(
                "channel \"{}\": sample (column {}, row {}) is not finite (NaN or inf); fill \
                 or mask-interpolate it in Gwyddion (Data Process → Correct Data) and save again",
                info.title,
                i % info.nx,
                i / info.nx
            ),
        ));
    }
    let dh = match dh_um {
        Some(d) => d,
        None => pixel_size_um(path, info)?,
    };
    let heights: Vec<f64> = match h_max_um {
        Some(h_max) => {
            if !(h_max.is_finite() && h_max >= 0.0) {
                return Err(Error::parse(
                    path,
                    format!("h_max_um = {h_max}; must be finite and ≥ 0 µm"),
                ));
            }
            let (lo, hi) = ch
                .data
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                    (a.min(v), b.max(v))
                });
            let scale = if hi > lo { h_max / (hi - lo) } else { 0.0 };
            ch.data.iter().map(|v| (v - lo) * scale).collect()
        }
        None => {
            let Some(m) = metres_per_unit(&info.z_unit) else {
                return Err(Error::parse(
                    path,
                    format!(
                        "channel \"{}\" has values in {:?}, not a length; give --hmax-um (or \
                         h_max_um in the sidecar) for its peak-to-valley height in µm",
                        info.title, info.z_unit
                    ),
                ));
            };
            ch.data.iter().map(|v| v * m * 1e6).collect()
        }
    };
    HeightField::new(info.nx, info.ny, dh, heights).map_err(|e| match e {
        Error::Invalid { .. } => Error::parse(path, e.to_string()),
        other => other,
    })
}

/// The pixel size in µm from the channel's extent and lateral unit.
fn pixel_size_um(path: &Path, info: &ChannelInfo) -> Result<f64> {
    let Some(m) = metres_per_unit(&info.xy_unit) else {
        return Err(Error::parse(
            path,
            format!(
                "lateral unit {:?} is not a length, so the pixel size is unknown; give --dh-um \
                 (or dh_um in the sidecar)",
                info.xy_unit
            ),
        ));
    };
    let dx = info.x_real / info.nx as f64 * m * 1e6;
    let dy = info.y_real / info.ny as f64 * m * 1e6;
    if !(dx.is_finite() && dx > 0.0 && dy.is_finite() && dy > 0.0) {
        return Err(Error::parse(
            path,
            format!(
                "physical size {} × {} {} is not a positive length",
                info.x_real, info.y_real, info.xy_unit
            ),
        ));
    }
    if (dx - dy).abs() > 0.005 * dx.max(dy) {
        return Err(Error::parse(
            path,
            format!(
                "pixels are not square ({:.3} nm along x, {:.3} nm along y); resample the scan \
                 to square pixels in Gwyddion (Basic Operations → Scale) or give --dh-um",
                dx * 1e3,
                dy * 1e3
            ),
        ));
    }
    Ok(dx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_convert_to_metres() {
        for (u, m) in [
            ("m", 1.0),
            ("mm", 1e-3),
            ("µm", 1e-6),
            ("um", 1e-6),
            ("nm", 1e-9),
            ("pm", 1e-12),
            ("Å", 1e-10),
            (" nm ", 1e-9),
        ] {
            assert_eq!(metres_per_unit(u), Some(m), "{u}");
        }
        for u in ["", "V", "A", "deg", "m^2", "Hz", "mV", "xm"] {
            assert_eq!(metres_per_unit(u), None, "{u}");
        }
    }

    fn info(title: &str, z: &str) -> ChannelInfo {
        ChannelInfo {
            title: title.into(),
            nx: 2,
            ny: 2,
            x_real: 1.0,
            y_real: 1.0,
            xy_unit: "m".into(),
            z_unit: z.into(),
        }
    }

    #[test]
    fn the_height_channel_is_found_by_title_and_unit() {
        let p = Path::new("x.gwy");
        let chans = [
            info("Phase", "deg"),
            info("Amplitude", "m"),
            info("Height", "m"),
        ];
        assert_eq!(choose_channel(p, &chans, None).unwrap(), 2);
        assert_eq!(choose_channel(p, &chans, Some("1")).unwrap(), 1);
        assert_eq!(choose_channel(p, &chans, Some("phase")).unwrap(), 0);
        let none = [info("Phase", "deg"), info("Current", "A")];
        let e = choose_channel(p, &none, None).unwrap_err().to_string();
        assert!(e.contains("\"Phase\"") && e.contains("\"Current\""), "{e}");
    }
}
