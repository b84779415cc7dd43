//! Reduced-precision storage of the DFT terms (MODEL §7, thesis eq. 1.1) against RG32F on
//! the same BRDF map. Stated tolerances, relative to the map's maximum per channel:
//! - RG16F (half floats scaled per term by the term's largest magnitude): 11-bit
//!   mantissas, so each texel is off by ≤ 2⁻¹² of its term's maximum; summed over taps and
//!   terms the map stays within 3·10⁻³ (measured: ≤ 5·10⁻⁴).
//! - UNORM16 (per-term extrema, eq. 1.1): each texel is off by ≤ 2⁻¹⁷ of its term's range,
//!   so the map agrees to 5·10⁻⁴ (measured: ≤ 10⁻⁴).

mod gpu_util;

use diffract::gpu::StorageFormat;
use diffract::spectrum::Expansion;
use gpu_util::*;

const SIZE: u32 = 33;

fn relative_error(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let max = b.iter().flatten().fold(0f32, |m, v| m.max(v.abs())) as f64;
    assert!(max > 0.05, "reference map is (nearly) empty: max {max}");
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .map(|(x, y)| (*x as f64 - *y as f64).abs() / max)
        .fold(0.0, f64::max)
}

fn check(heightfield: &str, expansion: Expansion) {
    let Some(mut r) = renderer() else { return };
    let p = prepare(&small_material(heightfield, expansion, 8, 1));
    let theta = theta_for_specular_pixel(9, SIZE);
    let mut maps = Vec::new();
    for format in [
        StorageFormat::Rg32f,
        StorageFormat::Rg16f,
        StorageFormat::Unorm16,
    ] {
        r.set_storage_format(format);
        let f = r
            .render_brdf_map(&p, theta, 0.0, SIZE, None)
            .unwrap_or_else(|e| panic!("{format}: {e}"));
        assert!(f.rgb.iter().flatten().all(|v| v.is_finite()));
        maps.push(f.rgb);
    }
    assert_no_validation(&r);
    let e16f = relative_error(&maps[1], &maps[0]);
    let e16u = relative_error(&maps[2], &maps[0]);
    eprintln!("{heightfield} {expansion}: RG16F {e16f:.2e}, UNORM16 {e16u:.2e} of max");
    assert!(e16f <= 3e-3, "RG16F differs by {e16f:.2e} of the maximum");
    assert!(e16u <= 5e-4, "UNORM16 differs by {e16u:.2e} of the maximum");
    // Reduced precision must actually have been used: identical maps would mean the
    // format switch did nothing.
    assert!(e16f > 0.0 && e16u > 0.0, "maps are bit-identical to RG32F");
}

#[test]
fn blazed_chebyshev_formats_agree() {
    check("builtin:blazed", Expansion::Chebyshev);
}

#[test]
fn elaphe_taylor_formats_agree() {
    check("builtin:elaphe", Expansion::Taylor);
}
