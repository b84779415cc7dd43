//! DFT terms of a height field (MODEL §3–4): the mean-centred Taylor terms `D_n` and the
//! Chebyshev terms `E_n`, fftshifted, normalised by `1/(N_x N_y)`, cropped to the band of
//! frequencies that a scene can reach, plus the windowed lookup `Ŵ_n(q)` that every
//! evaluator shares. Owns the on-disk term cache ([`cache`]). No colour, no GPU.

pub mod cache;
mod terms;

pub use terms::compute_terms;

use num_complex::Complex64;
pub use rustfft::num_complex;

use crate::heightfield::HeightField;
use crate::{Error, Result};

/// How `exp(i k w h)` is expanded into precomputable terms (MODEL §4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Expansion {
    /// Thesis Taylor series `Σ (kw)^n/n! · Ŵ[(i h)^n]`; cancels badly in f32 for `k|w|h ≳ 15`.
    Taylor,
    /// Jacobi–Anger series `Σ ε_n iⁿ J_n(kwA) · Ŵ[T_n(x)]`; every factor is bounded by 1.
    Chebyshev,
}

impl std::str::FromStr for Expansion {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "taylor" => Ok(Self::Taylor),
            "chebyshev" => Ok(Self::Chebyshev),
            _ => Err(Error::invalid(
                "expansion",
                format!("'{s}'; expected 'taylor' or 'chebyshev'"),
            )),
        }
    }
}

impl std::fmt::Display for Expansion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Taylor => "taylor",
            Self::Chebyshev => "chebyshev",
        })
    }
}

/// A rectangle of stored texels in the full fftshifted index space `[0, N_x) × [0, N_y)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Band {
    /// First stored column.
    pub x0: usize,
    /// First stored row.
    pub y0: usize,
    /// Stored columns.
    pub width: usize,
    /// Stored rows.
    pub height: usize,
}

/// What to precompute: expansion, number of terms and the frequency band to keep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TermRequest {
    /// Taylor or Chebyshev.
    pub expansion: Expansion,
    /// Highest term index `T`; terms `0..=T` are computed.
    pub max_term: usize,
    /// Shortest wavelength that will be looked up (µm); sets the reachable band.
    pub lambda_min_um: f64,
    /// Gather radius `R` of the Gaussian window (texels).
    pub window_radius: usize,
    /// Keep the whole spectrum instead of the reachable band.
    pub full_band: bool,
}

impl TermRequest {
    /// Checks ranges: `T ≤ 64`, `R ≤ 8`, `λ_min` in (0.1, 10) µm.
    pub fn validate(&self) -> Result<()> {
        if self.max_term > 64 {
            return Err(Error::invalid(
                "terms",
                format!("{}; at most 64 terms are supported", self.max_term),
            ));
        }
        if self.window_radius > 8 {
            return Err(Error::invalid(
                "window radius",
                format!("{}; at most 8 texels", self.window_radius),
            ));
        }
        if !(self.lambda_min_um > 0.1 && self.lambda_min_um < 10.0) {
            return Err(Error::invalid(
                "minimum wavelength",
                format!("{} µm", self.lambda_min_um),
            ));
        }
        Ok(())
    }
}

/// Per-term extrema of the real and imaginary parts (thesis eq. 1.1), for normalised
/// fixed-point storage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extrema {
    pub re_min: f64,
    pub re_max: f64,
    pub im_min: f64,
    pub im_max: f64,
}

/// The precomputed terms of one height field, cropped to a band.
///
/// `terms[n][y * band.width + x]` is `D_n` (Taylor) or `E_n` (Chebyshev) at full-spectrum
/// texel `(band.x0 + x, band.y0 + y)`, already multiplied by `1/(N_x N_y)` so that a flat
/// surface has value 1 at DC.
#[derive(Debug, Clone, PartialEq)]
pub struct TermStack {
    pub expansion: Expansion,
    /// Height-field samples along x and y (the full spectrum size).
    pub nx: usize,
    pub ny: usize,
    /// Height-field pixel size (µm).
    pub dh_um: f64,
    /// Stored band of texels.
    pub band: Band,
    /// One cropped complex image per term.
    pub terms: Vec<Vec<Complex64>>,
    /// Per-term extrema over the band.
    pub extrema: Vec<Extrema>,
    /// `max|h − mean|` (µm): the Taylor remainder bound of MODEL §4.
    pub max_deviation_um: f64,
    /// Chebyshev half range `A = (max h − min h)/2` (µm).
    pub half_range_um: f64,
}

