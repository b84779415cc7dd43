//! Variant profiling on lavapipe: every variant is timed and scored against the f64
//! reference and its own f64 model; the numbers must rank the variants the way the physics
//! says (thesis R = 1 worse than R = 3; compact storage worse than RG32F against the model).

mod gpu_util;

use diffract::heightfield::HeightField;
use diffract::material::Material;
use diffract::profile::{flss_variants, profile, table_variants, Frames, ProfileSetup};
use diffract::render::TableOptions;

#[test]
fn variants_report_error_and_time() {
    let Some(mut r) = gpu_util::renderer() else {
        return;
    };
    // A 65 µm patch (so the window spans ~0.6 texels and R matters) at a coarse dH keeps
    // the 1 nm reference cheap: 260² samples.
    let dir = std::env::temp_dir().join(format!("diffract-profile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("field.png");
    let n = 260;
    let dh = 0.25;
    let tau = 2.0 * std::f64::consts::PI;
    let h = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f64 * dh, (i / n) as f64 * dh);
            0.12 * (1.0 + (tau * x / 1.5).sin()) + 0.04 * (1.0 + (tau * (x + 2.0 * y) / 12.0).cos())
        })
        .collect();
    HeightField::new(n, n, dh, h).unwrap().save(&path).unwrap();
    let setup = ProfileSetup {
        base: Material {
            heightfield: path.to_string_lossy().into_owned(),
            ..Material::default()
        },
        // pq refuses this field (two incommensurate waves); tests/gpu_pq.rs covers it.
        variants: flss_variants(12)
            .into_iter()
            .filter(|v| v.kind != diffract::render::VariantKind::Pq)
            .chain(table_variants(&TableOptions {
                texel_uv: Some(0.02),
                step_nm: Some(20),
                ..TableOptions::default()
            }))
            .collect(),
        theta_i_deg: 50.0,
        phi_i_deg: 0.0,
        size: 32,
        pixels: 4,
        brightest: 4,
        frames: Frames::Fixed(1),
        mesh: None,
        per_vertex: false,
        cache_dir: None,
    };
    let run = profile(&mut r, &setup).unwrap();
    gpu_util::assert_no_validation(&r);
    println!(
        "{}",
        diffract::profile::format_table(r.device_name(), &setup, &run)
    );
    assert!(run.skipped.is_empty(), "{:?}", run.skipped);
    let reports = &run.reports;
    assert_eq!(reports.len(), setup.variants.len());
    // This map holds the grating's orders: the reference is not dark, and the table
    // variants' overshoot below zero (before the clamp) is reported.
    assert!(reports.iter().all(|r| !r.reference_dark));
    for rep in reports.iter().filter(|r| {
        r.variant.kind != diffract::render::VariantKind::Flss
            && r.variant.kind != diffract::render::VariantKind::Nmm
    }) {
        let o = rep
            .overshoot
            .expect("table variants report their overshoot");
        assert!((-1.0..=0.0).contains(&o), "{}: {o}", rep.variant.name);
    }
    assert!(reports
        .iter()
        .any(|r| r.variant.name == "taylor R=2 keep-all" && !r.variant.leave_out));
    for rep in reports {
        assert!(rep.wall_ms > 0.0 && rep.gpu_ms.is_none_or(|g| g > 0.0));
        assert_eq!(rep.frames, 1);
        let i = rep.intervals.rel_l2;
        assert!(i.lo <= rep.vs_reference.rel_l2 && rep.vs_reference.rel_l2 <= i.hi);
        for e in [rep.vs_reference, rep.vs_model] {
            assert!(e.rel_l2.is_finite() && e.max_de.is_finite() && e.mean_de <= e.max_de);
            assert!(e.p50_de <= e.p99_de && e.p99_de <= e.max_de);
        }
        assert!(rep.build_ms > 0.0 && rep.gpu_bytes > 0 && rep.fetches > 0);
    }
    // The stable table representations reproduce their f64 tables in float32.
    for name in ["chebyshev-w", "chebyshev-w 5nm", "volume"] {
        assert!(by_name(reports, name).vs_model.rel_l2 < 1e-4, "{name}");
    }
    assert!(
        by_name(reports, "volume rgba16f").vs_model.rel_l2
            > by_name(reports, "volume").vs_model.rel_l2
    );
    let csv = diffract::profile::format_csv(&run);
    assert_eq!(csv.lines().count(), reports.len() + 1);
    assert!(csv.starts_with(
        "variant,expansion,terms,window_radius,lambda_step_nm,storage,gpu_ms,wall_ms,rel_l2_ref"
    ));
    let by = |name: &str| by_name(reports, name);
    // float32 RG32F tracks its own f64 model closely; the compact formats less so.
    assert!(
        by("taylor R=2").vs_model.rel_l2 < 1e-3,
        "{:?}",
        by("taylor R=2").vs_model
    );
    assert!(by("taylor R=2 unorm16").vs_model.rel_l2 >= by("taylor R=2").vs_model.rel_l2);
    // The thesis window is the least accurate against the reference.
    assert!(
        by("thesis: taylor R=1").vs_reference.rel_l2 > by("taylor R=3").vs_reference.rel_l2,
        "R=1 {:?} vs R=3 {:?}",
        by("thesis: taylor R=1").vs_reference,
        by("taylor R=3").vs_reference
    );
    // With a 65 µm coherence window the spectral lines are a few nm wide: the wavelength
    // step dominates the error against the 1 nm reference.
    assert!(by("taylor R=2 10nm").vs_reference.rel_l2 > by("taylor R=2").vs_reference.rel_l2);
    assert!(by("taylor R=2 1nm").vs_reference.rel_l2 < 0.5 * by("taylor R=2").vs_reference.rel_l2);
    let _ = std::fs::remove_dir_all(dir);
}

