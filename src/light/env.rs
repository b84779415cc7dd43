//! Environment maps: equirectangular radiance around the scene (MODEL §10), loaded from
//! Radiance `.hdr` or OpenEXR files or made by a built-in model, checked before any work,
//! and importance-sampled by luminance.
//!
//! **Conventions** (so maps from other tools line up). World `+Y` is up. A direction `d`
//! sits at column `W·(0.5 + atan2(d.x, −d.z)/2π)` and row `H·acos(d.y)/π`: the top row is
//! the zenith, the centre column looks along `−Z`, and columns turn towards `+X`.
//! `rotate_deg` turns the map about `+Y`, counter-clockwise seen from above: what the file
//! holds at direction `d` appears at `R_y(rotate)·d`.
//!
//! **Units.** Values are linear-sRGB radiance, multiplied by `intensity`. Each pixel holds a
//! constant radiance over its patch of the sphere (lookups are nearest-pixel), so the
//! sampler's density matches the map exactly.
//!
//! **Sampling.** A pixel is chosen with probability proportional to its luminance times its
//! exact solid angle `(2π/W)·(cos θ_top − cos θ_bottom)` (MODEL §10 writes the first-order
//! form `(2π/W)(π/H) sin θ`), by a marginal CDF over rows and a conditional CDF over the
//! columns of each row; inside the pixel the direction is uniform in azimuth and in `cos θ`,
//! i.e. uniform in solid angle. The density in solid angle is then constant over each pixel,
//! `P(pixel)/Ω(pixel)`, and the luminance over the density is the same number everywhere.

use std::f64::consts::PI;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use image::ImageDecoder;

use crate::{Error, Result};

/// Prefix of the built-in maps.
pub const BUILTIN_PREFIX: &str = "builtin:";

/// The built-in maps' names.
pub const BUILTINS: [&str; 3] = ["white", "sky", "studio"];

/// Bytes a map pixel costs while it is in use: the decoded float RGB on the host (12), its
/// RGBA32F texel on the device (16), and the sampler's two f32 CDF entries (8).
pub const BYTES_PER_PIXEL: u64 = 36;

/// Memory budget of one environment map: an 8192×4096 map (an "8K" HDR panorama) fits.
pub const BUDGET_BYTES: u64 = 8192 * 4096 * BYTES_PER_PIXEL;

/// Largest map file read (bytes): an 8192×4096 EXR of uncompressed float32 RGBA is 512 MiB.
pub const MAX_FILE_BYTES: u64 = 1 << 30;

/// Where a map comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EnvSource {
    /// Uniform radiance 1 in every direction (the white furnace).
    White,
    /// A clear sky dome without the sun, over a dark ground ([`sky`]).
    Sky,
    /// A few soft boxes on black ([`studio`]).
    Studio,
    /// An equirectangular `.hdr` or `.exr` file.
    File(PathBuf),
}

impl EnvSource {
    /// `builtin:white|sky|studio` or a path ending in `.hdr` or `.exr`.
    pub fn parse(s: &str) -> Result<Self> {
        if let Some(name) = s.strip_prefix(BUILTIN_PREFIX) {
            return match name {
                "white" => Ok(EnvSource::White),
                "sky" => Ok(EnvSource::Sky),
                "studio" => Ok(EnvSource::Studio),
                _ => Err(Error::invalid(
                    "environment",
                    format!(
                        "unknown built-in map '{s}'; expected builtin:{}",
                        BUILTINS.join(", builtin:")
                    ),
                )),
            };
        }
        match extension(Path::new(s)).as_deref() {
            Some("hdr") | Some("exr") => Ok(EnvSource::File(PathBuf::from(s))),
            _ => Err(Error::invalid(
                "environment",
                format!(
                    "'{s}': an environment map is an equirectangular .hdr or .exr file, or builtin:{}",
                    BUILTINS.join(", builtin:")
                ),
            )),
        }
    }

    /// The file this source reads, if any.
    pub fn path(&self) -> Option<&Path> {
        match self {
            EnvSource::File(p) => Some(p),
            _ => None,
        }
    }

    /// How the source is named to users.
    pub fn name(&self) -> String {
        match self {
            EnvSource::White => "builtin:white".into(),
            EnvSource::Sky => "builtin:sky".into(),
            EnvSource::Studio => "builtin:studio".into(),
            EnvSource::File(p) => p.display().to_string(),
        }
    }
}

