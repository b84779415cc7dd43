//! Gwyddion Simple Field (`.gsf`), read from the format's description in the Gwyddion user
//! guide: the magic line `Gwyddion Simple Field 1.0`, then `name = value` lines (`XRes` and
//! `YRes` required; `XReal`, `YReal` default to 1; `XOffset`, `YOffset`, `XYUnits`, `ZUnits`,
//! `Title` and any other key optional), then one to four NUL bytes that align the data to a
//! multiple of 4 bytes from the start of the file, then `XRes·YRes` little-endian float32
//! values, row by row. One channel per file.

use std::path::Path;

use super::scan::{check_declared_size, Channel, ChannelInfo};
use crate::{Error, Result};

/// The first line of every `.gsf` file (without its line feed).
pub const MAGIC: &str = "Gwyddion Simple Field 1.0";

/// Largest header read (bytes). The header is text lines; a megabyte of them is far beyond
/// what any exporter writes, and a file without a NUL within it is not a `.gsf`.
const MAX_HEADER_BYTES: usize = 1 << 20;

/// Reads the one channel of a `.gsf` file, checking the header's sizes against the file
/// length and the limits before the data are decoded.
pub fn read(path: &Path) -> Result<Channel> {
    let bytes = crate::fsutil::read_bounded(path, "scan file", super::scan::MAX_SCAN_BYTES)?;
    parse(path, &bytes)
}

/// [`read`] on bytes already in memory (`path` names them in errors).
pub fn parse(path: &Path, bytes: &[u8]) -> Result<Channel> {
    let bad = |msg: String| Error::parse(path, msg);
    let magic_line = format!("{MAGIC}\n");
    if !bytes.starts_with(magic_line.as_bytes()) {
        return Err(bad(format!(
            "not a Gwyddion Simple Field file (it must begin with the line {MAGIC:?})"
        )));
    }
    let header_end = bytes
        .iter()
        .take(MAX_HEADER_BYTES)
        .position(|&b| b == 0)
        .ok_or_else(|| {
            bad(format!(
                "no NUL byte ends the header within {MAX_HEADER_BYTES} bytes (truncated or not a .gsf)"
            ))
        })?;
    let text = std::str::from_utf8(&bytes[magic_line.len()..header_end])
        .map_err(|e| bad(format!("header is not UTF-8 text: {e}")))?;
    let header = Header::parse(text).map_err(bad)?;
    // One to four NULs: the data begin at the next multiple of 4 after the first one.
    let data_start = (header_end / 4 + 1) * 4;
    if bytes.len() < data_start || bytes[header_end..data_start].iter().any(|&b| b != 0) {
        return Err(bad(format!(
            "the header's NUL padding must run to byte {data_start} (a multiple of 4)"
        )));
    }
    let available = (bytes.len() - data_start) as u64;
    let (nx, ny) = check_declared_size(path, header.xres, header.yres, 4, available)?;
    if available != (nx * ny * 4) as u64 {
        return Err(bad(format!(
            "{available} bytes of data after the header; {nx}×{ny} float32 values need {}",
            nx * ny * 4
        )));
    }
    let data = bytes[data_start..]
        .chunks_exact(4)
        .map(|b| f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])))
        .collect();
    Ok(Channel {
        info: ChannelInfo {
            title: header.title,
            nx,
            ny,
            x_real: header.x_real,
            y_real: header.y_real,
            xy_unit: header.xy_unit,
            z_unit: header.z_unit,
        },
        data,
    })
}

/// The header fields diffract uses.
#[derive(Debug)]
struct Header {
    xres: i64,
    yres: i64,
    x_real: f64,
    y_real: f64,
    xy_unit: String,
    z_unit: String,
    title: String,
}

impl Header {
    fn parse(text: &str) -> std::result::Result<Self, String> {
        let mut h = Header {
            xres: -1,
            yres: -1,
            x_real: 1.0,
            y_real: 1.0,
            xy_unit: String::new(),
            z_unit: String::new(),
            title: String::new(),
        };
        let (mut have_x, mut have_y) = (false, false);
        for (n, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            let lineno = n + 2;
            let (key, value) = line
                .split_once('=')
                .map(|(k, v)| (k.trim(), v.trim()))
                .ok_or_else(|| format!("header line {lineno}: {line:?} is not `name = value`"))?;
            let int = |v: &str| {
                v.parse::<i64>()
                    .map_err(|_| format!("header line {lineno}: {key} = {v:?} is not an integer"))
            };
            let real = |v: &str| match v.parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(x),
                _ => Err(format!(
                    "header line {lineno}: {key} = {v:?} is not a finite number"
                )),
            };
            match key {
                "XRes" => (h.xres, have_x) = (int(value)?, true),
                "YRes" => (h.yres, have_y) = (int(value)?, true),
                "XReal" => h.x_real = real(value)?,
                "YReal" => h.y_real = real(value)?,
                "XOffset" | "YOffset" => {
                    real(value)?;
                }
                "XYUnits" => h.xy_unit = value.to_string(),
                "ZUnits" => h.z_unit = value.to_string(),
                "Title" => h.title = value.to_string(),
                _ => {}
            }
        }
        if !(have_x && have_y) {
            return Err("the header lacks XRes or YRes (both are required)".into());
        }
        Ok(h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(header: &str, values: &[f32]) -> Vec<u8> {
        let mut b = format!("{MAGIC}\n{header}").into_bytes();
        let pad = 4 - b.len() % 4;
        b.extend(std::iter::repeat_n(0u8, pad));
        for v in values {
            b.extend(v.to_le_bytes());
        }
        b
    }

    #[test]
    fn reads_header_and_data() {
        let b = file(
            "XRes = 3\nYRes = 2\nXReal = 3e-6\nYReal = 2e-6\nXYUnits = m\nZUnits = nm\nTitle = Height\n",
            &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        );
        let c = parse(Path::new("a.gsf"), &b).unwrap();
        assert_eq!((c.info.nx, c.info.ny), (3, 2));
        assert_eq!(c.info.z_unit, "nm");
        assert_eq!(c.info.title, "Height");
        assert_eq!(c.data, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    }

    #[test]
    fn rejects_bad_headers() {
        let p = Path::new("a.gsf");
        for (header, values, want) in [
            ("XRes = 2\nYRes = 2\n", &[0.0f32; 3][..], "truncated"),
            ("XRes = 2\nYRes = 2\n", &[0.0f32; 5][..], "need 16"),
            ("XRes = 2\n", &[0.0f32; 4][..], "YRes"),
            ("XRes = 0\nYRes = 2\n", &[][..], "empty"),
            ("XRes = 99999\nYRes = 2\n", &[][..], "limit"),
            (
                "XRes = 2\nYRes = 2\nXReal = nan\n",
                &[0.0f32; 4][..],
                "finite",
            ),
            ("XRes = two\nYRes = 2\n", &[0.0f32; 4][..], "integer"),
        ] {
            let e = parse(p, &file(header, values)).unwrap_err().to_string();
            assert!(e.contains(want), "{header:?}: {e}");
        }
        let e = parse(p, b"Gwyddion Simple Field 2.0\n").unwrap_err();
        assert!(e.to_string().contains("not a Gwyddion"), "{e}");
    }
}
