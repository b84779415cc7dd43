//! Getting pictures out (and back in for tests): 8-bit sRGB PNG and float32 linear OpenEXR,
//! written atomically (temporary file in the target directory, then rename, so a failed or
//! interrupted write never replaces an existing file), plus the tolerance metrics that golden
//! image tests compare with (absolute-difference percentiles and CIEDE2000).
//!
//! Pixel buffers are row-major, top row first, linear sRGB (`[r, g, b]` per pixel). The
//! colour science (transfer curve, Lab, ΔE) is [`crate::colour`]'s; this module only moves
//! pixels and bytes. No non-finite value ever reaches a file: NaN and ±Inf are written as 0.

use rayon::prelude::*;
use std::path::Path;

use crate::colour;
use crate::fsutil::write_atomically;
use crate::{Error, Result};

fn image_err(path: &Path, msg: impl Into<String>) -> Error {
    Error::Image {
        path: path.to_path_buf(),
        msg: msg.into(),
    }
}

/// Checks that a `width × height` buffer of `len` pixels is consistent and non-empty.
fn check_size(path: &Path, width: u32, height: u32, len: usize) -> Result<()> {
    if width == 0 || height == 0 {
        return Err(image_err(path, format!("empty image ({width}×{height})")));
    }
    if width as u64 * height as u64 != len as u64 {
        return Err(image_err(
            path,
            format!(
                "{width}×{height} image needs {} pixels, got {len}",
                width as u64 * height as u64
            ),
        ));
    }
    Ok(())
}

fn finite_or_zero(x: f32) -> f32 {
    if x.is_finite() {
        x
    } else {
        0.0
    }
}

fn check_exposure(exposure: f32) -> Result<()> {
    if exposure.is_finite() && exposure > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            "exposure",
            format!("{exposure}; must be positive and finite"),
        ))
    }
}

/// Writes linear sRGB as an 8-bit sRGB PNG: multiply by `exposure`, clamp to [0, 1], apply
/// the sRGB transfer curve ([`colour::linear_to_srgb8`]). NaN and ±Inf become black.
pub fn write_png_srgb(
    path: &Path,
    width: u32,
    height: u32,
    linear_rgb: &[[f32; 3]],
    exposure: f32,
) -> Result<()> {
    check_size(path, width, height, linear_rgb.len())?;
    check_exposure(exposure)?;
    let bytes: Vec<u8> = linear_rgb
        .iter()
        .flat_map(|p| colour::linear_to_srgb8(p.map(|c| finite_or_zero(c) as f64), exposure as f64))
        .collect();
    let img = image::RgbImage::from_raw(width, height, bytes)
        .ok_or_else(|| image_err(path, "pixel buffer does not match the size"))?;
    let bytes = encode(
        path,
        image::DynamicImage::ImageRgb8(img),
        image::ImageFormat::Png,
    )?;
    write_bytes(path, &bytes)
}

/// Writes 8-bit RGB texels, already sRGB-encoded (a screenshot), as a PNG through the output
/// policy: encoded in memory, written to a temporary sibling and renamed over `path`.
pub fn write_png_rgb8(path: &Path, width: u32, height: u32, rgb: Vec<u8>) -> Result<()> {
    let img = image::RgbImage::from_raw(width, height, rgb)
        .ok_or_else(|| image_err(path, "pixel buffer does not match the size"))?;
    let bytes = encode(
        path,
        image::DynamicImage::ImageRgb8(img),
        image::ImageFormat::Png,
    )?;
    write_bytes(path, &bytes)
}

/// Encodes an image in memory: what can fail here is the encoder, never the disk.
fn encode(path: &Path, img: image::DynamicImage, format: image::ImageFormat) -> Result<Vec<u8>> {
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, format)
        .map_err(|e| image_err(path, format!("{format:?} encoding failed: {e}")))?;
    Ok(bytes.into_inner())
}

/// Writes encoded bytes through the output policy; an I/O failure (a full disk) says
/// `writing FILE: …`.
fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write as _;
    write_atomically(path, |w| {
        w.write_all(bytes)
            .and_then(|()| w.flush())
            .map_err(|e| Error::write(path, e))
    })
}