fn extension(p: &Path) -> Option<String> {
    p.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
}

/// An environment map with its intensity and rotation applied.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvMap {
    pub width: u32,
    pub height: u32,
    /// Row-major, top row (the zenith) first: linear-sRGB radiance × intensity.
    pub radiance: Vec<[f32; 3]>,
    /// Rotation about `+Y` in radians.
    pub rotate_rad: f64,
    /// The source's name, for messages.
    pub name: String,
}

/// Relative luminance of linear sRGB (the `Y` row of the sRGB → XYZ matrix).
pub fn luminance(rgb: [f32; 3]) -> f64 {
    0.2126 * f64::from(rgb[0]) + 0.7152 * f64::from(rgb[1]) + 0.0722 * f64::from(rgb[2])
}

/// The map coordinates `(x, y) ∈ [0, 1]²` (fractions of width and height) of a unit
/// direction in the map's own frame.
pub fn direction_to_map(d: [f64; 3]) -> (f64, f64) {
    let x = 0.5 + d[0].atan2(-d[2]) / (2.0 * PI);
    let y = d[1].clamp(-1.0, 1.0).acos() / PI;
    (x.rem_euclid(1.0), y)
}

/// The unit direction (map frame) at map coordinates `(x, y)`.
pub fn map_to_direction(x: f64, y: f64) -> [f64; 3] {
    let phi = (x - 0.5) * 2.0 * PI;
    let (st, ct) = (y * PI).sin_cos();
    let (sp, cp) = phi.sin_cos();
    [st * sp, ct, -st * cp]
}

/// `R_y(a)·d`, counter-clockwise about `+Y` seen from above (as the map turns).
pub(crate) fn rotate_y(d: [f64; 3], a: f64) -> [f64; 3] {
    let (s, c) = a.sin_cos();
    [c * d[0] + s * d[2], d[1], -s * d[0] + c * d[2]]
}

impl EnvMap {
    /// Loads and checks a map: a file's header is read and its size checked before anything
    /// is decoded; every pixel must be finite and non-negative. `intensity` (≥ 0) scales the
    /// radiance; `rotate_deg` turns the map about `+Y`.
    pub fn load(source: &EnvSource, intensity: f64, rotate_deg: f64) -> Result<EnvMap> {
        check_placement(intensity, rotate_deg)?;
        let (w, h, px) = match source {
            EnvSource::White => (8, 4, vec![[1.0f32; 3]; 32]),
            EnvSource::Sky => (256, 128, tabulate(256, 128, sky)),
            EnvSource::Studio => (256, 128, tabulate(256, 128, studio)),
            EnvSource::File(p) => read_map(p)?,
        };
        let mut map = EnvMap::from_pixels(w, h, px, &source.name())?;
        // The brightest pixel after the intensity is what float32 must hold on the device.
        let peak = map
            .radiance
            .iter()
            .flatten()
            .fold(0.0f64, |m, &c| m.max(f64::from(c)));
        super::check_radiometric(
            "environment radiance (brightest pixel × intensity)",
            peak * intensity,
        )
        .map_err(|msg| Error::invalid("environment", format!("{}: {msg}", source.name())))?;
        for p in &mut map.radiance {
            *p = p.map(|c| (f64::from(c) * intensity) as f32);
        }
        map.rotate_rad = rotate_deg.to_radians();
        Ok(map)
    }

    /// A map from pixels (row-major, top row first), checked as a loaded file is.
    pub fn from_pixels(
        width: u32,
        height: u32,
        radiance: Vec<[f32; 3]>,
        name: &str,
    ) -> Result<Self> {
        let bad = |msg: String| Error::Image {
            path: PathBuf::from(name),
            msg,
        };
        check_dimensions(width, height).map_err(bad)?;
        if radiance.len() as u64 != u64::from(width) * u64::from(height) {
            return Err(bad(format!(
                "{width}×{height} map needs {} pixels, got {}",
                u64::from(width) * u64::from(height),
                radiance.len()
            )));
        }
        if let Some(i) = radiance
            .iter()
            .position(|p| p.iter().any(|c| !c.is_finite() || *c < 0.0))
        {
            let p = radiance[i];
            return Err(bad(format!(
                "pixel ({}, {}) holds radiance [{}, {}, {}]; environment radiance must be finite and ≥ 0",
                i as u32 % width,
                i as u32 / width,
                p[0],
                p[1],
                p[2]
            )));
        }
        Ok(EnvMap {
            width,
            height,
            radiance,
            rotate_rad: 0.0,
            name: name.to_string(),
        })
    }

