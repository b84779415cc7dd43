//! `diffract render` fails with one clear error line, never a panic: a missing or broken
//! scene file, a missing height field, and out-of-range map parameters.

mod gpu_util;

use std::path::Path;

use clap::Parser;
use diffract::cli::render::{run, RenderArgs};
use diffract::Error;
use gpu_util::*;

#[derive(Parser)]
struct Cli {
    #[command(flatten)]
    args: RenderArgs,
}

fn args(list: &[&str]) -> RenderArgs {
    Cli::try_parse_from(std::iter::once("render").chain(list.iter().copied()))
        .expect("arguments parse")
        .args
}

fn tmp(name: &str) -> std::path::PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-output/errors");
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

#[test]
fn missing_scene_file_names_the_file() {
    let e = run(&args(&["--scene", "no/such/scene.toml", "--no-cache"])).unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.contains("no/such/scene.toml"), "{msg}");
    assert!(!msg.contains('\n'), "one line: {msg}");
}

#[test]
fn bad_scene_reports_the_line() {
    let path = tmp("bad.toml");
    std::fs::write(&path, "[camera]\neye = [0.0, 1.0]\nfov_y_deg = \"wide\"\n").unwrap();
    let e = run(&args(&["--scene", path.to_str().unwrap(), "--no-cache"])).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, Error::Parse { .. }), "{e:?}");
    assert!(msg.contains("bad.toml") && msg.contains("line"), "{msg}");
}

#[test]
fn missing_heightfield_names_the_file() {
    let path = tmp("missing_hf.toml");
    std::fs::write(&path, "[material]\nheightfield = \"nowhere/skin.png\"\n").unwrap();
    let e = run(&args(&["--scene", path.to_str().unwrap(), "--no-cache"])).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("skin.png"), "{msg}");
    assert!(!msg.contains('\n'), "one line: {msg}");
}

#[test]
fn unknown_output_extension_is_an_error_not_a_panic() {
    let Some(_) = renderer() else { return };
    let out = tmp("map.bmp");
    let e = run(&args(&[
        "--brdf-map",
        "--size",
        "8",
        "--heightfield",
        "builtin:blazed",
        "--terms",
        "2",
        "--window-radius",
        "1",
        "--lambda-step-nm",
        "50",
        "--no-cache",
        "-o",
        out.to_str().unwrap(),
    ]))
    .unwrap_err();
    assert!(e.to_string().contains("map.bmp"), "{e}");
}

#[test]
fn out_of_range_map_parameters_are_invalid() {
    let Some(mut r) = renderer() else { return };
    let p = prepare(&small_material(
        "builtin:blazed",
        diffract::spectrum::Expansion::Taylor,
        2,
        1,
    ));
    for (theta, size, lambda) in [
        (30.0, 0, None),
        (30.0, 5000, None),
        (95.0, 8, None),
        (f64::NAN, 8, None),
        (30.0, 8, Some(900.0)),
        (30.0, 8, Some(f64::INFINITY)),
    ] {
        match r.render_brdf_map(&p, theta, 0.0, size, lambda) {
            Err(Error::Invalid { .. }) => {}
            other => panic!(
                "θ {theta}, size {size}, λ {lambda:?}: {:?}",
                other.map(|f| f.width)
            ),
        }
    }
    assert_no_validation(&r);
}

#[test]
fn map_writes_exr_and_png() {
    let Some(_) = renderer() else { return };
    let out = tmp("map.exr");
    let png = out.with_extension("png");
    let _ = std::fs::remove_file(&png);
    run(&args(&[
        "--brdf-map",
        "--size",
        "16",
        "--theta-i",
        "20",
        "--heightfield",
        "builtin:blazed",
        "--terms",
        "2",
        "--window-radius",
        "1",
        "--lambda-step-nm",
        "50",
        "--png",
        "--no-cache",
        "-o",
        out.to_str().unwrap(),
    ]))
    .expect("render map");
    let (w, h, px) = diffract::image_io::read_exr(&out).expect("read EXR");
    assert_eq!((w, h), (16, 16));
    assert!(px.iter().flatten().all(|c| c.is_finite()));
    assert!(png.exists(), "--png writes {}", png.display());
}

/// The completion line of `render --brdf-map -o X.exr --png` names the PNG it wrote beside
/// the EXR as well as the EXR.
#[test]
fn the_completion_line_names_the_png_beside_the_exr() {
    let Some(_) = renderer() else { return };
    let out = tmp("named.exr");
    let png = out.with_extension("png");
    let _ = std::fs::remove_file(&png);
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_diffract"))
        .args([
            "render",
            "--brdf-map",
            "--size",
            "8",
            "--variant",
            "flss",
            "--heightfield",
            "builtin:blazed",
            "--terms",
            "2",
            "--window-radius",
            "1",
            "--lambda-step-nm",
            "50",
            "--png",
            "--no-cache",
            "-o",
        ])
        .arg(&out)
        .env("DIFFRACT_VALIDATION", "1")
        .output()
        .expect("run diffract");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let line = stdout.lines().last().unwrap_or_default();
    assert!(
        line.contains(&format!("{} + {}", out.display(), png.display())),
        "{line}"
    );
    assert!(png.exists());
}

/// A BRDF map's PNG without `--exposure` gets one chosen from the map and says which: its
/// diffraction shows (many lit pixels), where exposure 1 leaves the map nearly black; an
/// exposure asked for is kept and not said.
#[test]
fn a_map_png_without_an_exposure_shows_its_orders_and_says_its_exposure() {
    let Some(_) = renderer() else { return };
    let run = |name: &str, extra: &[&str]| {
        let out = tmp(name);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_diffract"))
            .args([
                "render",
                "--brdf-map",
                "--size",
                "65",
                "--table-step-nm",
                "20",
                "--table-texel",
                "0.01",
                "--no-cache",
                "-o",
            ])
            .arg(&out)
            .args(extra)
            .env("DIFFRACT_VALIDATION", "1")
            .output()
            .expect("run diffract");
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{err}");
        let img = image::open(&out).unwrap().to_rgb8();
        let lit = img.pixels().filter(|p| p.0.iter().any(|&c| c > 24)).count();
        (err, lit)
    };
    let (said, lit_auto) = run("auto.png", &[]);
    let line = said
        .lines()
        .find(|l| l.starts_with("exposure of the PNG: "))
        .unwrap_or_else(|| panic!("no exposure line:\n{said}"));
    assert!(line.contains("--exposure sets it"), "{line}");
    let (said, lit_one) = run("one.png", &["--exposure", "1"]);
    assert!(!said.contains("exposure of the PNG"), "{said}");
    assert!(
        lit_auto > 4 * lit_one.max(1),
        "lit pixels: chosen {lit_auto}, at 1 {lit_one}"
    );
}