/// Writes linear RGB as a float32 OpenEXR file (no curve, no clamping; NaN/±Inf become 0).
/// An EXR's numbers have no fixed meaning, so `units` says what they are (a scene's
/// radiance on its scale, a BRDF map's relative reflectance, which channel holds what): it
/// is the file's standard `comments` attribute and a `units` attribute of its own.
pub fn write_exr(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[[f32; 3]],
    units: &str,
) -> Result<()> {
    use exr::prelude::{Encoding, Image, Layer, LayerAttributes, SpecificChannels, WritableImage};
    check_size(path, width, height, rgb.len())?;
    let w = width as usize;
    use exr::meta::attribute::{AttributeValue, Text};
    let mut attributes = LayerAttributes::named("diffract");
    // An EXR string is bytes: the text goes in as UTF-8 (ρ, ×, § are not Latin-1 all).
    let text = || Text::from_slice_unchecked(units.as_bytes());
    attributes.comments = Some(text());
    attributes
        .other
        .insert(Text::from(EXR_UNITS), AttributeValue::Text(text()));
    let layer = Layer::new(
        (w, height as usize),
        attributes,
        Encoding::FAST_LOSSLESS,
        SpecificChannels::rgb(|p: exr::math::Vec2<usize>| {
            let [r, g, b] = rgb[p.y() * w + p.x()].map(finite_or_zero);
            (r, g, b)
        }),
    );
    let mut bytes = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .non_parallel()
        .to_buffered(&mut bytes)
        .map_err(|e| image_err(path, format!("OpenEXR: {e}")))?;
    write_bytes(path, bytes.get_ref())
}

/// The name of the attribute in which an EXR diffract writes says what its pixels hold.
pub const EXR_UNITS: &str = "units";

/// The `units` attribute of an OpenEXR file diffract wrote (`None`: there is none).
pub fn exr_units(path: &Path) -> Result<Option<String>> {
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| image_err(path, format!("OpenEXR: {e}")))?;
    Ok(meta.headers.first().and_then(|h| {
        match h
            .own_attributes
            .other
            .get(&exr::meta::attribute::Text::from(EXR_UNITS))
        {
            Some(exr::meta::attribute::AttributeValue::Text(t)) => {
                Some(String::from_utf8_lossy(t.bytes()).into_owned())
            }
            _ => None,
        }
    }))
}

/// Image file formats diffract writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputFormat {
    /// 8-bit sRGB PNG.
    Png,
    /// float32 linear OpenEXR.
    Exr,
}

/// The format a path's extension asks for, so callers can reject a bad name before any
/// work is done. A character device or a FIFO (`/dev/null`, `/dev/stdout`, a named pipe)
/// without either extension gets a PNG: it has no name to choose by.
pub fn output_format(path: &Path) -> Result<OutputFormat> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    let stream = || {
        use std::os::unix::fs::FileTypeExt;
        std::fs::metadata(path).is_ok_and(|m| {
            let t = m.file_type();
            t.is_char_device() || t.is_fifo()
        })
    };
    match ext.as_deref() {
        Some("png") => Ok(OutputFormat::Png),
        Some("exr") => Ok(OutputFormat::Exr),
        _ if stream() => Ok(OutputFormat::Png),
        _ => Err(image_err(
            path,
            "unknown output format: use a .png (8-bit sRGB) or .exr (float linear) file name",
        )),
    }
}

/// Writes PNG (8-bit sRGB) or EXR (float32 linear, scaled by `exposure` too, so both show
/// the same picture; `units` says what its numbers are, see [`write_exr`]) chosen by the
/// extension of `path` (case-insensitive).
pub fn write_image(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[[f32; 3]],
    exposure: f32,
    units: &str,
) -> Result<()> {
    match output_format(path)? {
        OutputFormat::Png => write_png_srgb(path, width, height, rgb, exposure),
        OutputFormat::Exr => {
            check_exposure(exposure)?;
            let scaled: Vec<[f32; 3]> = rgb.iter().map(|p| p.map(|c| c * exposure)).collect();
            let units = if exposure == 1.0 {
                units.to_string()
            } else {
                format!("{units}, × exposure {exposure}")
            };
            write_exr(path, width, height, &scaled, &units)
        }
    }
}

/// Largest side of an image read as a scene's texture (pixels): the side a 2D image has on
/// most Vulkan devices (`maxImageDimension2D`).
pub const MAX_TEXTURE_SIDE: u32 = 16384;