    /// The pixel `(column, row)` a world direction falls in.
    pub fn pixel_of(&self, d_world: [f64; 3]) -> (u32, u32) {
        let (x, y) = direction_to_map(rotate_y(d_world, -self.rotate_rad));
        let c = ((x * f64::from(self.width)) as u32).min(self.width - 1);
        let r = ((y * f64::from(self.height)) as u32).min(self.height - 1);
        (c, r)
    }

    /// The world direction of the middle of pixel `(col, row)`: its centre column, at the
    /// height (`cos θ`) halfway between its edges, so that half its solid angle lies each side.
    pub fn pixel_direction(&self, col: u32, row: u32) -> [f64; 3] {
        let h = f64::from(self.height);
        let ct = 0.5 * ((f64::from(row) / h * PI).cos() + (f64::from(row + 1) / h * PI).cos());
        let x = (f64::from(col) + 0.5) / f64::from(self.width);
        rotate_y(map_to_direction(x, ct.acos() / PI), self.rotate_rad)
    }

    /// Radiance (linear sRGB) arriving from world direction `d` (unit), nearest pixel.
    pub fn radiance(&self, d_world: [f64; 3]) -> [f64; 3] {
        let (c, r) = self.pixel_of(d_world);
        self.radiance[(r * self.width + c) as usize].map(f64::from)
    }

    /// Exact solid angle of a pixel of `row`: `(2π/W)·(cos θ_top − cos θ_bottom)`.
    pub fn pixel_solid_angle(&self, row: u32) -> f64 {
        let h = f64::from(self.height);
        let top = (f64::from(row) / h * PI).cos();
        let bottom = (f64::from(row + 1) / h * PI).cos();
        2.0 * PI / f64::from(self.width) * (top - bottom)
    }

    /// `∫ L dω` over the sphere per channel (exact for the piecewise-constant map).
    pub fn integral(&self) -> [f64; 3] {
        let mut s = [0.0; 3];
        for r in 0..self.height {
            let om = self.pixel_solid_angle(r);
            for c in 0..self.width {
                let p = self.radiance[(r * self.width + c) as usize];
                for k in 0..3 {
                    s[k] += f64::from(p[k]) * om;
                }
            }
        }
        s
    }

    /// The luminance moments `(∫ Y dω, ∫ Y² dω)` over the sphere (exact for the
    /// piecewise-constant map): the light sampler's share and choice
    /// ([`crate::light::set`]).
    pub fn moments(&self) -> (f64, f64) {
        let (mut power, mut square) = (0.0, 0.0);
        for (p, c) in self.radiance.iter().enumerate() {
            let omega = self.pixel_solid_angle(p as u32 / self.width);
            let y = luminance(*c).max(0.0);
            power += y * omega;
            square += y * y * omega;
        }
        (power, square)
    }
}

fn check_placement(intensity: f64, rotate_deg: f64) -> Result<()> {
    if !(intensity.is_finite() && intensity >= 0.0) {
        return Err(Error::invalid(
            "environment intensity",
            format!("{intensity}; must be finite and ≥ 0"),
        ));
    }
    if !rotate_deg.is_finite() {
        return Err(Error::invalid(
            "environment rotation",
            format!("{rotate_deg}°; must be finite"),
        ));
    }
    Ok(())
}

/// An equirectangular map is twice as wide as tall, and fits the memory budget.
fn check_dimensions(width: u32, height: u32) -> std::result::Result<(), String> {
    if width == 0 || height == 0 || u64::from(width) != 2 * u64::from(height) {
        return Err(format!(
            "the map is {width}×{height}; an equirectangular map is twice as wide as tall (2:1)"
        ));
    }
    let bytes = u64::from(width) * u64::from(height) * BYTES_PER_PIXEL;
    if bytes > BUDGET_BYTES {
        return Err(format!(
            "the {width}×{height} map needs {} MB ({BYTES_PER_PIXEL} bytes a pixel: host copy, device texel and sampling tables); the budget allows {} MB (8192×4096)",
            bytes.div_ceil(1_000_000),
            BUDGET_BYTES / 1_000_000
        ));
    }
    Ok(())
}

