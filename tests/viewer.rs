//! The desktop viewer under Xvfb with lavapipe: it opens a window, presents frames through the
//! swapchain with validation on and no messages, and its screenshot matches the offscreen
//! render of the same camera within the golden-image tolerance (tests/gpu_golden.rs); with
//! the BRDF map beside the mesh (`B`) the map matches `render_brdf_map` of the same light;
//! a window resized (and minimised) during the run recreates its swapchain and the next
//! screenshot has the new size. Also: synthetic mouse and key input drives the controls;
//! no display → one `error:` line; a shader edit with a syntax error reports file:line and
//! keeps the last good SPIR-V; a material edit rebuilds the table in the background while
//! frames go on, and the picture after it is the edited material's. Under an environment
//! (`--env`, `E`) the picture accumulated to the cap equals `render --env` of the same
//! scene, the BRDF map beside it `render_env_brdf_map`, a turn of the map starts the
//! accumulation again, and bad environment flags get one error line.
//!
//! Needs `Xvfb` (the `xvfb` package, installed by `.ci/run`). Without it the window tests
//! print SKIPPED and return; with `DIFFRACT_REQUIRE_XVFB=1` they fail instead.

mod gpu_util;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use diffract::brdf::truncation::{Precision, Reach};
use diffract::colour::{linear_to_srgb8, xyz_to_linear_srgb};
use diffract::heightfield::HeightField;
use diffract::image_io;
use diffract::light::env::{EnvMap, EnvSource};
use diffract::render::env::{render_env_brdf_map, EnvLighting, EnvMapRequest};
use diffract::render::VariantKind;
use diffract::scene::Scene;
use diffract::view::input::{
    tangent_frame_at_view, Controls, Effect, MaterialEdit, ViewState, HELP, MATERIAL_STEP,
    SHIPPED_FIELDS,
};
use diffract::view::reload::ShaderReload;
use glam::Vec3;
use gpu_util::*;
use winit::dpi::PhysicalPosition;
use winit::event::{MouseButton, MouseScrollDelta};
use winit::keyboard::{Key, ModifiersState, NamedKey};

