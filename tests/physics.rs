//! Physics checks of the CPU evaluators (MODEL §6, §8), with no GPU involved: flat mirror,
//! grating-equation peaks, model-vs-reference agreement (including the thesis R = 1 error),
//! Taylor vs Chebyshev convergence on a tall structure, and finiteness everywhere.

use diffract::brdf::{direction, model, reference, Shading};
use diffract::colour::ColourTable;
use diffract::heightfield::HeightField;
use diffract::spectrum::{compute_terms, Expansion, TermRequest, TermStack, Window};

const COH: f64 = 65.0;

fn field(n: usize, dh: f64, f: impl Fn(f64, f64) -> f64) -> HeightField {
    let h = (0..n * n)
        .map(|i| f((i % n) as f64 * dh, (i / n) as f64 * dh))
        .collect();
    HeightField::new(n, n, dh, h).unwrap()
}

/// Sinusoid of period `d` (µm) and peak-to-peak height `a` across x.
fn sinusoid(n: usize, dh: f64, d: f64, a: f64) -> HeightField {
    field(n, dh, |x, _| {
        0.5 * a * (1.0 + (2.0 * std::f64::consts::PI * x / d).cos())
    })
}

/// Sawtooth (blazed) grating of period `d` and height `a` across x.
fn blazed(n: usize, dh: f64, d: f64, a: f64) -> HeightField {
    field(n, dh, |x, _| a * (x / d).fract())
}

fn terms(hf: &HeightField, e: Expansion, t: usize, r: usize) -> (TermStack, Window) {
    let req = TermRequest {
        expansion: e,
        max_term: t,
        lambda_min_um: 0.38,
        window_radius: r,
        full_band: true,
    };
    let s = compute_terms(hf, &req).unwrap();
    let w = Window::new(hf.nx(), hf.ny(), hf.dh_um(), COH, r).unwrap();
    (s, w)
}

#[test]
fn flat_mirror_is_one_at_specular_and_dark_elsewhere() {
    let hf = field(64, 0.5, |_, _| 0.2);
    let no_fresnel = Shading {
        fresnel: false,
        ..Default::default()
    };
    let (s, w) = terms(&hf, Expansion::Taylor, 4, 3);
    for theta in [0.0, 30.0, 60.0, 85.0] {
        let wi = direction(theta, 20.0);
        let wr = direction(theta, 200.0);
        for l in [380.0, 550.0, 780.0] {
            let r = reference::rho(&hf, COH, &no_fresnel, wi, wr, l);
            let m = model::rho(&s, 4, &w, &no_fresnel, wi, wr, l);
            assert!((r - 1.0).abs() < 1e-12, "reference θ={theta} λ={l}: {r}");
            assert!((m - 1.0).abs() < 1e-12, "model θ={theta} λ={l}: {m}");
        }
        // With Fresnel the specular value is exactly R(θ)/R0.
        let r0 = diffract::brdf::schlick_r0(1.5);
        let fres = (r0 + (1.0 - r0) * (1.0 - theta.to_radians().cos()).powi(5)) / r0;
        let r = reference::rho(&hf, COH, &Shading::default(), wi, wr, 500.0);
        assert!((r - fres).abs() < 1e-9 * fres, "θ={theta}: {r} vs {fres}");
        // Well away from specular only window leakage remains.
        let off = direction((0.5 * theta).max(5.0), 200.0);
        for l in [380.0, 780.0] {
            let r = reference::rho(&hf, COH, &no_fresnel, wi, off, l);
            let m = model::rho(&s, 4, &w, &no_fresnel, wi, off, l);
            assert!(r < 1e-6 && m < 1e-6, "θ={theta} λ={l}: ref {r}, model {m}");
        }
    }
}

/// θr (signed as in the thesis: negative on the mirror side) of peak ρ for light at θi in
/// the xz plane, scanning θr ∈ [lo, hi] at 0.01°.
fn peak_theta_r(rho: impl Fn([f64; 3], [f64; 3]) -> f64, theta_i: f64, lo: f64, hi: f64) -> f64 {
    let wi = direction(theta_i, 0.0);
    let mut best = (f64::NEG_INFINITY, 0.0);
    let steps = ((hi - lo) / 0.01).round() as usize;
    for k in 0..=steps {
        let t = lo + k as f64 * 0.01;
        let wr = direction(t.abs(), if t < 0.0 { 180.0 } else { 0.0 });
        let r = rho(wi, wr);
        if r > best.0 {
            best = (r, t);
        }
    }
    best.1
}

