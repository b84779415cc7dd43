//! `render --env`: every bad environment map or flag gets one `error:` line and exit
//! status 1 before any device work; a small environment-lit BRDF map and a small scene lit
//! by an environment and a disc light are drawn and written.

mod gpu_util;

use std::path::{Path, PathBuf};
use std::process::Command;

fn dir(tag: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("target/test-output")
        .join(format!("env-cli-{tag}"));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn exr(path: &Path, w: u32, h: u32, px: &[[f32; 3]]) {
    let flat: Vec<f32> = px.iter().flatten().copied().collect();
    image::Rgb32FImage::from_raw(w, h, flat)
        .unwrap()
        .save(path)
        .unwrap();
}

fn render(args: &[&str], cwd: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_diffract"))
        .arg("render")
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

/// A small table for quick draws: coarse, few `w` nodes, a 20 nm step, no cache.
const TINY_TABLE: [&str; 7] = [
    "--table-texel",
    "0.02",
    "--table-w-nodes",
    "4",
    "--table-step-nm",
    "20",
    "--no-cache",
];

/// A small environment-lit BRDF map: 8², four samples, a blazed grating under the studio.
const SMALL_MAP: [&str; 9] = [
    "--brdf-map",
    "--env",
    "builtin:studio",
    "--heightfield",
    "builtin:blazed",
    "--size",
    "8",
    "--env-samples",
    "4",
];

/// `render ARGS` with [`TINY_TABLE`] writing `out`, which must succeed: its stdout.
fn render_tiny(args: &[&str], out: &Path, cwd: &Path) -> String {
    let _ = std::fs::remove_file(out);
    let mut all: Vec<&str> = args.to_vec();
    all.extend(TINY_TABLE);
    all.extend(["-o", out.to_str().unwrap()]);
    let o = render(&all, cwd);
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "{args:?}: {}{}",
        text,
        String::from_utf8_lossy(&o.stderr)
    );
    text
}

#[test]
fn bad_maps_and_flags_get_one_error_line() {
    let d = dir("bad");
    let mut nan = vec![[0.2f32; 3]; 32];
    nan[5] = [f32::NAN, 0.0, 0.0];
    exr(&d.join("nan.exr"), 8, 4, &nan);
    exr(&d.join("square.exr"), 4, 4, &[[1.0; 3]; 16]);
    let mut neg = vec![[0.2f32; 3]; 32];
    neg[0] = [-1.0, 0.0, 0.0];
    exr(&d.join("negative.exr"), 8, 4, &neg);
    std::fs::write(d.join("garbage.hdr"), b"not a radiance file").unwrap();
    let cases: &[(&[&str], &str)] = &[
        (&["--brdf-map", "--env", "missing.hdr"], "missing.hdr"),
        (&["--brdf-map", "--env", "sky.png"], ".hdr or .exr"),
        (&["--brdf-map", "--env", "builtin:moon"], "builtin:sky"),
        (&["--brdf-map", "--env", "nan.exr"], "finite"),
        (&["--brdf-map", "--env", "negative.exr"], "≥ 0"),
        (&["--brdf-map", "--env", "square.exr"], "2:1"),
        (&["--brdf-map", "--env", "garbage.hdr"], "header"),
        (
            &["--brdf-map", "--env", "builtin:sky", "--env-samples", "0"],
            "env samples",
        ),
        (
            &[
                "--brdf-map",
                "--env",
                "builtin:sky",
                "--env-intensity",
                "-2",
            ],
            "intensity",
        ),
        (&["--brdf-map", "--no-sun"], "need an environment"),
        (
            &["--brdf-map", "--env", "square.exr", "-o", "square.exr"],
            "refusing to overwrite an input",
        ),
        (&["--no-sun"], "[[disc_light]]"),
        (&["--env-rotate-deg", "30"], "need an environment"),
        (
            &["--env", "builtin:sky", "--variant", "coverage"],
            "cannot be lit by an environment",
        ),
        (
            &[
                "--brdf-map",
                "--env",
                "builtin:sky",
                "--variant",
                "coverage",
            ],
            "cannot be lit by an environment",
        ),
        (&["--env", "builtin:sky", "--per-vertex"], "--per-vertex"),
        (&["--brdf-map", "--shading", "compute"], "--shading compute"),
        (&["--shading", "compute", "--per-vertex"], "--per-vertex"),
        (&["--env", "builtin:sky", "--repeat", "2"], "--repeat"),
        (&["--env", "builtin:sky", "--size", "8"], "--size"),
        (
            &[
                "--env",
                "builtin:sky",
                "--width",
                "8192",
                "--height",
                "8192",
            ],
            "G-buffer pixels",
        ),
        (
            &["--env", "builtin:sky", "--env-samples", "70000"],
            "env samples",
        ),
        (&["--env", "builtin:sky", "--env-noise", "-1"], "env noise"),
        (&["--env", "builtin:sky", "--env-noise", "nan"], "env noise"),
        (
            &["--brdf-map", "--env", "builtin:sky", "--env-noise", "0.5"],
            "env noise",
        ),
    ];
    for (args, want) in cases {
        let o = render(args, &d);
        let err = String::from_utf8_lossy(&o.stderr);
        let lines: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert_eq!(lines.len(), 1, "{args:?}: {err}");
        assert!(
            err.trim_end().lines().last().unwrap().starts_with("error:"),
            "{args:?}: {err}"
        );
        assert!(lines[0].contains(want), "{args:?}: {err}");
    }
}

/// `--shading compute`: the sun-lit scene drawn by the G-buffer and the compute stages,
/// the sun's directions as point lights and the scene's ambient sky as the environment
/// they sample (until the noise target).
#[test]
fn the_sun_lit_scene_is_shaded_by_the_compute_stages_on_request() {
    if gpu_util::device().is_none() {
        return;
    }
    let d = dir("shading");
    let out = d.join("compute.png");
    let text = render_tiny(
        &["--shading", "compute", "--width", "32", "--height", "32"],
        &out,
        &d,
    );
    assert!(
        text.contains("in radiance units")
            && text.contains("under the scene's sky (ambient)")
            && text.contains("until the estimated noise is below"),
        "{text}"
    );
    let img = image::open(&out).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (32, 32));
}