/// Reads an `.hdr` or `.exr` file: the header's size is checked before decoding.
fn read_map(path: &Path) -> Result<(u32, u32, Vec<[f32; 3]>)> {
    let bad = |msg: String| Error::Image {
        path: path.to_path_buf(),
        msg,
    };
    // A pipe or a device would block or never end; the size is bounded before reading.
    crate::fsutil::check_input_file(path, "environment map", MAX_FILE_BYTES)?;
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let reader = BufReader::new(file);
    let decoded: std::result::Result<Vec<f32>, String> = match extension(path).as_deref() {
        Some("hdr") => {
            let dec = image::codecs::hdr::HdrDecoder::new(reader)
                .map_err(|e| bad(format!("cannot read the Radiance HDR header: {e}")))?;
            decode_checked(dec)
        }
        Some("exr") => {
            let dec =
                image::codecs::openexr::OpenExrDecoder::with_alpha_preference(reader, Some(false))
                    .map_err(|e| bad(format!("cannot read the OpenEXR header: {e}")))?;
            decode_checked(dec)
        }
        _ => return Err(bad("an environment map is a .hdr or .exr file".into())),
    };
    let raw = decoded.map_err(bad)?;
    let (w, h) = (raw[0].to_bits(), raw[1].to_bits());
    let px = raw[2..]
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    Ok((w, h, px))
}

/// Checks the decoder's dimensions, then decodes to RGB f32. The first two entries of the
/// result carry the width and height as bit patterns (one allocation, no extra copy).
fn decode_checked(dec: impl ImageDecoder) -> std::result::Result<Vec<f32>, String> {
    let (w, h) = dec.dimensions();
    check_dimensions(w, h)?;
    if dec.color_type() != image::ColorType::Rgb32F {
        return Err(format!("unexpected colour type {:?}", dec.color_type()));
    }
    let n = w as usize * h as usize * 3;
    let mut out = vec![0f32; n + 2];
    out[0] = f32::from_bits(w);
    out[1] = f32::from_bits(h);
    let bytes: &mut [u8] = bytemuck_cast(&mut out[2..]);
    dec.read_image(bytes)
        .map_err(|e| format!("cannot decode the map: {e}"))?;
    Ok(out)
}

/// `&mut [f32]` as its bytes (f32 has no padding and any byte pattern is a valid f32).
fn bytemuck_cast(v: &mut [f32]) -> &mut [u8] {
    let len = std::mem::size_of_val(v);
    // SAFETY: the slice is valid for `len` bytes, u8 has alignment 1, and every byte
    // pattern written through the result is a valid f32.
    unsafe { std::slice::from_raw_parts_mut(v.as_mut_ptr().cast::<u8>(), len) }
}

/// A `w`×`h` map's pixels (row-major, top row first) of the radiance `f` gives at each
/// pixel's centre direction (map frame).
pub(crate) fn tabulate(w: u32, h: u32, f: impl Fn([f64; 3]) -> [f64; 3]) -> Vec<[f32; 3]> {
    let mut px = Vec::with_capacity((w * h) as usize);
    for r in 0..h {
        for c in 0..w {
            let d = map_to_direction(
                (f64::from(c) + 0.5) / f64::from(w),
                (f64::from(r) + 0.5) / f64::from(h),
            );
            px.push(f(d).map(|x| x as f32));
        }
    }
    px
}

/// `builtin:sky`: a clear sky without the sun. Above the horizon the radiance runs from a
/// deep blue zenith `(0.10, 0.22, 0.60)` to a pale horizon `(0.60, 0.70, 0.85)` as
/// `(1 − cos θ)⁴` (the shape of Preetham's clear sky away from the sun's glow: dark
/// overhead, bright in the haze at the horizon); below it a dark ground `(0.10, 0.09,
/// 0.07)` that the haze brightens over its first few degrees. Radiance in linear sRGB,
/// on the scale of the sun's irradiance 1 per steradian (a clear sky gives about a tenth
/// of the sun's irradiance on the ground).
pub fn sky(d: [f64; 3]) -> [f64; 3] {
    let zenith = [0.10, 0.22, 0.60];
    let horizon = [0.60, 0.70, 0.85];
    let ground = [0.10, 0.09, 0.07];
    let y = d[1];
    let mix = |a: [f64; 3], b: [f64; 3], t: f64| [0, 1, 2].map(|k| a[k] + (b[k] - a[k]) * t);
    if y >= 0.0 {
        mix(zenith, horizon, (1.0 - y).powi(4))
    } else {
        mix(ground, horizon, (y / 0.05).exp())
    }
}

