//! Background builds (the viewer's): a build for a material that a later request has
//! superseded is cancelled at once, not run to its end before the wanted one starts; a
//! request the prepared variant already serves stops a superseded build too; and every
//! object of a cancelled build is destroyed (validation on).

mod gpu_util;

use std::sync::Arc;
use std::time::{Duration, Instant};

use diffract::material::{Material, PreparedMaterial};
use diffract::render::{Arrived, Readiness, Renderer, TableOptions, VariantKind};
use gpu_util::*;

/// Polls until a background build arrives (a guard against a hang, not a timing).
fn arrival(r: &mut Renderer) -> Arrived {
    let start = Instant::now();
    loop {
        if let Some(a) = r.poll_background().expect("background build") {
            return a;
        }
        assert!(
            start.elapsed() < Duration::from_secs(900),
            "no build arrived"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_superseded_build_is_cancelled() {
    let Some(mut r) = renderer() else { return };
    r.set_variant(VariantKind::ChebyshevW);
    r.set_region_margin(0.25);
    r.set_leave_out(true);
    r.set_table_options(TableOptions {
        texel_uv: Some(0.01),
        ..TableOptions::default()
    });
    let scene = plane_scene(3.0);
    let a: Arc<PreparedMaterial> = Arc::new(prepare(&scene.material));
    let b = Arc::new(prepare(&Material {
        coherence_um: scene.material.coherence_um * 1.25,
        ..scene.material.clone()
    }));
    let ask = |r: &mut Renderer, m: &Arc<PreparedMaterial>| {
        r.prepare_in_background(&scene, 1.0, m, None, false)
            .expect("request")
    };

    // `a` builds; `b` is asked for before `a` arrives: `a`'s build stops, `b`'s starts.
    assert_eq!(ask(&mut r, &a), Readiness::Building);
    assert_eq!(ask(&mut r, &b), Readiness::Building);
    assert_eq!(r.builds_cancelled(), 1);
    let first = arrival(&mut r);
    assert!(
        Arc::ptr_eq(&first.material, &b),
        "the first build to arrive is the wanted material's"
    );
    assert!(!r.building());
    assert_eq!(ask(&mut r, &b), Readiness::Ready);

    // Back to `b` while `a` builds again: `b` is prepared, so the answer is at once and
    // `a`'s build stops.
    assert_eq!(ask(&mut r, &a), Readiness::Building);
    assert_eq!(ask(&mut r, &b), Readiness::Ready);
    assert!(!r.building(), "the superseded build no longer runs");
    assert_eq!(r.builds_cancelled(), 2);

    // The same request twice is one build, not a cancellation.
    assert_eq!(ask(&mut r, &a), Readiness::Building);
    assert_eq!(ask(&mut r, &a), Readiness::Building);
    assert_eq!(r.builds_cancelled(), 2);
    assert!(Arc::ptr_eq(&arrival(&mut r).material, &a));
    assert_eq!(ask(&mut r, &a), Readiness::Ready);
    assert_no_validation(&r);
}