fn by_name<'a>(
    reports: &'a [diffract::profile::VariantReport],
    name: &str,
) -> &'a diffract::profile::VariantReport {
    reports
        .iter()
        .find(|r| r.variant.name == name)
        .unwrap_or_else(|| panic!("no variant {name}"))
}

/// A map too small to meet the blazed grating's lobes is dark: `profile` says so in its
/// table and CSV, and refuses to plot ratios of noise (one error line, non-zero exit, no
/// plot file); the CSV it wrote before stays.
#[test]
fn a_dark_map_is_not_plotted() {
    let dir = std::env::temp_dir().join(format!("diffract-profile-dark-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (csv, png) = (dir.join("p.csv"), dir.join("p.png"));
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_diffract"))
        .args(["profile", "--heightfield", "builtin:blazed", "--size", "8"])
        .args(["--only", "taylor R=2", "--pixels", "4", "--brightest", "4"])
        .args(["--frames", "1", "--mesh-size", "0", "--no-cache"])
        .arg("--csv")
        .arg(&csv)
        .arg("--plot")
        .arg(&png)
        .env("DIFFRACT_VALIDATION", "1")
        .output()
        .expect("run diffract");
    if gpu_util::binary_found_no_vulkan(&o) {
        return;
    }
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success(),
        "a dark map's plot must be refused: {err}"
    );
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errors.len(), 1, "{err}");
    assert!(
        errors[0].contains("the reference map is dark") && errors[0].contains("odd --size"),
        "{err}"
    );
    assert!(!png.exists(), "no plot of noise");
    let table = std::fs::read_to_string(&csv).expect("the CSV is written before the plot");
    let mut lines = table.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let row: Vec<&str> = lines.next().expect("one row").split(',').collect();
    let dark = header.iter().position(|h| *h == "reference_dark").unwrap();
    assert_eq!(
        row[dark], "true",
        "the row says the reference is dark: {row:?}"
    );
    let _ = std::fs::remove_dir_all(dir);
}
