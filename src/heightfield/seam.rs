//! Seams of a periodically tiled scan. The renderer treats a height field as one period of
//! an infinite surface; a scan's opposite edges do not match, so the tiling has a step along
//! every edge, and steps put energy along the spectrum's axes, away from the orders.
//!
//! The seam's share is measured with Moisan's periodic-plus-smooth decomposition
//! (L. Moisan, *Periodic plus smooth image decomposition*, JMIV 2011): the field is the sum
//! of a periodic part and a smooth part that carries every edge jump; the smooth part is the
//! solution of a Poisson equation whose source is the jumps, solved exactly by one FFT. Its
//! energy over the field's (mean-free) energy is the seam's share of the spectrum.
//!
//! `--tile` removes the seam three ways: `mirror` (the scan and its three reflections, a
//! field twice as large on each side that tiles without steps), `window` (a Tukey taper that
//! takes the outer eighth of each side smoothly to the mean height) and `grow` (a new
//! coherence-sized random surface with the scan's spectrum and histogram,
//! [`super::grow()`]).

use std::str::FromStr;

use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;

use super::{HeightField, MAX_SIDE};
use crate::{Error, Result};

/// How a scan is made to tile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Tile {
    /// Tiled as it is (the seam stays).
    None,
    /// The scan and its reflections: `2nx × 2ny`, seamless.
    Mirror,
    /// A Tukey taper over the outer [`TUKEY_FRACTION`] of each side towards the mean.
    Window,
    /// IAAFT growth to [`GROW_SIZE_UM`] (or the scan's size, if larger), seed 1.
    Grow,
}

impl FromStr for Tile {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "none" => Ok(Tile::None),
            "mirror" => Ok(Tile::Mirror),
            "window" => Ok(Tile::Window),
            "grow" => Ok(Tile::Grow),
            _ => Err(Error::invalid(
                "tile",
                format!("{s:?}; expected none, mirror, window or grow"),
            )),
        }
    }
}

impl std::fmt::Display for Tile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Tile::None => "none",
            Tile::Mirror => "mirror",
            Tile::Window => "window",
            Tile::Grow => "grow",
        })
    }
}

/// Fraction of each side the `window` taper covers (half at each edge).
pub const TUKEY_FRACTION: f64 = 0.25;

/// Side of a `grow`n field (µm): the default coherence length.
pub const GROW_SIZE_UM: f64 = super::DEFAULT_SIZE_UM;

/// In-place 2-D FFT of a row-major `nx × ny` grid (rows, then columns).
fn fft2(data: &mut [Complex64], nx: usize, ny: usize, inverse: bool) {
    let mut planner = FftPlanner::new();
    let (fx, fy) = if inverse {
        (planner.plan_fft_inverse(nx), planner.plan_fft_inverse(ny))
    } else {
        (planner.plan_fft_forward(nx), planner.plan_fft_forward(ny))
    };
    for row in data.chunks_exact_mut(nx) {
        fx.process(row);
    }
    let mut col = vec![Complex64::new(0.0, 0.0); ny];
    for c in 0..nx {
        for (r, v) in col.iter_mut().enumerate() {
            *v = data[r * nx + c];
        }
        fy.process(&mut col);
        for (r, v) in col.iter().enumerate() {
            data[r * nx + c] = *v;
        }
    }
}

/// The smooth part of Moisan's decomposition: it carries every jump across the edges.
pub fn smooth_part(hf: &HeightField) -> Vec<f64> {
    let (nx, ny) = (hf.nx(), hf.ny());
    let h = hf.heights_um();
    let mut v = vec![Complex64::new(0.0, 0.0); nx * ny];
    for c in 0..nx {
        let jump = h[(ny - 1) * nx + c] - h[c];
        v[c].re += jump;
        v[(ny - 1) * nx + c].re -= jump;
    }
    for r in 0..ny {
        let jump = h[r * nx + nx - 1] - h[r * nx];
        v[r * nx].re += jump;
        v[r * nx + nx - 1].re -= jump;
    }
    fft2(&mut v, nx, ny, false);
    let tau = std::f64::consts::TAU;
    for r in 0..ny {
        for c in 0..nx {
            let d = 2.0 * (tau * c as f64 / nx as f64).cos()
                + 2.0 * (tau * r as f64 / ny as f64).cos()
                - 4.0;
            let z = &mut v[r * nx + c];
            *z = if r == 0 && c == 0 {
                Complex64::new(0.0, 0.0)
            } else {
                *z / d
            };
        }
    }
    fft2(&mut v, nx, ny, true);
    let norm = (nx * ny) as f64;
    v.iter().map(|z| z.re / norm).collect()
}