impl TermStack {
    /// Index of zero frequency along x, `b = floor(N_x/2)` (thesis eq. 1.5).
    pub fn centre_x(&self) -> usize {
        self.nx / 2
    }
    /// Index of zero frequency along y.
    pub fn centre_y(&self) -> usize {
        self.ny / 2
    }
    /// Number of terms stored (`T + 1`).
    pub fn term_count(&self) -> usize {
        self.terms.len()
    }

    /// Term `n` at full-spectrum texel `(tx, ty)`. The DFT spectrum is periodic, so the
    /// index wraps modulo `N`; texels outside the stored band are zero (they are never
    /// reached by construction of the band).
    pub fn texel(&self, n: usize, tx: i64, ty: i64) -> Complex64 {
        let x = tx.rem_euclid(self.nx as i64) as usize;
        let y = ty.rem_euclid(self.ny as i64) as usize;
        let (Some(bx), Some(by)) = (x.checked_sub(self.band.x0), y.checked_sub(self.band.y0))
        else {
            return Complex64::new(0.0, 0.0);
        };
        if bx >= self.band.width || by >= self.band.height {
            return Complex64::new(0.0, 0.0);
        }
        self.terms[n][by * self.band.width + bx]
    }

    /// Bytes the stored band takes as RG32F layers on the GPU.
    pub fn gpu_bytes(&self) -> usize {
        self.term_count() * self.band.width * self.band.height * 8
    }
}

/// Gaussian window and lookup geometry shared by every evaluator (MODEL §3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    /// Gaussian std in texels along x and y: `σt = N·dH/(2π σs)`, `σs = coherence/4`.
    pub sigma_texels: [f64; 2],
    /// Gather radius `R` (texels around `floor(q)`).
    pub radius: usize,
}

impl Window {
    /// The window of a `coherence_um` coherence length for the given spectrum geometry.
    pub fn new(nx: usize, ny: usize, dh_um: f64, coherence_um: f64, radius: usize) -> Result<Self> {
        if !(coherence_um.is_finite() && coherence_um > 0.0) {
            return Err(Error::invalid(
                "coherence length",
                format!("{coherence_um} µm; must be a finite positive length"),
            ));
        }
        let sigma_s = coherence_um / 4.0;
        let s = |n: usize| n as f64 * dh_um / (2.0 * std::f64::consts::PI * sigma_s);
        Ok(Self {
            sigma_texels: [s(nx), s(ny)],
            radius,
        })
    }
}

/// Fractional lookup position `q = b + u·N·dH/λ` (thesis eq. 1.8) along one axis.
pub fn lookup_coord(b: usize, u: f64, n: usize, dh_um: f64, lambda_um: f64) -> f64 {
    b as f64 + u * n as f64 * dh_um / lambda_um
}

