//! The default scene as a person sees it: the close-up of the corn snake under
//! the sun's disc, with the default variant, must be free of aliasing. Supersampling is the
//! anti-aliasing: a 512² render and a 1024² render box-filtered to 512² (16 samples a pixel
//! against the default 9) differ, over the pixels the snake covers, by mean CIEDE2000 ≤ 2
//! and p99 ≤ 10. Without supersampling the same comparison fails, so the test can tell.
//! The default scene also has a golden image (64², `tests/golden/closeup_64.png`). Both
//! live in one test so the table of the view is built once (then read from a disk cache).

mod gpu_util;

use std::path::Path;

use diffract::image_io;
use diffract::render::{Picture, TableOptions, VariantKind};
use diffract::scene::Scene;
use gpu_util::golden::check_golden;
use gpu_util::*;

const MAX_MEAN_DELTA_E: f64 = 2.0;
const MAX_P99_DELTA_E: f64 = 10.0;

fn default_scene() -> Scene {
    Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/default_scene.toml"))
        .expect("default scene")
}

/// `scene` at `size`², supersampled `ss`×, resolved as `diffract render` writes a PNG, by a
/// renderer of its own (each `diffract render` is one process) whose table comes from the
/// disk cache `cache` after the first build.
fn render_at(scene: &Scene, size: u32, ss: u32, cache: &Path) -> Option<Picture> {
    let mut r = renderer()?;
    // What `diffract render` draws with (a renderer starts on flss).
    r.set_variant(VariantKind::Default);
    // The table at 5 nm instead of 1 nm keeps its build under a minute on two cores; the
    // test is about sampling in space, which the table's spectral step does not change.
    r.set_table_options(TableOptions {
        step_nm: Some(5),
        ..TableOptions::default()
    });
    r.set_cache_dir(Some(cache.to_path_buf()));
    let mut s = scene.clone();
    s.output.width = size;
    s.output.height = size;
    s.output.supersample = ss;
    let p = prepare(&s.material);
    let start = std::time::Instant::now();
    let frame = r
        .render_output(&s, None, &p, true)
        .expect("render the default scene");
    assert_no_validation(&r);
    eprintln!(
        "{size}² × {ss}²: GPU {:.0} ms, wall {:.1} s",
        frame.gpu_ms.unwrap_or(f64::NAN),
        start.elapsed().as_secs_f64()
    );
    Some(frame)
}

/// Mean and p99 ΔE2000 between `frame` (512²) and `fine` (1024²) box-filtered to 512², over
/// the pixels where either shows the snake (not the resolved background).
fn aliasing(scene: &Scene, frame: &Picture, fine: &Picture) -> (f64, f64, usize) {
    let (_, _, down) = image_io::box_downsample(fine.width, fine.height, &fine.rgb, 2).unwrap();
    let out = &scene.output;
    let mut bg = vec![out.background];
    image_io::apply_tone(&mut bg, 1.0, out.tone, out.white).unwrap();
    let near_bg = |p: &[f32; 3]| (0..3).all(|c| (p[c] - bg[0][c]).abs() <= 1e-6);
    let mask: Vec<bool> = frame
        .rgb
        .iter()
        .zip(&down)
        .map(|(a, b)| !(near_bg(a) && near_bg(b)))
        .collect();
    let covered = mask.iter().filter(|m| **m).count();
    let (mean, p99) = image_io::delta_e_over(&frame.rgb, &down, Some(&mask)).expect("ΔE");
    (mean, p99, covered)
}

#[test]
fn default_scene_matches_golden_and_is_free_of_aliasing() {
    let cache = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-output/look-cache");
    std::fs::create_dir_all(&cache).expect("cache dir");
    let scene = default_scene();
    let ss = scene.output.supersample;
    assert_eq!(ss, 3, "the default supersamples 3×3");
    let Some(small) = render_at(&scene, 64, 2, &cache) else {
        return;
    };
    assert!(small.rgb.iter().flatten().all(|c| c.is_finite()));
    check_golden("closeup_64", &small);

    let a = render_at(&scene, 512, ss, &cache).unwrap();
    let fine = render_at(&scene, 1024, 2, &cache).unwrap();
    let (mean, p99, covered) = aliasing(&scene, &a, &fine);
    eprintln!(
        "default 512² (9 samples) vs 1024² → 512² (16 samples), {covered} covered pixels: \
         ΔE2000 mean {mean:.3}, p99 {p99:.3}"
    );
    assert!(
        covered > 512 * 512 / 4,
        "the snake covers only {covered} pixels"
    );
    assert!(
        mean <= MAX_MEAN_DELTA_E && p99 <= MAX_P99_DELTA_E,
        "aliasing: mean ΔE {mean:.3} (≤ {MAX_MEAN_DELTA_E}), p99 {p99:.3} (≤ {MAX_P99_DELTA_E})"
    );

    // The same comparison without supersampling must see the aliasing, else this test
    // could not fail.
    let single = render_at(&scene, 512, 1, &cache).unwrap();
    let (mean1, p99_1, _) = aliasing(&scene, &single, &fine);
    eprintln!("one sample a pixel: ΔE2000 mean {mean1:.3}, p99 {p99_1:.3}");
    assert!(
        mean1 > mean && p99_1 > p99,
        "supersampling does not reduce the difference: 1 sample mean {mean1:.3} p99 {p99_1:.3}, \
         9 samples mean {mean:.3} p99 {p99:.3}"
    );
}