/// `builtin:studio`: three soft boxes on black, as a product photographer lights: a warm
/// key light (radiance 4) 35° up and 40° to the left of the map's centre, a cool, dimmer
/// fill (1.2) 20° up on the other side, and a top light (2.5) overhead, each a rectangle in
/// azimuth and elevation whose edges fall off smoothly over 3°.
pub fn studio(d: [f64; 3]) -> [f64; 3] {
    let az = d[0].atan2(-d[2]).to_degrees();
    let el = d[1].clamp(-1.0, 1.0).asin().to_degrees();
    // (azimuth, elevation, half width, half height, radiance)
    let boxes: [(f64, f64, f64, f64, [f64; 3]); 3] = [
        (-40.0, 35.0, 15.0, 10.0, [4.0, 3.8, 3.5]),
        (120.0, 20.0, 20.0, 12.0, [1.1, 1.2, 1.3]),
        (0.0, 80.0, 60.0, 8.0, [2.5, 2.5, 2.5]),
    ];
    let soft = |dist: f64| {
        let t = (1.0 - dist / 3.0).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    };
    let mut out = [0.0; 3];
    for (a, e, hw, hh, rad) in boxes {
        let da = ((az - a + 540.0).rem_euclid(360.0) - 180.0).abs();
        let de = (el - e).abs();
        let k = soft((da - hw).max(0.0)) * soft((de - hh).max(0.0));
        for c in 0..3 {
            out[c] += k * rad[c];
        }
    }
    out
}

/// Luminance importance sampling of an [`EnvMap`] (see the module's notes).
#[derive(Debug, Clone)]
pub struct EnvSampler {
    width: u32,
    height: u32,
    rotate_rad: f64,
    /// CDF over rows, `height + 1` entries from 0 to 1.
    pub marginal: Vec<f64>,
    /// Per row, the CDF over its columns, `width + 1` entries from 0 to 1.
    pub conditional: Vec<f64>,
    /// Probability of each pixel (row-major).
    pub prob: Vec<f64>,
    /// Solid angle of a pixel of each row.
    solid_angle: Vec<f64>,
    /// `Σ luminance·Ω`: the map's luminance integral.
    pub total: f64,
}

impl EnvSampler {
    /// The CDFs of a map. A black map has `total = 0` and cannot be sampled.
    pub fn new(map: &EnvMap) -> Self {
        let (w, h) = (map.width as usize, map.height as usize);
        let solid_angle: Vec<f64> = (0..map.height).map(|r| map.pixel_solid_angle(r)).collect();
        let mut prob = vec![0.0; w * h];
        let mut conditional = vec![0.0; h * (w + 1)];
        let mut row_sum = vec![0.0; h];
        for r in 0..h {
            let mut acc = 0.0;
            for c in 0..w {
                let p = luminance(map.radiance[r * w + c]) * solid_angle[r];
                prob[r * w + c] = p;
                acc += p;
                conditional[r * (w + 1) + c + 1] = acc;
            }
            row_sum[r] = acc;
            for c in 0..=w {
                let cdf = &mut conditional[r * (w + 1) + c];
                *cdf = if acc > 0.0 {
                    *cdf / acc
                } else {
                    c as f64 / w as f64
                };
            }
        }
        let total: f64 = row_sum.iter().sum();
        let mut marginal = vec![0.0; h + 1];
        let mut acc = 0.0;
        for r in 0..h {
            acc += row_sum[r];
            marginal[r + 1] = if total > 0.0 { acc / total } else { 0.0 };
        }
        if total > 0.0 {
            prob.iter_mut().for_each(|p| *p /= total);
        }
        EnvSampler {
            width: map.width,
            height: map.height,
            rotate_rad: map.rotate_rad,
            marginal,
            conditional,
            prob,
            solid_angle,
            total,
        }
    }