/// Largest bytes per pixel any decoder here produces (RGBA, 32-bit float channels).
const MAX_DECODED_PIXEL_BYTES: u64 = 16;

/// A reader for `path` that will decode it as `format`, once its header passed the size
/// check: the width and height are read from the header alone and an image with no pixels
/// or wider or taller than `max_side` is refused there, before any pixel is decoded. The
/// decoder is then held to that size and to the allocation it needs (a PNG whose header
/// claims 20000×20000 in a few hundred KB is refused in milliseconds, not after gigabytes).
/// `name` names the format in errors.
pub fn open_bounded(
    path: &Path,
    format: image::ImageFormat,
    name: &str,
    max_side: u32,
) -> Result<image::ImageReader<std::io::BufReader<std::fs::File>>> {
    let open = || -> Result<_> {
        let reader = image::ImageReader::open(path)
            .map_err(|e| Error::io(path, e))?
            .with_guessed_format()
            .map_err(|e| Error::io(path, e))?;
        if reader.format() != Some(format) {
            return Err(image_err(path, format!("not a {name} file")));
        }
        Ok(reader)
    };
    let (w, h) = open()?
        .into_dimensions()
        .map_err(|e| image_err(path, format!("cannot read the {name} header: {e}")))?;
    if w == 0 || h == 0 || w > max_side || h > max_side {
        return Err(image_err(
            path,
            format!("its header says {w}×{h} pixels; at most {max_side} a side can be read"),
        ));
    }
    let mut reader = open()?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(w);
    limits.max_image_height = Some(h);
    // The decoded image plus the decoder's own buffers (a row, the inflate window).
    limits.max_alloc = Some(u64::from(w) * u64::from(h) * MAX_DECODED_PIXEL_BYTES + (16 << 20));
    reader.limits(limits);
    Ok(reader)
}

/// Opens an image and insists on its format (by content, falling back to the extension),
/// bounded by its header ([`open_bounded`]).
fn open_as(path: &Path, format: image::ImageFormat, name: &str) -> Result<image::DynamicImage> {
    crate::fsutil::check_input_file(path, name, crate::fsutil::MAX_PNG_BYTES)?;
    open_bounded(path, format, name, MAX_TEXTURE_SIDE)?
        .decode()
        .map_err(|e| image_err(path, format!("cannot decode {name}: {e}")))
}

/// Interleaved RGB samples → `(width, height, pixels)`.
fn rgb_pixels<T: Copy>((w, h): (u32, u32), raw: Vec<T>) -> (u32, u32, Vec<[T; 3]>) {
    let px = raw.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    (w, h, px)
}

/// Reads an OpenEXR file as linear RGB floats (alpha dropped): `(width, height, pixels)`.
pub fn read_exr(path: &Path) -> Result<(u32, u32, Vec<[f32; 3]>)> {
    let img = open_as(path, image::ImageFormat::OpenExr, "OpenEXR")?.into_rgb32f();
    Ok(rgb_pixels(img.dimensions(), img.into_raw()))
}

/// Reads a PNG as 8-bit RGB (grey is expanded, alpha dropped, 16-bit reduced):
/// `(width, height, pixels)`. Values are the stored (sRGB-encoded) bytes.
pub fn read_png_rgb8(path: &Path) -> Result<(u32, u32, Vec<[u8; 3]>)> {
    let img = open_as(path, image::ImageFormat::Png, "PNG")?.into_rgb8();
    Ok(rgb_pixels(img.dimensions(), img.into_raw()))
}

/// Differences between two linear sRGB images of the same size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImageDiff {
    /// Mean of `|actual − expected|` over all channels of all pixels.
    pub mean_abs: f64,
    /// 99th percentile (nearest rank) of the per-channel absolute differences.
    pub p99_abs: f64,
    /// Largest per-channel absolute difference.
    pub max_abs: f64,
    /// Mean CIEDE2000 difference per pixel (linear sRGB → XYZ → CIELAB, D65 white `Y = 1`).
    pub mean_delta_e: f64,
    /// 95th percentile (nearest rank) of the per-pixel CIEDE2000 difference.
    pub p95_delta_e: f64,
}

impl std::fmt::Display for ImageDiff {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "|Δ| mean {:.5} p99 {:.5} max {:.5}; ΔE2000 mean {:.3} p95 {:.3}",
            self.mean_abs, self.p99_abs, self.max_abs, self.mean_delta_e, self.p95_delta_e
        )
    }
}

