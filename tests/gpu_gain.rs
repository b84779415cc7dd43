//! The shader's gain factor near grazing specular, where `ωi·ωr → −1`: `1 + ωi·ωr` must be
//! computed as `|ωi + ωr|²/2` (MODEL §2, `brdf::gain`), not by cancellation.
//!
//! A spectral BRDF map (flss) of a nearly flat surface has `|P̂|² = 1` at `u = v = 0`, so
//! the pixel whose view is the mirror of the light holds `C(ωi, ωr)` itself; with Fresnel
//! and shadowing off that is Stam's geometric term, exactly 1 at specular at every angle.
//! The pixel chosen is the one of a 51² map nearest the rim (θr = 88.9°), where
//! `1 + ωi·ωr ≈ 7.7e-4`: in float32, `1 + dot(ωi, ωr)` loses about 5e-5 of it. Measured on
//! lavapipe at the four pixels below: the old form gave `|ρ − 1|` = 1.0e-4, 1.0e-4, 7.9e-5,
//! 4.6e-5 (this test failed), `|ωi + ωr|²/2` gives at most 1.2e-7.

mod gpu_util;

use diffract::material::{Material, Terms};
use diffract::spectrum::Expansion;
use gpu_util::*;

const SIZE: u32 = 51;

#[test]
fn gain_at_grazing_specular_is_one_to_float32_rounding() {
    let Some(mut r) = renderer() else { return };
    // A sinusoid of 1 pm: |P̂|² = J0(k·w·A)² = 1 − 1e-12 at u = v = 0.
    let m = Material {
        heightfield: "builtin:sinusoidal".into(),
        h_max_um: Some(1e-6),
        expansion: Expansion::Chebyshev,
        terms: Terms::Auto,
        window_radius: 1,
        fresnel: false,
        shadowing: false,
        ..Material::default()
    };
    let p = prepare(&m);
    let mut worst = 0.0f64;
    // Pixels by the rim (found by search over the 51² map: the largest |ωr.xy| < 1), where
    // the light is placed at the mirror direction of each in turn.
    for (i, j) in [(30u32, 0u32), (0, 30), (36, 2), (48, 14)] {
        let wr = map_direction(i, j, SIZE).expect("inside the disk");
        let theta = (wr[0].hypot(wr[1])).asin().to_degrees();
        let phi = (-wr[1]).atan2(-wr[0]).to_degrees();
        let frame = r
            .render_brdf_map(&p, theta, phi, SIZE, Some(550.0))
            .expect("spectral map");
        let wi = uploaded_direction(theta, phi);
        let c = diffract::brdf::gain(wi, wr, &p.shading);
        assert!((c - 1.0).abs() < 1e-9, "f64 gain {c} at ({i},{j})");
        let rho = frame.at(i, j)[0] as f64;
        let err = (rho - 1.0).abs();
        worst = worst.max(err);
        eprintln!(
            "pixel ({i},{j}): θ = {theta:.3}°, 1 + ωi·ωr = {:.3e}, GPU ρ = {rho:.9} (|ρ − 1| = {err:.2e})",
            1.0 + wi[0] * wr[0] + wi[1] * wr[1] + wi[2] * wr[2]
        );
        assert!(rho.is_finite());
    }
    assert_no_validation(&r);
    // float32 rounding of the whole shader: a few ulps of 1.
    assert!(
        worst <= 2e-6,
        "|ρ − 1| up to {worst:.2e} at grazing specular"
    );
}
