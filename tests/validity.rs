//! The rigorous check of the scalar model (MODEL §11): the RCWA solver's own correctness
//! (Fresnel, energy, convergence are unit tests in `brdf::rcwa`), its agreement with the
//! scalar model where that model must hold (flat surfaces, shallow gratings), the direction
//! of the orders in both, the scalar side's units against the model's own BRDF, and the
//! `diffract validity` command.

use std::process::{Command, Output};

use diffract::brdf::rcwa::{self, Grating, Pair};
use diffract::brdf::Shading;
use diffract::spectrum::num_complex::Complex64;
use diffract::validity::{self, Profile, ScalarModel, Solve};

fn model(ior: f64) -> ScalarModel {
    ScalarModel {
        shading: Shading {
            ior,
            ..Shading::default()
        },
        coherence_um: 65.0,
    }
}

fn profile(period_um: f64, f: impl Fn(f64) -> f64) -> Profile {
    let m = validity::PROFILE_BINS;
    Profile {
        period_um,
        direction_deg: 0.0,
        heights_um: (0..m).map(|b| f((b as f64 + 0.5) / m as f64)).collect(),
        explained: 1.0,
    }
}

fn sinusoid(period_um: f64, depth_um: f64) -> Profile {
    Profile::sinusoid(period_um, depth_um)
}

#[test]
fn flat_surface_gives_the_fresnel_reflectance_in_both_models() {
    let flat = profile(1.0, |_| 0.2);
    for n in [1.5, 1.55] {
        let m = model(n);
        // Normal incidence: the exact Fresnel R0 on both sides.
        let c = validity::check(&flat, &m, 550.0, 0.0, Solve::Converge(0.02)).unwrap();
        let r0 = ((n - 1.0) / (n + 1.0)).powi(2);
        let row = c.rows.iter().find(|r| r.m == 0).unwrap();
        assert!((row.eta_te - r0).abs() < 1e-12, "{}", row.eta_te);
        assert!((row.eta_tm - r0).abs() < 1e-12, "{}", row.eta_tm);
        // The scalar side integrates the gain over the lobe, where it is not exactly its
        // specular value: 1.5e-5 relative at n = 1.5.
        assert!(
            (row.eta_scalar - r0).abs() < 1e-4 * r0,
            "{}",
            row.eta_scalar
        );
        // Oblique: RCWA gives Fresnel's R_s and R_p, the scalar model its Schlick R (to the
        // gain's variation across the lobe: 4e-4 at 60°, 1 % at 80°).
        for t in [30.0f64, 60.0] {
            let c = validity::check(&flat, &m, 550.0, t, Solve::Converge(0.02)).unwrap();
            let row = c.rows.iter().find(|r| r.m == 0).unwrap();
            let (rs, rp) = rcwa::fresnel(Complex64::new(n, 0.0), t);
            assert!((row.eta_te - rs).abs() < 1e-12 && (row.eta_tm - rp).abs() < 1e-12);
            let schlick = r0 + (1.0 - r0) * (1.0 - t.to_radians().cos()).powi(5);
            assert!(
                (row.eta_scalar - schlick).abs() < 1e-3 * schlick,
                "θ {t}: {} vs {schlick}",
                row.eta_scalar
            );
            assert!((row.theta_r_deg + t).abs() < 1e-9, "specular at −θi");
        }
    }
}

#[test]
fn shallow_gratings_approach_the_scalar_ratios() {
    // Λ/λ = 5, normal incidence: the first-order ratio error is small for shallow gratings
    // (the external check: within 10 % for Λ/λ ≥ 2.6 and d/λ ≤ 0.3).
    let m = model(1.55);
    let mut errors = Vec::new();
    for depth_over_lambda in [0.3, 0.1, 0.02] {
        let g = sinusoid(5.0 * 0.5, depth_over_lambda * 0.5);
        let c = validity::check(&g, &m, 500.0, 0.0, Solve::Converge(0.01)).unwrap();
        let e = c
            .rows
            .iter()
            .find(|r| r.m == 1)
            .unwrap()
            .ratio_error
            .unwrap();
        println!("d/λ = {depth_over_lambda}: η+1/η0 error {e:.4}");
        errors.push(e);
    }
    assert!(errors[1] < 0.02 && errors[2] < 0.02, "{errors:?}");
}

