//! Golden images: a render is compared with `tests/golden/*.png` by CIEDE2000 percentiles,
//! never bytewise (lavapipe and GPUs round differently). On failure the actual image and a
//! difference image (×10) are written to `target/test-output/`. With
//! `DIFFRACT_UPDATE_GOLDEN=1` the render replaces the golden instead.

use std::path::{Path, PathBuf};

use diffract::colour::linear_to_srgb8;
use diffract::image_io;
use diffract::render::Picture;

/// Mean CIEDE2000 over all pixels.
pub const MAX_MEAN_DELTA_E: f64 = 0.5;
/// 95th percentile of CIEDE2000: a few pixels on edges may differ between rasterisers.
pub const MAX_P95_DELTA_E: f64 = 1.5;
/// 99th percentile of the per-channel linear difference: the sparse diffraction colours
/// (a few percent of the pixels) are beyond the ΔE p95, so they are held by this one.
pub const MAX_P99_ABS: f64 = 0.03;

pub fn srgb8_to_linear(v: u8) -> f32 {
    let c = v as f64 / 255.0;
    (if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }) as f32
}

/// What a PNG of `frame` holds, back in linear: clamping and 8-bit quantisation included,
/// so actual and golden are compared like for like.
fn as_png_linear(rgb: &[[f32; 3]]) -> Vec<[f32; 3]> {
    rgb.iter()
        .map(|p| linear_to_srgb8(p.map(|c| c as f64), 1.0).map(srgb8_to_linear))
        .collect()
}

fn golden_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

pub fn output_dir() -> PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-output");
    std::fs::create_dir_all(&d).expect("create target/test-output");
    d
}

pub fn check_golden(name: &str, frame: &Picture) {
    let golden = golden_dir().join(format!("{name}.png"));
    if std::env::var("DIFFRACT_UPDATE_GOLDEN").is_ok_and(|v| v == "1") {
        std::fs::create_dir_all(golden_dir()).unwrap();
        image_io::write_png_srgb(&golden, frame.width, frame.height, &frame.rgb, 1.0).unwrap();
        eprintln!("wrote golden {}", golden.display());
        return;
    }
    let (w, h, px) = image_io::read_png_rgb8(&golden).unwrap_or_else(|e| {
        panic!("{e}\n(create it with DIFFRACT_UPDATE_GOLDEN=1 after inspecting a render)")
    });
    assert_eq!((w, h), (frame.width, frame.height), "golden size");
    let expected: Vec<[f32; 3]> = px.iter().map(|p| p.map(srgb8_to_linear)).collect();
    let actual = as_png_linear(&frame.rgb);
    let diff = image_io::compare_images(&actual, &expected);
    eprintln!("{name}: {diff}");
    let ok = diff.mean_delta_e <= MAX_MEAN_DELTA_E
        && diff.p95_delta_e <= MAX_P95_DELTA_E
        && diff.p99_abs <= MAX_P99_ABS;
    if !ok {
        let out = output_dir();
        let actual_path = out.join(format!("{name}_actual.png"));
        let diff_path = out.join(format!("{name}_diff.png"));
        image_io::write_png_srgb(&actual_path, w, h, &frame.rgb, 1.0).unwrap();
        let d = image_io::difference_image(&actual, &expected);
        image_io::write_png_srgb(&diff_path, w, h, &d, 10.0).unwrap();
        panic!(
            "{name} differs from {}: {diff} (limits: mean ΔE {MAX_MEAN_DELTA_E}, p95 ΔE \
             {MAX_P95_DELTA_E}, p99 |Δ| {MAX_P99_ABS}); see {} and {}",
            golden.display(),
            actual_path.display(),
            diff_path.display()
        );
    }
}
