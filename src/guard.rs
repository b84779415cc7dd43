//! Checks that run before any work: every output path can be written, no output would
//! replace an input (the same file, the PNG written beside an EXR, or a sidecar `.toml`
//! that another height field also reads), and numbers a command accepts are in range. The
//! commands call these at the top of `run`, before the Vulkan device or the term precompute
//! starts, so a mistake costs milliseconds and never destroys a file. Nothing here reads
//! file contents or computes anything.

use std::path::{Path, PathBuf};

use crate::heightfield::{sidecar_path, BUILTIN_PREFIX};
use crate::{Error, Result};

/// Height-field extensions whose sidecar is `stem.toml` (see `heightfield::io`).
const HEIGHTFIELD_EXTENSIONS: [&str; 2] = ["png", "f32"];

/// An output path must name a file (not a directory) in a directory that exists.
pub fn check_output(path: &Path) -> Result<()> {
    let bad = |msg: &str| {
        Err(Error::invalid(
            "output",
            format!("{}: {msg}", path.display()),
        ))
    };
    if path.as_os_str().is_empty() {
        return bad("empty path");
    }
    if path.file_name().is_none() {
        return bad("not a file name");
    }
    if path.is_dir() {
        return bad("is a directory");
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => Ok(()),
        Ok(_) => bad(&format!("{} is not a directory", dir.display())),
        Err(_) => bad(&format!("directory {} does not exist", dir.display())),
    }
}

/// A path made comparable: the canonical path of the file, or of its directory joined with
/// its name when the file does not exist yet.
fn comparable(p: &Path) -> PathBuf {
    if let Ok(c) = p.canonicalize() {
        return c;
    }
    let dir = match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    match (dir.canonicalize(), p.file_name()) {
        (Ok(d), Some(n)) => d.join(n),
        _ => p.to_path_buf(),
    }
}

/// Whether `a` and `b` name the same file: the same device and inode when both exist (hard
/// links, `./x`, symlinks), else the same comparable path.
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return ma.dev() == mb.dev() && ma.ino() == mb.ino();
        }
    }
    comparable(a) == comparable(b)
}

/// Refuses when an output names the same file as an input or as another output. `inputs`
/// and `outputs` pair a role ("height field", "--png image") with the path.
pub fn refuse_overwrite(inputs: &[(&str, PathBuf)], outputs: &[(&str, PathBuf)]) -> Result<()> {
    for (k, (out_role, out)) in outputs.iter().enumerate() {
        for (in_role, input) in inputs {
            if same_file(out, input) {
                return Err(Error::invalid(
                    "output",
                    format!(
                        "{out_role} {} is the {in_role} {}; refusing to overwrite an input",
                        out.display(),
                        input.display()
                    ),
                ));
            }
        }
        for (other_role, other) in &outputs[..k] {
            if same_file(out, other) {
                return Err(Error::invalid(
                    "output",
                    format!("{out_role} and {other_role} are both {}", out.display()),
                ));
            }
        }
    }
    Ok(())
}

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

/// Everything `diffract render` can check before the device and the precompute: flags that
/// belong to the other mode, sizes and angles, the material's numbers, the output paths,
/// outputs that would replace an input, and the size of the mesh file.
pub fn render_args(args: &crate::render::RenderArgs, scene: &crate::scene::Scene) -> Result<()> {
    use crate::render::MAX_MAP_SIZE;
    let png_sibling = args.out.with_extension("png");
    let exr_out = matches!(
        crate::image_io::output_format(&args.out)?,
        crate::image_io::OutputFormat::Exr
    );
    if args.brdf_map {
        refuse_flags(
            &[
                ("--width", args.width.is_some()),
                ("--height", args.height.is_some()),
            ],
            "a scene render (without --brdf-map)",
        )?;
        if let Some(s) = args.size {
            if !(1..=MAX_MAP_SIZE).contains(&s) {
                return Err(Error::invalid(
                    "BRDF map size",
                    format!("{s}; expected 1..={MAX_MAP_SIZE} pixels"),
                ));
            }
        }
        if let Some(t) = args.theta_i {
            in_range("theta-i", t, 0.0..=90.0, "°")?;
        }
        if let Some(p) = args.phi_i {
            finite("phi-i", p)?;
        }
        if let Some(l) = args.lambda_nm {
            let (lo, hi) = (
                crate::colour::LAMBDA_MIN_NM as f64,
                crate::colour::LAMBDA_MAX_NM as f64,
            );
            in_range("wavelength", l, lo..=hi, " nm")?;
        }
        if args.png && !exr_out {
            return Err(Error::invalid(
                "arguments",
                "--png adds a PNG beside an .exr output; this output is already a PNG",
            ));
        }
    } else {
        refuse_flags(
            &[
                ("--size", args.size.is_some()),
                ("--theta-i", args.theta_i.is_some()),
                ("--phi-i", args.phi_i.is_some()),
                ("--lambda-nm", args.lambda_nm.is_some()),
                ("--png", args.png),
            ],
            "--brdf-map",
        )?;
        for (what, v) in [
            ("width", args.width.unwrap_or(scene.output.width)),
            ("height", args.height.unwrap_or(scene.output.height)),
        ] {
            if !(1..=8192).contains(&v) {
                return Err(Error::invalid(
                    "image size",
                    format!("{what} {v}; expected 1..=8192"),
                ));
            }
        }
    }
    let material = args.material.apply(scene.material.clone());
    material.validate()?;

    let mut outputs = vec![("output", args.out.clone())];
    if args.brdf_map && args.png {
        outputs.push(("--png image", png_sibling));
    }
    for (_, o) in &outputs {
        check_output(o)?;
    }
    let mut inputs = heightfield_inputs(&material.heightfield);
    if let Some(s) = &args.scene {
        inputs.push(("scene", s.clone()));
    }
    if !args.brdf_map {
        if let Some(m) = &scene.mesh.path {
            inputs.push(("mesh", m.clone()));
        }
        if let Some(t) = scene.texture.as_ref().filter(|t| !t.is_builtin()) {
            inputs.push(("texture", t.path.clone()));
        }
    }
    refuse_overwrite(&inputs, &outputs)?;
    if !args.brdf_map {
        if let Some(m) = &scene.mesh.path {
            crate::fsutil::check_input_file(m, "mesh", crate::fsutil::MAX_OBJ_BYTES)?;
        }
        if let Some(t) = scene.texture.as_ref().filter(|t| !t.is_builtin()) {
            crate::fsutil::check_input_file(&t.path, "texture", crate::fsutil::MAX_PNG_BYTES)?;
        }
    }
    Ok(())
}