#[test]
fn blazed_grating_puts_its_power_where_the_facets_face_in_both_models() {
    // builtin:blazed's sawtooth rises towards +x: its facets face −x, so at normal
    // incidence the bright orders are the negative ones (θr < 0).
    let g = profile(2.5, |t| 0.25 * t);
    let m = model(1.5);
    for lambda in [450.0, 550.0, 650.0] {
        let c = validity::check(&g, &m, lambda, 0.0, Solve::Converge(0.02)).unwrap();
        let eta = |m: i64, scalar: bool| {
            c.rows
                .iter()
                .find(|r| r.m == m)
                .map(|r| {
                    if scalar {
                        r.eta_scalar
                    } else {
                        r.eta_unpolarised
                    }
                })
                .unwrap()
        };
        for scalar in [false, true] {
            assert!(
                eta(-1, scalar) > 2.0 * eta(1, scalar),
                "λ {lambda} scalar {scalar}: η−1 {} η+1 {}",
                eta(-1, scalar),
                eta(1, scalar)
            );
        }
        let r = c.rows.iter().find(|r| r.m == -1).unwrap();
        assert!(r.theta_r_deg < 0.0);
    }
}

#[test]
fn orders_lie_where_the_brdf_puts_them_with_the_same_power() {
    // The model's own BRDF on the real 2-D field, at each order's centre: ρ·R0 is the
    // order's power per lobe (the lobe is the window's, as for a flat mirror), so it must
    // match η_scalar of the extracted 1-D profile; and the brighter of ±1 must be the same
    // side as RCWA's.
    use diffract::brdf::truncation::{Precision, Reach};
    // The sawtooth's field holds 27 samples a period, which the model transforms as points
    // and the profile joins linearly: 3 % on its first order.
    for (source, tolerance) in [("builtin:blazed", 0.05), ("builtin:sinusoidal", 0.01)] {
        let material = diffract::material::Material {
            heightfield: source.into(),
            ..Default::default()
        };
        let p = material
            .prepare_for(
                None,
                &Reach::brdf_map(0.0),
                Precision::F64,
                &diffract::report::Stderr,
            )
            .unwrap();
        let prof = validity::extract_profile(&p.heightfield).unwrap();
        // The sawtooth's jump is smeared over one of the profile's 64 bins.
        assert!(prof.explained > 0.97, "{source}: {}", prof.explained);
        let sm = ScalarModel::of(&material);
        let lambda = 550.0;
        let c = validity::check(&prof, &sm, lambda, 0.0, Solve::Converge(0.02)).unwrap();
        let r0 = diffract::brdf::schlick_r0(material.ior);
        let stack = p.load_terms(&diffract::report::Stderr).unwrap();
        // Orders with at least 5 % of the brightest's power: a weak order of the sawtooth
        // depends on how its jump is sampled (the field's 27 samples a period against the
        // profile's 64 bins), 35 % for η−2 of builtin:blazed at 550 nm.
        let brightest = c.rows.iter().map(|r| r.eta_scalar).fold(0.0, f64::max);
        for row in c
            .rows
            .iter()
            .filter(|r| r.m.abs() <= 2 && r.eta_scalar >= 0.05 * brightest)
        {
            let s = (row.theta_r_deg.to_radians()).sin();
            // Direction of order m: x along the grating vector (here +x), light from +x.
            let wr = [s, 0.0, (1.0 - s * s).sqrt()];
            let rho = diffract::brdf::model::rho(
                stack,
                p.terms(),
                &p.window,
                &p.shading,
                [0.0, 0.0, 1.0],
                wr,
                lambda,
            );
            let rel = (r0 * rho - row.eta_scalar).abs() / row.eta_scalar.max(1e-6);
            println!(
                "{source} m {}: ρ·R0 {:.4e} η_scalar {:.4e}",
                row.m,
                r0 * rho,
                row.eta_scalar
            );
            assert!(
                rel < tolerance,
                "{source} m {}: ρR0 {} vs {}",
                row.m,
                r0 * rho,
                row.eta_scalar
            );
        }
        if source == "builtin:blazed" {
            let e = |m: i64| c.rows.iter().find(|r| r.m == m).unwrap();
            assert!(e(-1).eta_unpolarised > e(1).eta_unpolarised);
            assert!(e(-1).eta_scalar > e(1).eta_scalar);
        }
    }
}