    /// A world direction drawn from `(ξ1, ξ2) ∈ [0, 1)²` with its density in solid angle;
    /// `None` for a black map.
    pub fn sample(&self, xi1: f64, xi2: f64) -> Option<([f64; 3], f64)> {
        if self.total <= 0.0 {
            return None;
        }
        let (w, h) = (self.width as usize, self.height as usize);
        let (r, fr) = invert_cdf(&self.marginal, xi1);
        let row = &self.conditional[r * (w + 1)..(r + 1) * (w + 1)];
        let (c, fc) = invert_cdf(row, xi2);
        // Uniform in azimuth across the column and in cos θ across the row's band.
        let x = (c as f64 + fc) / w as f64;
        let top = (r as f64 / h as f64 * PI).cos();
        let bottom = ((r + 1) as f64 / h as f64 * PI).cos();
        let cos_t = top + (bottom - top) * fr;
        let y = cos_t.clamp(-1.0, 1.0).acos() / PI;
        let d = rotate_y(map_to_direction(x, y), self.rotate_rad);
        let pdf = self.prob[r * w + c] / self.solid_angle[r];
        Some((d, pdf))
    }

    /// Density in solid angle of drawing world direction `d` (unit).
    pub fn pdf(&self, d_world: [f64; 3]) -> f64 {
        if self.total <= 0.0 {
            return 0.0;
        }
        let (x, y) = direction_to_map(rotate_y(d_world, -self.rotate_rad));
        let c = ((x * f64::from(self.width)) as usize).min(self.width as usize - 1);
        let r = ((y * f64::from(self.height)) as usize).min(self.height as usize - 1);
        self.prob[r * self.width as usize + c] / self.solid_angle[r]
    }
}