/// `--table-budget-mb` holds the environment table as it holds every table: the spacing
/// is coarsened to fit, and a line says so and what it costs.
#[test]
fn the_environment_table_fits_the_table_budget() {
    if gpu_util::device().is_none() {
        return;
    }
    let d = dir("budget");
    let out = d.join("budget.exr");
    let _ = std::fs::remove_file(&out);
    let mut args: Vec<&str> = SMALL_MAP.to_vec();
    args.extend([
        "--table-budget-mb",
        "1",
        "--table-w-nodes",
        "4",
        "--table-step-nm",
        "20",
        "--no-cache",
        "-o",
        out.to_str().unwrap(),
    ]);
    let o = render(&args, &d);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("environment table coarsened from texel 0.0037") && err.contains("1 MB"),
        "{err}"
    );
}

/// `--variant` under an environment: the map is drawn by that variant's shader and the
/// report names it.
#[test]
fn a_variant_draws_the_environment_lit_map() {
    if gpu_util::device().is_none() {
        return;
    }
    let d = dir("variant");
    for variant in ["flss", "volume"] {
        let out = d.join(format!("{variant}.exr"));
        let text = render_tiny(
            &[SMALL_MAP.as_slice(), &["--variant", variant]].concat(),
            &out,
            &d,
        );
        assert!(text.contains(&format!("variant {variant} ")), "{text}");
        let (_, _, px) = diffract::image_io::read_exr(&out).unwrap();
        assert!(px.iter().flatten().all(|c| c.is_finite()));
        assert!(px.iter().any(|p| p[1] > 0.0), "{variant}: a black map");
    }
}

#[test]
fn a_small_environment_lit_map_is_drawn() {
    if gpu_util::device().is_none() {
        return;
    }
    let d = dir("ok");
    let out = d.join("studio.exr");
    let text = render_tiny(&SMALL_MAP, &out, &d);
    assert!(
        text.contains("environment table:") && text.contains("4 samples per pixel"),
        "{text}"
    );
    let (w, h, px) = diffract::image_io::read_exr(&out).unwrap();
    assert_eq!((w, h), (8, 8));
    assert_eq!(
        diffract::image_io::exr_units(&out).unwrap().as_deref(),
        Some("linear sRGB of the radiance an environment-lit BRDF map reflects")
    );
    // Linear sRGB: a saturated diffraction colour may lie outside the gamut (a negative
    // component); every value is finite.
    assert!(px.iter().flatten().all(|c| c.is_finite()));
    assert!(px.iter().any(|p| p[1] > 0.0), "a black map");
}

