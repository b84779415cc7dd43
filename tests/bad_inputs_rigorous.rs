//! Bad input to the rigorous and long-running commands (`validity`, `stability`,
//! `profile`), through the `diffract` binary as `tests/bad_inputs.rs` runs it: a refusal is
//! exit status 1 and exactly one `error:` line (only `warning:` lines may come before it),
//! before any work, with every file left as it was; an answer the solver could not
//! converge carries a `warning:` line with its estimated error.

mod files_util;
mod gpu_util;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use files_util::snapshot;

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-rig-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The binary with no term cache and, unless `vulkan`, no Vulkan driver: every refusal
/// must come before the device opens.
fn diffract(args: &[&str], vulkan: bool) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_diffract"));
    c.args(args).env("DIFFRACT_CACHE", "");
    if !vulkan {
        c.env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
            .env("VK_DRIVER_FILES", "/nonexistent/icd.json");
    }
    c
}

/// Runs `cmd` and checks a refusal: exit 1, one `error:` line holding `needle`, nothing
/// but `warning:` lines before it, within `limit`, and `dir` unchanged.
fn refused(mut cmd: Command, dir: &Path, needle: &str, limit: Duration) {
    let before = snapshot(dir);
    let t = Instant::now();
    let o: Output = cmd.output().unwrap();
    let secs = t.elapsed();
    let err = String::from_utf8_lossy(&o.stderr);
    let ctx = format!(
        "{cmd:?}\nstatus {:?}, {secs:?}\nstderr:\n{err}",
        o.status.code()
    );
    assert_eq!(o.status.code(), Some(1), "{ctx}");
    assert!(!err.contains("panicked"), "{ctx}");
    let lines: Vec<&str> = err.lines().collect();
    let errors: Vec<&&str> = lines.iter().filter(|l| l.starts_with("error")).collect();
    assert_eq!(errors.len(), 1, "expected exactly one error line: {ctx}");
    assert!(
        lines.last().is_some_and(|l| l.starts_with("error: ")),
        "the error line must be the last: {ctx}"
    );
    assert!(
        lines[..lines.len() - 1]
            .iter()
            .all(|l| l.starts_with("warning:")),
        "only warning lines may come before the error: {ctx}"
    );
    assert!(
        errors[0].contains(needle),
        "'{needle}' not in the error line: {ctx}"
    );
    assert!(
        o.stdout.is_empty(),
        "stdout: {}\n{ctx}",
        String::from_utf8_lossy(&o.stdout)
    );
    assert!(
        secs < limit,
        "refused after {secs:?}, not before any work: {ctx}"
    );
    assert_eq!(before, snapshot(dir), "files changed: {ctx}");
}

const QUICK: Duration = Duration::from_secs(5);

/// A `.f32` height field of `nx × ny` samples `dh_um` apart whose rows are the profile `f`
/// of x (µm), with its sidecar.
fn field(p: &Path, nx: usize, ny: usize, dh_um: f64, f: impl Fn(f64) -> f64) {
    let bytes: Vec<u8> = (0..nx * ny)
        .flat_map(|i| (f((i % nx) as f64 * dh_um) as f32).to_le_bytes())
        .collect();
    std::fs::write(p, bytes).unwrap();
    std::fs::write(
        p.with_extension("toml"),
        format!("nx = {nx}\nny = {ny}\ndh_um = {dh_um}\n"),
    )
    .unwrap();
}

/// A sinusoid of period 2.5 µm and depth 0.2 µm, 27 samples a period.
fn sinusoid(x: f64) -> f64 {
    0.1 * (1.0 + (2.0 * std::f64::consts::PI * x / 2.5).cos())
}

// ---- validity ------------------------------------------------------------------------------