/// The seam's share of the field's spectral energy (module docs), in `[0, 1]`.
pub fn seam_share(hf: &HeightField) -> f64 {
    let mean = hf.mean();
    let energy: f64 = hf.heights_um().iter().map(|h| (h - mean).powi(2)).sum();
    if energy <= 0.0 || hf.nx() < 2 || hf.ny() < 2 {
        return 0.0;
    }
    let s = smooth_part(hf);
    let sm = s.iter().sum::<f64>() / s.len() as f64;
    let seam: f64 = s.iter().map(|v| (v - sm).powi(2)).sum();
    (seam / energy).min(1.0)
}

fn tukey(i: usize, n: usize) -> f64 {
    let t = (i as f64 + 0.5) / n as f64;
    let edge = TUKEY_FRACTION / 2.0;
    let d = t.min(1.0 - t);
    if d >= edge {
        1.0
    } else {
        0.5 - 0.5 * (std::f64::consts::PI * d / edge).cos()
    }
}

/// Makes `hf` tile without a seam (module docs).
pub fn tile(hf: &HeightField, how: Tile) -> Result<HeightField> {
    let (nx, ny, dh) = (hf.nx(), hf.ny(), hf.dh_um());
    let h = hf.heights_um();
    match how {
        Tile::None => Ok(hf.clone()),
        Tile::Mirror => {
            if 2 * nx.max(ny) > MAX_SIDE {
                return Err(Error::invalid(
                    "tile",
                    format!(
                        "mirror doubles the {nx}×{ny} scan past the limit of {MAX_SIDE} samples a \
                         side; use window or grow"
                    ),
                ));
            }
            let fold = |i: usize, n: usize| if i < n { i } else { 2 * n - 1 - i };
            let out = (0..2 * ny)
                .flat_map(|r| (0..2 * nx).map(move |c| h[fold(r, ny) * nx + fold(c, nx)]))
                .collect();
            HeightField::new(2 * nx, 2 * ny, dh, out)
        }
        Tile::Window => {
            let mean = hf.mean();
            let out = (0..ny)
                .flat_map(|r| (0..nx).map(move |c| (c, r)))
                .map(|(c, r)| mean + tukey(c, nx) * tukey(r, ny) * (h[r * nx + c] - mean))
                .collect();
            HeightField::new(nx, ny, dh, out)
        }
        Tile::Grow => {
            let n = ((GROW_SIZE_UM / dh).round() as usize).clamp(nx.max(ny), MAX_SIDE);
            super::grow::grow(hf, n, 1)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(nx: usize, ny: usize, f: impl Fn(usize, usize) -> f64) -> HeightField {
        let h = (0..ny)
            .flat_map(|r| (0..nx).map(move |c| (c, r)))
            .map(|(c, r)| f(c, r))
            .collect();
        HeightField::new(nx, ny, 0.05, h).unwrap()
    }

    #[test]
    fn a_periodic_field_has_almost_no_seam_and_a_ramp_is_all_seam() {
        let tau = std::f64::consts::TAU;
        // Sampled periodic fields keep a floor: the wrap's ordinary one-sample step.
        let periodic = field(128, 96, |c, r| {
            (tau * c as f64 / 32.0).sin() + (tau * r as f64 / 24.0).cos()
        });
        let floor = seam_share(&periodic);
        assert!(floor < 5e-3, "{floor}");
        let ramp = field(64, 48, |c, _| c as f64);
        assert!(seam_share(&ramp) > 0.5, "{}", seam_share(&ramp));
        // 4.5 periods of a cosine: a step from −1 to 1 at the seam.
        let cut = field(144, 96, |c, _| (tau * c as f64 / 32.0).cos());
        let s = seam_share(&cut);
        assert!(s > 10.0 * floor && s < 0.9, "{s} (floor {floor})");
        for how in [Tile::Mirror, Tile::Window] {
            let t = tile(&cut, how).unwrap();
            assert!(seam_share(&t) < 0.1 * s, "{how}: {} vs {s}", seam_share(&t));
        }
    }
}
