//! `profile --picture`: the whole-picture rows. The default scene at 64² drawn by the
//! default variant at 1×1, 2×2 and 4×4 samples a pixel against the same scene at 8×8: every
//! score (relative L2, CIEDE2000 mean and p99, ꟻLIP) falls as the supersampling rises (at
//! 32² one glint can make a 2×2 picture's relative L2 the largest), the default table
//! filtered to the pixel's footprint beats it read at the pixels' centres (rel-L2, ꟻLIP
//! and, at 2×2, the ΔE2000 mean), the reference states its own
//! convergence, the rows are in the CSV and each row's ꟻLIP map is written. Bad picture
//! flags are one error line before any device work.

mod gpu_util;

use std::path::PathBuf;
use std::process::Command;

fn dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-picture-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn profile(args: &[&str], d: &std::path::Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_diffract"))
        .arg("profile")
        .args(args)
        .env("DIFFRACT_CACHE", d.join("cache"))
        .output()
        .expect("run diffract")
}

#[test]
fn the_picture_rows_fall_with_supersampling_against_a_finer_picture() {
    let d = dir("rows");
    let csv = d.join("p.csv");
    let maps = d.join("maps");
    let o = profile(
        &[
            "--only",
            "chebyshev-w",
            "--size",
            "17",
            "--pixels",
            "4",
            "--brightest",
            "2",
            "--frames",
            "1",
            "--picture-size",
            "64",
            "--picture-aa",
            "1,2,4",
            "--picture-reference-ss",
            "8",
            "--csv",
            csv.to_str().unwrap(),
            "--picture-maps",
            maps.to_str().unwrap(),
        ],
        &d,
    );
    if gpu_util::binary_found_no_vulkan(&o) {
        return;
    }
    let out = String::from_utf8_lossy(&o.stdout);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        out.contains("whole picture: the default scene at 64×64, its surface builtin:elaphe-grown")
            && out.contains("at 8×8 samples a pixel")
            && out.contains("the reference at half that rate is off by"),
        "{out}"
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<&str>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|c| c[col("kind")] == "picture")
        .collect();
    // The three modes (the default variant reads its table filtered to the pixel's
    // footprint), and the same unfiltered at the two smallest.
    assert_eq!(rows.len(), 5, "{text}");
    let num = |r: &Vec<&str>, name: &str| -> f64 { r[col(name)].parse().unwrap() };
    for r in &rows {
        assert_eq!(r.len(), header.len(), "{r:?}");
    }
    let score = |name: &str| rows[..3].iter().map(|r| num(r, name)).collect::<Vec<f64>>();
    let unfiltered = &rows[3..];
    assert!(
        unfiltered.iter().all(|r| r[0].contains("unfiltered")),
        "{text}"
    );
    // Filtered to its footprint, a pixel's picture is nearer the converged one than the
    // same mode read at the pixel's centre: relative L2 and ꟻLIP at both modes, and the
    // ΔE2000 mean at 2×2 (at 1×1 on a 64² picture the edges and the texture, which no
    // filter of the BRDF reaches, hold it within 1 % either way).
    for (k, r) in unfiltered.iter().enumerate() {
        let metrics: &[&str] = match k {
            0 => &["rel_l2_ref", "flip_mean"],
            _ => &["rel_l2_ref", "mean_de_ref", "flip_mean"],
        };
        for &metric in metrics {
            let (f, plain) = (num(&rows[k], metric), num(r, metric));
            eprintln!("{metric}: {} {f} against {plain} unfiltered", rows[k][0]);
            assert!(
                f < plain,
                "{}: {metric} {f} against {plain} unfiltered",
                rows[k][0]
            );
        }
    }
    for metric in ["rel_l2_ref", "p99_de_ref", "flip_mean", "mean_de_ref"] {
        let s = score(metric);
        eprintln!("{metric} at 1×1, 2×2, 4×4: {s:?}");
        assert!(
            s[0] > s[1] && s[1] > s[2] && s[2] >= 0.0,
            "{metric} must fall with supersampling: {s:?}"
        );
    }
    assert_eq!(score("picture_aa"), vec![1.0, 2.0, 4.0]);
    assert_eq!(num(&unfiltered[1], "picture_aa"), 2.0);
    for aa in [1, 2, 4] {
        let map = maps.join(format!("flip_chebyshev-w_{aa}_{aa}.png"));
        let (w, h, _) = diffract::image_io::read_png_rgb8(&map).expect("ꟻLIP map");
        assert_eq!((w, h), (64, 64));
    }
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn bad_picture_flags_are_one_error_line() {
    let d = dir("bad");
    let cases: [(&[&str], &str); 4] = [
        (&["--picture-aa", "0"], "picture-aa"),
        (
            &["--picture-aa", "4", "--picture-reference-ss", "4"],
            "picture-reference-ss",
        ),
        (&["--picture-size", "0"], "picture-size"),
        (
            &["--picture-size", "1024", "--picture-reference-ss", "16"],
            "8192",
        ),
    ];
    for (args, want) in cases {
        let o = profile(args, &d);
        let err = String::from_utf8_lossy(&o.stderr);
        let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert_eq!(lines.len(), 1, "{args:?}: {err}");
        assert!(lines[0].contains(want), "{args:?}: {err}");
    }
    let _ = std::fs::remove_dir_all(&d);
}
