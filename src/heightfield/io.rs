//! Height-field files: 8/16-bit grey PNG (`h = g·h_max`; grey stored as RGB/RGBA or as a
//! palette with R = G = B is accepted, as measurement tools and the thesis write it) and raw
//! little-endian `.f32` heights in µm, each with an optional TOML sidecar (`elaphe.png` → `elaphe.toml`) giving
//! `dh_um`, `h_max_um` (images) or `nx`, `ny` (raw). Caller-supplied values override the
//! sidecar. Writes go through a temporary sibling file and a rename, so a failed save never
//! leaves a half-written file behind.

use std::path::{Path, PathBuf};

use super::generate::{generate, GratingKind, GratingSpec};
use super::HeightField;
use crate::fsutil::write_atomic;
use crate::{Error, Result};

/// Prefix that selects a generated default grating instead of a file.
pub const BUILTIN_PREFIX: &str = "builtin:";

/// The keys a sidecar may hold; anything else is rejected so typos do not pass silently.
#[derive(Debug, Default, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
struct Sidecar {
    #[serde(skip_serializing_if = "Option::is_none")]
    nx: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    ny: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    dh_um: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    h_max_um: Option<f64>,
}

/// File formats by extension.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Format {
    Png,
    RawF32,
}

fn format_of(path: &Path) -> Result<Format> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("png") => Ok(Format::Png),
        Some("f32") => Ok(Format::RawF32),
        _ => Err(Error::Image {
            path: path.to_path_buf(),
            msg: "unknown height-field format; expected .png (8/16-bit grayscale), .f32 \
                  (raw little-endian heights in µm), or a Gwyddion scan (.gsf, .gwy)"
                .into(),
        }),
    }
}

/// `elaphe.png` → `elaphe.toml`.
pub fn sidecar_path(path: &Path) -> PathBuf {
    path.with_extension("toml")
}

/// Reads the sidecar beside `path`, or an empty one when there is none.
fn read_sidecar(path: &Path) -> Result<Sidecar> {
    let side = sidecar_path(path);
    let text =
        match crate::fsutil::read_text_bounded(&side, "sidecar", crate::fsutil::MAX_TOML_BYTES) {
            Ok(t) => t,
            Err(Error::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
                return Ok(Sidecar::default())
            }
            Err(e) => return Err(e),
        };
    toml::from_str(&text).map_err(|e| Error::parse(&side, one_line_toml_error(&text, &e)))
}

/// toml's own message spans several lines (with a source excerpt); the crate prints errors
/// on one line, so rebuild it as "line L, column C: message".
fn one_line_toml_error(text: &str, e: &toml::de::Error) -> String {
    let msg = e.message().trim().replace('\n', "; ");
    match e.span() {
        Some(span) => {
            let before = &text[..span.start.min(text.len())];
            let line = before.matches('\n').count() + 1;
            let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
            format!("line {line}, column {column}: {msg}")
        }
        None => msg,
    }
}

fn check_h_max(h_max: f64, path: &Path) -> Result<f64> {
    if h_max.is_finite() && h_max >= 0.0 {
        Ok(h_max)
    } else {
        Err(Error::parse(
            path,
            format!("h_max_um = {h_max}; the height of grey level 1 must be finite and ≥ 0 µm"),
        ))
    }
}

/// Attaches the file name to validation errors from [`HeightField::new`].
fn with_path(path: &Path) -> impl FnOnce(Error) -> Error + '_ {
    move |e| match e {
        Error::Invalid { .. } => Error::parse(path, e.to_string()),
        other => other,
    }
}