/// Index 1 is no interface (every order ratio 0/0), an index closer to 1 than 1.0003
/// reflects less than the solver resolves, and NaN, infinities and indices ≤ 0 are no
/// index: each is refused before the height field is read.
#[test]
fn validity_refuses_an_index_without_an_interface() {
    let d = scratch("ior");
    for (ior, needle) in [
        ("1", "the rigorous check needs n ≥ 1.0003"),
        ("1.0", "nothing is reflected"),
        ("1.0001", "reflects R0 = 2.5e-9"),
        ("1.00000001", "the rigorous check needs n ≥ 1.0003"),
        ("0", "1 ≤ n ≤ 4"),
        ("-1", "1 ≤ n ≤ 4"),
        ("-0", "1 ≤ n ≤ 4"),
        ("nan", "1 ≤ n ≤ 4"),
        ("inf", "1 ≤ n ≤ 4"),
    ] {
        let arg = format!("--ior={ior}");
        refused(diffract(&["validity", &arg], false), &d, needle, QUICK);
    }
    // --limits solves sinusoids of the material's index: the same check.
    refused(
        diffract(&["validity", "--limits", "--ior", "1"], false),
        &d,
        "nothing is reflected",
        QUICK,
    );
    // The smallest accepted index gives finite order ratios.
    let o = diffract(
        &[
            "validity",
            "--ior",
            "1.0003",
            "--lambda-nm",
            "550",
            "--theta-i",
            "0",
        ],
        false,
    )
    .output()
    .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!out.contains("NaN") && !out.contains('∞'), "{out}");
    let _ = std::fs::remove_dir_all(&d);
}

/// Runs `validity` on `hf` at one wavelength and angle; returns stdout and stderr.
fn validity(hf: &Path, lambda: &str, theta: &str) -> (String, String) {
    let o = diffract(
        &[
            "validity",
            "--heightfield",
            hf.to_str().unwrap(),
            "--lambda-nm",
            lambda,
            "--theta-i",
            theta,
        ],
        false,
    )
    .output()
    .unwrap();
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout).to_string(),
        String::from_utf8_lossy(&o.stderr).to_string(),
    );
    assert!(o.status.success(), "{err}");
    (out, err)
}

/// A deep 2.5 µm sinusoid at 450 nm and 30° needs more than the solver's 128 slices to
/// converge to 2 %: the answer carries a warning with the change of its last refinement
/// (a measured number, not `inf`). As a 2-D field and as a 1-D scan (one row).
#[test]
fn validity_warns_with_the_estimated_error_of_an_unconverged_solve() {
    let d = scratch("unconverged");
    for (name, ny) in [("field.f32", 8), ("scan.f32", 1)] {
        let p = d.join(name);
        field(&p, 108, ny, 2.5 / 27.0, sinusoid);
        let (out, err) = validity(&p, "450", "30");
        assert!(!out.contains("inf"), "{out}");
        let warnings: Vec<&str> = err.lines().filter(|l| l.starts_with("warning:")).collect();
        assert_eq!(warnings.len(), 1, "{err}");
        assert!(
            warnings[0].contains("without converging to 2 %")
                && warnings[0].contains("the estimated error of its orders"),
            "{err}"
        );
        assert!(out.contains("× 128 slices"), "{out}");
    }
    // A converged solve carries no warning.
    let (out, err) = validity(&d.join("field.f32"), "650", "0");
    assert!(
        !err.contains("warning:") && !out.contains("inf"),
        "{err}\n{out}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// A flat field is refused by validity's own check (no ridges) before any of the loader's
/// report lines (levelling, seam): the one line is the error.
#[test]
fn validity_refuses_a_flat_field_before_any_report_line() {
    let d = scratch("flat");
    let p = d.join("flat.f32");
    field(&p, 64, 64, 0.09, |_| 0.0);
    let hf = p.to_str().unwrap();
    for extra in [
        &["--level", "plane"][..],
        &["--level", "plane,rows", "--tile", "mirror"],
    ] {
        let mut args = vec!["validity", "--heightfield", hf];
        args.extend_from_slice(extra);
        refused(diffract(&args, false), &d, "no ridges", QUICK);
    }
    let _ = std::fs::remove_dir_all(&d);
}

// ---- stability's output directory ------------------------------------------------------------

/// Runs `cmd` as an unprivileged user where the test runs as root (root writes anywhere);
/// without root, the directories' modes alone do it.
fn unprivileged(cmd: &mut Command) {
    use std::os::unix::process::CommandExt;
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } == 0 {
        cmd.uid(65534).gid(65534);
    }
}

/// The smallest matrix: one height, angle and wavelength, no GPU, no model axis.
const SMALL: [&str; 9] = [
    "stability",
    "--no-gpu",
    "--no-model",
    "--hmax-um",
    "0.05",
    "--theta-i",
    "0",
    "--lambda-nm",
    "580",
];

/// `stability -o DIR` creates DIR (not its parents) after the run and writes its files into
/// it: a DIR in a read-only directory, a read-only DIR, a DIR whose parent is missing or a
/// file, and a link to nothing are refused before the matrix runs, and nothing is created.
#[test]
fn stability_checks_its_output_directory_before_any_work() {
    use std::os::unix::fs::PermissionsExt;
    let d = scratch("stab-out");
    std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o755)).unwrap();
    let ro = d.join("ro");
    std::fs::create_dir(&ro).unwrap();
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
    std::fs::write(d.join("file"), "keep").unwrap();
    std::os::unix::fs::symlink(d.join("nowhere"), d.join("dangling")).unwrap();
    for (out, needle) in [
        (ro.join("new"), "cannot be created: directory"),
        (
            ro.clone(),
            "cannot be written (read-only or permission denied)",
        ),
        (d.join("missing/new"), "does not exist"),
        (d.join("file/new"), "is not a directory"),
        (d.join("file"), "not a directory"),
        (d.join("dangling"), "is a link to nothing"),
    ] {
        let mut cmd = diffract(&SMALL, false);
        cmd.arg("-o").arg(&out);
        unprivileged(&mut cmd);
        refused(cmd, &d, needle, QUICK);
    }
    // A new directory in a writable one is created, and holds the report.
    let o = diffract(&SMALL, false)
        .arg("-o")
        .arg(d.join("new"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(d.join("new/stability.md").is_file());
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).unwrap();
    let _ = std::fs::remove_dir_all(&d);
}

