//! Checks that run before any work: every output path can be written, no output would
//! replace an input (the same file, the PNG written beside an EXR, or a sidecar `.toml`
//! that another height field also reads), and numbers a command accepts are in range. The
//! commands call these at the top of `run`, before the Vulkan device or the term precompute
//! starts, so a mistake costs milliseconds and never destroys a file. Nothing here reads
//! file contents or computes anything. The output policy itself (what may be written, and
//! how) is [`crate::fsutil::check_outputs`]; this module lists each command's inputs and
//! outputs for it.

use std::path::{Path, PathBuf};

use crate::heightfield::{sidecar_path, BUILTIN_PREFIX};
use crate::{Error, Result};

/// Height-field extensions whose sidecar is `stem.toml` (see `heightfield::io`).
const HEIGHTFIELD_EXTENSIONS: [&str; 4] = ["png", "f32", "gsf", "gwy"];

pub use crate::fsutil::{check_output, check_outputs, refuse_overwrite, same_file};

/// The files a height-field source reads: the image and its sidecar (none for `builtin:`).
pub fn heightfield_inputs(spec: &str) -> Vec<(&'static str, PathBuf)> {
    if spec.starts_with(BUILTIN_PREFIX) || spec.is_empty() {
        return Vec::new();
    }
    let p = PathBuf::from(spec);
    vec![
        ("height-field sidecar", sidecar_path(&p)),
        ("height field", p),
    ]
}

/// `diffract heightfield -o X.f32` writes `X.toml`: refuse when an existing `X.png` (or
/// `X.f32`) other than `out` reads that sidecar, since rewriting it would change (or break)
/// that height field.
pub fn refuse_shared_sidecar(out: &Path) -> Result<()> {
    let side = sidecar_path(out);
    if !side.exists() {
        return Ok(());
    }
    for ext in HEIGHTFIELD_EXTENSIONS {
        let other = out.with_extension(ext);
        if other.exists() && !same_file(&other, out) {
            return Err(Error::invalid(
                "output",
                format!(
                    "{} would rewrite {}, which is also the sidecar of {}; choose another name",
                    out.display(),
                    side.display(),
                    other.display()
                ),
            ));
        }
    }
    Ok(())
}

/// A finite number in `range`, named in the error with its unit.
pub fn in_range(
    what: &'static str,
    v: f64,
    range: std::ops::RangeInclusive<f64>,
    unit: &str,
) -> Result<f64> {
    if v.is_finite() && range.contains(&v) {
        Ok(v)
    } else {
        Err(Error::invalid(
            what,
            format!(
                "{v}{unit}; expected {}{unit} to {}{unit}",
                range.start(),
                range.end()
            ),
        ))
    }
}

/// The time budgets (s) a command accepts (`profile --budget-s`, `stability --budget-s`):
/// from one second (less cannot hold one measured row or cell) to 1e6 s (eleven days).
pub const BUDGET_RANGE_S: std::ops::RangeInclusive<f64> = 1.0..=1e6;

/// A `--budget-s` in [`BUDGET_RANGE_S`], with one message for every command.
pub fn budget_s(v: f64) -> Result<f64> {
    in_range("budget-s", v, BUDGET_RANGE_S, " s")
}

/// A finite number (an angle that wraps, for instance).
pub fn finite(what: &'static str, v: f64) -> Result<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Error::invalid(
            what,
            format!("{v}; must be a finite number"),
        ))
    }
}

/// Flags given for another mode: `flags` pairs a flag name with whether it was given.
pub fn refuse_flags(flags: &[(&str, bool)], needs: &str) -> Result<()> {
    let given: Vec<&str> = flags.iter().filter(|f| f.1).map(|f| f.0).collect();
    if given.is_empty() {
        Ok(())
    } else {
        Err(Error::invalid(
            "arguments",
            format!("{} only apply with {needs}", given.join(", ")),
        ))
    }
}

/// Every file a scene render reads: the scene file, the height field of `heightfield` (the
/// scene's material after the command line's overrides) and its sidecar, the mesh, the
/// texture and the environment map (`env`, the `--env` flag, else the scene's
/// `[environment] map`). Each may be the target of a mistaken output path.
pub fn scene_inputs(
    scene_path: Option<&Path>,
    scene: &crate::scene::Scene,
    heightfield: &str,
    env: Option<&str>,
) -> Vec<(&'static str, PathBuf)> {
    let mut inputs = heightfield_inputs(heightfield);
    if let Some(s) = scene_path {
        inputs.push(("scene", s.to_path_buf()));
    }
    if let Some(m) = &scene.mesh.path {
        inputs.push(("mesh", m.clone()));
    }
    if let Some(t) = scene.texture.as_ref().filter(|t| !t.is_builtin()) {
        inputs.push(("texture", t.path.clone()));
    }
    let env = env.or(scene.environment.as_ref().map(|e| e.map.as_str()));
    inputs.extend(env_input(env));
    inputs
}

/// The file an environment source (`--env`) reads: none for `builtin:` maps.
pub fn env_input(env: Option<&str>) -> Option<(&'static str, PathBuf)> {
    env.filter(|m| !m.starts_with(crate::light::env::BUILTIN_PREFIX))
        .map(|m| ("environment map", PathBuf::from(m)))
}

/// `diffract heightfield -o OUT [--from-sample S]`: the image and its sidecar must be
/// writable, neither may be the sample or its sidecar, and the sidecar must not belong to
/// another height field.
pub fn heightfield_args(out: &Path, sample: Option<&str>) -> Result<()> {
    let inputs = sample.map(heightfield_inputs).unwrap_or_default();
    check_outputs(
        &inputs,
        &[("-o", out.to_path_buf()), ("-o sidecar", sidecar_path(out))],
    )?;
    refuse_shared_sidecar(out)
}

/// A finite number above zero.
pub fn positive(what: &'static str, v: f64, unit: &str) -> Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(Error::invalid(
            what,
            format!("{v}{unit}; must be positive and finite"),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("diffract-guard-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn same_file_sees_through_dots_and_links() {
        let d = tmp("same");
        let a = d.join("a.png");
        std::fs::write(&a, b"x").unwrap();
        assert!(same_file(&a, &d.join(".").join("a.png")));
        let link = d.join("b.png");
        std::fs::hard_link(&a, &link).unwrap();
        assert!(same_file(&a, &link));
        assert!(!same_file(&a, &d.join("c.png")));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn outputs_must_have_a_directory() {
        let d = tmp("out");
        assert!(check_output(&d.join("a.png")).is_ok());
        assert!(check_output(&d.join("missing/a.png")).is_err());
        assert!(check_output(&d).is_err());
        assert!(check_output(Path::new("")).is_err());
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn shared_sidecar_is_refused() {
        let d = tmp("side");
        std::fs::write(d.join("x.png"), b"png").unwrap();
        std::fs::write(d.join("x.toml"), b"dh_um = 0.1").unwrap();
        assert!(refuse_shared_sidecar(&d.join("x.f32")).is_err());
        assert!(refuse_shared_sidecar(&d.join("x.png")).is_ok());
        assert!(refuse_shared_sidecar(&d.join("y.f32")).is_ok());
        let _ = std::fs::remove_dir_all(&d);
    }
}
