//! The renderer's warnings and progress reach the report its owner gave it, not stderr: a
//! table that must be coarsened to fit its memory budget says so to a collecting report,
//! and the table build's progress bar goes there too (hidden).

mod gpu_util;

use std::sync::Arc;

use diffract::render::{TableOptions, VariantKind};
use diffract::report::Collect;
use diffract::spectrum::Expansion;
use gpu_util::*;

#[test]
fn a_coarsened_table_warns_through_the_report() {
    let Some(mut r) = renderer() else { return };
    let report = Arc::new(Collect::default());
    r.set_report(report.clone());
    let m = small_material("builtin:sinusoidal", Expansion::Chebyshev, 6, 1);
    let prepared = prepare(&m);
    r.set_variant(VariantKind::Volume);
    // A spacing far finer than 1 MB can hold: the table is coarsened to fit.
    r.set_table_options(TableOptions {
        texel_uv: Some(1e-4),
        w_nodes: Some(2),
        step_nm: Some(20),
        budget_bytes: 1 << 20,
        ..TableOptions::default()
    });
    let frame = r.render_brdf_map(&prepared, 30.0, 0.0, 8, None).unwrap();
    assert!(frame.rgb.iter().flatten().all(|c| c.is_finite()));
    let warnings = report.warnings();
    assert!(
        warnings.iter().any(|w| w.starts_with("volume table over u")
            && w.contains("coarsened from texel 0.0001")
            && w.contains("to fit 1 MB")
            && w.contains("never above its samples")),
        "the coarsening warning reached the report: {warnings:?}"
    );
    assert_eq!(report.bars(), ["volume table"], "the build's progress bar");
    assert_no_validation(&r);
}

#[test]
fn a_table_that_fits_says_nothing() {
    let Some(mut r) = renderer() else { return };
    let report = Arc::new(Collect::default());
    r.set_report(report.clone());
    let prepared = prepare(&small_material(
        "builtin:sinusoidal",
        Expansion::Chebyshev,
        6,
        1,
    ));
    r.set_variant(VariantKind::Volume);
    r.set_table_options(TableOptions {
        w_nodes: Some(2),
        step_nm: Some(20),
        ..TableOptions::default()
    });
    r.render_brdf_map(&prepared, 30.0, 0.0, 8, None).unwrap();
    assert_eq!(report.warnings(), Vec::<String>::new());
    assert_no_validation(&r);
}

/// `render --repeat N` draws N more times and reports their median GPU time beside the
/// first draw's, on its one result line; the map it writes is the same picture.
#[test]
fn render_repeat_reports_the_median_of_the_draws_after_the_first() {
    let dir = std::env::temp_dir().join(format!("diffract-repeat-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let run = |out: &str, extra: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_diffract"))
            .args(["render", "--brdf-map", "--size", "8", "--variant", "flss"])
            .args([
                "--heightfield",
                "builtin:sinusoidal",
                "--lambda-step-nm",
                "40",
            ])
            .arg("-o")
            .arg(dir.join(out))
            .args(extra)
            .env("DIFFRACT_VALIDATION", "1")
            .output()
            .expect("run diffract")
    };
    let o = run("once.exr", &[]);
    if binary_found_no_vulkan(&o) {
        return;
    }
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let once = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(!once.contains("median"), "{once}");
    let o = run("again.exr", &["--repeat", "3"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let again = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        again.contains("(median of 3 draws after the first, "),
        "the result line says what it timed: {again}"
    );
    assert_eq!(
        std::fs::read(dir.join("once.exr")).unwrap(),
        std::fs::read(dir.join("again.exr")).unwrap(),
        "the same picture"
    );
    let _ = std::fs::remove_dir_all(dir);
}
