//! The sun's disc pre-filtered into a table (`render` of a mesh with a table variant): the
//! shader evaluates the disc's centre once, and each pixel equals the f64 model of that one
//! evaluation (the kept pre-filtered table, Algorithm 2's frame, cosθi, exposure).

mod gpu_util;

use diffract::colour::xyz_to_linear_srgb;
use diffract::render::{TableOptions, VariantKind};
use gpu_util::*;

#[test]
fn one_evaluation_of_the_prefiltered_table_matches_its_f64_model() {
    let Some(mut r) = renderer() else { return };
    let scene = plane_scene(3.0);
    assert_eq!(scene.light.disk_samples().len(), 8);
    let p = prepare(&scene.material);
    r.set_variant(VariantKind::ChebyshevW);
    r.set_keep_models(true);
    r.set_table_options(TableOptions {
        step_nm: Some(10),
        texel_uv: Some(0.004),
        w_nodes: Some(6),
        ..TableOptions::default()
    });
    let frame = r.render_scene(&scene, &p).expect("render plane");
    assert_no_validation(&r);
    assert!(
        frame.variant.name.contains("pre-filtered"),
        "{}",
        frame.variant.name
    );
    let model = r.table_model().expect("kept model");
    let (w, h) = (frame.width, frame.height);
    let max = frame.rgb.iter().flatten().fold(0.0f32, |a, b| a.max(*b)) as f64;
    assert!(max > 0.05, "max {max}: the orders were missed");
    let inv = scene
        .camera
        .view_proj(scene.output.aspect())
        .as_dmat4()
        .inverse();
    let eye = glam::DVec3::from(scene.camera.eye.map(|c| c as f64));
    // The plane's tangent frame is the world frame; one direction, the disc's centre.
    let wi = glam::DVec3::from(scene.light.towards_light().to_array().map(f64::from));
    let scale = scene.light.intensity as f64 * scene.output.exposure as f64;
    let (mut checked, mut worst) = (0, 0.0f64);
    for j in 0..h {
        for i in 0..w {
            let hit = plane_hit(&inv, i, j, w, h);
            if hit.x.abs() > 0.99 || hit.y.abs() > 0.99 {
                continue;
            }
            let wr = (eye - hit).normalize();
            let rgb = xyz_to_linear_srgb(model.xyz(&p.shading, wi.to_array(), wr.to_array()));
            let gpu = frame.at(i, j);
            for c in 0..3 {
                let want = wi.z * scale * rgb[c];
                worst = worst.max((gpu[c] as f64 - want).abs());
            }
            checked += 1;
        }
    }
    eprintln!("{checked} pixels: GPU vs f64 model {worst:.3e} (max {max:.3})");
    assert!(checked > 1000, "{checked} pixels checked");
    // float32 arithmetic, interpolated frames and filtering weights.
    assert!(
        worst <= 3e-3 * max,
        "GPU vs f64 model {worst:e} (max {max})"
    );
}

/// A table that holds the disc integrates at 2 nm unless a step is asked for; an explicit
/// step is kept, 1 nm included (1 nm once read as "nothing asked" and became 2).
#[test]
fn an_explicit_wavelength_step_is_kept_for_a_disc_table() {
    let Some(mut r) = renderer() else { return };
    let scene = plane_scene(3.0);
    let p = prepare(&scene.material);
    r.set_variant(VariantKind::ChebyshevW);
    for (asked, built) in [(None, "dλ=2 "), (Some(1), "dλ=1 "), (Some(5), "dλ=5 ")] {
        r.set_table_options(TableOptions {
            step_nm: asked,
            texel_uv: Some(0.02),
            w_nodes: Some(4),
            ..TableOptions::default()
        });
        let frame = r.render_scene(&scene, &p).expect("render plane");
        let name = &frame.variant.name;
        assert!(
            name.contains("pre-filtered") && name.contains(built),
            "{asked:?}: {name}"
        );
    }
    assert_no_validation(&r);
}
