//! The CPU model (MODEL §6.2): the thesis FLSS algorithm (Algorithm 3) in f64, term for term
//! and tap for tap what the GPU shader computes. Comparing it with the [`reference`]
//! isolates approximation error (terms `T`, window radius `R`, `Δλ`); comparing it with the
//! GPU isolates float32 and driver error.
//!
//! [`reference`]: super::reference

use crate::colour::ColourTable;
use crate::spectrum::num_complex::Complex64;
use crate::spectrum::{lookup_coord, windowed, Expansion, TermStack, Window};

use super::{bessel, integrated, spectral, Shading};

/// The windowed, normalised transform `P̂(ku, kv)` assembled from terms `0..=terms`
/// (clamped to the stack), at wavelength `lambda_um`.
pub fn p_hat(
    stack: &TermStack,
    terms: usize,
    window: &Window,
    uvw: [f64; 3],
    lambda_um: f64,
) -> Complex64 {
    let t = terms.min(stack.term_count().saturating_sub(1));
    let [u, v, w] = uvw;
    let q = [
        lookup_coord(stack.centre_x(), u, stack.nx, stack.dh_um, lambda_um),
        lookup_coord(stack.centre_y(), v, stack.ny, stack.dh_um, lambda_um),
    ];
    let k = 2.0 * std::f64::consts::PI / lambda_um;
    let mut p = Complex64::new(0.0, 0.0);
    match stack.expansion {
        Expansion::Taylor => {
            // (kw)^n / n! built incrementally (MODEL §4).
            let kw = k * w;
            let mut scale = 1.0;
            for n in 0..=t {
                p += windowed(stack, n, window, q) * scale;
                scale *= kw / (n + 1) as f64;
            }
        }
        Expansion::Chebyshev => {
            let a = k * w * stack.half_range_um;
            let j = bessel::jn_all(a, t);
            // ε_n iⁿ: 1, 2i, −2, −2i, 2, ...
            let mut i_pow = Complex64::new(1.0, 0.0);
            for (n, jn) in j.iter().enumerate() {
                let eps = if n == 0 { 1.0 } else { 2.0 };
                p += windowed(stack, n, window, q) * i_pow * (eps * jn);
                i_pow *= Complex64::new(0.0, 1.0);
            }
        }
    }
    p
}

/// Spectral relative reflectance `ρ_λ = C(ωi, ωr)·|P̂|²` at `lambda_nm`.
pub fn rho(
    stack: &TermStack,
    terms: usize,
    window: &Window,
    shading: &Shading,
    wi: [f64; 3],
    wr: [f64; 3],
    lambda_nm: f64,
) -> f64 {
    spectral(wi, wr, shading, |d| {
        p_hat(stack, terms, window, d, lambda_nm * 1e-3).norm_sqr()
    })
}

/// CIE XYZ of the reflected D65 light, integrated over `table`'s wavelengths.
pub fn xyz(
    stack: &TermStack,
    terms: usize,
    window: &Window,
    shading: &Shading,
    table: &ColourTable,
    wi: [f64; 3],
    wr: [f64; 3],
) -> [f64; 3] {
    integrated(wi, wr, shading, |d| {
        table.integrate(|l| p_hat(stack, terms, window, d, l * 1e-3).norm_sqr())
    })
}