#[test]
fn a_small_scene_under_an_environment_and_a_disc_light_is_drawn() {
    if gpu_util::device().is_none() {
        return;
    }
    let d = dir("scene");
    let scene = d.join("lit.toml");
    std::fs::write(
        &scene,
        "[mesh]\nbuiltin = \"sphere\"\n[material]\nheightfield = \"builtin:blazed\"\n\
         [output]\nwidth = 12\nheight = 8\nsupersample = 2\n\
         [environment]\nmap = \"builtin:studio\"\nintensity = 0.5\n\
         [[disc_light]]\ndirection = [0.0, -1.0, -1.0]\nangular_diameter_deg = 12.0\n\
         colour = [1.0, 0.8, 0.6]\n",
    )
    .unwrap();
    let out = d.join("lit.exr");
    let _ = std::fs::remove_file(&out);
    let o = render(
        &[
            "--scene",
            scene.to_str().unwrap(),
            "--no-sun",
            "--env-samples",
            "8",
            "--table-texel",
            "0.02",
            "--table-w-nodes",
            "4",
            "--table-step-nm",
            "20",
            "--no-cache",
            "-o",
            out.to_str().unwrap(),
        ],
        &d,
    );
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{}{}",
        text,
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        text.contains("environment table:")
            && text.contains("8 at most (up to 8, until the estimated noise is below ΔE2000 0.3)")
            && text.contains("1 disc light(s), sun off"),
        "{text}"
    );
    let (w, h, px) = diffract::image_io::read_exr(&out).unwrap();
    assert_eq!((w, h), (12, 8));
    assert!(px.iter().flatten().all(|c| c.is_finite()));
    assert!(px.iter().any(|p| p[1] > 0.0), "a black picture");
    // The file says what its numbers are.
    let units = diffract::image_io::exr_units(&out)
        .unwrap()
        .unwrap_or_default();
    assert!(
        units.starts_with("linear sRGB of a scene of radiance (× exposure ")
            && units.contains("/ S = "),
        "{units}"
    );
}

#[test]
fn a_second_render_reads_the_environment_table_from_the_cache() {
    if gpu_util::device().is_none() {
        return;
    }
    let d = dir("cache");
    let cache = d.join("cache");
    let _ = std::fs::remove_dir_all(&cache);
    let run = |out: &str| {
        let o = render(
            &[
                "--brdf-map",
                "--env",
                "builtin:sky",
                "--heightfield",
                "builtin:blazed",
                "--size",
                "8",
                "--env-samples",
                "4",
                "--table-texel",
                "0.02",
                "--table-w-nodes",
                "4",
                "--table-step-nm",
                "20",
                "--cache-dir",
                cache.to_str().unwrap(),
                "-o",
                out,
            ],
            &d,
        );
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).to_string()
    };
    let cold = run("cold.exr");
    let warm = run("warm.exr");
    assert!(cold.contains("built on CPU ("), "{cold}");
    assert!(warm.contains("loaded from cache, prepared in "), "{warm}");
    // The cache holds the samples as float32: the pictures agree to that rounding.
    let read = |f: &str| diffract::image_io::read_exr(&d.join(f)).unwrap().2;
    let (a, b) = (read("cold.exr"), read("warm.exr"));
    let peak = a.iter().flatten().fold(0f32, |m, c| m.max(c.abs()));
    let worst = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0f32, |m, (x, y)| m.max((x - y).abs()));
    assert!(peak > 0.1 && worst < 1e-5 * peak, "{worst} of {peak}");
}

/// Off a terminal, a table build that outlasts the progress period prints progress lines
/// into the log before its report line (the period shortened to 0.5 s for the test).
#[test]
fn a_long_environment_table_build_prints_progress_into_a_redirected_log() {
    if gpu_util::device().is_none() {
        return;
    }
    let d = dir("progress");
    let out = Command::new(env!("CARGO_BIN_EXE_diffract"))
        .args([
            "render",
            "--brdf-map",
            "--size",
            "4",
            "--env",
            "builtin:white",
            "--env-samples",
            "4",
            "--table-step-nm",
            "10",
            "--table-texel",
            "0.01",
            "--no-cache",
            "-o",
        ])
        .arg(d.join("p.exr"))
        .env("DIFFRACT_PROGRESS_SECS", "0.5")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    // A line of the build under way: fewer planes done than there are.
    let mut during = err.lines().filter_map(|l| {
        let rest = l.strip_prefix("environment table: ")?;
        let (done, _) = rest.split_once(" (")?;
        let (pos, len) = done.split_once('/')?;
        Some((pos.parse::<u64>().ok()?, len.parse::<u64>().ok()?))
    });
    assert!(
        during.any(|(pos, len)| pos < len),
        "no progress line during the table build:\n{err}"
    );
    assert!(err.contains(" s left"), "{err}");
}
