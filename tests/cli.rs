//! The `diffract` binary's contract with scripts: `brdf` and `heightfield` produce files on
//! success, and bad input gives exactly one `error:` line, exit status 1 and no output file
//! (an existing output is left untouched). Argument errors found by the parser (unknown
//! flags, missing or malformed values) follow the same contract; `--help` and `--version`
//! print and exit 0.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn diffract(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_diffract"))
        .args(args)
        .env("DIFFRACT_CACHE", "")
        // No argument error may wait for (or be hidden by) the device.
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .output()
        .expect("run diffract")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn assert_one_error_line(o: &Output, needle: &str) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "expected exit status 1: {err}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.starts_with("warning:")).collect();
    assert_eq!(lines.len(), 1, "expected one error line, got:\n{err}");
    assert!(lines[0].starts_with("error: "), "{err}");
    assert!(lines[0].contains(needle), "'{needle}' not in: {err}");
    assert!(!err.contains("panicked"), "{err}");
}

fn write(p: &Path, s: &str) {
    std::fs::write(p, s).unwrap();
}

const HEADER: &str = "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm\n";

#[test]
fn brdf_model_and_reference_answer_the_same_queries() {
    let d = scratch("brdf");
    let hf = d.join("sin.png");
    let o = diffract(&[
        "heightfield",
        "--kind",
        "sinusoidal",
        "--size-um",
        "20",
        "--dh-um",
        "0.0625",
        "-o",
        hf.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let q = d.join("q.csv");
    write(
        &q,
        &format!("{HEADER}75,0,50,180,500\n30,0,30,180,\n0,0,10,90,620\n"),
    );
    let mut results = Vec::new();
    for method in ["model", "reference"] {
        let out = d.join(format!("{method}.csv"));
        let o = diffract(&[
            "brdf",
            "--heightfield",
            hf.to_str().unwrap(),
            "--queries",
            q.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--method",
            method,
            "--terms",
            "16",
            "--window-radius",
            "4",
            "--lambda-step-nm",
            "5",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let text = std::fs::read_to_string(&out).unwrap();
        let mut lines = text.lines();
        assert_eq!(
            lines.next().unwrap(),
            "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm,rho,X,Y,Z"
        );
        let rows: Vec<Vec<String>> = lines
            .map(|l| l.split(',').map(String::from).collect())
            .collect();
        assert_eq!(rows.len(), 3);
        assert_eq!(rows[1][4], "", "integrated rows keep an empty lambda");
        assert_eq!(rows[1][5], rows[1][7], "integrated rho is Y");
        results.push(rows);
    }
    for (m, r) in results[0].iter().zip(&results[1]) {
        for c in 5..9 {
            let (a, b): (f64, f64) = (m[c].parse().unwrap(), r[c].parse().unwrap());
            assert!(a.is_finite() && b.is_finite());
            assert!(
                (a - b).abs() <= 1e-4 * b.abs().max(1e-6),
                "model {a} vs reference {b}"
            );
        }
    }
}

#[test]
fn bad_query_rows_are_reported_with_their_line() {
    let d = scratch("badrow");
    let q = d.join("q.csv");
    let out = d.join("r.csv");
    write(&out, "previous results\n");
    write(
        &q,
        &format!("{HEADER}75,0,50,180,500\n75,zero,50,180,500\n"),
    );
    let o = diffract(&[
        "brdf",
        "--heightfield",
        "builtin:blazed",
        "--queries",
        q.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_one_error_line(&o, "line 3");
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "previous results\n");
}

#[test]
fn nonsense_parameters_and_missing_files_fail_cleanly() {
    let d = scratch("bad");
    let q = d.join("q.csv");
    write(&q, &format!("{HEADER}75,0,50,180,500\n"));
    let out = d.join("r.csv");
    let (q, out) = (q.to_str().unwrap(), out.to_str().unwrap());
    let cases: [(&[&str], &str); 6] = [
        (
            &["brdf", "--queries", "/nonexistent/q.csv", "--out", out],
            "/nonexistent/q.csv",
        ),
        (
            &[
                "brdf",
                "--heightfield",
                "/nonexistent/h.png",
                "--queries",
                q,
                "--out",
                out,
            ],
            "/nonexistent/h.png",
        ),
        (
            &["brdf", "--queries", q, "--out", out, "--coherence-um", "-3"],
            "coherence",
        ),
        (
            &["brdf", "--queries", q, "--out", out, "--terms", "1000"],
            "terms",
        ),
        (
            &[
                "brdf",
                "--queries",
                q,
                "--out",
                out,
                "--lambda-step-nm",
                "7",
            ],
            "wavelength step",
        ),
        (
            &[
                "brdf",
                "--queries",
                q,
                "--out",
                out,
                "--expansion",
                "fourier",
            ],
            "expansion",
        ),
    ];
    for (args, needle) in cases {
        let o = diffract(args);
        assert_one_error_line(&o, needle);
        assert!(!Path::new(out).exists(), "{args:?} wrote an output");
    }
}

/// Errors the parser finds are one `error:` line (no usage block, no colour codes) and exit
/// status 1, like every other error: an unknown flag, a missing value, a value outside an
/// enum, a malformed number, a missing required flag, an unknown or missing command.
#[test]
fn argument_errors_are_one_line_and_exit_1() {
    let cases: [(&[&str], &str); 10] = [
        (
            &["render", "--bogus"],
            "unexpected argument '--bogus' found",
        ),
        // clap's tip is kept on the same line.
        (
            &["render", "--brdf-mapp"],
            "tip: a similar argument exists: '--brdf-map'",
        ),
        (
            &["render", "--size"],
            "a value is required for '--size <SIZE>'",
        ),
        (
            &["brdf", "--queries", "q.csv", "--expansion", "fourier"],
            "invalid value 'fourier' for '--expansion <EXPANSION>'",
        ),
        (
            &["profile", "--frames", "three"],
            "invalid value 'three' for '--frames <FRAMES>': not a number; expected a whole number ≥ 0",
        ),
        (
            &["render", "--width", "-5"],
            "invalid value '-5' for '--width <WIDTH>'",
        ),
        (
            &["brdf"],
            "the following required arguments were not provided: --queries <QUERIES>, --out <OUT>",
        ),
        (&["rendr"], "unrecognized subcommand 'rendr'"),
        (&[], "no command given; expected one of: render, brdf"),
        (&["cache", "purge"], "invalid value 'purge' for '[ACTION]'"),
    ];
    for (args, needle) in cases {
        let o = diffract(args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains('\u{1b}'), "{args:?}: colour codes in {err:?}");
        assert!(o.stdout.is_empty(), "{args:?}: stdout {:?}", o.stdout);
        assert_one_error_line(&o, needle);
    }
}

/// A negative number after a space is a value, not a flag: it reaches the range checks, which
/// name the number.
#[test]
fn negative_numbers_parse_and_reach_the_range_checks() {
    let cases: [(&[&str], &str); 5] = [
        (
            &["profile", "--no-cache", "--table-texel", "-1"],
            "invalid table texel: -1; must be positive",
        ),
        (
            &["render", "--brdf-map", "--theta-i", "-5", "-o", "m.exr"],
            "invalid theta-i: -5°",
        ),
        (
            &["stability", "--no-gpu", "--tolerance", "-1e-3"],
            "invalid tolerance: -1e-3; must be in [1e-6, 1)",
        ),
        (
            &["eval-grating", "--step-deg", "-0.5"],
            "invalid step-deg: -0.5°",
        ),
        (
            &["render", "--brdf-map", "--phi-i", "-inf", "-o", "m.exr"],
            "invalid phi-i: -inf; must be a finite number",
        ),
    ];
    for (args, needle) in cases {
        assert_one_error_line(&diffract(args), needle);
    }
}

/// `--help` and `--version` still print on stdout and exit 0.
#[test]
fn help_and_version_exit_0() {
    for args in [&["--help"][..], &["render", "--help"], &["help", "profile"]] {
        let o = diffract(args);
        assert_eq!(o.status.code(), Some(0), "{args:?}");
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(out.contains("Usage: diffract"), "{args:?}: {out}");
    }
    let o = diffract(&["--version"]);
    assert_eq!(o.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&o.stdout).starts_with("diffract "));
}