/// The interval `i` of a CDF (`cdf[0] = 0 … cdf[n] = 1`) holding `xi`, skipping empty
/// intervals, and the fraction of the way through it.
fn invert_cdf(cdf: &[f64], xi: f64) -> (usize, f64) {
    let n = cdf.len() - 1;
    let xi = xi.clamp(0.0, 1.0 - f64::EPSILON);
    // First index with cdf[i + 1] > xi.
    let i = cdf[1..].partition_point(|&c| c <= xi).min(n - 1);
    let span = cdf[i + 1] - cdf[i];
    let f = if span > 0.0 {
        ((xi - cdf[i]) / span).clamp(0.0, 1.0)
    } else {
        0.5
    };
    (i, f)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
        (0..3).all(|k| (a[k] - b[k]).abs() <= tol)
    }

    #[test]
    fn map_conventions_of_the_model() {
        // The centre column looks along −Z, a quarter turn right is +X, the top row the zenith.
        assert!((direction_to_map([0.0, 0.0, -1.0]).0 - 0.5).abs() < 1e-12);
        assert!((direction_to_map([1.0, 0.0, 0.0]).0 - 0.75).abs() < 1e-12);
        assert!((direction_to_map([-1.0, 0.0, 0.0]).0 - 0.25).abs() < 1e-12);
        assert!(direction_to_map([0.0, 1.0, 0.0]).1.abs() < 1e-12);
        assert!((direction_to_map([0.0, -1.0, 0.0]).1 - 1.0).abs() < 1e-12);
        for (x, y) in [(0.1, 0.2), (0.5, 0.5), (0.9, 0.7), (0.33, 0.95)] {
            let (x2, y2) = direction_to_map(map_to_direction(x, y));
            assert!((x - x2).abs() < 1e-12 && (y - y2).abs() < 1e-12);
        }
        // Rotating by 90° brings what the file holds along −Z to −X... turned towards +X
        // counter-clockwise seen from above: −Z → −X.
        let mut px = vec![[0.0f32; 3]; 32];
        px[8 + 4] = [5.0; 3]; // row 1, column 4: just above the horizon, along −Z
        let mut m = EnvMap::from_pixels(8, 4, px, "t").unwrap();
        let along = map_to_direction(4.5 / 8.0, 1.5 / 4.0);
        assert_eq!(m.radiance(along), [5.0; 3]);
        m.rotate_rad = 90f64.to_radians();
        assert_eq!(m.radiance(rotate_y(along, m.rotate_rad)), [5.0; 3]);
        assert!(rotate_y([0.0, 0.0, -1.0], m.rotate_rad)[0] < -0.99);
    }

    #[test]
    fn pixel_solid_angles_cover_the_sphere() {
        let m = EnvMap::load(&EnvSource::White, 1.0, 0.0).unwrap();
        let s = m.integral();
        assert!(close(s, [4.0 * PI; 3], 1e-12), "{s:?}");
        for src in [EnvSource::Sky, EnvSource::Studio] {
            let m = EnvMap::load(&src, 2.0, 30.0).unwrap();
            assert_eq!((m.width, m.height), (256, 128));
            assert!(m.integral()[1] > 0.0);
        }
    }

    fn test_map() -> EnvMap {
        // A studio map plus a small bright disc: most of the probability in a few pixels.
        let mut m = EnvMap::load(&EnvSource::Studio, 1.0, 25.0).unwrap();
        m.radiance[40 * 256 + 100] = [500.0, 400.0, 300.0];
        m
    }

    #[test]
    fn the_density_integrates_to_one_and_matches_the_samples() {
        let m = test_map();
        let s = EnvSampler::new(&m);
        // ∫ pdf dω on a grid finer than the map's pixels (midpoints in azimuth and cos θ).
        let (nx, ny) = (2048, 2048);
        let mut integral = 0.0;
        for j in 0..ny {
            let ct = 1.0 - 2.0 * (j as f64 + 0.5) / ny as f64;
            let st = (1.0 - ct * ct).sqrt();
            for i in 0..nx {
                let phi = 2.0 * PI * (i as f64 + 0.5) / nx as f64;
                integral += s.pdf([st * phi.cos(), ct, st * phi.sin()]);
            }
        }
        integral *= 4.0 * PI / (nx * ny) as f64;
        assert!((integral - 1.0).abs() < 2e-3, "∫ pdf dω = {integral}");
        // Every sample's density is the density of its direction, and luminance over the
        // density is the map's luminance integral everywhere (zero variance).
        let mut hits = vec![0usize; s.prob.len()];
        let n = 200_000;
        for k in 0..n {
            let xi1 = (k as f64 + 0.5) / n as f64;
            let xi2 = (k as f64 * 0.618_033_988_749_895).fract();
            let (d, pdf) = s.sample(xi1, xi2).unwrap();
            assert!(((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - 1.0).abs() < 1e-12);
            assert!(
                (s.pdf(d) / pdf - 1.0).abs() < 1e-9,
                "{k}: {} vs {pdf}",
                s.pdf(d)
            );
            let est = luminance(m.radiance(d).map(|x| x as f32)) / pdf;
            assert!(
                (est / s.total - 1.0).abs() < 1e-6,
                "{k}: {est} vs {}",
                s.total
            );
            let (c, r) = m.pixel_of(d);
            hits[(r * m.width + c) as usize] += 1;
        }
        // Sample counts per pixel follow the probabilities (the bright pixel and the boxes).
        let bright = 40 * 256 + 100;
        let want = s.prob[bright] * n as f64;
        assert!(
            (hits[bright] as f64 - want).abs() < 4.0 * want.sqrt() + 2.0,
            "{} vs {want}",
            hits[bright]
        );
        let black: usize = hits
            .iter()
            .zip(&s.prob)
            .filter(|(_, p)| **p == 0.0)
            .map(|(h, _)| h)
            .sum();
        assert_eq!(black, 0, "samples in black pixels");
    }

    #[test]
    fn a_black_map_cannot_be_sampled() {
        let m = EnvMap::from_pixels(4, 2, vec![[0.0; 3]; 8], "black").unwrap();
        let s = EnvSampler::new(&m);
        assert!(s.sample(0.3, 0.7).is_none());
        assert_eq!(s.pdf([0.0, 1.0, 0.0]), 0.0);
    }

    #[test]
    fn bad_maps_and_sources_get_one_clear_error() {
        let cases: Vec<(std::result::Result<EnvMap, Error>, &str)> = vec![
            (EnvMap::from_pixels(6, 4, vec![[1.0; 3]; 24], "a"), "2:1"),
            (
                EnvMap::from_pixels(4, 2, vec![[f32::NAN, 0.0, 0.0]; 8], "a"),
                "finite",
            ),
            (
                EnvMap::from_pixels(4, 2, vec![[f32::INFINITY; 3]; 8], "a"),
                "finite",
            ),
            (
                EnvMap::from_pixels(4, 2, vec![[0.0, -1.0, 0.0]; 8], "a"),
                "≥ 0",
            ),
            (EnvMap::from_pixels(20000, 10000, Vec::new(), "a"), "budget"),
            (EnvMap::load(&EnvSource::White, -1.0, 0.0), "intensity"),
            (EnvMap::load(&EnvSource::White, 1.0, f64::NAN), "rotation"),
            (
                EnvMap::load(&EnvSource::File("/nonexistent/map.hdr".into()), 1.0, 0.0),
                "map.hdr",
            ),
        ];
        for (r, want) in cases {
            let e = r.unwrap_err().to_string();
            assert!(e.contains(want) && !e.contains('\n'), "{e}");
        }
        assert!(EnvSource::parse("builtin:moon")
            .unwrap_err()
            .to_string()
            .contains("builtin:sky"));
        assert!(EnvSource::parse("map.png")
            .unwrap_err()
            .to_string()
            .contains(".hdr"));
        assert_eq!(
            EnvSource::parse("a/B.HDR").unwrap(),
            EnvSource::File("a/B.HDR".into())
        );
        assert_eq!(EnvSource::parse("builtin:sky").unwrap(), EnvSource::Sky);
    }

    fn tmp(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("diffract-env-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn write_exr_raw(path: &Path, w: u32, h: u32, px: &[[f32; 3]]) {
        let flat: Vec<f32> = px.iter().flatten().copied().collect();
        image::Rgb32FImage::from_raw(w, h, flat)
            .unwrap()
            .save(path)
            .unwrap();
    }

    #[test]
    fn map_files_load_and_every_bad_file_gets_one_error_line() {
        let d = tmp("files");
        // A 16×8 Radiance map: RGBE keeps 8 bits of mantissa under the largest channel.
        let px: Vec<image::Rgb<f32>> = (0..128)
            .map(|i| image::Rgb([i as f32 * 0.1, 1.0, 0.5 + (i % 3) as f32]))
            .collect();
        let hdr = d.join("ok.hdr");
        let f = std::fs::File::create(&hdr).unwrap();
        image::codecs::hdr::HdrEncoder::new(f)
            .encode(&px, 16, 8)
            .unwrap();
        let m = EnvMap::load(&EnvSource::parse(hdr.to_str().unwrap()).unwrap(), 2.0, 0.0).unwrap();
        assert_eq!((m.width, m.height), (16, 8));
        for (a, b) in m.radiance.iter().zip(&px) {
            let top = b.0.iter().fold(0f32, |m, x| m.max(*x));
            for c in 0..3 {
                assert!(
                    (a[c] - 2.0 * b.0[c]).abs() <= 0.01 * 2.0 * top,
                    "{a:?} {b:?}"
                );
            }
        }
        let exr = d.join("ok.exr");
        write_exr_raw(&exr, 8, 4, &[[0.25, 0.5, 1.0]; 32]);
        let m = EnvMap::load(&EnvSource::File(exr), 1.0, 0.0).unwrap();
        assert_eq!(m.radiance[5], [0.25, 0.5, 1.0]);
        // The corpus: each gets one line naming its fault.
        let mut nan = vec![[0.5f32; 3]; 32];
        nan[9] = [0.0, f32::NAN, 0.0];
        let mut inf = vec![[0.5f32; 3]; 32];
        inf[3] = [f32::INFINITY, 0.0, 0.0];
        let mut neg = vec![[0.5f32; 3]; 32];
        neg[31] = [0.0, 0.0, -2.0];
        type Pixels = Option<(u32, u32, Vec<[f32; 3]>)>;
        let cases: [(&str, Pixels, &str); 7] = [
            ("nan.exr", Some((8, 4, nan)), "pixel (1, 1)"),
            ("inf.exr", Some((8, 4, inf)), "finite"),
            ("negative.exr", Some((8, 4, neg)), "≥ 0"),
            ("square.exr", Some((8, 8, vec![[1.0; 3]; 64])), "2:1"),
            ("wide.exr", Some((12, 4, vec![[1.0; 3]; 48])), "2:1"),
            ("garbage.hdr", None, "header"),
            ("garbage.exr", None, "header"),
        ];
        for (name, content, want) in cases {
            let p = d.join(name);
            match content {
                Some((w, h, px)) => write_exr_raw(&p, w, h, &px),
                None => std::fs::write(&p, b"#?RADIANCE\nnot a map at all").unwrap(),
            }
            let e = EnvMap::load(&EnvSource::File(p), 1.0, 0.0)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(want) && e.contains(name) && !e.contains('\n'),
                "{name}: {e}"
            );
        }
        // A header that claims a map beyond the budget is refused before decoding.
        let big = d.join("big.hdr");
        std::fs::write(
            &big,
            b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 20000 +X 40000\n",
        )
        .unwrap();
        let e = EnvMap::load(&EnvSource::File(big), 1.0, 0.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("budget") && !e.contains('\n'), "{e}");
        std::fs::remove_dir_all(&d).ok();
    }
}