/// Nearest-rank percentile `q ∈ (0, 1]` of `v` (sorted in place; NaN sorts last).
fn percentile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_unstable_by(f64::total_cmp);
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

/// CIELAB of a linear sRGB colour ([`colour::linear_srgb_to_xyz`]: linear white `(1,1,1)`
/// lands on `L* = 100`).
fn linear_srgb_to_lab(rgb: [f32; 3]) -> [f64; 3] {
    colour::xyz_to_lab(colour::linear_srgb_to_xyz(rgb.map(f64::from)))
}

/// Compares two linear sRGB images pixel by pixel. Any non-finite value, and a size
/// mismatch (which makes the images incomparable), yields infinite differences so that every
/// tolerance check fails loudly instead of passing on garbage.
pub fn compare_images(actual: &[[f32; 3]], expected: &[[f32; 3]]) -> ImageDiff {
    if actual.len() != expected.len() || actual.is_empty() {
        let inf = f64::INFINITY;
        return ImageDiff {
            mean_abs: inf,
            p99_abs: inf,
            max_abs: inf,
            mean_delta_e: inf,
            p95_delta_e: inf,
        };
    }
    let mut abs = Vec::with_capacity(actual.len() * 3);
    let mut de = Vec::with_capacity(actual.len());
    for (a, e) in actual.iter().zip(expected) {
        let finite = a.iter().chain(e).all(|c| c.is_finite());
        for c in 0..3 {
            abs.push(if finite {
                (a[c] as f64 - e[c] as f64).abs()
            } else {
                f64::INFINITY
            });
        }
        de.push(if finite {
            colour::delta_e2000(linear_srgb_to_lab(*a), linear_srgb_to_lab(*e))
        } else {
            f64::INFINITY
        });
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let mean_abs = mean(&abs);
    let mean_delta_e = mean(&de);
    let max_abs = abs.iter().copied().fold(0.0, f64::max);
    ImageDiff {
        mean_abs,
        p99_abs: percentile(&mut abs, 0.99),
        max_abs,
        mean_delta_e,
        p95_delta_e: percentile(&mut de, 0.95),
    }
}

/// Per-channel `|actual − expected|` for looking at a failed comparison (write it with some
/// exposure). Pixels that are non-finite in either image, or that exist in only one of them,
/// are marked magenta `[1, 0, 1]`. The result has the length of the longer input.
pub fn difference_image(actual: &[[f32; 3]], expected: &[[f32; 3]]) -> Vec<[f32; 3]> {
    const MARK: [f32; 3] = [1.0, 0.0, 1.0];
    (0..actual.len().max(expected.len()))
        .map(|i| match (actual.get(i), expected.get(i)) {
            (Some(a), Some(e)) if a.iter().chain(e).all(|c| c.is_finite()) => {
                [0, 1, 2].map(|c| (a[c] - e[c]).abs())
            }
            _ => MARK,
        })
        .collect()
}

/// The tone curve applied to linear colour (after the exposure) before the sRGB transfer
/// curve of an 8-bit PNG. EXR output stays linear and skips it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Tone {
    /// Identity: values above 1 clip (the sRGB curve clamps).
    #[default]
    Linear,
    /// Extended Reinhard, per channel: `f(x) = x·(1 + x/W²)/(1 + x)` with white point `W`.
    /// Slope 1 at black (dark colours are as in `linear`), `f(W) = 1`, a smooth shoulder
    /// in between, so a BRDF map or a render whose specular peak is 100× its diffraction
    /// colours keeps both visible. Per channel, so very bright saturated colours go towards
    /// white as on film.
    Filmic,
}

/// Default white point of [`Tone::Filmic`]: the linear value (after exposure) shown as 1.
pub const DEFAULT_TONE_WHITE: f32 = 8.0;

/// One channel through the tone curve; negative and non-finite values give 0.
pub fn tone_map(x: f32, tone: Tone, white: f32) -> f32 {
    if !(x.is_finite() && x > 0.0) {
        return 0.0;
    }
    match tone {
        Tone::Linear => x,
        Tone::Filmic => {
            let x = f64::from(x);
            let w = f64::from(white);
            (x * (1.0 + x / (w * w)) / (1.0 + x)) as f32
        }
    }
}

