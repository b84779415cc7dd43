//! The desktop viewer under Xvfb with lavapipe: it opens a window, presents frames through the
//! swapchain with validation on and no messages, and its screenshot matches the offscreen
//! render of the same camera within the golden-image tolerance (tests/gpu_golden.rs). Also:
//! no display → one `error:` line; a shader edit with a syntax error reports file:line and
//! keeps the last good SPIR-V.
//!
//! Needs `Xvfb` (the `xvfb` package, installed by `.ci/run`). Without it the window tests
//! print SKIPPED and return; with `DIFFRACT_REQUIRE_XVFB=1` they fail instead.

mod gpu_util;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use diffract::colour::linear_to_srgb8;
use diffract::image_io;
use diffract::scene::Scene;
use diffract::view::reload::ShaderReload;
use gpu_util::*;

/// Limits of tests/gpu_golden.rs: the swapchain path must agree with the offscreen path as
/// closely as lavapipe agrees with a golden image.
const MAX_MEAN_DELTA_E: f64 = 0.5;
const MAX_P95_DELTA_E: f64 = 1.5;
const MAX_P99_ABS: f64 = 0.03;

fn srgb8_to_linear(v: u8) -> f32 {
    let c = v as f64 / 255.0;
    (if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }) as f32
}

fn output_dir() -> PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-output");
    std::fs::create_dir_all(&d).expect("create target/test-output");
    d
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-viewer-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

/// An Xvfb server on a free display number, killed on drop.
struct Xvfb {
    child: Child,
    display: String,
}

