//! Never silently wrong: each troublesome case gives the right number,
//! a refusal or a warning; automatic `T` meets its tolerance against the f64 reference
//! across a reduced stability matrix; the GPU stays within the stated float32 bound of its
//! f64 model in every non-refused cell; the grazing limit is continuous; the
//! grating-equation experiment finds the ridge period on a crop whose edges do not tile.

mod gpu_util;

use diffract::brdf::truncation::{Precision, Reach};
use diffract::brdf::{direction, gain, model, reference, Shading};
use diffract::heightfield::{GratingKind, GratingSpec, HeightField};
use diffract::material::{Material, Terms};
use diffract::spectrum::Expansion;
use diffract::stability::{self, Evaluator, MatrixSpec, Status};

fn material(src: &str, h_max: Option<f64>, expansion: Expansion, terms: Terms) -> Material {
    Material {
        heightfield: src.into(),
        h_max_um: h_max,
        expansion,
        terms,
        ..Material::default()
    }
}

/// Max `|ρ_model − ρ_ref|/C` over in-plane directions and the specular one.
fn model_error(p: &diffract::material::PreparedMaterial, theta_i: f64, lambda: f64) -> f64 {
    let s = Shading::default();
    let wi = direction(theta_i, 0.0);
    let mut dirs: Vec<[f64; 3]> = (-8..=8)
        .map(|k| {
            let t = k as f64 * 10.0 + 3.0;
            if t < 0.0 {
                direction(-t, 0.0)
            } else {
                direction(t, 180.0)
            }
        })
        .collect();
    dirs.push(direction(theta_i, 180.0));
    let mut worst = 0.0f64;
    for wr in dirs {
        let c = gain(wi, wr, &s);
        if c == 0.0 {
            continue;
        }
        let m = model::rho(
            p.stack.get().unwrap(),
            p.terms(),
            &p.window,
            &s,
            wi,
            wr,
            lambda,
        );
        let r = reference::rho(&p.heightfield, p.material.coherence_um, &s, wi, wr, lambda);
        assert!(m.is_finite() && r.is_finite());
        worst = worst.max((m - r).abs() / c);
    }
    worst
}

#[test]
fn why_tall_taylor_default_now_switches_to_chebyshev_and_is_right() {
    // Was: builtin:elaphe --hmax-um 2 with Taylor, T = 30 gave ρ up to 2.8e17; a 2 µm
    // sinusoid gave 37498 where the reference gives 0.0054.
    for src in ["builtin:sinusoidal", "builtin:elaphe"] {
        let m = material(src, Some(2.0), Expansion::Taylor, Terms::Auto);
        let p = m.prepare(None, &diffract::report::Stderr).unwrap();
        assert_eq!(p.plan.expansion, Expansion::Chebyshev, "{src}");
        assert_eq!(p.stack.get().unwrap().expansion, Expansion::Chebyshev);
        assert!(
            p.plan
                .warnings
                .iter()
                .any(|w| w.contains("using chebyshev")),
            "{src}: {:?}",
            p.plan.warnings
        );
        assert!(p.plan.meets_tolerance());
        let e = model_error(&p, 45.0, 450.0);
        println!(
            "{src} h_max 2 µm: chebyshev T = {}, error {e:.2e}",
            p.terms()
        );
        assert!(e <= m.tolerance, "{src}: error {e} above {}", m.tolerance);
    }
}

#[test]
fn why_explicit_terms_that_cannot_meet_the_tolerance_warn_with_the_expected_error() {
    let m = material(
        "builtin:sinusoidal",
        Some(2.0),
        Expansion::Taylor,
        Terms::Fixed(30),
    );
    let hf = HeightField::load_source(&m.heightfield, None, m.h_max_um).unwrap();
    let plan = m.plan(&hf, &Reach::ALL, Precision::F32).unwrap();
    assert_eq!((plan.expansion, plan.terms), (Expansion::Taylor, 30));
    assert_eq!(plan.warnings.len(), 1);
    assert!(
        plan.warnings[0].contains("expected error"),
        "{:?}",
        plan.warnings
    );
    // Low enough, the same T is silent.
    let low = material(
        "builtin:sinusoidal",
        Some(0.1),
        Expansion::Taylor,
        Terms::Fixed(30),
    );
    let hf = HeightField::load_source(&low.heightfield, None, low.h_max_um).unwrap();
    assert!(low
        .plan(&hf, &Reach::ALL, Precision::F32)
        .unwrap()
        .warnings
        .is_empty());
}

