//! Meshes as they arrive from elsewhere: one triangle without normals, negative indices,
//! coordinates around 1e30. `diffract render` draws each (repaired, with a warning) or
//! refuses it with one line; none builds a table for directions no pixel shows. And the
//! device outputs of `render`: `/dev/null` is written into, a full device is named as a
//! write error. Needs Vulkan (lavapipe is enough).

mod gpu_util;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-awkward-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs `diffract` with a watchdog: a run still going after `limit` is killed and the test
/// fails as a hang (a generous bound, far above the seconds these take on lavapipe; it
/// catches a run that never ends, it does not time one).
fn run_bounded(args: &[&str], dir: &Path, limit: Duration) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_diffract"))
        .args(args)
        .current_dir(dir)
        .env("DIFFRACT_CACHE", dir.join("cache"))
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let o = child.wait_with_output().unwrap();
            panic!(
                "diffract {args:?} still running after {limit:?} (a hang): {}",
                String::from_utf8_lossy(&o.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A scene of the default general settings with only this mesh, rendered at 32×32.
fn render_mesh(d: &Path, name: &str, obj: &str) -> Output {
    std::fs::write(d.join(format!("{name}.obj")), obj).unwrap();
    std::fs::write(
        d.join(format!("{name}.toml")),
        format!("[mesh]\npath = \"{name}.obj\"\n"),
    )
    .unwrap();
    let scene = format!("{name}.toml");
    let out = format!("{name}.png");
    run_bounded(
        &[
            "render", "--scene", &scene, "--width", "32", "--height", "32", "-o", &out,
        ],
        d,
        Duration::from_secs(180),
    )
}

#[test]
fn render_draws_or_refuses_every_awkward_mesh_with_one_line() {
    let d = scratch("meshes");
    // (name, OBJ, a phrase the warnings must hold)
    let cases: [(&str, &str, &str); 4] = [
        // Faces +z, away from the default light: nothing lit, a black image in seconds.
        (
            "triangle",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            "is lit and seen from its front: the image shows no diffraction",
        ),
        (
            "negative",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -3\n",
            "the image shows no diffraction",
        ),
        (
            "huge",
            "v 1e30 1e30 0\nv 1.001e30 1e30 0\nv 1e30 1.001e30 0\nvn 0 0 1\nvn 0 0 1\nvn 0 0 1\nf 1//1 2//2 3//3\n",
            "recentred at the origin and scaled by",
        ),
        // Faces +y: lit by the default light and seen by the default camera.
        ("lit", "v 0 0 0\nv 0 0 1\nv 1 0 0\nf 1 2 3\n", "sun's disc pre-filtered"),
    ];
    for (name, obj, phrase) in cases {
        let o = render_mesh(&d, name, obj);
        if gpu_util::binary_found_no_vulkan(&o) {
            return;
        }
        let err = String::from_utf8_lossy(&o.stderr);
        let all = format!("{}{err}", String::from_utf8_lossy(&o.stdout));
        assert!(o.status.success(), "{name}: {err}");
        assert!(all.contains(phrase), "{name}: `{phrase}` not in: {all}");
        if name == "lit" {
            assert!(!all.contains("no diffraction"), "{all}");
        }
        assert!(!err.contains("error:"), "{name}: {err}");
        let img = image::open(d.join(format!("{name}.png"))).unwrap();
        assert_eq!((img.width(), img.height()), (32, 32), "{name}");
    }
    // What cannot be repaired is refused with one line.
    let o = render_mesh(&d, "flat", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.trim_end().lines().last().unwrap().contains("zero area"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn render_writes_into_devices_and_names_a_full_one_as_a_write_error() {
    use std::os::unix::fs::FileTypeExt;
    let d = scratch("devices");
    let map = [
        "render",
        "--brdf-map",
        "--size",
        "8",
        "--variant",
        "flss",
        "--terms",
        "2",
        "-o",
    ];
    let with = |out: &'static str| -> Vec<&'static str> {
        let mut v = map.to_vec();
        v.push(out);
        v
    };
    let o = run_bounded(&with("/dev/null"), &d, Duration::from_secs(180));
    if gpu_util::binary_found_no_vulkan(&o) {
        return;
    }
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::metadata("/dev/null")
        .unwrap()
        .file_type()
        .is_char_device());
    if Path::new("/dev/full").exists() {
        let o = run_bounded(&with("/dev/full"), &d, Duration::from_secs(180));
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        let last = err.trim_end().lines().last().unwrap();
        assert_eq!(
            last, "error: writing /dev/full: No space left on device (os error 28)",
            "{err}"
        );
    }
    let _ = std::fs::remove_dir_all(&d);
}
