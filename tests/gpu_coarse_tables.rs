//! A table coarser than the spacing that resolves the coherence lobe (a small budget, or a
//! coarse `--table-texel`) loses accuracy gradually: the BRDF map drawn from it never rises
//! above the map from the fine table by more than float16 rounding, and the warning of a
//! coarsened table states how far the lobes' peaks fall. Needs Vulkan (lavapipe is enough).

mod gpu_util;

use std::path::Path;
use std::process::Command;

/// About 52°, where the mirror direction is the centre of pixel 3 of the map's middle row:
/// the fine map then holds the specular peak itself, the largest value of `G`, so a coarse
/// map's pixel elsewhere cannot legitimately exceed it (a 33² map's pixels otherwise miss
/// the lobes' peaks, and a smoothed lobe is wider).
fn theta_i() -> String {
    format!("{}", gpu_util::theta_for_specular_pixel(3, 33))
}

/// The largest value of any channel of a `render --brdf-map` EXR with these extra options,
/// and the run's stderr; `None` where the machine has no Vulkan driver.
fn map_peak(dir: &Path, name: &str, extra: &[&str]) -> Option<(f32, String)> {
    let out = dir.join(format!("{name}.exr"));
    let o = Command::new(env!("CARGO_BIN_EXE_diffract"))
        .args([
            "render",
            "--brdf-map",
            "--size",
            "33",
            "--theta-i",
            &theta_i(),
            "--table-step-nm",
            "20",
            "--cache-dir",
        ])
        .arg(dir.join("cache"))
        .args(extra)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    if gpu_util::binary_found_no_vulkan(&o) {
        return None;
    }
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{name}: {err}");
    let (_, _, px) = diffract::image_io::read_exr(&out).unwrap();
    // A sun-lit BRDF map's EXR holds XYZ in its R, G, B, and says so.
    let units = diffract::image_io::exr_units(&out)
        .unwrap()
        .unwrap_or_default();
    assert!(units.starts_with("CIE X, Y, Z (in R, G, B)"), "{units}");
    let peak = px.iter().flatten().fold(0.0f32, |m, &c| m.max(c));
    Some((peak, err))
}

#[test]
fn a_coarse_table_never_rises_above_the_fine_tables_peak() {
    let d = std::env::temp_dir().join(format!("diffract-coarse-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    let Some((fine, _)) = map_peak(&d, "fine", &[]) else {
        return;
    };
    assert!(fine > 0.0);
    let cases: [(&str, &[&str]); 5] = [
        ("budget 8 MB", &["--table-budget-mb", "8"]),
        ("budget 4 MB", &["--table-budget-mb", "4"]),
        ("budget 2 MB", &["--table-budget-mb", "2"]),
        ("texel 0.005", &["--table-texel", "0.005"]),
        ("texel 0.02", &["--table-texel", "0.02"]),
    ];
    for (name, extra) in cases {
        let (peak, err) = map_peak(&d, &name.replace(' ', "-"), extra).unwrap();
        eprintln!("{name}: map peak {peak:.4e} against the fine table's {fine:.4e}");
        // Float16 texels round by 4.9e-4; the series in w adds about 1e-4 of the peak.
        assert!(
            peak <= fine * 1.002,
            "{name}: peak {peak} above the fine table's {fine}: {err}"
        );
        assert!(peak > 0.0, "{name}: an empty map");
        if name.starts_with("budget") {
            assert!(err.contains("never above its samples"), "{name}: {err}");
            assert!(err.contains("% low"), "{name}: {err}");
        }
    }
    let _ = std::fs::remove_dir_all(&d);
}
