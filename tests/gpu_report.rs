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
        step_nm: 20,
        budget_bytes: 1 << 20,
        ..TableOptions::default()
    });
    let frame = r.render_brdf_map(&prepared, 30.0, 0.0, 8, None).unwrap();
    assert!(frame.rgb.iter().flatten().all(|c| c.is_finite()));
    let warnings = report.warnings();
    assert!(
        warnings.iter().any(|w| w.starts_with("volume table over u")
            && w.contains("coarsened from texel 0.0001")
            && w.ends_with("to fit 1 MB")),
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
        step_nm: 20,
        ..TableOptions::default()
    });
    r.render_brdf_map(&prepared, 30.0, 0.0, 8, None).unwrap();
    assert_eq!(report.warnings(), Vec::<String>::new());
    assert_no_validation(&r);
}
