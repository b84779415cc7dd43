//! Progress on a terminal: the slow steps draw a bar or a spinner on stderr when
//! stderr is a terminal, and print nothing but their normal lines when it is not (scripts,
//! CI logs). The terminal is a pseudo-terminal made by util-linux `script`; stdout goes to a
//! file, so what the terminal shows is stderr alone. Without `script` (or, for the GPU
//! commands, without a Vulkan driver) the terminal half is skipped with a notice, and fails
//! instead under `DIFFRACT_REQUIRE_VULKAN=1`, as CI runs; the quiet half always runs.

mod gpu_util;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_diffract")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-term-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `s` quoted for `sh`.
fn quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// Whether util-linux `script` can make a pseudo-terminal; without it, a notice, or a panic
/// under `DIFFRACT_REQUIRE_VULKAN=1` (CI runs every test).
fn have_script() -> bool {
    let ok = Command::new("script")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        assert!(
            !gpu_util::vulkan_required(),
            "DIFFRACT_REQUIRE_VULKAN=1 but util-linux `script` is not installed (no pseudo-terminal)"
        );
        eprintln!("SKIPPED: util-linux `script` is not installed (no pseudo-terminal)");
    }
    ok
}

/// Runs `diffract args` with stderr on a pseudo-terminal and stdout into `d/stdout.txt`:
/// returns (what the terminal received, stdout, exit status of the command).
fn on_terminal(d: &Path, args: &[&str]) -> (String, String, bool) {
    let stdout = d.join("stdout.txt");
    let mut line = quote(bin());
    for a in args {
        line.push(' ');
        line.push_str(&quote(a));
    }
    line.push_str(&format!(" >{}", quote(stdout.to_str().unwrap())));
    // -e: script exits with the command's status; -q: no "Script started" lines; the
    // transcript file is /dev/null, the terminal's output comes back on script's stdout.
    let o = Command::new("script")
        .args(["-qec", &line, "/dev/null"])
        .env("TERM", "xterm")
        .env("DIFFRACT_CACHE", "")
        .stdin(Stdio::null())
        .output()
        .expect("run script");
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        std::fs::read_to_string(&stdout).unwrap_or_default(),
        o.status.success(),
    )
}

/// The same command with stderr and stdout piped (not a terminal).
fn piped(args: &[&str]) -> Output {
    Command::new(bin())
        .args(args)
        .env("DIFFRACT_CACHE", "")
        .stdin(Stdio::null())
        .output()
        .expect("run diffract")
}

/// What a drawn bar or spinner leaves in a terminal's byte stream: escape sequences
/// (indicatif redraws with `\r` and `ESC[2K`) or a carriage return that does not end a line
/// (a terminal turns every `\n` into `\r\n`, so those do not count).
fn has_drawing(s: &str) -> bool {
    s.contains('\u{1b}') || s.replace("\r\n", "\n").contains('\r')
}

/// Stderr of a run that is not on a terminal: no drawing, and every line is a warning or
/// one the command prints anyway (`allowed` prefixes).
fn assert_quiet(o: &Output, allowed: &[&str]) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "stderr:\n{err}");
    assert!(!has_drawing(&err), "progress drawn on a pipe: {err:?}");
    for l in err.lines() {
        assert!(
            l.starts_with("warning:") || allowed.iter().any(|a| l.starts_with(a)),
            "unexpected stderr line on a pipe: {l:?}"
        );
    }
}

/// A 512² height field (PNG + sidecar; 17 terms of it are above the size from which the
/// term precompute shows a bar) and `n` spectrally integrated queries: a couple of seconds
/// in all, so both bars have time to draw.
fn brdf_inputs(d: &Path, n: usize) -> (PathBuf, PathBuf) {
    let hf = d.join("hf.png");
    image::GrayImage::from_fn(512, 512, |x, y| {
        image::Luma([((x * 37 + y * 11) % 256) as u8])
    })
    .save(&hf)
    .unwrap();
    std::fs::write(d.join("hf.toml"), "dh_um = 0.078\nh_max_um = 0.2\n").unwrap();
    let q = d.join("q.csv");
    let mut text = String::from("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm\n");
    for i in 0..n {
        text.push_str(&format!("30,0,{},180,\n", i % 80));
    }
    std::fs::write(&q, text).unwrap();
    (hf, q)
}