/// Multiplies by `exposure` and applies the tone curve in place: what a PNG writer then
/// encodes with exposure 1 (`write_png_srgb(…, 1.0)`).
pub fn apply_tone(rgb: &mut [[f32; 3]], exposure: f32, tone: Tone, white: f32) -> Result<()> {
    check_exposure(exposure)?;
    if !(white.is_finite() && white > 0.0) {
        return Err(Error::invalid(
            "tone white point",
            format!("{white}; must be positive and finite"),
        ));
    }
    for p in rgb {
        *p = p.map(|c| tone_map(c * exposure, tone, white));
    }
    Ok(())
}

/// The levels below a `width × height` texture whose texel `i` (row-major) has linear colour
/// `at(i)`: each level halves each side (rounding down, at least 1) and holds the mean of the
/// 2×2 texels of the level above that it covers (an odd side's last row or column joins the
/// texels before it, so that every texel counts), down to 1×1. A pixel that covers many
/// texels reads the level of its footprint (trilinearly) instead of one texel's colour. The
/// texture itself is read through `at` once and not copied (an 8-bit texture need not be
/// held in float).
pub fn mip_levels(
    width: u32,
    height: u32,
    at: impl Fn(usize) -> [f32; 3] + Sync,
) -> Vec<(u32, u32, Vec<[f32; 3]>)> {
    let mut levels: Vec<(u32, u32, Vec<[f32; 3]>)> = Vec::new();
    let (mut w, mut h) = (width as usize, height as usize);
    while w > 1 || h > 1 {
        let next = match levels.last() {
            Some((_, _, src)) => halve(w, h, |i| src[i]),
            None => halve(w, h, &at),
        };
        (w, h) = ((w / 2).max(1), (h / 2).max(1));
        levels.push((w as u32, h as u32, next));
    }
    levels
}

/// The level below a `w × h` one whose texel `i` is `at(i)` ([`mip_levels`]).
fn halve(w: usize, h: usize, at: impl Fn(usize) -> [f32; 3] + Sync) -> Vec<[f32; 3]> {
    let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
    // Source texels [lo, hi) of level texel i along a side of n source texels.
    let span = |i: usize, n: usize, m: usize| {
        let lo = (i * n) / m;
        let hi = ((i + 1) * n) / m;
        (lo, hi.max(lo + 1))
    };
    let mut out = vec![[0.0f32; 3]; nw * nh];
    // Rows in parallel: a 4096×1024 texture's chain is made for every draw that blends it.
    out.par_chunks_mut(nw).enumerate().for_each(|(y, row)| {
        let (y0, y1) = span(y, h, nh);
        for (x, texel) in row.iter_mut().enumerate() {
            let (x0, x1) = span(x, w, nw);
            let mut sum = [0.0f64; 3];
            for sy in y0..y1 {
                for sx in x0..x1 {
                    let p = at(sy * w + sx);
                    for c in 0..3 {
                        sum[c] += f64::from(finite_or_zero(p[c]));
                    }
                }
            }
            let n = ((y1 - y0) * (x1 - x0)) as f64;
            *texel = sum.map(|s| (s / n) as f32);
        }
    });
    out
}

/// Box-filters a supersampled frame: every `factor × factor` block of linear colour becomes
/// its mean (the pixel integrates radiance, as a sensor does; the tone curve comes after).
/// Non-finite samples count as 0. `width` and `height` must be multiples of `factor ≥ 1`.
pub fn box_downsample(
    width: u32,
    height: u32,
    rgb: &[[f32; 3]],
    factor: u32,
) -> Result<(u32, u32, Vec<[f32; 3]>)> {
    let bad = |msg: String| Error::invalid("supersampled frame", msg);
    if factor == 0 {
        return Err(bad("supersampling factor 0".into()));
    }
    if width as u64 * height as u64 != rgb.len() as u64 || rgb.is_empty() {
        return Err(bad(format!(
            "{width}×{height} frame with {} pixels",
            rgb.len()
        )));
    }
    if !width.is_multiple_of(factor) || !height.is_multiple_of(factor) {
        return Err(bad(format!(
            "{width}×{height} is not a multiple of the factor {factor}"
        )));
    }
    let (w, h, f) = (width / factor, height / factor, factor as usize);
    let scale = 1.0 / (f * f) as f64;
    let mut out = Vec::with_capacity((w * h) as usize);
    for y in 0..h as usize {
        for x in 0..w as usize {
            let mut sum = [0.0f64; 3];
            for sy in 0..f {
                let row = (y * f + sy) * width as usize;
                for sx in 0..f {
                    let p = rgb[row + x * f + sx];
                    for c in 0..3 {
                        sum[c] += f64::from(finite_or_zero(p[c]));
                    }
                }
            }
            out.push(sum.map(|s| (s * scale) as f32));
        }
    }
    Ok((w, h, out))
}