impl HeightField {
    /// Reads a PNG (8/16-bit grey; RGB/RGBA/palette with R = G = B; alpha ignored) or raw `.f32` height field. `dh_um`
    /// and `h_max_um` override the sidecar; a value missing from both is an error naming
    /// both places. Never panics on a bad file.
    ///
    /// Scans are not read here: [`HeightField::load`] sends them to [`super::load`].
    pub(super) fn read_image(
        path: &Path,
        dh_um: Option<f64>,
        h_max_um: Option<f64>,
    ) -> Result<HeightField> {
        let format = format_of(path)?;
        // A missing file (or a device, or a huge file) is the first thing to report, before
        // any complaint about its scale.
        let limit = match format {
            Format::Png => crate::fsutil::MAX_PNG_BYTES,
            Format::RawF32 => (super::MAX_SIDE * super::MAX_SIDE * 4) as u64,
        };
        crate::fsutil::check_input_file(path, "height field", limit)?;
        let side = read_sidecar(path)?;
        let side_path = sidecar_path(path);
        let dh = dh_um.or(side.dh_um).ok_or_else(|| {
            Error::parse(
                path,
                format!(
                    "pixel size unknown: give dh_um (--dh-um or the scene) or `dh_um` in {}",
                    side_path.display()
                ),
            )
        })?;
        match format {
            Format::Png => {
                let h_max = h_max_um.or(side.h_max_um).ok_or_else(|| {
                    Error::parse(
                        path,
                        format!(
                            "height scale unknown: give h_max_um (--hmax-um or the scene) or \
                             `h_max_um` in {}",
                            side_path.display()
                        ),
                    )
                })?;
                let h_max = check_h_max(h_max, path)?;
                let (nx, ny, grey) = read_png(path)?;
                for (key, want, got) in [("nx", side.nx, nx), ("ny", side.ny, ny)] {
                    if want.is_some_and(|w| w != got) {
                        return Err(Error::parse(
                            &side_path,
                            format!(
                                "{key} = {} but {} is {nx}×{ny}",
                                want.unwrap_or(0),
                                path.display()
                            ),
                        ));
                    }
                }
                let heights = grey.into_iter().map(|g| g * h_max).collect();
                HeightField::new(nx, ny, dh, heights).map_err(with_path(path))
            }
            Format::RawF32 => {
                if h_max_um.is_some() || side.h_max_um.is_some() {
                    return Err(Error::parse(
                        path,
                        "h_max_um only applies to grayscale images; .f32 heights are already in µm",
                    ));
                }
                let (Some(nx), Some(ny)) = (side.nx, side.ny) else {
                    return Err(Error::parse(
                        path,
                        format!(
                            "raw .f32 heights need `nx` and `ny` in {}",
                            side_path.display()
                        ),
                    ));
                };
                let heights = read_f32(path, nx, ny)?;
                HeightField::new(nx, ny, dh, heights).map_err(with_path(path))
            }
        }
    }
}

/// The field a source names as stored, before any levelling: a built-in field or a PNG or
/// `.f32` file ([`HeightField::read_image`]). Scans are [`super::load`]'s.
pub(super) fn read_source(
    spec: &str,
    dh_um: Option<f64>,
    h_max_um: Option<f64>,
) -> Result<HeightField> {
    let Some(name) = spec.strip_prefix(BUILTIN_PREFIX) else {
        return HeightField::read_image(Path::new(spec), dh_um, h_max_um);
    };
    match name.to_ascii_lowercase().as_str() {
        "elaphe-measured" => return measured_elaphe(dh_um, h_max_um),
        "elaphe-grown" => {
            return super::grow::grow(&measured_elaphe(dh_um, h_max_um)?, GROWN_SAMPLES, 1)
        }
        _ => {}
    }
    let kind: GratingKind = name.parse()?;
    let mut grating = GratingSpec::default_for(kind);
    if let Some(dh) = dh_um {
        grating.dh_um = dh;
    }
    let hf = generate(&grating)?;
    match h_max_um {
        None => Ok(hf),
        Some(h_max) => {
            if !(h_max.is_finite() && h_max >= 0.0) {
                return Err(Error::invalid(
                    "h_max",
                    format!("{h_max} µm; must be finite and ≥ 0"),
                ));
            }
            let (lo, hi) = hf.range();
            let scale = if hi > lo { h_max / (hi - lo) } else { 0.0 };
            let heights = hf.heights_um.iter().map(|h| (h - lo) * scale).collect();
            HeightField::new(hf.nx, hf.ny, hf.dh_um, heights)
        }
    }
}

/// A scan's sidecar overrides: `dh_um` and `h_max_um` (the peak-to-valley height).
pub(super) fn sidecar_scale(path: &Path) -> Result<(Option<f64>, Option<f64>)> {
    let side = read_sidecar(path)?;
    if side.nx.is_some() || side.ny.is_some() {
        return Err(Error::parse(
            sidecar_path(path),
            "nx and ny do not apply to a scan file; its header gives the size",
        ));
    }
    Ok((side.dh_um, side.h_max_um))
}