#[test]
fn first_order_peaks_follow_the_grating_equation() {
    // 26 periods of 2.5 µm in a 65 µm patch, dH = 65/704 µm as in the shipped gratings.
    let n = 704;
    let dh = 65.0 / n as f64;
    let d = 2.5;
    let shading = Shading::default();
    for (name, hf) in [
        ("sinusoidal", sinusoid(n, dh, d, 0.2)),
        ("blazed", blazed(n, dh, d, 0.25)),
    ] {
        let (s, w) = terms(&hf, Expansion::Taylor, 12, 3);
        let theta_i: f64 = 75.0;
        for lambda in [400.0, 500.0, 600.0, 700.0] {
            // First order on the mirror side: sin θi + sin θr = λ/d (MODEL §8).
            let want = ((lambda * 1e-3 / d) - theta_i.to_radians().sin())
                .asin()
                .to_degrees();
            let got = peak_theta_r(
                |wi, wr| model::rho(&s, 12, &w, &shading, wi, wr, lambda),
                theta_i,
                want - 3.0,
                want + 3.0,
            );
            assert!(
                (got - want).abs() <= 0.05,
                "{name} λ={lambda}: peak at {got}°, grating equation {want}°"
            );
            let d_est = lambda * 1e-3 / (theta_i.to_radians().sin() + got.to_radians().sin());
            assert!((d_est - d).abs() < 0.01, "{name} λ={lambda}: d = {d_est}");
        }
        // The reference agrees on the peak position at one wavelength.
        let lambda: f64 = 550.0;
        let want = ((lambda * 1e-3 / d) - theta_i.to_radians().sin())
            .asin()
            .to_degrees();
        let got = peak_theta_r(
            |wi, wr| reference::rho(&hf, COH, &shading, wi, wr, lambda),
            theta_i,
            want - 0.3,
            want + 0.3,
        );
        assert!(
            (got - want).abs() <= 0.05,
            "{name} reference: {got} vs {want}"
        );
    }
}

/// Directions covering normal, oblique, grazing light and view, `u = v = 0` and off-plane.
fn direction_set() -> Vec<([f64; 3], [f64; 3])> {
    let mut v = Vec::new();
    for (ti, pi, tr, pr) in [
        (0.0, 0.0, 0.0, 0.0),      // u = v = 0 at normal incidence
        (40.0, 10.0, 40.0, 190.0), // u = v = 0, oblique
        (75.0, 0.0, 50.0, 180.0),
        (75.0, 0.0, 30.0, 180.0),
        (30.0, 0.0, 10.0, 0.0),
        (60.0, 45.0, 20.0, 250.0),
        (85.0, 0.0, 85.0, 180.0),  // grazing specular
        (88.0, 0.0, 60.0, 180.0),  // grazing light
        (20.0, 90.0, 87.0, 270.0), // grazing view
    ] {
        v.push((direction(ti, pi), direction(tr, pr)));
    }
    v
}

/// In-plane θr sweeps (0.5° steps, so lookups fall between texels as well as on them) plus
/// `direction_set()`, at three wavelengths.
fn sweep() -> Vec<([f64; 3], [f64; 3], f64)> {
    let mut pairs = direction_set();
    for ti in [30.0, 75.0] {
        for k in 0..=356 {
            let tr: f64 = -89.0 + 0.5 * k as f64;
            pairs.push((
                direction(ti, 0.0),
                direction(tr.abs(), if tr < 0.0 { 180.0 } else { 0.0 }),
            ));
        }
    }
    pairs
        .into_iter()
        .flat_map(|(wi, wr)| [380.0, 550.0, 780.0].map(|l| (wi, wr, l)))
        .collect()
}

/// Max |model − reference| over the sweep, relative to the largest reference value.
fn model_error(hf: &HeightField, refs: &[f64], e: Expansion, t: usize, r: usize) -> f64 {
    let (s, w) = terms(hf, e, t, r);
    let shading = Shading::default();
    let max_ref = refs.iter().cloned().fold(0.0, f64::max);
    let max_err = sweep()
        .iter()
        .zip(refs)
        .map(|((wi, wr, l), a)| {
            let b = model::rho(&s, t, &w, &shading, *wi, *wr, *l);
            assert!(b.is_finite());
            (a - b).abs()
        })
        .fold(0.0, f64::max);
    max_err / max_ref
}