#[test]
fn why_chebyshev_at_5_um_is_refused_with_the_limit_and_what_to_change() {
    // Was: 30% off without a word.
    let m = material(
        "builtin:sinusoidal",
        Some(5.0),
        Expansion::Chebyshev,
        Terms::Auto,
    );
    let e = m
        .prepare(None, &diffract::report::Stderr)
        .unwrap_err()
        .to_string();
    assert!(!e.contains('\n'), "{e}");
    for want in ["64 terms", "peak-to-valley", "tolerance"] {
        assert!(e.contains(want), "`{e}` lacks `{want}`");
    }
    // A BRDF map at grazing light reaches |w| ≤ 1 + cos 89° only; 5 µm is then plannable.
    let hf = HeightField::load_source(&m.heightfield, None, m.h_max_um).unwrap();
    let plan = m.plan(&hf, &Reach::brdf_map(89.0), Precision::F32);
    assert!(plan.is_ok(), "{plan:?}");
}

#[test]
fn why_overflowing_inputs_are_rejected_with_one_line() {
    let one_line = |e: diffract::Error, want: &str| {
        let s = e.to_string();
        assert!(
            !s.contains('\n') && s.contains(want),
            "`{s}` lacks `{want}`"
        );
    };
    // h_max = 1e6 µm.
    one_line(
        HeightField::load_source("builtin:sinusoidal", None, Some(1e6)).unwrap_err(),
        "±1000 µm",
    );
    // One .f32 sample of 1e30.
    let mut h = vec![0.1; 64];
    h[9] = 1e30;
    one_line(
        HeightField::new(8, 8, 0.05, h).unwrap_err(),
        "column 1, row 1",
    );
    // dH = 1e-300 and 1e-20 µm (the latter gave ρ ≠ 0 off specular).
    for dh in [1e-300, 1e-20, 1e-10] {
        one_line(HeightField::new(8, 8, dh, vec![0.1; 64]).unwrap_err(), "dH");
    }
    // coherence = 1e308 µm.
    let m = Material {
        coherence_um: 1e308,
        ..Material::default()
    };
    one_line(m.validate().unwrap_err(), "coherence");
    // Explicit Taylor T that float32 cannot hold (terms reach max|h − mean|^T).
    let tall = Material {
        heightfield: "builtin:sinusoidal".into(),
        h_max_um: Some(600.0),
        expansion: Expansion::Taylor,
        terms: Terms::Fixed(20),
        ..Material::default()
    };
    one_line(
        tall.prepare(None, &diffract::report::Stderr).unwrap_err(),
        "overflows float32",
    );
}

#[test]
fn why_smallest_pixel_size_gives_zero_off_specular_in_model_and_reference() {
    // At the smallest accepted dH the patch is far below a wavelength: only the specular
    // order propagates, so ρ off specular is 0.
    let n = 16;
    let h: Vec<f64> = (0..n * n)
        .map(|i| 0.05 * ((i % n) as f64 * 0.7).sin())
        .collect();
    let hf = HeightField::new(n, n, diffract::heightfield::MIN_DH_UM, h).unwrap();
    let m = Material::default();
    // float32 could not resolve this 2e-5-texel window: the GPU planner refuses it.
    let e = m
        .plan(&hf, &Reach::ALL, Precision::F32)
        .unwrap_err()
        .to_string();
    assert!(e.contains("larger patch"), "{e}");
    let plan = m.plan(&hf, &Reach::ALL, Precision::F64).unwrap();
    let p = m
        .prepare_planned(hf.clone(), plan, None, &diffract::report::Stderr)
        .unwrap();
    let wi = direction(30.0, 0.0);
    for t in [0.0, 10.0, 50.0] {
        let wr = direction(t, 180.0);
        let a = model::rho(
            p.stack.get().unwrap(),
            p.terms(),
            &p.window,
            &p.shading,
            wi,
            wr,
            500.0,
        );
        let b = reference::rho(&hf, m.coherence_um, &p.shading, wi, wr, 500.0);
        assert!(a.abs() < 1e-12 && b.abs() < 1e-12, "θr = {t}: {a} {b}");
    }
    let spec = model::rho(
        p.stack.get().unwrap(),
        p.terms(),
        &p.window,
        &p.shading,
        wi,
        direction(30.0, 180.0),
        500.0,
    );
    let spec_ref = reference::rho(
        &hf,
        m.coherence_um,
        &p.shading,
        wi,
        direction(30.0, 180.0),
        500.0,
    );
    // All the light is in the specular order (|P̂|² = |mean e^{ikwh}|² < 1 on this field).
    assert!(
        spec > 0.1 && (spec - spec_ref).abs() < 1e-6,
        "specular {spec} vs {spec_ref}"
    );
}

