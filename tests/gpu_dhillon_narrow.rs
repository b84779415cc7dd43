//! `dhillon` on a narrow reachable `w` interval: a plane seen from afar through a 12° lens,
//! where `w = −(ωi + ωr)·n` spans less than 1 % of its range. Raw powers of `w` wrote values
//! a hundred times the right ones there (±1.5e30 with 24 nodes, black with 64), exiting 0.
//! Powers of `ŵ` mapped onto the interval are well conditioned: with 12, 24 and 64 nodes
//! `render --variant dhillon` must agree with `chebyshev-w` (the same samples in a stable
//! basis) or be refused with exit 1 and one `error:` line naming the expected error.

mod gpu_util;

use std::path::{Path, PathBuf};
use std::process::Command;

use diffract::heightfield::HeightField;

fn scratch() -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-dhillon-narrow-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A 65 µm patch of 130² samples: 5 µm ridges along x and a weaker 13 µm diagonal wave,
/// so the 10°-light's first and second orders fall inside the lens's view.
fn field(dir: &Path) -> PathBuf {
    let n = 130;
    let dh = 0.5;
    let tau = 2.0 * std::f64::consts::PI;
    let h = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f64 * dh, (i / n) as f64 * dh);
            0.1 * (1.0 + (tau * x / 5.0).sin()) + 0.03 * (1.0 + (tau * (x + y) / 13.0).cos())
        })
        .collect();
    let path = dir.join("field.png");
    HeightField::new(n, n, dh, h).unwrap().save(&path).unwrap();
    path
}

/// The plane facing +z seen from 8 units away through a 12° lens: `ωr` within 6° of the
/// normal, `w ∈ [−1.985, −1.98]`. A point light 10° off the normal; no texture, no tone
/// curve, so pixels are the diffraction colour times a constant.
fn scene(dir: &Path, field: &Path) -> PathBuf {
    let s = 10f64.to_radians().sin();
    let c = 10f64.to_radians().cos();
    let text = format!(
        r#"[camera]
eye = [0.0, 0.0, 8.0]
target = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y_deg = 12.0
[light]
direction = [{}, 0.0, {}]
intensity = 1.0
angular_diameter_deg = 0.0
disk_samples = 1
[mesh]
builtin = "plane"
[material]
heightfield = "{}"
terms = 8
window_radius = 2
lambda_step_nm = 10
[output]
width = 24
height = 24
exposure = 50.0
supersample = 1
tone = "linear"
background = [0.0, 0.0, 0.0]
"#,
        -s,
        -c,
        field.display()
    );
    let path = dir.join("lens12.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn render(dir: &Path, scene: &Path, variant: &str, nodes: usize) -> std::process::Output {
    let out = dir.join(format!("{variant}-{nodes}.exr"));
    Command::new(env!("CARGO_BIN_EXE_diffract"))
        .args(["render", "--scene"])
        .arg(scene)
        .args(["--variant", variant, "--table-step-nm", "10"])
        .args(["--table-w-nodes", &nodes.to_string()])
        // The representations compared at the pixels' centres, chebyshev-w's levels for
        // the pixel footprint left out.
        .args(["--table-levels", "1"])
        .arg("-o")
        .arg(&out)
        .env("DIFFRACT_CACHE", dir.join("cache"))
        .env("DIFFRACT_VALIDATION", "1")
        .output()
        .expect("run diffract")
}

fn image(dir: &Path, variant: &str, nodes: usize) -> Vec<[f32; 3]> {
    diffract::image_io::read_exr(&dir.join(format!("{variant}-{nodes}.exr")))
        .unwrap()
        .2
}

#[test]
fn dhillon_on_a_plane_through_a_narrow_lens_is_right_or_refused() {
    if gpu_util::renderer().is_none() {
        return;
    }
    let dir = scratch();
    let scene = scene(&dir, &field(&dir));
    // Bilinear in (u, v) on the same nodes as dhillon, linear in w over an interval where
    // G's phases move by 0.02 rad: what dhillon must reproduce up to float32.
    let o = render(&dir, &scene, "volume", 3);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let volume = image(&dir, "volume", 3);
    let mut drawn = 0;
    for nodes in [12, 24, 64] {
        // The same samples in the stable basis (the table cache shares them).
        let o = render(&dir, &scene, "chebyshev-w", nodes);
        assert!(
            o.status.success(),
            "chebyshev-w {nodes}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let want = image(&dir, "chebyshev-w", nodes);
        let peak = want.iter().flatten().fold(0.0f32, |m, x| m.max(*x)) as f64;
        assert!(peak > 0.0, "the lens must see the orders");
        let o = render(&dir, &scene, "dhillon", nodes);
        let stderr = String::from_utf8_lossy(&o.stderr);
        if !o.status.success() {
            assert_eq!(o.status.code(), Some(1), "{stderr}");
            let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
            assert_eq!(lines.len(), 1, "one line: {stderr}");
            assert!(
                lines[0].starts_with("error:") && lines[0].contains("expected error"),
                "{stderr}"
            );
            eprintln!("dhillon, {nodes} w nodes: refused: {}", lines[0]);
            continue;
        }
        drawn += 1;
        let got = image(&dir, "dhillon", nodes);
        let (mut worst, mut lo, mut hi) = (0.0f64, f32::INFINITY, f32::NEG_INFINITY);
        let mut off_volume = 0.0f64;
        for ((g, w), v) in got.iter().zip(&want).zip(&volume) {
            for c in 0..3 {
                assert!(g[c].is_finite());
                worst = worst.max((g[c] - w[c]).abs() as f64);
                off_volume = off_volume.max((g[c] - v[c]).abs() as f64);
                lo = lo.min(g[c]);
                hi = hi.max(g[c]);
            }
        }
        eprintln!(
            "dhillon, {nodes} w nodes: values {lo:.4}..{hi:.4}, chebyshev-w peak {peak:.4}, max |Δ| {worst:.2e} ({:.2e} of the peak), against volume {off_volume:.2e} ({:.2e})",
            worst / peak,
            off_volume / peak
        );
        // Against volume (bilinear in (u, v) on the same nodes, exact in w to ~1e-5 here):
        // float32 and the series in w only. Against chebyshev-w's cubic splines in (u, v):
        // the (u, v) interpolation too, a few per cent of the peak. The monomial basis was
        // off by a factor of 100 and more. (Pixels are linear sRGB: saturated orders are
        // legitimately negative in some channel.)
        assert!(
            off_volume <= 1e-3 * peak,
            "dhillon {nodes} vs volume: {off_volume:e} vs {peak:e}"
        );
        assert!(
            worst <= 0.05 * peak,
            "dhillon {nodes}: {worst:e} vs {peak:e}"
        );
    }
    // Every case was decided: the narrow interval is exactly where mapped powers are
    // stable, so at least the default count draws.
    assert!(drawn >= 1, "dhillon refused every node count");
    let _ = std::fs::remove_dir_all(dir);
}