#[test]
fn model_agrees_with_reference_for_r_at_least_2_and_records_the_thesis_r1_error() {
    // An irregular structure so every texel of the spectrum matters: two crossed sinusoids
    // plus a detuned ripple, 65 µm patch, dH = 0.25 µm (aliasing is identical in both
    // evaluators, so it does not enter this comparison).
    let n = 260;
    let dh = 0.25;
    let hf = field(n, dh, |x, y| {
        let tau = 2.0 * std::f64::consts::PI;
        0.15 * (1.0 + (tau * x / 2.5).sin())
            + 0.05 * (tau * (x / 6.5 + y / 13.0)).cos()
            + 0.03 * (tau * y / 1.625).sin()
    });
    let shading = Shading::default();
    let refs: Vec<f64> = sweep()
        .iter()
        .map(|(wi, wr, l)| reference::rho(&hf, COH, &shading, *wi, *wr, *l))
        .collect();
    assert!(refs.iter().all(|r| r.is_finite() && *r >= 0.0));
    let e: Vec<f64> = (1..=4)
        .map(|r| model_error(&hf, &refs, Expansion::Taylor, 24, r))
        .collect();
    let c4 = model_error(&hf, &refs, Expansion::Chebyshev, 24, 4);
    println!(
        "max |model − reference| / peak, T = 24: R=1 {:.3e}, R=2 {:.3e}, R=3 {:.3e}, R=4 {:.3e}; Chebyshev R=4 {c4:.3e}",
        e[0], e[1], e[2], e[3]
    );
    // R = 1 truncates the Gaussian at ~1.6σ: a visible error, measured, not hidden.
    // Measured here: R=1 2.1e-2, R=2 4.4e-6, R=3 and R=4 9e-9 (the T = 24 Taylor floor),
    // Chebyshev R=4 2e-9.
    assert!(e[0] > 1e-2, "R=1 error suspiciously small: {}", e[0]);
    assert!(e[1] < 2e-5, "R=2: {}", e[1]);
    assert!(e[2] < 1e-7, "R=3: {}", e[2]);
    assert!(e[3] < 1e-7, "R=4: {}", e[3]);
    assert!(c4 < 1e-7, "Chebyshev R=4: {c4}");
    assert!(e[0] > e[1] && e[1] > e[2] && e[3] <= e[2]);
}

#[test]
fn integrated_colour_of_model_matches_reference() {
    let n = 260;
    let hf = blazed(n, 0.25, 2.5, 0.25);
    let (s, w) = terms(&hf, Expansion::Chebyshev, 20, 4);
    let table = ColourTable::new(5).unwrap();
    let shading = Shading::default();
    for (wi, wr) in direction_set().into_iter().take(5) {
        let a = reference::xyz(&hf, COH, &shading, &table, wi, wr);
        let b = model::xyz(&s, 20, &w, &shading, &table, wi, wr);
        for c in 0..3 {
            assert!(
                (a[c] - b[c]).abs() <= 1e-4 * a[1].max(1e-3),
                "{a:?} vs {b:?}"
            );
        }
    }
}

/// For each tolerance, the smallest T whose model is within it (relative to the peak) of
/// the reference at every probe; `usize::MAX` if T = 60 does not reach it.
fn terms_needed(
    hf: &HeightField,
    e: Expansion,
    wi: [f64; 3],
    probes: &[[f64; 3]],
    tols: &[f64],
) -> Vec<usize> {
    let shading = Shading::GEOMETRIC;
    let lambda = 380.0;
    let refs: Vec<f64> = probes
        .iter()
        .map(|wr| reference::rho(hf, COH, &shading, wi, *wr, lambda))
        .collect();
    let peak = refs.iter().cloned().fold(0.0, f64::max);
    let (s, w) = terms(hf, e, 60, 4);
    let errs: Vec<f64> = (0..=60)
        .map(|t| {
            probes
                .iter()
                .zip(&refs)
                .map(|(wr, r)| (model::rho(&s, t, &w, &shading, wi, *wr, lambda) - r).abs())
                .fold(0.0, f64::max)
                / peak
        })
        .collect();
    tols.iter()
        .map(|tol| errs.iter().position(|e| e <= tol).unwrap_or(usize::MAX))
        .collect()
}