// The limits of the golden images (gpu_util::golden): the swapchain path must agree with
// the offscreen path as closely as lavapipe agrees with a golden image.
use gpu_util::golden::{
    output_dir, srgb8_to_linear, MAX_MEAN_DELTA_E, MAX_P95_DELTA_E, MAX_P99_ABS,
};

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
    ///
    /// Tests run on parallel threads of one process, so each call takes its own display
    /// number from a counter; and a server counts as started only when the display's lock
    /// file names this child. (Seeing the socket alone is not enough: it may belong to a
    /// server another test started on the same number, which dies with that test.)
    fn start() -> Option<Xvfb> {
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let base = 50 + (std::process::id() % 200) * 20;
        for _ in 0..40 {
            let n = base + NEXT.fetch_add(1, Ordering::Relaxed) % 4000;
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
            let lock = format!("/tmp/.X{n}-lock");
            let pid = x.child.id().to_string();
            let start = Instant::now();
            while start.elapsed() < Duration::from_secs(20) {
                let ours = std::fs::read_to_string(&lock).is_ok_and(|l| l.trim() == pid);
                if ours && Path::new(&socket).exists() {
                    return Some(x);
                }
                if let Ok(Some(_)) = x.child.try_wait() {
                    break; // lost a race for this display number: try the next
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            // `x` drops here: the child is killed and reaped
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
    // A screenshot replaces its file by a rename: a hard link to the old file keeps it.
    std::fs::write(&shot, b"the old screenshot").unwrap();
    let old = dir.join("old.png");
    std::fs::hard_link(&shot, &old).unwrap();
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

    assert_eq!(
        std::fs::read(&old).unwrap(),
        b"the old screenshot",
        "the screenshot was written into the old file instead of a new one renamed over it"
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

/// Bad viewer options (the map's exposure, the `--at` hook): one `error:` line naming the
/// option, exit 1, before any window opens.
#[test]
fn bad_view_options_are_one_error_line() {
    for (args, names) in [
        (&["--map-exposure", "-1"][..], "map exposure"),
        (&["--map-exposure", "inf"][..], "map exposure"),
        (&["--exposure", "-2"][..], "exposure"),
        (&["--at", "b"][..], "--at"),
        (&["--at", "x:b"][..], "--at"),
        (&["--at", "1:resize=0x4"][..], "--at"),
        (&["--at", "1:minimise=0"][..], "--at"),
        (&["--at", "1:jump"][..], "--at"),
    ] {
        let out = diffract()
            .args(["view", "--frames", "1"])
            .args(args)
            .env_remove("DISPLAY")
            .env_remove("WAYLAND_DISPLAY")
            .output()
            .expect("run diffract view");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        let lines: Vec<&str> = stderr.lines().collect();
        assert_eq!(lines.len(), 1, "{args:?}: one line expected:\n{stderr}");
        assert!(
            lines[0].starts_with("error: invalid ") && lines[0].contains(names),
            "{args:?}: {stderr}"
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

fn key(c: &str) -> Key {
    Key::Character(c.into())
}

fn eye_distance(c: &Controls) -> f32 {
    Vec3::from(c.state.camera.eye).distance(Vec3::from(c.state.camera.target))
}

/// Synthetic mouse and keys through the viewer's input handling: drags orbit, pan and turn
/// the light, the wheel zooms, keys change exposure, variant, switches and the map, `H`
/// asks for the help, and nothing moves without a button held.
#[test]
fn synthetic_input_drives_the_controls() {
    let scene = Scene::load(&rainbow_scene_path()).expect("scene");
    let mut c = Controls::new(ViewState::from_scene(&scene), VariantKind::Flss);
    let start = c.clone();
    let r0 = eye_distance(&c);

    // Left drag orbits: the eye moves on its sphere about the fixed target.
    c.button(MouseButton::Left, true);
    assert_eq!(
        c.cursor_moved(10.0, 10.0),
        Effect::None,
        "first position: no drag yet"
    );
    assert_eq!(c.cursor_moved(40.0, 25.0), Effect::View);
    assert_ne!(
        c.state.camera.eye, start.state.camera.eye,
        "orbit moves the eye"
    );
    assert_eq!(c.state.camera.target, start.state.camera.target);
    assert!(
        (eye_distance(&c) - r0).abs() < 1e-4 * r0,
        "orbit keeps the distance"
    );
    assert_eq!(
        c.state.light_dir, start.state.light_dir,
        "orbit leaves the light"
    );
    c.button(MouseButton::Left, false);

    // No button: moving does nothing.
    let before = c.state.camera.clone();
    assert_eq!(c.cursor_moved(80.0, 80.0), Effect::None);
    assert_eq!(c.state.camera.eye, before.eye);

    // Middle drag and shift + left drag pan: eye and target shift together.
    for (k, (button, shift)) in [(MouseButton::Middle, false), (MouseButton::Left, true)]
        .into_iter()
        .enumerate()
    {
        let before = c.state.camera.clone();
        c.modifiers(if shift {
            ModifiersState::SHIFT
        } else {
            ModifiersState::empty()
        });
        c.button(button, true);
        assert_eq!(c.cursor_moved(100.0 + 30.0 * k as f64, 90.0), Effect::View);
        c.button(button, false);
        c.modifiers(ModifiersState::empty());
        let shift_eye = Vec3::from(c.state.camera.eye) - Vec3::from(before.eye);
        let shift_target = Vec3::from(c.state.camera.target) - Vec3::from(before.target);
        assert!(
            shift_eye.length() > 1e-3,
            "{button:?}: pan moves the camera"
        );
        assert!(
            shift_eye.distance(shift_target) < 1e-5,
            "{button:?}: eye and target move together"
        );
    }

    // Wheel: a line up brings the eye 10 % closer; pixel deltas count 40 px per line.
    let r = eye_distance(&c);
    assert_eq!(c.wheel(MouseScrollDelta::LineDelta(0.0, 2.0)), Effect::View);
    assert!((eye_distance(&c) - 0.81 * r).abs() < 1e-4 * r);
    assert_eq!(
        c.wheel(MouseScrollDelta::PixelDelta(PhysicalPosition::new(
            0.0, -80.0
        ))),
        Effect::View
    );
    assert!((eye_distance(&c) - r).abs() < 1e-4 * r, "zoomed back out");

    // Right drag and arrow keys turn the light; the camera stays.
    let cam = c.state.camera.clone();
    let l0 = c.state.light_dir;
    c.button(MouseButton::Right, true);
    c.cursor_moved(0.0, 0.0);
    assert_eq!(c.cursor_moved(20.0, 0.0), Effect::View);
    c.button(MouseButton::Right, false);
    assert!(
        c.state.light_dir.distance(l0) > 0.05,
        "right drag turns the light"
    );
    assert!((c.state.light_dir.length() - 1.0).abs() < 1e-5);
    assert_eq!(c.state.camera.eye, cam.eye);
    for arrow in [NamedKey::ArrowLeft, NamedKey::ArrowUp] {
        let l = c.state.light_dir;
        assert_eq!(c.key(&Key::Named(arrow)), Effect::View);
        assert!(
            c.state.light_dir.distance(l) > 0.02,
            "{arrow:?} turns the light"
        );
    }

    // Exposure.
    let e = c.state.exposure;
    assert_eq!(c.key(&key("+")), Effect::View);
    assert!((c.state.exposure - 1.25 * e).abs() < 1e-6);
    c.key(&key("-"));
    c.key(&key("-"));
    assert!((c.state.exposure - e / 1.25).abs() < 1e-6);
    let m = c.state.map_exposure;
    assert_eq!(c.key(&key("]")), Effect::View);
    assert!((c.state.map_exposure - 1.25 * m).abs() < 1e-4);
    assert!(
        (c.state.exposure - e / 1.25).abs() < 1e-6,
        "] leaves the mesh's exposure"
    );
    c.key(&key("["));
    assert!((c.state.map_exposure - m).abs() < 1e-4);

    // V cycles every variant and wraps around.
    let mut seen = vec![c.variant];
    for _ in 0..VariantKind::ALL.len() {
        match c.key(&key("v")) {
            Effect::Rebuild(line) => assert!(line.contains(c.variant.name()), "{line}"),
            other => panic!("V: {other:?}"),
        }
        seen.push(c.variant);
    }
    assert_eq!(seen.first(), seen.last(), "wraps around: {seen:?}");
    for k in VariantKind::ALL {
        assert!(seen.contains(&k), "{k:?} reached: {seen:?}");
    }

    // F / S / T toggle the switches (upper case too) and ask for a rebuild.
    let s0 = c.state.clone();
    assert!(matches!(c.key(&key("f")), Effect::Rebuild(l) if l.starts_with("Fresnel")));
    assert!(matches!(c.key(&key("S")), Effect::Rebuild(l) if l.starts_with("shadowing")));
    assert!(matches!(c.key(&key("t")), Effect::Rebuild(l) if l.starts_with("texture")));
    assert_eq!(
        (c.state.fresnel, c.state.shadowing, c.state.texture),
        (!s0.fresnel, !s0.shadowing, !s0.texture)
    );

    // B toggles the map, H the help, P a screenshot, Q / Esc quit, others nothing.
    assert!(!c.map);
    assert_eq!(c.key(&key("b")), Effect::Map);
    assert!(c.map);
    assert_eq!(c.key(&key("B")), Effect::Map);
    assert!(!c.map);
    assert_eq!(c.key(&key("h")), Effect::Help);
    assert!(HELP.contains("BRDF map"), "the help lists B:\n{HELP}");
    assert_eq!(c.key(&key("p")), Effect::Screenshot);
    assert_eq!(c.key(&key("q")), Effect::Quit);
    assert_eq!(c.key(&Key::Named(NamedKey::Escape)), Effect::Quit);
    assert_eq!(c.key(&key("y")), Effect::None);
    assert_eq!(c.key(&Key::Named(NamedKey::Tab)), Effect::None);

    // E asks for the next environment; , and . turn it by 5°; R held turns it with a left
    // drag (0.5° a pixel) instead of orbiting, until R is released.
    assert_eq!(c.key(&key("e")), Effect::Env);
    assert!(HELP.contains("next environment"), "{HELP}");
    assert_eq!(c.key(&key(".")), Effect::View);
    assert_eq!(c.key(&key(".")), Effect::View);
    assert_eq!(c.key(&key(",")), Effect::View);
    assert!((c.state.env_rotate_deg - 5.0).abs() < 1e-12);
    let eye = c.state.camera.eye;
    assert_eq!(c.key(&key("r")), Effect::None);
    c.button(MouseButton::Left, true);
    c.cursor_left();
    c.cursor_moved(10.0, 10.0);
    assert_eq!(c.cursor_moved(30.0, 10.0), Effect::View);
    assert!((c.state.env_rotate_deg - 15.0).abs() < 1e-9);
    assert_eq!(
        c.state.camera.eye, eye,
        "the drag turned the map, not the camera"
    );
    c.key_released(&key("r"));
    assert_eq!(c.cursor_moved(40.0, 10.0), Effect::View);
    assert!((c.state.env_rotate_deg - 15.0).abs() < 1e-9);
    assert_ne!(c.state.camera.eye, eye, "without R the drag orbits");
    c.button(MouseButton::Left, false);

    // Z / X scale the heights, K / L the coherence length (by 1.25 a step, upper case
    // too), N cycles the scene's own field and every shipped one; each asks for a material.
    assert_eq!(c.material, MaterialEdit::default());
    let material_line = |e: Effect| match e {
        Effect::Material(line) => line,
        other => panic!("a material key gave {other:?}"),
    };
    assert!(material_line(c.key(&key("x"))).contains("height ×1.2500"));
    assert!(material_line(c.key(&key("X"))).contains("height ×1.5625"));
    assert!(material_line(c.key(&key("z"))).contains("height ×1.2500"));
    assert_eq!(c.material.height_steps, 1);
    assert!((c.material.height_scale() - MATERIAL_STEP).abs() < 1e-12);
    assert!(material_line(c.key(&key("k"))).contains("coherence length ×0.8000"));
    assert!(material_line(c.key(&key("L"))).contains("coherence length ×1.0000"));
    assert!(material_line(c.key(&key("l"))).contains("coherence length ×1.2500"));
    assert_eq!(c.material.coherence_steps, 1);
    let mut fields = vec![c.material.heightfield("scene.png").to_string()];
    for _ in 0..=SHIPPED_FIELDS.len() {
        let line = material_line(c.key(&key("n")));
        let field = c.material.heightfield("scene.png").to_string();
        assert!(
            line.contains(&field) || (field == "scene.png" && line.contains("scene's own")),
            "{line} names {field}"
        );
        fields.push(field);
    }
    assert_eq!(fields.first(), fields.last(), "N wraps around: {fields:?}");
    for f in SHIPPED_FIELDS {
        assert!(fields.iter().any(|g| g == f), "{f} reached: {fields:?}");
    }
    assert!(HELP.contains("coherence length") && HELP.contains("next height field"));
    // The height and coherence edits stayed through the field changes.
    assert_eq!(
        (c.material.height_steps, c.material.coherence_steps),
        (1, 1)
    );
}

/// The map's light is the scene light in the tangent frame of the surface the camera looks
/// at: the rainbow plane (normal +z, tangent +x) lit along (0.23, 0, −0.973) gives
/// θi = atan(0.23/0.973), φi = 180°; turning the light moves it; a light below the horizon
/// is laid onto it (θi = 90°).
#[test]
fn map_light_follows_the_light_control() {
    let scene = Scene::load(&rainbow_scene_path()).expect("scene");
    let mesh = scene.mesh.load().expect("mesh");
    let frame = tangent_frame_at_view(&mesh, &scene.camera).expect("frame");
    let mut c = Controls::new(ViewState::from_scene(&scene), VariantKind::Flss);
    let (theta, phi) = c.state.map_light_angles(frame);
    assert!(
        (theta - (0.23f64 / 0.973).atan().to_degrees()).abs() < 1e-3,
        "θi {theta}"
    );
    assert!((phi.abs() - 180.0).abs() < 1e-3, "φi {phi}");
    c.key(&Key::Named(NamedKey::ArrowRight));
    let (t2, p2) = c.state.map_light_angles(frame);
    assert!(
        (t2, p2) != (theta, phi),
        "the light key moves the map's light"
    );
    c.state.light_dir = Vec3::new(0.3, 0.0, 0.95).normalize();
    let (t3, _) = c.state.map_light_angles(frame);
    assert!((t3 - 90.0).abs() < 1e-9, "below the horizon: {t3}");
}

/// Runs `diffract view` on the display with validation on; fails on a non-zero exit or any
/// validation message. Returns stdout.
fn run_view(x: &Xvfb, dir: &Path, args: &[&str]) -> String {
    let out = diffract()
        .arg("view")
        .args(args)
        .env("DISPLAY", &x.display)
        .env_remove("WAYLAND_DISPLAY")
        .env("DIFFRACT_VALIDATION", "1")
        .env("DIFFRACT_CACHE", dir)
        .output()
        .expect("run diffract view");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "diffract view {args:?} failed ({}):\n{stdout}\n{stderr}",
        out.status
    );
    assert!(
        !stderr.contains("[vulkan"),
        "validation messages from the viewer:\n{stderr}"
    );
    stdout
}

/// Linear values of the sub-rectangle `(x0, y0, w, h)` of a screenshot.
fn crop(px: &[[u8; 3]], width: u32, (x0, y0, w, h): (u32, u32, u32, u32)) -> Vec<[f32; 3]> {
    let mut out = Vec::with_capacity((w * h) as usize);
    for y in y0..y0 + h {
        for x in x0..x0 + w {
            out.push(px[(y * width + x) as usize].map(srgb8_to_linear));
        }
    }
    out
}

/// Linear values after the 8-bit sRGB round trip the swapchain applies.
fn through_srgb8(rgb: &[[f32; 3]]) -> Vec<[f32; 3]> {
    rgb.iter()
        .map(|p| linear_to_srgb8(p.map(|c| c as f64), 1.0).map(srgb8_to_linear))
        .collect()
}

fn check_close(what: &str, actual: &[[f32; 3]], expected: &[[f32; 3]], side: (u32, u32)) {
    let diff = image_io::compare_images(actual, expected);
    eprintln!("{what}: {diff}");
    let ok = diff.mean_delta_e <= MAX_MEAN_DELTA_E
        && diff.p95_delta_e <= MAX_P95_DELTA_E
        && diff.p99_abs <= MAX_P99_ABS;
    if !ok {
        let o = output_dir();
        let (w, h) = side;
        let name = what.replace(' ', "_");
        image_io::write_png_srgb(&o.join(format!("{name}_actual.png")), w, h, actual, 1.0).unwrap();
        image_io::write_png_srgb(&o.join(format!("{name}_expected.png")), w, h, expected, 1.0)
            .unwrap();
        let d = image_io::difference_image(actual, expected);
        image_io::write_png_srgb(&o.join(format!("{name}_diff.png")), w, h, &d, 10.0).unwrap();
        panic!(
            "{what}: {diff} (limits: mean ΔE {MAX_MEAN_DELTA_E}, p95 ΔE {MAX_P95_DELTA_E}, p99 \
             |Δ| {MAX_P99_ABS}); see {}",
            o.display()
        );
    }
}

/// A height field whose map has broad lobes: a 64² map of the rainbow's blazed grating
/// misses its thin lines between pixel centres.
const GROWN: &str = "builtin:elaphe-grown";

/// `B` pressed after the first frame (through the `--at` hook, the path of a real key): the
/// map takes the left square of a 128×64 window, the mesh the right one. The map is lit
/// inside its disk, black outside, and equals the offscreen `render_brdf_map` of the same
/// light shown as sRGB with the same exposure (300); the mesh equals the offscreen render of its
/// 64×64 viewport. `H` prints the help again.
#[test]
fn map_mode_screenshot_matches_offscreen_brdf_map() {
    let Some(x) = Xvfb::start() else { return };
    let dir = temp_dir("map");
    let shot = dir.join("map.png");
    let scene_path = rainbow_scene_path();
    let stdout = run_view(
        &x,
        &dir,
        &[
            "--scene",
            scene_path.to_str().unwrap(),
            "--variant",
            "flss",
            "--width",
            "128",
            "--height",
            "64",
            "--vsync",
            "off",
            "--frames",
            "3",
            "--heightfield",
            GROWN,
            "--map-exposure",
            "300",
            "--exposure",
            "300",
            "--at",
            "1:b",
            "--at",
            "1:h",
            "--screenshot",
            shot.to_str().unwrap(),
        ],
    );
    assert!(stdout.contains("BRDF map on"), "{stdout}");
    assert_eq!(
        stdout.matches("keys and mouse").count(),
        2,
        "help at start and on H:\n{stdout}"
    );
    let (w, h, px) = image_io::read_png_rgb8(&shot).expect("screenshot PNG");
    assert_eq!((w, h), (128, 64));

    let mut scene = Scene::load(&scene_path).expect("scene");
    scene.material.heightfield = GROWN.into();
    scene.output.exposure = 300.0;
    let mesh = scene.mesh.load().expect("mesh");
    let frame = tangent_frame_at_view(&mesh, &scene.camera).expect("frame");
    let (theta, phi) = ViewState::from_scene(&scene).map_light_angles(frame);
    assert!(
        stdout.contains(&format!("θi = {theta:.6}°, φi = {phi:.6}°")),
        "the viewer drew the map for θi {theta}, φi {phi}:\n{stdout}"
    );

    let Some(mut r) = renderer() else { return };
    r.set_variant(VariantKind::Flss);
    let prepared = prepare(&scene.material);
    // The viewer's map shares the scene's table, and so its units: radiance on the
    // picture's scale (MODEL §10), which an offscreen map draws when asked.
    let response = diffract::brdf::table::Response::radiance(
        prepared.material.coherence_um,
        &prepared.shading,
    );
    r.set_table_options(diffract::render::TableOptions {
        response,
        ..r.table_options()
    });
    let side = 64;
    let map = r
        .render_brdf_map(&prepared, theta, phi, side, None)
        .expect("offscreen map");
    let exposure = 300.0;
    let expected: Vec<[f32; 3]> = through_srgb8(
        &map.rgb
            .iter()
            .map(|p| xyz_to_linear_srgb(p.map(|c| c as f64)).map(|c| (c * exposure) as f32))
            .collect::<Vec<_>>(),
    );
    let actual = crop(&px, w, (0, 0, side, side));
    let (mut lit, mut inside) = (0, 0);
    for j in 0..side {
        for i in 0..side {
            let p = actual[(j * side + i) as usize];
            match map_direction(i, j, side) {
                Some(_) => {
                    inside += 1;
                    lit += usize::from(p.iter().any(|&c| c > 0.02));
                }
                None => assert_eq!(p, [0.0; 3], "({i}, {j}) outside the disk is black"),
            }
        }
    }
    eprintln!("map: {lit} of {inside} disk pixels lit");
    assert!(
        lit * 50 >= inside,
        "the map is lit inside its disk: {lit} of {inside}"
    );
    check_close("viewer map", &actual, &expected, (side, side));

    let mut mesh_scene = scene.clone();
    mesh_scene.output.width = 64;
    mesh_scene.output.height = 64;
    let offscreen = r
        .render_scene(&mesh_scene, &prepared)
        .expect("offscreen render");
    assert_no_validation(&r);
    let expected = through_srgb8(&offscreen.rgb);
    let actual = crop(&px, w, (64, 0, 64, 64));
    let lit = actual
        .iter()
        .filter(|p| p.iter().any(|&c| c > 0.02))
        .count();
    eprintln!("mesh: {lit} of 4096 pixels lit");
    // Sparse sparkle at 64² (32 pixels above 0.02 under the sun's disc, which spreads each
    // glint thinner than a point light did): enough that a black mesh fails.
    assert!(lit >= 16, "the mesh beside the map is lit: {lit} pixels");
    check_close("viewer mesh beside the map", &actual, &expected, (64, 64));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A window resized during the run (the `--at` hook asks X for a new size, as a user's drag
/// would) recreates the swapchain without validation messages and the screenshot after it
/// has the new size and equals the offscreen render at that size; a zero extent (what a
/// minimised window reports) skips frames and recreates the swapchain when it ends.
#[test]
fn resize_and_minimise_recreate_the_swapchain() {
    let Some(x) = Xvfb::start() else { return };
    let dir = temp_dir("resize");
    let shot = dir.join("resized.png");
    let scene_path = rainbow_scene_path();
    let stdout = run_view(
        &x,
        &dir,
        &[
            "--scene",
            scene_path.to_str().unwrap(),
            "--variant",
            "flss",
            "--width",
            "48",
            "--height",
            "32",
            "--vsync",
            "off",
            "--frames",
            "6",
            "--at",
            "1:resize=80x48",
            "--at",
            "3:minimise=2",
            "--screenshot",
            shot.to_str().unwrap(),
        ],
    );
    assert!(
        stdout.contains("swapchain recreated: 48×32 → 80×48"),
        "resize recreates the swapchain:\n{stdout}"
    );
    assert!(
        stdout.contains("window minimised (zero extent): frames skipped"),
        "{stdout}"
    );
    assert!(
        stdout.contains("swapchain recreated: 80×48 → 80×48"),
        "recreated after the zero extent:\n{stdout}"
    );
    let (w, h, px) = image_io::read_png_rgb8(&shot).expect("screenshot PNG");
    assert_eq!((w, h), (80, 48), "the screenshot has the new size");

    let Some(mut r) = renderer() else { return };
    r.set_variant(VariantKind::Flss);
    let mut scene = Scene::load(&scene_path).expect("scene");
    scene.output.width = 80;
    scene.output.height = 48;
    let prepared = prepare(&scene.material);
    let offscreen = r.render_scene(&scene, &prepared).expect("offscreen render");
    assert_no_validation(&r);
    let actual = crop(&px, w, (0, 0, w, h));
    check_close(
        "viewer after resize",
        &actual,
        &through_srgb8(&offscreen.rgb),
        (w, h),
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Rebuilds while frames are in flight: `V` (flss → nmm), a resize, `F`, the BRDF map on
/// and off, with two frames in flight and validation on. The old passes and the old
/// swapchain are retired through the frame layer's deferred release (the viewer reports how
/// many objects it retired) and the device counted no `vkDeviceWaitIdle` by the end of the
/// run; validation stays silent (an object destroyed while a frame uses it would be
/// reported).
#[test]
fn variant_switch_and_resize_in_flight_make_no_idle_wait() {
    let Some(x) = Xvfb::start() else { return };
    let dir = temp_dir("in-flight");
    let shot = dir.join("after.png");
    let scene_path = rainbow_scene_path();
    let stdout = run_view(
        &x,
        &dir,
        &[
            "--scene",
            scene_path.to_str().unwrap(),
            "--variant",
            "flss",
            "--width",
            "48",
            "--height",
            "32",
            "--vsync",
            "off",
            "--frames",
            "9",
            "--at",
            "1:v",
            "--at",
            "2:resize=64x40",
            "--at",
            "3:f",
            "--at",
            "4:b",
            "--at",
            "6:b",
            "--at",
            "7:v",
            "--screenshot",
            shot.to_str().unwrap(),
        ],
    );
    assert!(stdout.contains("variant → nmm"), "{stdout}");
    assert!(stdout.contains("variant → pq"), "{stdout}");
    assert!(
        stdout.contains("swapchain recreated: 48×32 → 64×40"),
        "{stdout}"
    );
    assert!(stdout.contains("BRDF map on") && stdout.contains("BRDF map off"));
    let pacing = stdout
        .lines()
        .find(|l| l.starts_with("frame pacing:"))
        .unwrap_or_else(|| panic!("no frame pacing line:\n{stdout}"));
    eprintln!("{pacing}");
    let number_before = |what: &str| -> u64 {
        let head = &pacing[..pacing
            .find(what)
            .unwrap_or_else(|| panic!("{what}: {pacing}"))];
        head.trim_end()
            .rsplit(|c: char| !c.is_ascii_digit())
            .next()
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("{what}: {pacing}"))
    };
    assert_eq!(number_before(" frames in flight"), 2, "{pacing}");
    assert!(number_before(" submitted") >= 9, "{pacing}");
    // The passes of flss, nmm (F) and the first pq-less rebuilds, the map pass, the old
    // swapchain: at least one per rebuild.
    let retired = number_before(" objects retired");
    assert!(retired >= 5, "rebuilds retire their old objects: {pacing}");
    assert_eq!(
        number_before(" device idle waits"),
        0,
        "no vkDeviceWaitIdle in the frame path: {pacing}"
    );
    let (w, h, _) = image_io::read_png_rgb8(&shot).expect("screenshot PNG");
    assert_eq!((w, h), (64, 40));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `X` (heights ×1.25) pressed on the second settled frame of the default variant (a
/// table): the material loads and its table builds on worker threads while the window goes
/// on presenting frames (the viewer counts them); the first frame came from a coarse table
/// before the real one. The screenshot after the edit equals the offscreen render of the
/// scene with every height ×1.25, and differs from the unedited render by more.
#[test]
fn material_edit_rebuilds_in_the_background_while_frames_go_on() {
    let Some(x) = Xvfb::start() else { return };
    let dir = temp_dir("material-edit");
    let shot = dir.join("taller.png");
    let scene_path = rainbow_scene_path();
    let stdout = run_view(
        &x,
        &dir,
        &[
            "--scene",
            scene_path.to_str().unwrap(),
            "--vsync",
            "off",
            "--frames",
            "4",
            "--at",
            "1:x",
            "--screenshot",
            shot.to_str().unwrap(),
        ],
    );
    assert!(
        stdout.contains("(a coarse table first)") && stdout.contains("coarse table ready"),
        "the first frames come from a coarse table:\n{stdout}"
    );
    assert!(stdout.contains("height ×1.2500"), "{stdout}");
    assert!(
        stdout.contains("material loaded: builtin:blazed"),
        "{stdout}"
    );
    // The builds: the first (after its coarse stand-in) and the edit's.
    let meanwhile: Vec<u32> = stdout
        .lines()
        .filter(|l| l.starts_with("build ready in "))
        .map(|l| {
            l.split("; ")
                .nth(1)
                .and_then(|t| t.split(' ').next())
                .and_then(|n| n.parse().ok())
                .unwrap_or_else(|| panic!("{l}"))
        })
        .collect();
    assert_eq!(meanwhile.len(), 2, "two builds:\n{stdout}");
    // The window is not held by the build: the key press draws its frame at once, with the
    // old table (a still view then draws one a second until the build arrives).
    assert!(
        meanwhile[1] >= 1,
        "frames presented while the edited table built: {}\n{stdout}",
        meanwhile[1]
    );
    let (w, h, px) = image_io::read_png_rgb8(&shot).expect("screenshot PNG");
    let actual = crop(&px, w, (0, 0, w, h));

    let scene = Scene::load(&scene_path).expect("scene");
    let m = &scene.material;
    let hf = HeightField::load_source(&m.heightfield, m.dh_um, m.h_max_um)
        .and_then(|hf| hf.scaled(MATERIAL_STEP))
        .expect("scaled field");
    let plan = m
        .plan_loaded(&hf, &Reach::ALL, Precision::F32, &diffract::report::Stderr)
        .expect("plan");
    let taller = m
        .prepare_planned(hf, plan, None, &diffract::report::Stderr)
        .expect("taller material");
    let Some(mut r) = renderer() else { return };
    r.set_variant(VariantKind::Default.resolve());
    r.set_leave_out(true);
    let edited = r.render_scene(&scene, &taller).expect("offscreen render");
    let unedited = r
        .render_scene(&scene, &prepare(&scene.material))
        .expect("offscreen render");
    assert_no_validation(&r);
    let to_edited = image_io::compare_images(&actual, &through_srgb8(&edited.rgb));
    let to_unedited = image_io::compare_images(&actual, &through_srgb8(&unedited.rgb));
    eprintln!(
        "after the edit: against the taller render {to_edited}; against the unedited {to_unedited}"
    );
    assert!(
        to_unedited.mean_delta_e > 2.0 * to_edited.mean_delta_e.max(0.05),
        "the edit changed the picture towards the taller render: {to_edited} vs {to_unedited}"
    );
    check_close(
        "viewer after the height edit",
        &actual,
        &through_srgb8(&edited.rgb),
        (w, h),
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Closing the window while the default scene's first table builds (`Q` before the first
/// frame) stops the build at its next step: the viewer exits cleanly, every object of the
/// half-built table destroyed (validation on), and no build is reported ready.
#[test]
fn closing_during_a_build_stops_it_cleanly() {
    let Some(x) = Xvfb::start() else { return };
    let dir = temp_dir("close-while-building");
    let stdout = run_view(&x, &dir, &["--vsync", "off", "--at", "0:q"]);
    assert!(
        stdout.contains("building chebyshev-w in the background"),
        "{stdout}"
    );
    assert!(
        !stdout.contains("build ready"),
        "the quit came before the build finished:\n{stdout}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The default scene at 48×48 without supersampling (so the viewer's pixels are
/// `render`'s), written into `dir`; with `extra` appended.
fn small_default_scene(dir: &Path, extra: &str) -> PathBuf {
    let base = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/default_scene.toml"),
    )
    .unwrap();
    let text = base
        .replace("width = 512", "width = 48")
        .replace("height = 512", "height = 48")
        .replace("supersample = 3 ", "supersample = 1 ");
    assert!(
        text.contains("supersample = 1 "),
        "the default scene's [output] moved"
    );
    let path = dir.join("small.toml");
    std::fs::write(&path, text + extra).unwrap();
    path
}

/// A small environment table: 20 nm, texel 0.02 (a few seconds to build, then cached).
const SMALL_TABLE: [&str; 4] = ["--table-step-nm", "20", "--table-texel", "0.02"];

/// `diffract view` under `x` in `dir` (screenshots asked with `P` land there), the cache in
/// `dir`: stdout, after checking success and no validation message.
fn run_view_in(x: &Xvfb, dir: &Path, args: &[&str]) -> String {
    let out = diffract()
        .arg("view")
        .args(args)
        .current_dir(dir)
        .env("DISPLAY", &x.display)
        .env_remove("WAYLAND_DISPLAY")
        .env("DIFFRACT_VALIDATION", "1")
        .env("DIFFRACT_CACHE", dir.join("cache"))
        .output()
        .expect("run diffract view");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "diffract view {args:?} failed ({}):\n{stdout}\n{stderr}",
        out.status
    );
    assert!(
        !stderr.contains("[vulkan") && !stderr.contains("warning"),
        "validation messages or warnings from the viewer:\n{stderr}"
    );
    stdout
}

/// `diffract render` of `scene` with `args` into `dir/name` (the cache in `dir`): its
/// linear pixels.
fn render_env_png(dir: &Path, scene: &Path, args: &[&str], name: &str) -> Vec<[f32; 3]> {
    let png = dir.join(name);
    // The viewer's default under an environment is `chebyshev-w`, not `render`'s pair.
    let named = args.contains(&"--variant");
    let out = diffract()
        .args(["render", "--scene"])
        .arg(scene)
        .args(args)
        .args(if named {
            &[][..]
        } else {
            &["--variant", "chebyshev-w"][..]
        })
        .arg("--out")
        .arg(&png)
        .env("DIFFRACT_VALIDATION", "1")
        .env("DIFFRACT_CACHE", dir.join("cache"))
        .output()
        .expect("run diffract render");
    assert!(
        out.status.success(),
        "diffract render {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    read_linear(&png)
}

fn read_linear(png: &Path) -> Vec<[f32; 3]> {
    let (_, _, px) = image_io::read_png_rgb8(png).expect("PNG");
    px.iter().map(|p| p.map(srgb8_to_linear)).collect()
}

/// Mean ΔE2000 of the viewer's accumulated environment-lit picture against `render`'s of
/// the same scene and samples. The two integrate the same samples of the same sequence
/// (the viewer in batches, `render` in one dispatch), so they differ by the float
/// summation order and the 8-bit rounding alone: measured identical 8-bit pixels (mean
/// ΔE 0.000, 48×48, lavapipe); the limit leaves room for a device that rounds a sum
/// differently.
const MAX_ENV_MEAN_DELTA_E: f64 = 0.02;

/// `view --env builtin:sky --env-samples 16`: the picture accumulated to the cap is
/// `render --env builtin:sky --env-samples 16` of the same scene, and the log shows the
/// samples growing to the cap.
#[test]
fn environment_lit_view_matches_render() {
    let Some(x) = Xvfb::start() else { return };
    let dir = temp_dir("env-sky");
    let scene = small_default_scene(&dir, "");
    let scene_arg = scene.to_str().unwrap();
    let env = ["--env", "builtin:sky", "--env-samples", "16"];
    let mut args = vec!["--scene", scene_arg, "--vsync", "off", "--frames", "2"];
    args.extend(env);
    args.extend(SMALL_TABLE);
    args.extend(["--screenshot", "view.png"]);
    let stdout = run_view_in(&x, &dir, &args);
    // Growing: some count short of the cap (how many a frame takes follows its pace),
    // then the cap.
    let partial = stdout.lines().any(|l| {
        l.strip_prefix("sky: ")
            .and_then(|r| r.strip_suffix("/16 spp"))
            .and_then(|k| k.parse::<u32>().ok())
            .is_some_and(|k| (1..16).contains(&k))
    });
    assert!(partial, "{stdout}");
    assert!(stdout.contains("sky: 16/16 spp in "), "{stdout}");
    let view = read_linear(&dir.join("view.png"));
    let mut render_args = env.to_vec();
    render_args.extend(SMALL_TABLE);
    let render = render_env_png(&dir, &scene, &render_args, "render.png");
    let diff = image_io::compare_images(&view, &render);
    eprintln!("view vs render under builtin:sky, 16 spp: {diff}");
    assert!(
        diff.mean_delta_e <= MAX_ENV_MEAN_DELTA_E,
        "{diff} (limit mean ΔE {MAX_ENV_MEAN_DELTA_E})"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `view --variant volume --env builtin:sky`: the environment-lit picture is drawn by the
/// variant the view shows, as `render --env --variant volume` draws it.
#[test]
fn the_environment_lit_view_draws_the_variant_shown() {
    let Some(x) = Xvfb::start() else { return };
    let dir = temp_dir("env-variant");
    let scene = small_default_scene(&dir, "");
    let scene_arg = scene.to_str().unwrap();
    let env = [
        "--env",
        "builtin:sky",
        "--env-samples",
        "8",
        "--variant",
        "volume",
    ];
    let mut args = vec!["--scene", scene_arg, "--vsync", "off", "--frames", "2"];
    args.extend(env);
    args.extend(SMALL_TABLE);
    args.extend(["--screenshot", "view.png"]);
    let stdout = run_view_in(&x, &dir, &args);
    assert!(stdout.contains("environment: building volume"), "{stdout}");
    assert!(stdout.contains("sky: 8/8 spp in "), "{stdout}");
    let view = read_linear(&dir.join("view.png"));
    let mut render_args = env.to_vec();
    render_args.extend(SMALL_TABLE);
    let render = render_env_png(&dir, &scene, &render_args, "render.png");
    let diff = image_io::compare_images(&view, &render);
    eprintln!("view vs render, volume under builtin:sky, 8 spp: {diff}");
    assert!(
        diff.mean_delta_e <= MAX_ENV_MEAN_DELTA_E,
        "{diff} (limit mean ΔE {MAX_ENV_MEAN_DELTA_E})"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `E` after a sun-lit frame switches to builtin:sky: the picture accumulates to the cap
/// (the log counts the samples), `.` turns the map by 5° and the accumulation starts again;
/// the last frame is `render --env builtin:sky --env-rotate-deg 5` and differs from the
/// sun-lit frame.
#[test]
fn e_switches_to_the_environment_and_a_turn_restarts_it() {
    let Some(x) = Xvfb::start() else { return };
    let dir = temp_dir("env-key");
    let scene = small_default_scene(&dir, "");
    let scene_arg = scene.to_str().unwrap();
    let mut args = vec!["--scene", scene_arg, "--vsync", "off", "--frames", "4"];
    args.extend([
        "--env-samples",
        "8",
        "--at",
        "0:p",
        "--at",
        "1:e",
        "--at",
        "2:.",
    ]);
    args.extend(SMALL_TABLE);
    args.extend(["--screenshot", "turned.png"]);
    let stdout = run_view_in(&x, &dir, &args);
    let at = |needle: &str| {
        stdout
            .find(needle)
            .unwrap_or_else(|| panic!("'{needle}' missing:\n{stdout}"))
    };
    assert!(at("environment → sky") < at("sky: 1/8 spp"), "{stdout}");
    assert!(at("sky: 1/8 spp") < at("sky: 8/8 spp in "), "{stdout}");
    assert!(
        at("sky: 8/8 spp in ") < at("sky: accumulation restarts (was 8/8 spp)"),
        "{stdout}"
    );
    assert!(
        at("sky: accumulation restarts") < at("environment turned to 5°"),
        "{stdout}"
    );
    assert_eq!(stdout.matches("sky: 8/8 spp in ").count(), 2, "{stdout}");
    let sun = read_linear(&dir.join("diffract-view-1.png"));
    let turned = read_linear(&dir.join("turned.png"));
    let mut render_args = vec!["--env", "builtin:sky", "--env-samples", "8"];
    render_args.extend(["--env-rotate-deg", "5"]);
    render_args.extend(SMALL_TABLE);
    let render = render_env_png(&dir, &scene, &render_args, "render.png");
    let diff = image_io::compare_images(&turned, &render);
    eprintln!("view after E and . vs render turned by 5°: {diff}");
    assert!(
        diff.mean_delta_e <= MAX_ENV_MEAN_DELTA_E,
        "{diff} (limit mean ΔE {MAX_ENV_MEAN_DELTA_E})"
    );
    let from_sun = image_io::compare_images(&turned, &sun);
    eprintln!("view after E and . vs the sun-lit frame: {from_sun}");
    assert!(from_sun.mean_delta_e > 1.0, "{from_sun}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// With the BRDF map beside the mesh (`--map`) under builtin:sky, the map's square is the
/// environment-lit map (`render_env_brdf_map` of the viewer's map light, over the mirror
/// scale, times the map exposure) and the mesh beside it is `render --env builtin:sky`,
/// both accumulated to the cap.
#[test]
fn the_map_beside_the_mesh_is_lit_by_the_environment() {
    let Some(x) = Xvfb::start() else { return };
    let dir = temp_dir("env-map");
    let scene_path = small_default_scene(&dir, "");
    let scene_arg = scene_path.to_str().unwrap();
    let env = ["--env", "builtin:sky", "--env-samples", "16"];
    let mut args = vec!["--scene", scene_arg, "--width", "96", "--vsync", "off"];
    args.extend(["--frames", "2", "--map", "--screenshot", "map.png"]);
    args.extend(env);
    args.extend(SMALL_TABLE);
    let stdout = run_view_in(&x, &dir, &args);
    assert!(stdout.contains("sky: 16/16 spp"), "{stdout}");
    let (w, h, px) = image_io::read_png_rgb8(&dir.join("map.png")).expect("screenshot");
    assert_eq!((w, h), (96, 48));

    let mut render_args = env.to_vec();
    render_args.extend(SMALL_TABLE);
    let render = render_env_png(&dir, &scene_path, &render_args, "render.png");
    let diff = image_io::compare_images(&crop(&px, w, (48, 0, 48, 48)), &render);
    eprintln!("mesh beside the map vs render: {diff}");
    assert!(diff.mean_delta_e <= MAX_ENV_MEAN_DELTA_E, "{diff}");

    let Some(dev) = device() else { return };
    let scene = Scene::load(&scene_path).expect("scene");
    let m = &scene.material;
    let hf = m
        .load_heightfield(&diffract::report::Stderr)
        .expect("height field");
    let spec =
        diffract::cli::env::map_table_spec(Some(0.02), None, Some(20), m.coherence_um).unwrap();
    let cache = dir.join("cache");
    let (lighting, cached) = EnvLighting::build_cached(
        &hf,
        m.coherence_um,
        &m.shading(),
        &spec,
        Some(&cache),
        &diffract::report::Stderr,
    )
    .expect("table");
    assert!(cached, "the viewer's table is in the cache");
    let mesh = scene.mesh.load().expect("mesh");
    let frame = tangent_frame_at_view(&mesh, &scene.camera).expect("frame");
    let (theta, phi) = ViewState::from_scene(&scene).map_light_angles(frame);
    let sky = EnvMap::load(&EnvSource::Sky, 1.0, 0.0).unwrap();
    let side = 48;
    let req = EnvMapRequest {
        env: &sky,
        shading: m.shading(),
        samples: 16,
        size: side,
        sun: Some((diffract::brdf::direction(theta, phi), 1.0)),
        seed: 0,
        brdf: None,
        per_dispatch: None,
    };
    let pic = render_env_brdf_map(&dev, &lighting, &req).expect("env map");
    let gain = f64::from(diffract::view::input::DEFAULT_MAP_EXPOSURE) / lighting.mirror_scale;
    let expected = through_srgb8(
        &pic.xyz
            .iter()
            .map(|p| xyz_to_linear_srgb(p.map(f64::from)).map(|c| (c * gain) as f32))
            .collect::<Vec<_>>(),
    );
    let actual = crop(&px, w, (0, 0, side, side));
    let lit = actual
        .iter()
        .filter(|p| p.iter().any(|&c| c > 0.02))
        .count();
    eprintln!("map: {lit} of {} pixels lit", side * side);
    assert!(lit * 10 > (side * side) as usize, "the map is lit: {lit}");
    let diff = image_io::compare_images(&actual, &expected);
    eprintln!("environment-lit map vs render_env_brdf_map: {diff}");
    assert!(diff.mean_delta_e <= MAX_ENV_MEAN_DELTA_E, "{diff}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A scene with `[environment]` is shown lit by it: no warning, the window is the only
/// thing missing here (one error line).
#[test]
fn an_environment_scene_needs_no_warning() {
    let dir = temp_dir("env-scene");
    let scene = small_default_scene(&dir, "\n[environment]\nmap = \"builtin:sky\"\n");
    let out = diffract()
        .args(["view", "--scene", scene.to_str().unwrap(), "--frames", "1"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("WAYLAND_SOCKET")
        .output()
        .expect("run diffract view");
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert_eq!(lines.len(), 1, "{stderr}");
    assert!(
        lines[0].starts_with("error: cannot show a window:"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Bad environment flags: one error line, exit 1, before any window opens.
#[test]
fn bad_env_flags_are_one_error_line() {
    let dir = temp_dir("env-bad");
    let missing = dir.join("missing.hdr");
    for args in [
        vec!["--env", missing.to_str().unwrap()],
        vec!["--env", "builtin:moon"],
        vec!["--env", "sky.png"],
        vec!["--env-samples", "0"],
        vec!["--env", "builtin:sky", "--env-intensity", "-1"],
        vec!["--env-rotate-deg", "nan"],
        vec!["--env", "builtin:sky", "--env-noise", "0.5"],
    ] {
        let out = diffract()
            .args(["view", "--frames", "1"])
            .args(&args)
            .env_remove("DISPLAY")
            .env_remove("WAYLAND_DISPLAY")
            .output()
            .expect("run diffract view");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        let lines: Vec<&str> = stderr.lines().collect();
        assert_eq!(lines.len(), 1, "{args:?}: one line expected:\n{stderr}");
        assert!(
            lines[0].starts_with("error: ") && !lines[0].contains("window"),
            "{args:?}: {stderr}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