impl Xvfb {
    /// `None` (after printing SKIPPED) when Xvfb is not installed.
    fn start() -> Option<Xvfb> {
        let base = 50 + (std::process::id() % 200);
        for n in base..base + 20 {
            if Path::new(&format!("/tmp/.X11-unix/X{n}")).exists()
                || Path::new(&format!("/tmp/.X{n}-lock")).exists()
            {
                continue;
            }
            let child = match Command::new("Xvfb")
                .args([
                    &format!(":{n}"),
                    "-screen",
                    "0",
                    "320x240x24",
                    "-nolisten",
                    "tcp",
                ])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
            {
                Ok(c) => c,
                Err(e) => {
                    if std::env::var("DIFFRACT_REQUIRE_XVFB").is_ok_and(|v| v == "1") {
                        panic!("DIFFRACT_REQUIRE_XVFB=1 but Xvfb cannot start: {e}");
                    }
                    eprintln!("SKIPPED: cannot start Xvfb ({e}); install the xvfb package");
                    return None;
                }
            };
            let mut x = Xvfb {
                child,
                display: format!(":{n}"),
            };
            let socket = format!("/tmp/.X11-unix/X{n}");
            let start = Instant::now();
            while start.elapsed() < Duration::from_secs(20) {
                if Path::new(&socket).exists() {
                    return Some(x);
                }
                if let Ok(Some(_)) = x.child.try_wait() {
                    break; // lost a race for this display number: try the next
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = x.child.kill();
        }
        panic!("Xvfb is installed but no display could be started");
    }
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn diffract() -> Command {
    Command::new(env!("CARGO_BIN_EXE_diffract"))
}

fn rainbow_scene_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/rainbow_64.toml")
}

/// The viewer presents 6 frames under validation and its last swapchain image equals the
/// offscreen render of the same scene and camera.
#[test]
fn screenshot_matches_offscreen_render() {
    let Some(x) = Xvfb::start() else { return };
    let dir = temp_dir("shot");
    let shot = dir.join("view.png");
    let out = diffract()
        .args(["view", "--scene"])
        .arg(rainbow_scene_path())
        .args([
            "--variant",
            "flss",
            "--frames",
            "6",
            "--vsync",
            "off",
            "--screenshot",
        ])
        .arg(&shot)
        .env("DISPLAY", &x.display)
        .env_remove("WAYLAND_DISPLAY")
        .env("DIFFRACT_VALIDATION", "1")
        .env("DIFFRACT_CACHE", &dir)
        .output()
        .expect("run diffract view");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "diffract view failed ({}):\n{stdout}\n{stderr}",
        out.status
    );
    assert!(
        !stderr.contains("[vulkan"),
        "validation messages from the viewer:\n{stderr}"
    );
    assert!(
        stdout.contains("keys and mouse"),
        "key help printed:\n{stdout}"
    );

    let (w, h, px) = image_io::read_png_rgb8(&shot).expect("screenshot PNG");
    let scene = Scene::load(&rainbow_scene_path()).expect("scene");
    assert_eq!((w, h), (scene.output.width, scene.output.height));
    let Some(mut r) = renderer() else { return };
    let prepared = prepare(&scene.material);
    let frame = r.render_scene(&scene, &prepared).expect("offscreen render");
    assert_no_validation(&r);
    let expected: Vec<[f32; 3]> = frame
        .rgb
        .iter()
        .map(|p| linear_to_srgb8(p.map(|c| c as f64), 1.0).map(srgb8_to_linear))
        .collect();
    let actual: Vec<[f32; 3]> = px.iter().map(|p| p.map(srgb8_to_linear)).collect();
    // Not trivially equal: the scene has colour, so a black screenshot would fail.
    assert!(
        expected.iter().any(|p| p.iter().any(|&c| c > 0.05)),
        "the offscreen render is empty"
    );
    let diff = image_io::compare_images(&actual, &expected);
    eprintln!("viewer vs offscreen: {diff}");
    let ok = diff.mean_delta_e <= MAX_MEAN_DELTA_E
        && diff.p95_delta_e <= MAX_P95_DELTA_E
        && diff.p99_abs <= MAX_P99_ABS;
    if !ok {
        let o = output_dir();
        image_io::write_png_srgb(&o.join("viewer_actual.png"), w, h, &actual, 1.0).unwrap();
        image_io::write_png_srgb(&o.join("viewer_expected.png"), w, h, &expected, 1.0).unwrap();
        let d = image_io::difference_image(&actual, &expected);
        image_io::write_png_srgb(&o.join("viewer_diff.png"), w, h, &d, 10.0).unwrap();
        panic!(
            "viewer screenshot differs from the offscreen render: {diff} (limits: mean ΔE \
             {MAX_MEAN_DELTA_E}, p95 ΔE {MAX_P95_DELTA_E}, p99 |Δ| {MAX_P99_ABS}); see {}",
            o.display()
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// No display: one `error:` line, non-zero exit, no panic.
#[test]
fn no_display_is_one_error_line() {
    for display in [None, Some(":4711")] {
        let mut cmd = diffract();
        cmd.args(["view", "--variant", "flss", "--frames", "1"])
            .env_remove("WAYLAND_DISPLAY")
            .env_remove("WAYLAND_SOCKET");
        match display {
            Some(d) => cmd.env("DISPLAY", d),
            None => cmd.env_remove("DISPLAY"),
        };
        let out = cmd.output().expect("run diffract view");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success(),
            "{display:?}: exit status {}",
            out.status
        );
        assert_eq!(
            out.status.code(),
            Some(1),
            "{display:?}: not a panic: {stderr}"
        );
        let lines: Vec<&str> = stderr.lines().collect();
        assert_eq!(lines.len(), 1, "{display:?}: one line expected:\n{stderr}");
        assert!(
            lines[0].starts_with("error: cannot show a window:"),
            "{display:?}: {stderr}"
        );
    }
}

/// A syntax error in a watched shader: the reload reports `flss.frag:<line>` and the last
/// good SPIR-V stays; fixing it compiles again.
#[test]
fn shader_syntax_error_keeps_last_good_and_reports_line() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("glsl");
    let dir = temp_dir("glsl");
    for e in std::fs::read_dir(&src).unwrap() {
        let p = e.unwrap().path();
        std::fs::copy(&p, dir.join(p.file_name().unwrap())).unwrap();
    }
    let mut reload = ShaderReload::new(&dir).expect("watch");
    assert!(!reload.changed().unwrap(), "nothing changed yet");
    let good = reload
        .compile_all()
        .expect("the shipped shaders compile")
        .clone();
    assert!(good.contains_key("flss.frag") && good.contains_key("diffraction.vert"));

    let frag = dir.join("flss.frag");
    let original = std::fs::read_to_string(&frag).unwrap();
    // Append a broken declaration: its 1-based line number is one past the last line.
    let bad_line = original.lines().count() + 1;
    let mut broken: Vec<String> = original.lines().map(str::to_string).collect();
    broken.push("float oops = ;".to_string());
    // Make sure the modification time moves even on coarse file systems.
    std::thread::sleep(Duration::from_millis(20));
    std::fs::write(&frag, broken.join("\n") + "\n").unwrap();
    let bump = std::time::SystemTime::now() + Duration::from_secs(2);
    std::fs::File::options()
        .write(true)
        .open(&frag)
        .unwrap()
        .set_modified(bump)
        .unwrap();
    assert!(reload.changed().unwrap(), "the edit is seen");
    let err = reload.compile_all().expect_err("a syntax error must fail");
    eprintln!("{err}");
    assert!(
        err.contains(&format!("flss.frag:{bad_line}:")),
        "message names flss.frag:{bad_line}: {err}"
    );
    assert_eq!(reload.last_good(), &good, "the last good SPIR-V is kept");

    // The kept SPIR-V still draws: a pass built from it renders like the built-in one.
    if let Some(mut r) = renderer() {
        let scene = Scene::load(&rainbow_scene_path()).expect("scene");
        let p = prepare(&scene.material);
        r.set_variant(diffract::render::VariantKind::Flss);
        let built_in = r.render_scene(&scene, &p).expect("built-in");
        r.set_shader_overrides(reload.last_good().clone());
        let reloaded = r.render_scene(&scene, &p).expect("reloaded");
        assert_no_validation(&r);
        let diff = image_io::compare_images(&reloaded.rgb, &built_in.rgb);
        assert!(diff.p99_abs < 1e-4, "same source, same image: {diff}");
    }

    std::fs::write(&frag, &original).unwrap();
    std::fs::File::options()
        .write(true)
        .open(&frag)
        .unwrap()
        .set_modified(bump + Duration::from_secs(2))
        .unwrap();
    assert!(reload.changed().unwrap());
    reload.compile_all().expect("fixed again");
    let _ = std::fs::remove_dir_all(&dir);
}