#[test]
fn taylor_and_chebyshev_both_converge_on_a_tall_structure() {
    // h_max = 1 µm at 380 nm with grazing light (MODEL §4: a = k|w|·max|h−mean| ≈ 9).
    let hf = sinusoid(260, 0.25, 2.5, 1.0);
    let wi = direction(85.0, 0.0);
    // Probe every propagating diffraction order at 380 nm: sin θr = mλ/d − sin θi.
    let s_i = 85f64.to_radians().sin();
    let probes: Vec<[f64; 3]> = (-30..=30)
        .map(|m| m as f64 * 0.38 / 2.5 - s_i)
        .filter(|s| s.abs() < 0.999)
        .map(|s| {
            let t = s.asin().to_degrees();
            // Signed θr in the plane of incidence: negative on the mirror side (φ = 180°).
            direction(t.abs(), if t < 0.0 { 180.0 } else { 0.0 })
        })
        .collect();
    let tols = [1e-2, 1e-4, 1e-6, 1e-8];
    let taylor = terms_needed(&hf, Expansion::Taylor, wi, &probes, &tols);
    let cheb = terms_needed(&hf, Expansion::Chebyshev, wi, &probes, &tols);
    println!("terms needed at h = 1 µm, 380 nm, θi = 85°, tolerances {tols:?}: Taylor T = {taylor:?}, Chebyshev T = {cheb:?}");
    for (i, tol) in tols.iter().enumerate() {
        assert!(
            taylor[i] <= 60 && cheb[i] <= 60,
            "tol {tol}: Taylor {}, Chebyshev {}",
            taylor[i],
            cheb[i]
        );
        assert!(
            cheb[i] < taylor[i],
            "tol {tol}: Chebyshev should need fewer terms"
        );
    }
}

#[test]
fn evaluators_never_produce_nan_or_inf() {
    let hf = blazed(64, 0.25, 2.0, 0.8);
    let table = ColourTable::new(20).unwrap();
    for e in [Expansion::Taylor, Expansion::Chebyshev] {
        let (s, w) = terms(&hf, e, 30, 2);
        for ti in [0.0, 45.0, 89.0, 89.999, 90.0] {
            for tr in [0.0, 45.0, 89.0, 89.999, 90.0] {
                for pr in [0.0, 90.0, 180.0] {
                    let wi = direction(ti, 0.0);
                    let wr = direction(tr, pr);
                    for shading in [Shading::default(), Shading::GEOMETRIC] {
                        let m = model::xyz(&s, 30, &w, &shading, &table, wi, wr);
                        assert!(m.iter().all(|v| v.is_finite()), "{e} {ti} {tr} {pr}: {m:?}");
                        let r = model::rho(&s, 30, &w, &shading, wi, wi, 380.0);
                        assert!(r.is_finite() && r >= 0.0);
                        let r = reference::rho(&hf, COH, &shading, wi, wr, 380.0);
                        assert!(r.is_finite() && r >= 0.0);
                    }
                }
            }
        }
    }
}

#[test]
fn grating_equation_experiment_recovers_the_blazed_period() {
    // MODEL §8 on the shipped blazed grating (2.5 µm); the thesis reports 2499.997 nm.
    let material = diffract::material::Material {
        heightfield: "builtin:blazed".into(),
        terms: diffract::material::Terms::Fixed(12),
        window_radius: 3,
        ..Default::default()
    };
    let p = material.prepare(None, &diffract::report::Stderr).unwrap();
    let r =
        diffract::eval::grating_equation(&p, 75.0, 0.0, &[400.0, 480.0, 560.0, 640.0, 700.0], 0.01)
            .unwrap();
    println!(
        "blazed: mean {:.3} nm, variance {:.3} nm²",
        r.mean_nm, r.variance_nm2
    );
    assert_eq!(r.samples.len(), 5);
    assert!((r.mean_nm - 2500.0).abs() < 1.0, "mean {}", r.mean_nm);
    assert!(r.variance_nm2 < 1.0, "variance {}", r.variance_nm2);
}
