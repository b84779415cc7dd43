//! The default picture does not change by accident: `diffract render` of the embedded
//! default scene, from an empty cache, against `assets/figures/default_closeup.png`, by
//! CIEDE2000 over the snake's pixels (every pixel whose reference colour is not the
//! background's). Needs Vulkan (lavapipe is enough); skipped loudly without it unless
//! `DIFFRACT_REQUIRE_VULKAN=1`.

mod gpu_util;

use std::path::Path;
use std::process::Command;

use diffract::colour::{delta_e2000, xyz_to_lab};
use diffract::image_io::read_png_rgb8;

/// Mean CIEDE2000 over the snake's pixels the default picture may move by.
const MAX_MEAN: f64 = 0.5;
/// 99th percentile: the sparse diffraction colours (a few per cent of the pixels) live here.
const MAX_P99: f64 = 6.0;

fn srgb8_to_xyz(p: [u8; 3]) -> [f64; 3] {
    let lin = p.map(|v| {
        let c = v as f64 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    });
    // IEC 61966-2-1 linear sRGB → XYZ (D65).
    let m = [
        [0.4124, 0.3576, 0.1805],
        [0.2126, 0.7152, 0.0722],
        [0.0193, 0.1192, 0.9505],
    ];
    [0, 1, 2].map(|r| m[r][0] * lin[0] + m[r][1] * lin[1] + m[r][2] * lin[2])
}

/// ΔE2000 statistics of `actual` against `reference` over the reference's non-background
/// pixels (the background is the colour of its top-left pixel, ±2 levels): mean, p99,
/// largest, and the pixel count.
fn delta_e_over_snake(reference: &Path, actual: &Path) -> (f64, f64, f64, usize) {
    let (w, h, r) = read_png_rgb8(reference).expect("reference PNG");
    let (w2, h2, a) = read_png_rgb8(actual).expect("actual PNG");
    assert_eq!((w, h), (w2, h2), "image sizes");
    let bg = r[0];
    let mut d: Vec<f64> = r
        .iter()
        .zip(&a)
        .filter(|(p, _)| (0..3).any(|c| (p[c] as i32 - bg[c] as i32).abs() > 2))
        .map(|(p, q)| delta_e2000(xyz_to_lab(srgb8_to_xyz(*p)), xyz_to_lab(srgb8_to_xyz(*q))))
        .collect();
    assert!(
        d.len() > (w * h / 10) as usize,
        "the snake covers too few pixels"
    );
    d.sort_by(f64::total_cmp);
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let p99 = d[(d.len() * 99 / 100).min(d.len() - 1)];
    (mean, p99, d[d.len() - 1], d.len())
}

fn reference() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/figures/default_closeup.png")
}

#[test]
fn a_png_against_itself_differs_by_nothing() {
    let (mean, p99, max, n) = delta_e_over_snake(&reference(), &reference());
    assert!(n > 0 && mean == 0.0 && p99 == 0.0 && max == 0.0);
}

#[test]
fn the_cold_default_render_matches_the_default_closeup() {
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-output");
    std::fs::create_dir_all(&out).unwrap();
    let cache = out.join("default-closeup-cache");
    let _ = std::fs::remove_dir_all(&cache);
    let png = out.join("default_closeup.png");
    let run = Command::new(env!("CARGO_BIN_EXE_diffract"))
        .args(["render", "-o"])
        .arg(&png)
        .env("DIFFRACT_CACHE", &cache)
        .output()
        .expect("run diffract");
    let stderr = String::from_utf8_lossy(&run.stderr);
    let _ = std::fs::remove_dir_all(&cache);
    // Only a missing driver skips (the shared rule): a Vulkan error or a validation
    // message fails the test.
    if gpu_util::binary_found_no_vulkan(&run) {
        return;
    }
    assert!(run.status.success(), "render failed: {stderr}");
    let (mean, p99, max, n) = delta_e_over_snake(&reference(), &png);
    eprintln!("ΔE2000 over {n} snake pixels: mean {mean:.3}, p99 {p99:.2}, max {max:.2}");
    assert!(mean <= MAX_MEAN, "mean ΔE2000 {mean:.3} > {MAX_MEAN}");
    assert!(p99 <= MAX_P99, "p99 ΔE2000 {p99:.2} > {MAX_P99}");
}