const QUERIES: usize = 6_000;

fn brdf_args<'a>(hf: &'a str, q: &'a str, out: &'a str) -> Vec<&'a str> {
    vec![
        "brdf",
        "--heightfield",
        hf,
        "--queries",
        q,
        "--out",
        out,
        "--terms",
        "16",
        "--lambda-step-nm",
        "10",
        "--no-cache",
    ]
}

const EVAL: [&str; 9] = [
    "eval-grating",
    "--heightfield",
    "builtin:blazed",
    "--no-cache",
    "--terms",
    "6",
    "--lambdas-nm",
    "400",
    "700",
];

fn eval_args() -> Vec<&'static str> {
    let mut v = EVAL.to_vec();
    v.extend(["20", "--step-deg", "0.02"]);
    v
}

#[test]
fn term_precompute_and_brdf_queries_draw_bars_on_a_terminal() {
    if !have_script() {
        return;
    }
    let d = scratch("brdf-tty");
    let (hf, q) = brdf_inputs(&d, QUERIES);
    let out = d.join("r.csv");
    let args = brdf_args(
        hf.to_str().unwrap(),
        q.to_str().unwrap(),
        out.to_str().unwrap(),
    );
    let (tty, stdout, ok) = on_terminal(&d, &args);
    assert!(ok, "terminal run failed:\n{tty}");
    assert!(tty.contains("\r\u{1b}[2K"), "no bar drawn: {tty:?}");
    assert!(tty.contains("DFT terms"), "no precompute bar: {tty:?}");
    assert!(
        tty.contains("/17"),
        "no precompute position/length: {tty:?}"
    );
    assert!(tty.contains("queries"), "no query bar: {tty:?}");
    assert!(
        tty.contains(&format!("/{QUERIES}")),
        "no query position/length: {tty:?}"
    );
    // The bar is cleared and the one completion line follows it; the answers go to the file.
    assert!(
        tty.contains(&format!("{QUERIES} queries answered")),
        "{tty:?}"
    );
    assert!(stdout.is_empty(), "stdout: {stdout}");
    assert!(out.exists());
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn term_precompute_and_brdf_queries_are_quiet_on_a_pipe() {
    let d = scratch("brdf-pipe");
    let (hf, q) = brdf_inputs(&d, QUERIES);
    let out = d.join("r.csv");
    let args = brdf_args(
        hf.to_str().unwrap(),
        q.to_str().unwrap(),
        out.to_str().unwrap(),
    );
    let o = piped(&args);
    let done = format!("{QUERIES} queries answered by the Model evaluator");
    assert_quiet(&o, &[&done]);
    assert!(String::from_utf8_lossy(&o.stderr).contains(&done));
    assert!(out.exists());
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn eval_grating_draws_a_spinner_on_a_terminal() {
    if !have_script() {
        return;
    }
    let d = scratch("eval-tty");
    let (tty, stdout, ok) = on_terminal(&d, &eval_args());
    assert!(ok, "terminal run failed:\n{tty}");
    assert!(tty.contains("\r\u{1b}[2K"), "no spinner drawn: {tty:?}");
    assert!(
        tty.contains("grating equation"),
        "the spinner is not named: {tty:?}"
    );
    assert!(stdout.contains("period mean"), "stdout: {stdout}");
    assert!(
        !tty.contains("period mean"),
        "stdout leaked onto stderr: {tty:?}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn eval_grating_is_quiet_on_a_pipe() {
    let o = piped(&eval_args());
    assert_quiet(&o, &[]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("period mean"));
}

/// A 64² height field for the GPU commands (a fast precompute; their own bar or spinner is
/// what is checked).
fn small_field(d: &Path) -> PathBuf {
    let hf = d.join("small.png");
    image::GrayImage::from_fn(64, 64, |x, y| {
        image::Luma([((x * 37 + y * 11) % 256) as u8])
    })
    .save(&hf)
    .unwrap();
    std::fs::write(d.join("small.toml"), "dh_um = 0.1\nh_max_um = 0.2\n").unwrap();
    hf
}

/// Whether a piped run failed only because this machine has no Vulkan driver (then the GPU
/// half is skipped with a notice, like the other GPU tests; a failure under
/// `DIFFRACT_REQUIRE_VULKAN=1`). A real Vulkan error is not a skip: the test reports it.
fn no_vulkan(o: &Output) -> bool {
    gpu_util::binary_found_no_vulkan(o)
}

fn render_args(hf: &str, out: &str) -> Vec<String> {
    [
        "render",
        "--variant",
        "flss",
        "--brdf-map",
        "--size",
        "32",
        "--heightfield",
        hf,
        "--terms",
        "2",
        "--window-radius",
        "1",
        "--lambda-step-nm",
        "50",
        "--no-cache",
        "-o",
        out,
    ]
    .map(String::from)
    .to_vec()
}

#[test]
fn render_draws_a_spinner_on_a_terminal_only() {
    let d = scratch("render");
    let hf = small_field(&d);
    let out = d.join("m.exr");
    let args = render_args(hf.to_str().unwrap(), out.to_str().unwrap());
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = piped(&args);
    if no_vulkan(&o) {
        return;
    }
    // `render`'s one report line of what it left out is printed on a pipe too.
    assert_quiet(&o, &["left out:", "model check:"]);
    assert!(String::from_utf8_lossy(&o.stdout)
        .contains("BRDF map (XYZ of the relative reflectance ρ) 32×32"));
    if !have_script() {
        return;
    }
    let (tty, stdout, ok) = on_terminal(&d, &args);
    assert!(ok, "terminal run failed:\n{tty}");
    assert!(tty.contains("\r\u{1b}[2K"), "no spinner drawn: {tty:?}");
    assert!(
        tty.contains("rendering"),
        "the spinner is not named: {tty:?}"
    );
    assert!(
        stdout.contains("BRDF map (XYZ of the relative reflectance ρ) 32×32"),
        "stdout: {stdout}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn profile_draws_its_bars_on_a_terminal_only() {
    let d = scratch("profile");
    let hf = small_field(&d);
    let args = [
        "profile",
        "--heightfield",
        hf.to_str().unwrap(),
        "--size",
        "16",
        "--pixels",
        "8",
        "--brightest",
        "4",
        "--frames",
        "1",
        "--mesh-size",
        "0",
        "--only",
        "thesis: taylor R=1",
        "--no-cache",
    ];
    let o = piped(&args);
    if no_vulkan(&o) {
        return;
    }
    // On a pipe: no bar, but a line as the run starts and one as each row finishes.
    assert_quiet(&o, &["profile: ", "model check:"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.lines()
            .any(|l| l.starts_with("profile: thesis: taylor R=1: warm-up")),
        "no line for the row: {err}"
    );
    assert!(String::from_utf8_lossy(&o.stdout).contains("| thesis: taylor R=1 |"));
    if !have_script() {
        return;
    }
    let (tty, stdout, ok) = on_terminal(&d, &args);
    assert!(ok, "terminal run failed:\n{tty}");
    assert!(tty.contains("\r\u{1b}[2K"), "no bar drawn: {tty:?}");
    assert!(
        tty.contains("profile: thesis: taylor R=1"),
        "no profile bar: {tty:?}"
    );
    assert!(
        tty.contains("f64 reference at 1 nm"),
        "no reference bar: {tty:?}"
    );
    assert!(
        stdout.contains("| thesis: taylor R=1 |"),
        "stdout: {stdout}"
    );
    let _ = std::fs::remove_dir_all(&d);
}
