//! BRDF maps from the GPU agree with the f64 CPU model (`brdf::model`) of the same algorithm
//! at sampled pixels, for Taylor and Chebyshev, blazed and Elaphe-like gratings: the only
//! difference allowed is float32 arithmetic.
//!
//! Tolerance: |GPU − CPU| ≤ 10⁻³ · max(map) + 10⁻⁶ per XYZ channel. Float32 errors come
//! from the lookup coordinate (q ≈ 340 texels at 2⁻²⁴ relative precision shifts the Gaussian
//! weights by ~10⁻⁴), the Taylor cancellation (~6·10⁻⁸·e^{k|w|h}) and the summation order.

mod gpu_util;

use diffract::brdf;
use diffract::spectrum::Expansion;
use gpu_util::*;

const SIZE: u32 = 41;

fn check_xyz_map(heightfield: &str, expansion: Expansion, specular_pixel: u32) {
    let Some(mut r) = renderer() else { return };
    let (theta, phi) = (theta_for_specular_pixel(specular_pixel, SIZE), 0.0);
    let m = small_material(heightfield, expansion, 6, 1);
    let p = prepare(&m);
    let frame = r
        .render_brdf_map(&p, theta, phi, SIZE, None)
        .expect("render BRDF map");
    assert_no_validation(&r);
    assert_eq!((frame.width, frame.height), (SIZE, SIZE));
    assert!(frame
        .rgb
        .iter()
        .flatten()
        .all(|v| v.is_finite() && *v >= 0.0));

    let max = frame.rgb.iter().map(|p| p[1]).fold(0.0f32, f32::max) as f64;
    // The specular peak and the orders are hit: a map of tails only would test nothing.
    assert!(
        max > 0.05,
        "{heightfield}: max Y {max} — the peaks were missed"
    );
    let tol = 1e-3 * max + 1e-6;
    let wi = uploaded_direction(theta, phi);
    let terms = p.terms();
    let mut worst = 0.0f64;
    let pixels = sample_pixels(SIZE, wi, 8);
    assert!(pixels.len() >= 20);
    for &(i, j) in &pixels {
        let wr = map_direction(i, j, SIZE).unwrap();
        let cpu = brdf::model::xyz(
            p.stack.get().unwrap(),
            terms,
            &p.window,
            &p.shading,
            &p.colour,
            wi,
            wr,
        );
        let gpu = frame.at(i, j);
        for c in 0..3 {
            let err = (gpu[c] as f64 - cpu[c]).abs();
            worst = worst.max(err / max);
            assert!(
                err <= tol,
                "{heightfield} {expansion}: pixel ({i},{j}) channel {c}: GPU {} vs CPU {} (max {max})",
                gpu[c],
                cpu[c]
            );
        }
    }
    // Outside the disk the map is black.
    assert_eq!(frame.at(0, 0), [0.0; 3]);
    eprintln!(
        "{heightfield} {expansion}: worst error {worst:.2e} of max Y {max:.3e}; GPU {:?} ms, wall {:.0} ms",
        frame.gpu_ms, frame.wall_ms
    );
}

#[test]
fn blazed_taylor_map_matches_cpu_model() {
    check_xyz_map("builtin:blazed", Expansion::Taylor, 12);
}

#[test]
fn blazed_chebyshev_map_matches_cpu_model() {
    check_xyz_map("builtin:blazed", Expansion::Chebyshev, 12);
}

#[test]
fn elaphe_taylor_map_matches_cpu_model() {
    check_xyz_map("builtin:elaphe", Expansion::Taylor, 6);
}

#[test]
fn elaphe_chebyshev_map_matches_cpu_model() {
    check_xyz_map("builtin:elaphe", Expansion::Chebyshev, 6);
}

#[test]
fn spectral_map_matches_cpu_rho() {
    let Some(mut r) = renderer() else { return };
    let m = small_material("builtin:blazed", Expansion::Chebyshev, 6, 2);
    let p = prepare(&m);
    let (theta, phi, lambda) = (theta_for_specular_pixel(9, SIZE), 0.0, 550.0);
    let frame = r
        .render_brdf_map(&p, theta, phi, SIZE, Some(lambda))
        .expect("render spectral map");
    assert_no_validation(&r);
    let max = frame.rgb.iter().map(|p| p[0]).fold(0.0f32, f32::max) as f64;
    assert!(max > 0.05, "max ρ {max}: the peaks were missed");
    let wi = uploaded_direction(theta, phi);
    for (i, j) in sample_pixels(SIZE, wi, 8) {
        let wr = map_direction(i, j, SIZE).unwrap();
        let cpu = brdf::model::rho(
            p.stack.get().unwrap(),
            p.terms(),
            &p.window,
            &p.shading,
            wi,
            wr,
            lambda,
        );
        let gpu = frame.at(i, j);
        assert_eq!(gpu[0], gpu[1]);
        assert_eq!(gpu[0], gpu[2]);
        let err = (gpu[0] as f64 - cpu).abs();
        assert!(
            err <= 1e-3 * max + 1e-6,
            "pixel ({i},{j}): GPU {} vs CPU {cpu}",
            gpu[0]
        );
    }
}

/// Later maps of the same size and material reuse the first map's pipeline, target and
/// command buffer and only rewrite the uniform block: a map drawn after a
/// spectral map and a map at another angle is the map a fresh renderer draws.
#[test]
fn a_reused_map_pass_draws_what_a_fresh_one_draws() {
    let Some(mut r) = renderer() else { return };
    let p = prepare(&small_material(
        "builtin:blazed",
        Expansion::Chebyshev,
        4,
        1,
    ));
    r.render_brdf_map(&p, 70.0, 45.0, 24, Some(550.0))
        .expect("spectral map");
    // Builds the XYZ pass, which the next map reuses.
    r.render_brdf_map(&p, 10.0, 0.0, 24, None)
        .expect("first map");
    let reused = r.render_brdf_map(&p, 35.0, 20.0, 24, None).expect("reused");
    assert_no_validation(&r);
    let Some(mut fresh) = renderer() else { return };
    let want = fresh
        .render_brdf_map(&p, 35.0, 20.0, 24, None)
        .expect("fresh map");
    assert_no_validation(&fresh);
    assert!(want.rgb.iter().flatten().any(|v| *v > 0.0));
    assert_eq!(reused.rgb, want.rgb);
}