/// Mean and 99th percentile (nearest rank) of the per-pixel CIEDE2000 difference over the
/// pixels where `mask` is true (all pixels without a mask): the anti-aliasing criterion
/// compares a render with a supersampled one over the pixels the object covers. `None` when
/// the sizes differ or no pixel is selected; a non-finite pixel counts as ΔE = ∞.
pub fn delta_e_over(
    actual: &[[f32; 3]],
    expected: &[[f32; 3]],
    mask: Option<&[bool]>,
) -> Option<(f64, f64)> {
    if actual.len() != expected.len() || mask.is_some_and(|m| m.len() != actual.len()) {
        return None;
    }
    let mut de: Vec<f64> = actual
        .iter()
        .zip(expected)
        .enumerate()
        .filter(|(i, _)| mask.is_none_or(|m| m[*i]))
        .map(|(_, (a, e))| {
            if a.iter().chain(e).all(|c| c.is_finite()) {
                colour::delta_e2000(linear_srgb_to_lab(*a), linear_srgb_to_lab(*e))
            } else {
                f64::INFINITY
            }
        })
        .collect();
    if de.is_empty() {
        return None;
    }
    let mean = de.iter().sum::<f64>() / de.len() as f64;
    Some((mean, percentile(&mut de, 0.99)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The texture, then [`mip_levels`].
    fn mip_chain(width: u32, height: u32, rgb: &[[f32; 3]]) -> Vec<(u32, u32, Vec<[f32; 3]>)> {
        let mut chain = vec![(width, height, rgb.to_vec())];
        chain.extend(mip_levels(width, height, |i| rgb[i]));
        chain
    }

    #[test]
    fn a_mip_chain_halves_to_one_texel_and_keeps_the_mean() {
        // A checkerboard of black and white: every coarser level is uniform grey.
        let board: Vec<[f32; 3]> = (0..64 * 16)
            .map(|i| [((i % 64 + i / 64) % 2) as f32; 3])
            .collect();
        let chain = mip_chain(64, 16, &board);
        let sizes: Vec<(u32, u32)> = chain.iter().map(|(w, h, _)| (*w, *h)).collect();
        assert_eq!(
            sizes,
            [(64, 16), (32, 8), (16, 4), (8, 2), (4, 1), (2, 1), (1, 1)]
        );
        for (w, h, level) in &chain[1..] {
            assert_eq!(level.len(), (w * h) as usize);
            assert!(
                level.iter().flatten().all(|&c| (c - 0.5).abs() < 1e-6),
                "{w}×{h}"
            );
        }
        // Odd sides: a 5×3 ramp; the last column and row join the texels before them.
        let ramp: Vec<[f32; 3]> = (0..15)
            .map(|i| [(i % 5) as f32, (i / 5) as f32, 1.0])
            .collect();
        let chain = mip_chain(5, 3, &ramp);
        assert_eq!(chain[1].0, 2);
        assert_eq!(chain[1].1, 1);
        assert_eq!(chain[1].2, vec![[0.5, 1.0, 1.0], [3.0, 1.0, 1.0]]);
        assert_eq!(chain[2].2, vec![[1.75, 1.0, 1.0]]);
        assert_eq!(chain.len(), 3);
    }

    fn tmp_dir(tag: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("diffract-imgio-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn gradient(w: u32, h: u32) -> Vec<[f32; 3]> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 / w as f32, (i / w) as f32 / h as f32);
                [x, y, 0.25 + 0.5 * x * y]
            })
            .collect()
    }

    #[test]
    fn exr_round_trip_is_exact_and_sanitised() {
        let d = tmp_dir("exr");
        let p = d.join("a.exr");
        let mut px = gradient(7, 5);
        px[3] = [f32::NAN, f32::INFINITY, 12.5];
        write_exr(&p, 7, 5, &px, "test units: X, Y, Z").unwrap();
        let (w, h, back) = read_exr(&p).unwrap();
        assert_eq!((w, h), (7, 5));
        assert_eq!(back[3], [0.0, 0.0, 12.5]);
        for (i, (a, b)) in px.iter().zip(&back).enumerate() {
            if i != 3 {
                assert_eq!(a, b);
            }
        }
        assert_eq!(
            exr_units(&p).unwrap().as_deref(),
            Some("test units: X, Y, Z")
        );
        // Through write_image, the exposure is part of what the numbers are.
        write_image(&p, 7, 5, &px, 2.0, "radiance").unwrap();
        assert_eq!(
            exr_units(&p).unwrap().as_deref(),
            Some("radiance, × exposure 2")
        );
        assert_eq!(read_exr(&p).unwrap().2[0], px[0].map(|c| 2.0 * c));
        let _ = std::fs::remove_dir_all(d);
    }

    #[test]
    fn png_applies_exposure_and_the_srgb_curve() {
        let d = tmp_dir("png");
        let p = d.join("a.png");
        let px = vec![
            [0.0, 0.5, 1.0],
            [0.25, f32::NAN, f32::INFINITY],
            [2.0, -1.0, 0.214],
        ];
        write_png_srgb(&p, 3, 1, &px, 2.0).unwrap();
        let (w, h, back) = read_png_rgb8(&p).unwrap();
        assert_eq!((w, h), (3, 1));
        assert_eq!(back[0], [0, 255, 255]);
        // 0.5 linear = 188 in sRGB; NaN and Inf are black.
        assert_eq!(back[1], [188, 0, 0]);
        assert_eq!(back[2][0], 255);
        assert_eq!(back[2][1], 0);
        // 0.428 linear ≈ 0.686 sRGB → 175.
        assert_eq!(back[2][2], 175);
        let _ = std::fs::remove_dir_all(d);
    }

    #[test]
    fn bad_sizes_and_extensions_are_rejected_without_touching_the_file() {
        let d = tmp_dir("bad");
        let p = d.join("keep.png");
        std::fs::write(&p, b"precious").unwrap();
        assert!(write_png_srgb(&p, 2, 2, &[[0.0; 3]; 3], 1.0).is_err());
        assert!(write_png_srgb(&p, 0, 0, &[], 1.0).is_err());
        assert!(write_png_srgb(&p, 1, 1, &[[0.0; 3]], 0.0).is_err());
        assert!(write_image(&d.join("x.jpg"), 1, 1, &[[0.0; 3]], 1.0, "").is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"precious");
        // No temporary files are left behind.
        let names: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
        let _ = std::fs::remove_dir_all(d);
    }

    #[test]
    fn comparison_metrics() {
        let a = gradient(10, 10);
        let same = compare_images(&a, &a);
        assert_eq!(same.max_abs, 0.0);
        assert_eq!(same.p95_delta_e, 0.0);
        let mut b = a.clone();
        b[0] = [a[0][0] + 0.5, a[0][1], a[0][2]];
        let d = compare_images(&a, &b);
        assert!((d.max_abs - 0.5).abs() < 1e-6);
        assert!((d.mean_abs - 0.5 / 300.0).abs() < 1e-6);
        // One pixel in 100 changed: under the 99th percentile of 300 channel values.
        assert_eq!(d.p99_abs, 0.0);
        assert!(d.mean_delta_e > 0.0 && d.p95_delta_e == 0.0);
        // White vs mid grey is a large colour difference; white vs itself none.
        let w = compare_images(&[[1.0; 3]], &[[0.18; 3]]);
        assert!(w.mean_delta_e > 30.0, "{w}");
        // Linear white is (within the 4-digit matrix) the D65 white of CIELAB.
        let white = linear_srgb_to_lab([1.0; 3]);
        assert!((white[0] - 100.0).abs() < 0.01, "{white:?}");
        assert!(white[1].abs() < 0.05 && white[2].abs() < 0.05, "{white:?}");
        assert!(compare_images(&a, &a[1..]).max_abs.is_infinite());
        let mut n = a.clone();
        n[5][1] = f32::NAN;
        assert!(compare_images(&n, &a).max_abs.is_infinite());
        let diff = difference_image(&n, &b);
        assert_eq!(diff.len(), 100);
        assert_eq!(diff[5], [1.0, 0.0, 1.0]);
        assert!((diff[0][0] - 0.5).abs() < 1e-6);
    }

    #[test]
    fn box_downsample_averages_blocks_and_keeps_the_mean() {
        let px = vec![
            [1.0, 0.0, 2.0],
            [3.0, 0.0, 2.0],
            [0.0, 8.0, f32::NAN],
            [0.0, 0.0, 4.0],
            [5.0, 4.0, 2.0],
            [7.0, 4.0, 2.0],
            [0.0, 0.0, 0.0],
            [4.0, 4.0, 4.0],
        ];
        // 4×2 → 2×1: NaN counts as 0.
        let (w, h, out) = box_downsample(4, 2, &px, 2).unwrap();
        assert_eq!((w, h), (2, 1));
        assert_eq!(out, vec![[4.0, 2.0, 2.0], [1.0, 3.0, 2.0]]);
        // Factor 1 is the identity (up to the NaN), and the mean is kept for any factor.
        let g = gradient(12, 6);
        assert_eq!(box_downsample(12, 6, &g, 1).unwrap().2, g);
        let mean =
            |v: &[[f32; 3]]| v.iter().map(|p| p[0] + p[1] + p[2]).sum::<f32>() / v.len() as f32;
        for f in [2, 3, 6] {
            let (w, h, d) = box_downsample(12, 6, &g, f).unwrap();
            assert_eq!((w, h), (12 / f, 6 / f));
            assert!((mean(&d) - mean(&g)).abs() < 1e-5, "{f}");
        }
        assert!(box_downsample(12, 6, &g, 4).is_err());
        assert!(box_downsample(12, 6, &g, 0).is_err());
        assert!(box_downsample(12, 5, &g, 1).is_err());
    }

    #[test]
    fn filmic_tone_curve_is_monotone_with_unit_slope_and_white_at_w() {
        for x in [0.0, 0.25, 1.0, 3.0, 100.0] {
            assert_eq!(tone_map(x, Tone::Linear, 8.0), x);
        }
        assert_eq!(tone_map(f32::NAN, Tone::Filmic, 8.0), 0.0);
        assert_eq!(tone_map(-1.0, Tone::Filmic, 8.0), 0.0);
        assert_eq!(tone_map(f32::INFINITY, Tone::Linear, 8.0), 0.0);
        // Slope 1 at black: f(ε) ≈ ε.
        let e = 1e-4;
        assert!((tone_map(e, Tone::Filmic, 8.0) / e - 1.0).abs() < 2e-4);
        // f(W) = 1 and the curve rises monotonically below and above it.
        for w in [1.0, 4.0, 8.0, 50.0] {
            assert!((tone_map(w, Tone::Filmic, w) - 1.0).abs() < 1e-6, "{w}");
        }
        let mut prev = 0.0;
        for i in 1..2000 {
            let y = tone_map(i as f32 * 0.01, Tone::Filmic, 8.0);
            assert!(y > prev && y <= i as f32 * 0.01, "{i}");
            prev = y;
        }
        // Exposure first, then the curve; a bad white point is an error.
        let mut px = vec![[0.5, 2.0, 16.0]];
        apply_tone(&mut px, 2.0, Tone::Filmic, 8.0).unwrap();
        let want = [1.0f32, 4.0, 32.0].map(|x| tone_map(x, Tone::Filmic, 8.0));
        assert_eq!(px[0], want);
        assert!(apply_tone(&mut px, 1.0, Tone::Filmic, 0.0).is_err());
        assert!(apply_tone(&mut px, 0.0, Tone::Linear, 8.0).is_err());
    }

    #[test]
    fn delta_e_over_a_mask() {
        let a = vec![[0.5f32; 3], [0.5; 3], [0.2, 0.3, 0.4]];
        let mut b = a.clone();
        b[2] = [0.4, 0.3, 0.2];
        let (mean, p99) = delta_e_over(&a, &b, Some(&[true, true, false])).unwrap();
        assert_eq!((mean, p99), (0.0, 0.0));
        let (mean, p99) = delta_e_over(&a, &b, None).unwrap();
        assert!(mean > 0.0 && p99 > mean, "{mean} {p99}");
        assert!(delta_e_over(&a, &b, Some(&[false; 3])).is_none());
        assert!(delta_e_over(&a, &b[..2], None).is_none());
    }
}