// ---- time budgets ----------------------------------------------------------------------------

/// `profile --budget-s` and `stability --budget-s` take the same range (1 s to 1e6 s) with
/// the same message.
#[test]
fn profile_and_stability_take_the_same_budgets() {
    let d = scratch("budget");
    let out = d.join("s");
    for b in ["1e-9", "0.5", "0", "1e12", "1000001", "nan", "inf"] {
        let mut lines = Vec::new();
        for args in [
            vec!["profile", "--budget-s", b],
            vec![
                "stability",
                "--no-gpu",
                "--budget-s",
                b,
                "-o",
                out.to_str().unwrap(),
            ],
        ] {
            refused(
                diffract(&args, false),
                &d,
                "expected 1 s to 1000000 s",
                QUICK,
            );
            let o = diffract(&args, false).output().unwrap();
            lines.push(String::from_utf8_lossy(&o.stderr).to_string());
        }
        assert_eq!(lines[0], lines[1], "budget {b}");
        assert!(
            lines[0].starts_with("error: invalid budget-s: "),
            "{}",
            lines[0]
        );
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// `stability --budget-s` holds for the whole run (the device, the lighting and table cases
/// and the GPU pipelines, built once before the cells, are steps of its setup): it ends
/// within 20 % of its budget, or one `warning:` line names the step that took the time.
#[test]
fn stability_keeps_its_budget_or_says_why() {
    let d = scratch("budget-kept");
    let out = d.join("s");
    let budget = 2.0;
    let t = Instant::now();
    let o = diffract(
        &[
            "stability",
            "--hmax-um",
            "0",
            "--theta-i",
            "0",
            "--lambda-nm",
            "380",
            "--budget-s",
            "2",
            "-o",
            out.to_str().unwrap(),
        ],
        true,
    )
    .output()
    .unwrap();
    if gpu_util::binary_found_no_vulkan(&o) {
        return;
    }
    let secs = t.elapsed().as_secs_f64();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("GPU pipeline(s) built"), "{err}");
    let explained: Vec<&str> = err
        .lines()
        .filter(|l| l.starts_with("warning: stability took"))
        .collect();
    assert!(
        secs <= 1.2 * budget || explained.len() == 1,
        "{secs:.1} s on a {budget} s budget, unexplained: {err}"
    );
    let _ = std::fs::remove_dir_all(&d);
}
