//! Golden images guard the whole pipeline (scene → mesh → shaders → readback → PNG): a
//! render is compared with `tests/golden/*.png` by CIEDE2000 percentiles, never bytewise
//! (lavapipe and GPUs round differently). On failure the actual image and a difference
//! image (×10) are written to `target/test-output/`.
//!
//! To (re)create a golden after an intended change, inspect the new render, then run
//! `DIFFRACT_UPDATE_GOLDEN=1 cargo test --release --test gpu_golden`.

mod gpu_util;

use std::path::Path;

use diffract::scene::Scene;
use gpu_util::golden::check_golden;
use gpu_util::*;

/// The flat-scales example (the first default scene) at 64×64.
#[test]
fn default_scene_matches_golden() {
    let Some(mut r) = renderer() else { return };
    // The scene the golden was made with, kept as an example when the default became the
    // close-up; the new default gets its goldens once the renderer draws all its keys.
    let mut scene = Scene::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/examples/flat_scales.toml"),
    )
    .expect("flat_scales example");
    scene.output.width = 64;
    scene.output.height = 64;
    let p = prepare(&scene.material);
    let frame = r.render_scene(&scene, &p).expect("render");
    assert_no_validation(&r);
    check_golden("default_64", &frame);
}

/// The first-order spectrum of the blazed grating on a plane (see gpu_scene.rs): the
/// golden where the diffraction colours themselves are held.
#[test]
fn rainbow_plane_matches_golden() {
    let Some(mut r) = renderer() else { return };
    let scene = Scene::from_toml_str(
        include_str!("golden/rainbow_64.toml"),
        Path::new("tests/golden/rainbow_64.toml"),
    )
    .expect("scene");
    let p = prepare(&scene.material);
    let frame = r.render_scene(&scene, &p).expect("render");
    assert_no_validation(&r);
    check_golden("rainbow_64", &frame);
}