/// The windowed value `Ŵ_n(q)` of MODEL §3: the Gaussian-weighted sum of term `n` over the
/// `(2R+1)²` texels around `floor(q)`. (The `1/(N_x N_y)` is already in the stack.)
pub fn windowed(stack: &TermStack, n: usize, window: &Window, q: [f64; 2]) -> Complex64 {
    let r = window.radius as i64;
    if !(q[0].is_finite() && q[1].is_finite()) {
        return Complex64::new(0.0, 0.0);
    }
    // The spectrum is periodic: a lookup far outside it (a huge `dH` from the command line)
    // is moved back by whole periods, so the integer texel range below cannot overflow.
    // Ordinary lookups are left bit-for-bit alone.
    const FAR: f64 = (1u64 << 31) as f64;
    let wrap = |v: f64, n: usize| {
        if v.abs() < FAR {
            v
        } else {
            v.rem_euclid(n as f64)
        }
    };
    let q = [wrap(q[0], stack.nx), wrap(q[1], stack.ny)];
    let ax = q[0].floor() as i64;
    let ay = q[1].floor() as i64;
    let inv2sx = 1.0 / (2.0 * window.sigma_texels[0] * window.sigma_texels[0]);
    let inv2sy = 1.0 / (2.0 * window.sigma_texels[1] * window.sigma_texels[1]);
    let mut acc = Complex64::new(0.0, 0.0);
    for ty in ay - r..=ay + r {
        let dy = ty as f64 - q[1];
        let gy = (-dy * dy * inv2sy).exp();
        for tx in ax - r..=ax + r {
            let dx = tx as f64 - q[0];
            let g = gy * (-dx * dx * inv2sx).exp();
            acc += stack.texel(n, tx, ty) * g;
        }
    }
    acc
}

/// The band of texels that lookups can reach for wavelengths ≥ `lambda_min_um` with gather
/// radius `radius` (MODEL §3): `b ± (2·N·dH/λ_min + R + 1)`, or the whole spectrum when
/// that is at least as large. Saturating arithmetic: a huge `dH` (user input) or radius
/// means "the whole spectrum", never an overflow.
pub fn reachable_band(hf: &HeightField, lambda_min_um: f64, radius: usize) -> Band {
    let axis = |n: usize| -> (usize, usize) {
        // `as usize` saturates (and maps NaN to 0); the sums below must saturate too.
        let reach = ((2.0 * n as f64 * hf.dh_um() / lambda_min_um).ceil() as usize)
            .saturating_add(radius)
            .saturating_add(1);
        let b = n / 2;
        if reach.saturating_mul(2).saturating_add(1) >= n || reach > b {
            (0, n)
        } else {
            (b - reach, 2 * reach + 1)
        }
    };
    let (x0, width) = axis(hf.nx());
    let (y0, height) = axis(hf.ny());
    Band {
        x0,
        y0,
        width,
        height,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reachable_band_saturates_for_huge_pixels() {
        // HeightField::new refuses dH above 1 mm (the CLI's `--dh-um 1e18` is an error line
        // now); the band arithmetic still saturates for the largest field it accepts and
        // any radius.
        for dh in [1e3, 999.0] {
            let hf = HeightField::new(8, 6, dh, vec![0.0; 48]).unwrap();
            let b = reachable_band(&hf, 0.38, usize::MAX);
            assert_eq!((b.x0, b.y0, b.width, b.height), (0, 0, 8, 6));
        }
        let hf = HeightField::new(512, 512, 1e-4, vec![0.0; 512 * 512]).unwrap();
        let b = reachable_band(&hf, 0.38, 1);
        assert!(b.width < 512 && b.x0 + b.width <= 512, "{b:?}");
    }

    #[test]
    fn windowed_lookups_far_outside_the_spectrum_do_not_overflow() {
        let hf = HeightField::new(8, 8, 1e3, (0..64).map(|i| i as f64 * 1e-3).collect()).unwrap();
        let req = TermRequest {
            expansion: Expansion::Taylor,
            max_term: 1,
            lambda_min_um: 0.38,
            window_radius: 2,
            full_band: false,
        };
        let stack = compute_terms(&hf, &req).unwrap();
        let w = Window::new(8, 8, 1e3, 65.0, 2).unwrap();
        for q in [
            [1e30, -1e30],
            [9.3e18, 4.0],
            [f64::NAN, 0.0],
            [f64::INFINITY, 1.0],
        ] {
            assert!(windowed(&stack, 1, &w, q).re.is_finite());
        }
        // Near the spectrum nothing changes: one period away is the same lookup.
        let a = windowed(&stack, 1, &w, [3.25, 4.5]);
        let b = windowed(&stack, 1, &w, [3.25 + 8.0 * (1u64 << 32) as f64, 4.5]);
        assert!((a - b).norm() <= 1e-9 * a.norm().max(1e-300), "{a} {b}");
    }
}