#[test]
fn reciprocity_holds_for_an_asymmetric_grating() {
    // η_m(θi) = η_m(θi' = θr,m) for both polarisations (the reciprocity theorem of
    // gratings): a check on the orders' bookkeeping that energy conservation cannot make.
    // The truncated series holds it to the truncation error (the reciprocal incidence
    // keeps a different window of harmonics): 5e-4 relative at 51 orders.
    let g = Grating {
        period_um: 1.2,
        profile_um: (0..64).map(|j| 0.3 * j as f64 / 64.0).collect(),
        index: Complex64::new(1.55, 0.0),
    };
    let (lambda, theta) = (0.5, 20.0);
    let a = Pair::solve(&g, lambda, theta, 25, 32).unwrap();
    for o in a.te.reflected.iter().filter(|o| o.m != 0) {
        let back = o.sin_theta.asin().to_degrees();
        let b = Pair::solve(&g, lambda, back, 25, 32).unwrap();
        for (x, y) in [(&a.te, &b.te), (&a.tm, &b.tm)] {
            let (e1, e2) = (x.eta_r(o.m), y.eta_r(o.m));
            assert!((e1 - e2).abs() < 2e-3 * e1, "m {}: {e1} vs {e2}", o.m);
        }
    }
}

fn diffract(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_diffract"))
        .args(args)
        .env("DIFFRACT_CACHE", "")
        .output()
        .expect("run diffract")
}