/// `diffract heightfield -o OUT`: the image and its sidecar must be writable, and the
/// sidecar must not belong to another height field.
pub fn heightfield_args(out: &Path) -> Result<()> {
    check_output(out)?;
    refuse_overwrite(&[], &[("output", out.to_path_buf())])?;
    refuse_shared_sidecar(out)
}

/// Finest viewing-angle step of `eval-grating` (degrees): 179 800 samples per wavelength,
/// about a minute and a quarter with the default material.
pub const MIN_STEP_DEG: f64 = 1e-3;
/// Most wavelengths `eval-grating` evaluates (0.1 nm steps over 380–780 nm).
pub const MAX_WAVELENGTHS: f64 = 4001.0;

/// `diffract eval-grating`: angles, steps and wavelengths, and the material's numbers.
pub fn eval_args(args: &crate::eval::EvalArgs) -> Result<()> {
    let t = args.theta_i;
    if !(t.is_finite() && (0.0..90.0).contains(&t)) {
        return Err(Error::invalid(
            "theta-i",
            format!("{t}°; must be in [0, 90)"),
        ));
    }
    finite("azimuth", args.azimuth)?;
    in_range("step-deg", args.step_deg, MIN_STEP_DEG..=1.0, "°")?;
    if let [from, to, step] = args.lambdas_nm[..] {
        if step.is_finite() && step > 0.0 && ((to - from) / step).floor() + 1.0 > MAX_WAVELENGTHS {
            return Err(Error::invalid(
                "wavelengths",
                format!("{from}..{to} step {step} nm is more than {MAX_WAVELENGTHS} wavelengths"),
            ));
        }
    }
    args.material
        .apply(crate::material::Material::default())
        .validate()
}

/// `diffract profile`: map size, angles, scored pixels (no more than the map's disk holds),
/// repeats, the material's numbers and the CSV path.
pub fn profile_args(args: &crate::profile::ProfileArgs) -> Result<()> {
    use crate::render::{map_direction, MAX_MAP_SIZE};
    if !(1..=MAX_MAP_SIZE).contains(&args.size) {
        return Err(Error::invalid(
            "BRDF map size",
            format!("{}; expected 1..={MAX_MAP_SIZE} pixels", args.size),
        ));
    }
    in_range("theta-i", args.theta_i, 0.0..=90.0, "°")?;
    finite("phi-i", args.phi_i)?;
    let inside = (0..args.size)
        .flat_map(|j| (0..args.size).map(move |i| (i, j)))
        .filter(|&(i, j)| map_direction(i, j, args.size).is_some())
        .count();
    let scored = args.pixels.saturating_add(args.brightest);
    if scored == 0 || scored > inside {
        return Err(Error::invalid(
            "pixels",
            format!(
                "{} spread + {} brightest; a {}² map has {inside} pixels inside its disk to score (at least 1)",
                args.pixels, args.brightest, args.size
            ),
        ));
    }
    if !(1..=1000).contains(&args.frames) {
        return Err(Error::invalid(
            "frames",
            format!("{}; expected 1..=1000", args.frames),
        ));
    }
    if args.mesh_size > 8192 {
        return Err(Error::invalid(
            "mesh-size",
            format!("{}; expected 0 (none) ..=8192", args.mesh_size),
        ));
    }
    if args.variant_terms > 64 {
        return Err(Error::invalid(
            "variant-terms",
            format!("{}; at most 64 terms are supported", args.variant_terms),
        ));
    }
    let material = args.material.apply(crate::material::Material::default());
    material.validate()?;
    for (flag, out) in [("--csv", &args.csv), ("--plot", &args.plot)] {
        if let Some(out) = out {
            check_output(out)?;
            refuse_overwrite(
                &heightfield_inputs(&material.heightfield),
                &[(flag, out.clone())],
            )?;
        }
    }
    Ok(())
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