impl HeightField {
    /// Saves by extension: `.png` → 16-bit grayscale with heights shifted so the minimum is
    /// 0 and the sidecar giving `dh_um` and `h_max_um = max − min`; `.f32` → raw
    /// little-endian µm with `nx`, `ny`, `dh_um` in the sidecar. PNG quantises heights to
    /// steps of `h_max/65535`.
    pub fn save(&self, path: &Path) -> Result<()> {
        let (data, sidecar) = match format_of(path)? {
            Format::Png => {
                let (lo, hi) = self.range();
                let span = hi - lo;
                let levels: Vec<u16> = self
                    .heights_um
                    .iter()
                    .map(|h| {
                        if span > 0.0 {
                            ((h - lo) / span * 65535.0).round().clamp(0.0, 65535.0) as u16
                        } else {
                            0
                        }
                    })
                    .collect();
                let bytes: Vec<u8> = levels.iter().flat_map(|v| v.to_ne_bytes()).collect();
                let mut png = Vec::new();
                let (w, h) = (self.nx as u32, self.ny as u32);
                image::ImageEncoder::write_image(
                    image::codecs::png::PngEncoder::new(&mut png),
                    &bytes,
                    w,
                    h,
                    image::ExtendedColorType::L16,
                )
                .map_err(|e| Error::Image {
                    path: path.to_path_buf(),
                    msg: format!("PNG encoding failed: {e}"),
                })?;
                let side = Sidecar {
                    dh_um: Some(self.dh_um),
                    h_max_um: Some(span),
                    ..Sidecar::default()
                };
                (png, side)
            }
            Format::RawF32 => {
                let bytes = self
                    .heights_um
                    .iter()
                    .flat_map(|&h| (h as f32).to_le_bytes())
                    .collect();
                let side = Sidecar {
                    nx: Some(self.nx),
                    ny: Some(self.ny),
                    dh_um: Some(self.dh_um),
                    ..Sidecar::default()
                };
                (bytes, side)
            }
        };
        let side_path = sidecar_path(path);
        let text =
            toml::to_string(&sidecar).map_err(|e| Error::parse(&side_path, e.to_string()))?;
        // Sidecar first: a crash between the two renames leaves a new sidecar beside an old
        // image at worst, never an image without its scale.
        write_atomic(&side_path, text.as_bytes())?;
        write_atomic(path, &data)
    }
}

/// The shipped AFM crop of an *Elaphe guttata* shed (`assets/measured/README.md`).
const MEASURED_ELAPHE_PNG: &[u8] = include_bytes!("../../assets/measured/elaphe_afm_100x100.png");

/// Sample spacing of the measured crop (µm): the thesis's Elaphe ridge period, 1144.262 nm
/// (grating-equation experiment), over the crop's 100/6 samples per ridge (1.144262·6/100,
/// as in the shipped sidecar).
pub const MEASURED_ELAPHE_DH_UM: f64 = 0.06865572;

/// Height of grey level 1 of the measured crop (µm): the thesis's one-finger Elaphe patch
/// (the same AFM scan) used 0.4347 µm.
pub const MEASURED_ELAPHE_H_MAX_UM: f64 = 0.4347;

/// Side of `builtin:elaphe-grown`: 960 samples of 68.7 nm = 65.9 µm, just over the 65 µm
/// coherence length (960 = 2⁶·3·5 keeps the FFTs fast).
pub const GROWN_SAMPLES: usize = 960;

/// `builtin:elaphe-measured`: the embedded crop with its calibration or the overrides.
fn measured_elaphe(dh_um: Option<f64>, h_max_um: Option<f64>) -> Result<HeightField> {
    let origin = Path::new("builtin:elaphe-measured");
    let h_max = check_h_max(h_max_um.unwrap_or(MEASURED_ELAPHE_H_MAX_UM), origin)?;
    let img = image::load_from_memory(MEASURED_ELAPHE_PNG).map_err(|e| Error::Image {
        path: origin.to_path_buf(),
        msg: format!("cannot decode: {e}"),
    })?;
    let (nx, ny, grey) = grey_of_image(&img, "image", origin)?;
    let heights = grey.into_iter().map(|g| g * h_max).collect();
    HeightField::new(nx, ny, dh_um.unwrap_or(MEASURED_ELAPHE_DH_UM), heights)
        .map_err(with_path(origin))
}

/// PNG colour type 3 (indexed): byte 25 of the file is the IHDR colour type.
fn png_is_palette(path: &Path) -> bool {
    use std::io::Read as _;
    let mut head = [0u8; 26];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok_and(|()| &head[12..16] == b"IHDR" && head[25] == 3)
}

/// The grey values `g ∈ [0, 1]` of interleaved samples with `channels` per pixel (1 to 4):
/// grey and grey+alpha directly; RGB and RGBA only where `R = G = B` at every pixel (alpha
/// is ignored). `max` is the largest sample value (255 or 65535).
pub(super) fn grey_of_samples<T: Copy + Into<f64> + PartialEq + std::fmt::Display>(
    samples: &[T],
    channels: usize,
    nx: usize,
    max: f64,
) -> std::result::Result<Vec<f64>, String> {
    if channels <= 2 {
        return Ok(samples
            .chunks_exact(channels)
            .map(|p| p[0].into() / max)
            .collect());
    }
    let mut grey = Vec::with_capacity(samples.len() / channels);
    for (i, p) in samples.chunks_exact(channels).enumerate() {
        for (c, name) in [(1, 'G'), (2, 'B')] {
            if p[c] != p[0] {
                return Err(format!(
                    "not grey: pixel (column {}, row {}) has R = {} but {name} = {}; a height \
                     field stored as RGB/RGBA needs R = G = B",
                    i % nx,
                    i / nx,
                    p[0],
                    p[c]
                ));
            }
        }
        grey.push(p[0].into() / max);
    }
    Ok(grey)
}