#[test]
fn validity_runs_on_the_default_material_and_writes_csv() {
    let dir = std::env::temp_dir().join(format!("diffract-validity-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("orders.csv");
    let o = diffract(&[
        "validity",
        "--lambda-nm",
        "550",
        "--theta-i",
        "0",
        "--theta-i",
        "60",
        "--csv",
        csv.to_str().unwrap(),
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        out.contains("builtin:elaphe") && out.contains("explains"),
        "{out}"
    );
    assert_eq!(out.matches("overall: ").count(), 2, "{out}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let header = text.lines().next().unwrap();
    for col in [
        "m",
        "theta_r_deg",
        "eta_te",
        "eta_tm",
        "eta_unpolarised",
        "eta_scalar",
    ] {
        assert!(header.split(',').any(|c| c == col), "{header}");
    }
    assert!(text.lines().count() > 4);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_gets_one_error_line() {
    for (args, needle) in [
        (vec!["validity", "--theta-i", "95"], "theta-i"),
        (vec!["validity", "--lambda-nm", "-3"], "lambda-nm"),
        (vec!["validity", "--ior", "0.5"], "1 ≤ n ≤ 4"),
        (
            vec!["validity", "--heightfield", "/nonexistent/h.png"],
            "h.png",
        ),
        (vec!["validity", "--rcwa-tolerance", "0"], "rcwa-tolerance"),
    ] {
        let o = diffract(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(lines.len(), 1, "{args:?}: {err}");
        assert!(
            lines[0].starts_with("error: ") && lines[0].contains(needle),
            "{err}"
        );
    }
}

/// The limits table (`diffract validity --limits`, docs/accuracy.md) on two of its cells: a
/// shallow long-period sinusoid where scalar theory holds, a deep one where it does not, as
/// one Markdown table whose cells are the checks' own errors.
#[test]
fn limits_table_sorts_shallow_from_deep_gratings() {
    let m = model(1.55);
    let mut cells = 0;
    let table =
        validity::limits_table(&m, 500.0, &[0.0], &[5.0], &[0.05, 1.0], 0.02, || cells += 1)
            .unwrap();
    assert_eq!(cells, 2);
    let shallow = validity::check(&sinusoid(2.5, 0.025), &m, 500.0, 0.0, Solve::Converge(0.02))
        .unwrap()
        .error;
    let deep = validity::check(&sinusoid(2.5, 0.5), &m, 500.0, 0.0, Solve::Converge(0.02))
        .unwrap()
        .error;
    assert!(shallow < 0.05, "shallow {shallow}");
    assert!(deep > 0.1, "deep {deep}");
    let row = format!(
        "| 5 | {} | {} |",
        validity::percent(shallow),
        validity::percent(deep)
    );
    assert!(table.contains(&row), "{table}\nwants {row}");
    assert!(table.contains("| Λ/λ \\ d/λ | 0.05 | 1 |"), "{table}");

    // On the command line it prints to stdout and takes no output files.
    let out = diffract(&["validity", "--limits", "--csv", "x.csv"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("--limits"), "{err}");
}

/// A field of `n`² samples `dh` apart with heights `f(x, y)` (µm).
fn field(n: usize, dh: f64, f: impl Fn(f64, f64) -> f64) -> diffract::heightfield::HeightField {
    let h = (0..n * n)
        .map(|i| f((i % n) as f64 * dh, (i / n) as f64 * dh))
        .collect();
    diffract::heightfield::HeightField::new(n, n, dh, h).unwrap()
}

#[test]
fn the_model_check_names_a_tilt_instead_of_solving_it() {
    use diffract::validity::ModelCheck;
    // An unlevelled tilt over 12.8 µm: its strongest "period" below 10 µm is the ramp's.
    let tilt = field(128, 0.1, |x, y| 0.02 * x + 0.01 * y);
    let m = diffract::material::Material::default();
    let line =
        ModelCheck::start(m, tilt, vec![0.0], None).finish(std::time::Duration::from_secs(120));
    assert!(
        line.contains("a tilt, a bow or the seam of its tiled edges, not ridges"),
        "{line}"
    );
}

#[test]
fn the_model_check_is_cached_per_field_and_waits_no_longer_than_asked() {
    use diffract::validity::ModelCheck;
    use std::time::Duration;
    let dir = std::env::temp_dir().join(format!("diffract-check-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    // Ten periods of a shallow 1.28 µm sinusoid: ridges the rigorous solver speaks for.
    let tau = std::f64::consts::TAU;
    let ridges = field(64, 0.2, |x, _| 0.05 * (tau * x / 1.28).sin());
    let m = diffract::material::Material::default();
    let start = || ModelCheck::start(m.clone(), ridges.clone(), vec![0.0], Some(dir.clone()));
    let cut = start().finish(Duration::ZERO);
    assert!(cut.contains("not finished within 0.0 s"), "{cut}");
    let full = start().finish(Duration::from_secs(300));
    assert!(
        full.starts_with("model check: scalar order ratios") && full.contains("1.280 µm ridges"),
        "{full}"
    );
    // The line itself is cached: the next check of the same field and angles reads it.
    let cached = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .filter_map(|e| std::fs::read_to_string(e.path()).ok())
        .any(|t| t.starts_with("# diffract model check\n") && t.contains(&full));
    assert!(cached, "no cached line in {}", dir.display());
    assert_eq!(start().finish(Duration::from_secs(300)), full);
    // Another angle is another line.
    let other = ModelCheck::start(m.clone(), ridges.clone(), vec![60.0], Some(dir.clone()))
        .finish(Duration::from_secs(300));
    assert!(other.contains("θi ≈ 60°"), "{other}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_unconverged_cell_of_the_limits_table_shows_its_estimated_error() {
    // A 2.5 µm sinusoid 0.2 µm deep at 450 nm and 30°: the solver's 128 slices leave a
    // change of about 3 % in its orders, above a 2 % tolerance.
    let m = model(1.5);
    let (period, depth) = (2.5 / 0.45, 0.2 / 0.45);
    let table =
        validity::limits_table(&m, 450.0, &[30.0], &[period], &[depth], 0.02, || {}).unwrap();
    assert!(
        table.contains("unconverged") && table.contains("(±"),
        "{table}"
    );
    // Converged at a looser tolerance: the plain figure.
    let loose =
        validity::limits_table(&m, 450.0, &[30.0], &[period], &[depth], 0.1, || {}).unwrap();
    assert!(!loose.contains("unconverged"), "{loose}");
}