#[test]
fn why_grazing_limit_is_continuous_at_exactly_90_degrees() {
    // Along the specular direction C = [R/R0]·S exactly (the geometric term is 1), with
    // R → 1 and S = 1 as θ → 90°: C → 1/R0 = 25 (n = 1.5) with Fresnel, 1 without.
    for (shading, limit) in [(Shading::default(), 25.0), (Shading::GEOMETRIC, 1.0)] {
        for phi in [0.0, 30.0, 90.0, 137.0] {
            let mut prev = None;
            for t in [89.9, 89.99, 89.999, 89.999_99, 90.0 - 1e-9, 90.0] {
                let c = gain(direction(t, phi), direction(t, phi + 180.0), &shading);
                let ct = t.to_radians().cos();
                // Schlick: R/R0 = 1 + (1/R0 − 1)(1 − cos θ)^5 ... within 6·cos θ of the limit.
                assert!(
                    (c - limit).abs() <= limit * 6.0 * ct + 1e-9,
                    "θ = {t}, φ = {phi}: C = {c}, limit {limit}"
                );
                if let Some(p) = prev {
                    assert!(c >= p - 1e-9 || limit == 1.0, "not monotone: {p} → {c}");
                }
                prev = Some(c);
            }
        }
    }
    // And ρ itself (model and reference) at exactly 90° on a flat field: the limit.
    let hf = HeightField::new(16, 16, 0.05, vec![0.2; 256]).unwrap();
    let m = Material {
        fresnel: false,
        shadowing: false,
        ..Material::default()
    };
    let plan = m.plan(&hf, &Reach::ALL, Precision::F32).unwrap();
    let p = m
        .prepare_planned(hf.clone(), plan, None, &diffract::report::Stderr)
        .unwrap();
    let (wi, wr) = (direction(90.0, 0.0), direction(90.0, 180.0));
    let a = model::rho(
        p.stack.get().unwrap(),
        p.terms(),
        &p.window,
        &p.shading,
        wi,
        wr,
        500.0,
    );
    let b = reference::rho(&hf, m.coherence_um, &p.shading, wi, wr, 500.0);
    assert!((a - 1.0).abs() < 1e-9 && (b - 1.0).abs() < 1e-9, "{a} {b}");
}

/// `n × n` crop of `hf` from (0, 0) with an unlevelled-scan tilt of `seam_um` across x
/// (as AFM data often has), optionally transposed: its periodic extension has a seam.
fn crop(hf: &HeightField, n: usize, seam_um: f64, transpose: bool) -> HeightField {
    let mut h = Vec::with_capacity(n * n);
    for r in 0..n {
        for c in 0..n {
            let v = hf.at(c as i64, r as i64) + seam_um * c as f64 / n as f64;
            h.push(v);
        }
    }
    if transpose {
        h = (0..n * n).map(|i| h[(i % n) * n + i / n]).collect();
    }
    HeightField::new(n, n, hf.dh_um(), h).unwrap()
}

/// The old rule on a scan: the peak nearest to specular above 5% of the strongest, outside
/// the lobe; the period it implies per wavelength.
fn old_rule(r: &diffract::eval::GratingReport) -> Vec<f64> {
    let si = r.theta_i_deg.to_radians().sin();
    r.rho
        .iter()
        .zip(&r.lambdas_nm)
        .filter_map(|(rho, l)| {
            let u = |k: usize| (si + r.thetas_deg[k].to_radians().sin()).abs();
            let lobe = (10.0 * l * 1e-3 / (2.0 * std::f64::consts::PI * 65.0 / 4.0)).max(0.05);
            let peaks: Vec<usize> = (1..rho.len() - 1)
                .filter(|&k| u(k) > lobe && rho[k] > rho[k - 1] && rho[k] >= rho[k + 1])
                .collect();
            let top = peaks.iter().map(|&k| rho[k]).fold(0.0, f64::max);
            peaks
                .iter()
                .filter(|&&k| rho[k] >= 0.05 * top)
                .map(|&k| u(k))
                .min_by(f64::total_cmp)
                .map(|uk| l / uk)
        })
        .collect()
}