/// Decodes a grey PNG into values `g ∈ [0, 1]`, row-major: 8/16-bit grey (with or without
/// alpha), and what tools and the thesis write for grey: RGB/RGBA with `R = G = B`
/// (8/16-bit) and palette images whose colours are all grey. Alpha is ignored.
fn read_png(path: &Path) -> Result<(usize, usize, Vec<f64>)> {
    let image_err = |msg: String| Error::Image {
        path: path.to_path_buf(),
        msg,
    };
    // The size is checked from the header before anything is decoded.
    let side = super::MAX_SIDE as u32;
    let reader = crate::image_io::open_bounded(path, image::ImageFormat::Png, "PNG", side)?;
    let img = reader
        .decode()
        .map_err(|e| image_err(format!("cannot decode: {e}")))?;
    // The decoder expands a palette to RGB(A); say so, or "RGB" would puzzle the user.
    let what = if png_is_palette(path) {
        "palette image"
    } else {
        "image"
    };
    grey_of_image(&img, what, path)
}

/// The grey values of a decoded image ([`grey_of_samples`]); `what` names the image kind
/// in the error.
fn grey_of_image(
    img: &image::DynamicImage,
    what: &str,
    path: &Path,
) -> Result<(usize, usize, Vec<f64>)> {
    let image_err = |msg: String| Error::Image {
        path: path.to_path_buf(),
        msg,
    };
    let (nx, ny) = (img.width() as usize, img.height() as usize);
    let ch = usize::from(img.color().channel_count());
    use image::DynamicImage as D;
    let grey = match img {
        D::ImageLuma8(_) | D::ImageLumaA8(_) | D::ImageRgb8(_) | D::ImageRgba8(_) => {
            grey_of_samples(img.as_bytes(), ch, nx, 255.0)
        }
        D::ImageLuma16(b) => grey_of_samples(b.as_raw(), ch, nx, 65535.0),
        D::ImageLumaA16(b) => grey_of_samples(b.as_raw(), ch, nx, 65535.0),
        D::ImageRgb16(b) => grey_of_samples(b.as_raw(), ch, nx, 65535.0),
        D::ImageRgba16(b) => grey_of_samples(b.as_raw(), ch, nx, 65535.0),
        other => {
            return Err(image_err(format!(
                "{:?} image; a height field must be an 8- or 16-bit grey image (grey, or \
                 RGB/RGBA/palette with R = G = B)",
                other.color()
            )))
        }
    }
    .map_err(|m| image_err(format!("{what} {m}")))?;
    Ok((nx, ny, grey))
}

/// Reads `nx·ny` little-endian f32 heights; the file length must match exactly.
fn read_f32(path: &Path, nx: usize, ny: usize) -> Result<Vec<f64>> {
    let expected = nx
        .checked_mul(ny)
        .and_then(|n| n.checked_mul(4))
        .filter(|_| nx <= super::MAX_SIDE && ny <= super::MAX_SIDE)
        .ok_or_else(|| {
            Error::parse(
                sidecar_path(path),
                format!(
                    "size {nx}×{ny} exceeds the limit of {} samples a side",
                    super::MAX_SIDE
                ),
            )
        })?;
    // The length first, then a read bounded by it: a sidecar saying 16 KB must not let a
    // huge (or endless) file into memory.
    let len = std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len();
    let data = if len == expected as u64 {
        crate::fsutil::read_bounded(path, "raw .f32 height field", expected as u64)?
    } else {
        Vec::new()
    };
    if len != expected as u64 || data.len() != expected {
        return Err(Error::Image {
            path: path.to_path_buf(),
            msg: format!(
                "{} bytes; {nx}×{ny} f32 heights need {expected} (truncated or wrong sidecar?)",
                len
            ),
        });
    }
    Ok(data
        .chunks_exact(4)
        .map(|b| f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_errors_name_line_and_column() {
        let text = "dh_um = 0.1\nh_max_um = \"x\"\n";
        let e = toml::from_str::<Sidecar>(text).unwrap_err();
        let msg = one_line_toml_error(text, &e);
        assert!(msg.starts_with("line 2, column "), "{msg}");
        assert!(!msg.contains('\n'));
        let text = "dh_um = 0.1\n\nfoo = 1\n";
        let e = toml::from_str::<Sidecar>(text).unwrap_err();
        let msg = one_line_toml_error(text, &e);
        assert!(
            msg.starts_with("line 3, column 1") && msg.contains("foo"),
            "{msg}"
        );
    }

    #[test]
    fn unknown_extension_is_rejected() {
        assert!(format_of(Path::new("a.jpg")).is_err());
        assert!(format_of(Path::new("noext")).is_err());
        assert_eq!(format_of(Path::new("A.PNG")).unwrap(), Format::Png);
    }
}
