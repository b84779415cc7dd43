//! `chebyshev-w` with its table read over a pixel's footprint (`--table-levels` > 1: the
//! mean over the footprint's box from summed-area planes, where the device filters float32),
//! on lavapipe with validation on: a BRDF map (one direction a pixel, a point footprint)
//! reads the table at its points and draws the unfiltered map; the default scene reads
//! boxes where its pixels span many lobes, and its light is the converged picture's (8×8
//! samples a pixel) where the pixels' centres alone miss a tenth of it.

mod gpu_util;

use diffract::render::{TableOptions, VariantKind};
use diffract::scene::Scene;
use gpu_util::*;

fn options(levels: usize) -> TableOptions {
    TableOptions {
        levels,
        ..TableOptions::RENDER
    }
}

#[test]
fn a_point_reads_the_table_and_a_pixel_its_footprint() {
    let Some(mut r) = renderer() else { return };
    r.set_variant(VariantKind::ChebyshevW);
    let mut scene = Scene::default_scene();
    scene.output.width = 48;
    scene.output.height = 48;
    scene.output.supersample = 1;
    let prepared = prepare(&scene.material);

    let mut maps = Vec::new();
    let mut scenes = Vec::new();
    for levels in [1, 6] {
        r.set_table_options(options(levels));
        let map = r
            .render_brdf_map(&prepared, 40.0, 0.0, 24, None)
            .expect("map");
        maps.push(map.rgb);
        let frame = r.render_scene(&scene, &prepared).expect("scene");
        if levels > 1 {
            assert!(
                frame
                    .variant
                    .name
                    .contains("summed-area planes for the pixel footprint"),
                "{}",
                frame.variant.name
            );
        }
        scenes.push(frame.rgb);
    }
    // The scene converged over each pixel: 8×8 samples a pixel, unfiltered.
    r.set_table_options(options(1));
    let mut fine = scene.clone();
    fine.output.supersample = 8;
    let converged = r
        .render_output(&fine, None, &prepared, false)
        .expect("supersampled scene")
        .rgb;
    assert_no_validation(&r);

    let peak = maps[0].iter().flatten().fold(0.0f32, |m, &x| m.max(x));
    assert!(peak > 0.0);
    let worst = maps[0]
        .iter()
        .zip(&maps[1])
        .flat_map(|(a, b)| (0..3).map(move |c| (a[c] - b[c]).abs()))
        .fold(0.0f32, f32::max);
    assert!(worst <= 1e-3 * peak, "a map moved by {worst} (peak {peak})");

    let sum = |p: &[[f32; 3]]| p.iter().flatten().map(|&x| f64::from(x)).sum::<f64>();
    let (plain, filtered, truth) = (sum(&scenes[0]), sum(&scenes[1]), sum(&converged));
    let changed = scenes[0]
        .iter()
        .zip(&scenes[1])
        .filter(|(a, b)| (0..3).any(|c| (a[c] - b[c]).abs() > 1e-3 * a[c].abs().max(1e-3)))
        .count();
    eprintln!(
        "scene: {changed} pixels changed; light {filtered:.4} filtered, {plain:.4} at the pixels' centres, {truth:.4} converged"
    );
    assert!(changed > 50, "{changed} pixels changed by the footprint");
    // Filtering averages G over the footprint: the light stays the converged picture's,
    // where a pixel's centre alone hits or misses sparse glints (how near the picture
    // comes to the converged one is profile --picture's, tests/gpu_profile_picture.rs).
    assert!(
        (filtered / truth - 1.0).abs() < 0.05,
        "the footprint keeps the light: {filtered} against {truth} converged"
    );
    assert!(
        (filtered - truth).abs() < (plain - truth).abs(),
        "filtered {filtered}, unfiltered {plain}, converged {truth}"
    );
}