#[test]
fn why_grating_experiment_finds_the_ridge_period_on_a_non_tiling_crop_in_x_and_y() {
    // An irregular Elaphe-like field (finger-like ridges), cropped to 99² samples (9.1 µm,
    // 8.02 ridge periods) with a 0.1 µm unlevelled-scan tilt: its periodic extension has a
    // seam, so the crop is a grating of its own period whose first order is bright. The old
    // rule (first peak above 5% of the strongest) reported that crop period; the thesis's
    // rule (peak reflectance away from the specular lobe) reports the ridge period. In x
    // (ridges along y, azimuth 0) and in y (the crop transposed, azimuth 90°).
    let spec = GratingSpec::default_for(GratingKind::Elaphe);
    let truth_nm = spec.waves().unwrap().0.period_um * 1e3;
    let full = diffract::heightfield::generate(&spec).unwrap();
    let m = Material {
        window_radius: 3,
        ..Material::default()
    };
    // 0.1 µm over 9.1 µm (a 0.6° tilt): the crop's first order is then bright enough for
    // the old rule (≥ 5%) and stays below the 20% a sub-harmonic needs to be read as the
    // first order (at 0.2 µm the seam's orders outshine that share and the rule fails).
    let seam = 0.1;
    for (transpose, azimuth) in [(false, 0.0), (true, 90.0)] {
        let hf = crop(&full, 99, seam, transpose);
        let crop_nm = 99.0 * hf.dh_um() * 1e3;
        let plan = m.plan(&hf, &Reach::brdf_map(75.0), Precision::F64).unwrap();
        let p = m
            .prepare_planned(hf, plan, None, &diffract::report::Stderr)
            .unwrap();
        let r = diffract::eval::grating_equation(
            &p,
            75.0,
            azimuth,
            &[450.0, 550.0, 650.0, 700.0],
            0.02,
        )
        .unwrap();
        let old = old_rule(&r);
        println!(
            "azimuth {azimuth}: mean {:.1} nm (ridge {truth_nm:.1}, crop {crop_nm:.0}), variance {:.2}; old rule {old:?}",
            r.mean_nm, r.variance_nm2
        );
        assert!(
            old.iter().any(|d| (d - truth_nm).abs() > 0.5 * truth_nm),
            "the old rule would have found the ridge here: {old:?}"
        );
        assert_eq!(r.samples.len(), 4);
        assert!(
            (r.mean_nm - truth_nm).abs() < 0.01 * truth_nm,
            "azimuth {azimuth}: {} vs {truth_nm}",
            r.mean_nm
        );
        if azimuth == 0.0 {
            let dir = std::env::temp_dir().join(format!("diffract-eval-{}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            let png = dir.join("grating.png");
            diffract::eval::write_plot(&r, &png).unwrap();
            assert!(std::fs::metadata(&png).unwrap().len() > 1000);
            std::fs::remove_dir_all(&dir).ok();
        }
    }
}

/// A reduced matrix on the 128² sinusoid: 4 heights × 3 angles × 2 wavelengths × both
/// expansions × auto and T = 30, f64 model and (where Vulkan exists) the GPU.
fn reduced(evaluators: Vec<Evaluator>) -> MatrixSpec {
    let (field, period) = stability::default_field().unwrap();
    let mut s = MatrixSpec::full(field, "sinusoid", Some(period));
    s.h_max_um = vec![0.05, 0.5, 2.0, 5.0];
    s.theta_i_deg = vec![0.0, 80.0, 89.99];
    s.lambdas_nm = vec![380.0, 780.0];
    s.evaluators = evaluators;
    s.map_size = 9;
    s.validation = true;
    s
}

#[test]
fn automatic_terms_meet_the_tolerance_against_the_reference_across_the_matrix() {
    let spec = reduced(vec![Evaluator::Model]);
    let cells = stability::run_matrix(&spec, None, |_| {}).unwrap();
    for line in stability::summary(&spec, &cells) {
        println!("{line}");
    }
    let mut refused = 0;
    for c in &cells {
        assert_ne!(c.status, Status::Fail, "{c:?}");
        if c.terms_mode == Terms::Auto {
            match c.status {
                Status::Refused => refused += 1,
                _ => {
                    let e = c.error.unwrap();
                    assert!(e <= spec.tolerance, "auto T above tolerance: {c:?}");
                }
            }
        }
    }
    // The 5 µm field at full reach is beyond 64 Chebyshev terms; nothing else is.
    assert!(refused > 0);
    assert!(cells
        .iter()
        .filter(|c| c.status == Status::Refused)
        .all(|c| c.h_max_um == 5.0));
    // The old default (Taylor, T = 30) is warned about where it is wrong.
    assert!(cells.iter().any(|c| c.terms_mode == Terms::Fixed(30)
        && c.expansion == Expansion::Taylor
        && c.status == Status::Warned
        && c.error.unwrap() > 1.0));
}

#[test]
fn gpu_stays_within_the_float32_bound_of_its_model_in_every_non_refused_cell() {
    let Some(mut r) = gpu_util::renderer() else {
        return;
    };
    let mut spec = reduced(vec![Evaluator::Gpu]);
    spec.h_max_um = vec![0.05, 0.5, 2.0];
    spec.terms_modes = vec![Terms::Auto];
    let cells = stability::run_matrix(&spec, Some(&mut r), |_| {}).unwrap();
    gpu_util::assert_no_validation(&r);
    for c in &cells {
        println!(
            "h {} θi {} λ {} {}: used {:?} {} error {:?} f32 {:?} ≤ {:?}",
            c.h_max_um,
            c.theta_i_deg,
            c.lambda_nm,
            c.expansion,
            c.used,
            c.status,
            c.error,
            c.f32_error,
            c.f32_bound
        );
        assert_ne!(c.status, Status::Refused, "{c:?}");
        let (e, b) = (c.f32_error.unwrap(), c.f32_bound.unwrap());
        assert!(e.is_finite() && e <= b, "GPU off its f64 model: {c:?}");
        assert!(
            c.error.unwrap() <= spec.tolerance,
            "GPU off the reference: {c:?}"
        );
        assert_ne!(c.status, Status::Fail, "{c:?}");
    }
}

#[test]
fn cli_refuses_and_warns_on_one_line() {
    let dir = std::env::temp_dir().join(format!("diffract-stab-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let q = dir.join("q.csv");
    std::fs::write(
        &q,
        "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm\n60,0,60,180,500\n",
    )
    .unwrap();
    let out = dir.join("r.csv");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "brdf",
            "--queries",
            q.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--method",
            "model",
            "--no-cache",
            "--heightfield",
            "builtin:sinusoidal",
        ];
        args.extend_from_slice(extra);
        std::process::Command::new(env!("CARGO_BIN_EXE_diffract"))
            .args(&args)
            .output()
            .unwrap()
    };
    for (extra, want) in [
        (&["--hmax-um", "1e6"][..], "±1000 µm"),
        (&["--hmax-um", "5"][..], "no supported expansion"),
        (&["--coherence-um", "1e308"][..], "coherence"),
    ] {
        let o = run(extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{extra:?}");
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.starts_with("error: ") && err.contains(want), "{err}");
        assert!(!err.contains("panicked"));
    }
    let o = run(&["--hmax-um", "2", "--expansion", "taylor", "--terms", "30"]);
    assert!(o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("warning: --terms 30 with taylor: expected error"),
        "{err}"
    );
    let o = run(&["--hmax-um", "2", "--expansion", "taylor"]);
    assert!(o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("warning: taylor cannot meet the tolerance"),
        "{err}"
    );
    let csv = std::fs::read_to_string(&out).unwrap();
    assert!(!csv.contains("inf") && !csv.contains("NaN"), "{csv}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Regular rounded ridges (Xenopeltis-like) of period `d_um` and height `h_um`, `n²`
/// samples of `dh_um`, with a faint deterministic roughness as a scan would have.
fn ridges(n: usize, dh_um: f64, d_um: f64, h_um: f64) -> HeightField {
    let tau = 2.0 * std::f64::consts::PI;
    let mut s = 0x9e37_79b9_u64;
    let h = (0..n * n)
        .map(|i| {
            let x = (i % n) as f64 * dh_um;
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = ((s >> 40) as f64 / (1u64 << 24) as f64 - 0.5) * 0.02 * h_um;
            h_um * (0.5 + 0.5 * (tau * x / d_um).cos()).powi(2) + noise
        })
        .collect();
    HeightField::new(n, n, dh_um, h).unwrap()
}

#[test]
fn grating_experiment_finds_the_ridge_period_on_whole_and_fractional_crops() {
    // 100 samples holding exactly 10 periods of 900 nm: the crop's orders (|u| = jλ/L) fall
    // on the ridge's at j = 10m, and the sub-harmonic rule alone took the crop's first order
    // (9 000 nm) for the grating's. 100 samples of 83.7 nm hold 9.3 periods instead. The
    // height field's spectrum finds 900 nm within 1% on both, tall and shallow.
    let d_um = 0.9;
    let m = Material {
        window_radius: 3,
        ..Material::default()
    };
    for (dh, what) in [(0.09, "whole (10 periods)"), (0.0837, "fractional (9.3)")] {
        for h in [0.06, 0.6] {
            let hf = ridges(100, dh, d_um, h);
            let found = diffract::eval::ridge_period_um(&hf, 0.0).expect("a ridge period");
            assert!(
                (found - d_um).abs() < 0.01 * d_um,
                "{what}, h {h}: spectrum says {found}"
            );
            assert!(diffract::eval::ridge_period_um(&hf, 30.0).is_none());
            let plan = m.plan(&hf, &Reach::brdf_map(75.0), Precision::F64).unwrap();
            let p = m
                .prepare_planned(hf, plan, None, &diffract::report::Stderr)
                .unwrap();
            let r = diffract::eval::grating_equation(&p, 75.0, 0.0, &[450.0, 550.0, 650.0], 0.02)
                .unwrap();
            println!(
                "{what}, h {h} µm: mean {:.1} nm, variance {:.2} nm²",
                r.mean_nm, r.variance_nm2
            );
            assert_eq!(r.samples.len(), 3);
            let spectrum_nm = r.ridge_period_nm.expect("the spectrum's period");
            assert!((spectrum_nm - 900.0).abs() < 9.0, "{what}: {spectrum_nm}");
            // The reflectance of a crop sits on the crop's own orders jλ/L: a whole number
            // of periods puts the ridge's first order on one (j = 10), a fractional number
            // between two, where the experiment reads the nearest, L/9 = 930 nm for 9.3
            // periods (the crop, not the method, limits it: half a bin is d²/2L = 4.8%).
            let length_nm = 100.0 * dh * 1e3;
            let nearest = length_nm / (length_nm / 900.0).round();
            assert!(
                (r.mean_nm - nearest).abs() < 0.01 * nearest,
                "{what}, h {h} µm: {} nm (nearest crop order {nearest} nm)",
                r.mean_nm
            );
            assert!((r.mean_nm - 900.0).abs() < 9.0 || dh != 0.09);
        }
    }
}

#[test]
fn table_variants_on_narrow_regions_are_right_or_refused() {
    // A distant camera on a plane (narrow w) and thin strips of view (narrow u, narrow v):
    // every table variant evaluated in float32 as its shader does is within the tolerance
    // of the exact G there, or refused.
    let (field, period) = stability::default_field().unwrap();
    let mut spec = MatrixSpec::full(field, "sinusoid", Some(period));
    spec.h_max_um = vec![0.25, 1.0];
    let cells = stability::run_table_cases(&spec).unwrap();
    println!("{}", stability::table_cases_markdown(&spec, &cells));
    assert_eq!(cells.len(), 2 * 3 * 3);
    for c in &cells {
        // The regions hold the first order: the errors are of a real signal.
        assert!(c.peak > 1e-3, "{c:?}");
        assert_ne!(c.status, Status::Fail, "{c:?}");
        if c.status == Status::Refused {
            assert!(c.message.contains("expected error"), "{c:?}");
        }
    }
    // The narrow w interval is where mapped powers are stable: dhillon draws there.
    assert!(cells
        .iter()
        .filter(|c| c.case == "narrow w" && c.variant.name() == "dhillon")
        .all(|c| c.status == Status::Pass));
}

/// `diffract stability` on the command line: the axes it is given, a time budget whose
/// left-out cells are reported (each with its estimated cost, none dropped), and the model
/// axis (the scalar model against the rigorous solver) in its own CSV and section.
#[test]
fn the_command_reports_skipped_cells_and_the_model_axis() {
    let dir = std::env::temp_dir().join(format!("diffract-stab-budget-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let run = |out: &str, extra: &[&str]| {
        let out = dir.join(out);
        let mut args = vec!["stability", "--no-gpu", "-o", out.to_str().unwrap()];
        args.extend_from_slice(extra);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_diffract"))
            .args(&args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr).to_string();
        assert!(o.status.success(), "{err}");
        assert!(!err.contains("panicked"), "{err}");
        let read = |f: &str| std::fs::read_to_string(out.join(f)).unwrap();
        (
            read("stability.csv"),
            read("stability-model.csv"),
            read("stability.md"),
            err,
        )
    };

    // Every axis given, no budget pressure: the model axis solves the normal-incidence cells
    // of a shallow sinusoid (period 2.8 wavelengths: scalar theory holds) and refuses the
    // grazing one, which is beyond the rigorous solver.
    let axes = [
        "--hmax-um",
        "0.05",
        "--theta-i",
        "0",
        "89.99",
        "--lambda-nm",
        "580",
    ];
    let (csv, model, md, err) = run("axes", &axes);
    assert_eq!(csv.lines().count() - 1, 8, "{csv}");
    assert!(!csv.contains(",skipped,"), "{csv}");
    let rows: Vec<&str> = model.lines().skip(1).collect();
    assert_eq!(rows.len(), 2, "{model}");
    let normal: Vec<&str> = rows[0].split(',').collect();
    let e: f64 = normal[3].parse().unwrap();
    assert!(normal[..3] == ["0.05", "0", "580"] && e < 0.1, "{model}");
    assert!(rows[1].contains("beyond the rigorous solver"), "{model}");
    assert!(
        md.contains("## The model against Maxwell's equations"),
        "{md}"
    );
    assert!(
        err.contains("stability: model h_max 0.05 µm, θi 0°, λ 580 nm"),
        "{err}"
    );

    // The default axes on a budget of one second: the cells past it are in the CSV as
    // skipped, with their estimate, and the header counts them.
    let (csv, model, md, err) = run("budget", &["--budget-s", "1"]);
    let cells = 3 * 3 * 2 * 2 * 2;
    assert_eq!(csv.lines().count() - 1, cells, "{csv}");
    let skipped = csv.lines().filter(|l| l.contains(",skipped,")).count();
    assert!(skipped > 0, "{csv}");
    assert!(
        csv.lines()
            .filter(|l| l.contains(",skipped,"))
            .all(|l| l.contains("over the time budget: estimated")),
        "{csv}"
    );
    assert!(
        md.contains(&format!("{skipped} skipped by the 1 s budget")),
        "{md}"
    );
    assert_eq!(model.lines().count() - 1, 18, "{model}");
    assert!(model.contains("over the time budget"), "{model}");
    assert!(
        err.contains(&format!("stability: {cells}/{cells} cells")),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The lighting cases on the device: a sun hidden in an HDR sky, a grazing environment and
/// a black map with one pixel, each drawn by every variant that can be lit by an
/// environment against the f64 quadrature (MIS at the default 256 samples within 5 % of
/// every lit pixel's Y).
#[test]
fn lighting_cases_meet_their_bound_on_the_device() {
    let Some(mut renderer) = gpu_util::renderer() else {
        return;
    };
    let cells = stability::lighting::run(&mut renderer).unwrap();
    let variants = stability::lighting::lit_variants();
    assert!(variants.len() >= 6, "{variants:?}");
    assert_eq!(cells.len(), 3 * variants.len());
    for c in &cells {
        eprintln!("{c:?}");
        // nmm and pq need a period, which the flat patch does not have.
        if c.status == Status::Refused && ["nmm", "pq"].contains(&c.variant) {
            assert!(c.message.contains("period"), "{c:?}");
            continue;
        }
        assert_eq!(c.status, Status::Pass, "{c:?}");
        assert!(c.lit > 0 && c.quadrature < 0.02, "{c:?}");
    }
    assert_eq!(renderer.validation_messages(), 0);
}
