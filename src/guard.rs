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
const HEIGHTFIELD_EXTENSIONS: [&str; 2] = ["png", "f32"];

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
    table_args(&args.table)?;
    let material = args.material.apply(scene.material.clone());
    material.validate()?;

    let mut outputs = vec![("output", args.out.clone())];
    if args.brdf_map && args.png {
        outputs.push(("--png image", png_sibling));
    }
    check_outputs(
        &scene_inputs(args.scene.as_deref(), scene, &material.heightfield),
        &outputs,
    )?;
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

/// Every file a scene render reads: the scene file, the height field of `heightfield` (the
/// scene's material after the command line's overrides) and its sidecar, the mesh and the
/// texture. Each may be the target of a mistaken output path.
pub fn scene_inputs(
    scene_path: Option<&Path>,
    scene: &crate::scene::Scene,
    heightfield: &str,
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
    inputs
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

/// The table variants' options (`--table-*`), checked the same way by every command that
/// takes them, whichever variant is drawn: a spacing above zero, a `w` node count the
/// table supports, a wavelength step that divides the visible range, a budget of at least
/// 1 MB.
pub fn table_args(t: &crate::render::TableArgs) -> Result<()> {
    use crate::brdf::table::MAX_NODES_W;
    if let Some(texel) = t.table_texel {
        positive("table texel", texel, "")?;
    }
    if let Some(n) = t.table_w_nodes {
        if !(2..=MAX_NODES_W).contains(&n) {
            return Err(Error::invalid(
                "table w nodes",
                format!("{n}; expected 2..={MAX_NODES_W}"),
            ));
        }
    }
    crate::colour::ColourTable::new(t.table_step_nm)?;
    if t.table_budget_mb == 0 {
        return Err(Error::invalid(
            "table budget",
            "0 MB; expected at least 1 MB",
        ));
    }
    Ok(())
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
    let material = args.material.apply(crate::material::Material::default());
    material.validate()?;
    if let Some(plot) = &args.plot {
        check_outputs(
            &heightfield_inputs(&material.heightfield),
            &[("--plot", plot.clone())],
        )?;
    }
    Ok(())
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
    if let Some(q) = args.mesh_quads {
        if !(1..=32).contains(&q) || args.mesh_size == 0 {
            return Err(Error::invalid(
                "mesh-quads",
                format!("{q}; expected 1..=32 with a mesh view (--mesh-size > 0)"),
            ));
        }
    }
    table_args(&args.table)?;
    if args.variant_terms > 64 {
        return Err(Error::invalid(
            "variant-terms",
            format!("{}; at most 64 terms are supported", args.variant_terms),
        ));
    }
    let material = args.material.apply(crate::material::Material::default());
    material.validate()?;
    let outputs: Vec<(&str, PathBuf)> = [("--csv", &args.csv), ("--plot", &args.plot)]
        .into_iter()
        .filter_map(|(flag, out)| out.clone().map(|o| (flag, o)))
        .collect();
    check_outputs(&heightfield_inputs(&material.heightfield), &outputs)
}

/// Files `diffract stability -o DIR` writes into `DIR`.
pub const STABILITY_FILES: [&str; 3] = ["stability.csv", "stability.md", "stability.png"];

/// `diffract stability`: every number of the matrix (heights, angles, wavelengths, term
/// counts, the tolerance, the map size) and the output directory, whose files must not be
/// the height field or its sidecar.
pub fn stability_args(args: &crate::stability::StabilityArgs) -> Result<()> {
    use crate::brdf::truncation::MAX_TERMS;
    use crate::render::MAX_MAP_SIZE;
    let t = args.tolerance;
    if !(t.is_finite() && t > 0.0 && t < 1.0) {
        return Err(Error::invalid(
            "tolerance",
            format!("{t}; must be in (0, 1)"),
        ));
    }
    for &h in &args.hmax_um {
        if !(h.is_finite() && h >= 0.0) {
            return Err(Error::invalid(
                "hmax-um",
                format!("{h} µm; must be finite and ≥ 0"),
            ));
        }
    }
    for &th in &args.theta_i {
        if !(th.is_finite() && (0.0..90.0).contains(&th)) {
            return Err(Error::invalid(
                "theta-i",
                format!("{th}°; expected [0, 90)"),
            ));
        }
    }
    let (lo, hi) = (
        crate::colour::LAMBDA_MIN_NM as f64,
        crate::colour::LAMBDA_MAX_NM as f64,
    );
    for &l in &args.lambda_nm {
        in_range("wavelength", l, lo..=hi, " nm")?;
    }
    for &n in &args.fixed_terms {
        if n > MAX_TERMS {
            return Err(Error::invalid(
                "fixed-terms",
                format!("{n}; at most {MAX_TERMS} terms are supported"),
            ));
        }
    }
    if let Some(dh) = args.dh_um {
        positive("dh-um", dh, " µm")?;
        if args.heightfield.is_none() {
            return Err(Error::invalid(
                "arguments",
                "--dh-um only applies with --heightfield",
            ));
        }
    }
    if !(1..=MAX_MAP_SIZE).contains(&args.map_size) {
        return Err(Error::invalid(
            "map-size",
            format!("{}; expected 1..={MAX_MAP_SIZE} pixels", args.map_size),
        ));
    }
    let dir = &args.out;
    if dir.as_os_str().is_empty() {
        return Err(Error::invalid("output", "empty directory path"));
    }
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => {
            let outputs: Vec<(&str, PathBuf)> = STABILITY_FILES
                .iter()
                .map(|f| ("-o", dir.join(f)))
                .collect();
            let inputs = args
                .heightfield
                .as_deref()
                .map(heightfield_inputs)
                .unwrap_or_default();
            check_outputs(&inputs, &outputs)
        }
        Ok(_) => Err(Error::invalid(
            "output",
            format!("{}: not a directory", dir.display()),
        )),
        // Created after the run, with its parents: the nearest existing one must be a
        // directory. A new directory holds no input.
        Err(_) => {
            let mut up = dir.parent();
            while let Some(p) = up.filter(|p| !p.as_os_str().is_empty()) {
                if let Ok(m) = std::fs::metadata(p) {
                    if m.is_dir() {
                        return Ok(());
                    }
                    return Err(Error::invalid(
                        "output",
                        format!("{}: {} is not a directory", dir.display(), p.display()),
                    ));
                }
                up = p.parent();
            }
            Ok(())
        }
    }
}

/// `diffract view`: the screenshot must be a PNG that can be written and is none of the
/// files the scene reads.
pub fn view_args(args: &crate::view::ViewArgs, scene: &crate::scene::Scene) -> Result<()> {
    table_args(&args.table)?;
    if let Some(p) = &args.screenshot {
        if p.extension().and_then(|e| e.to_str()) != Some("png") {
            return Err(Error::invalid(
                "screenshot",
                format!("{}: must be a .png file", p.display()),
            ));
        }
        let material = args.material.apply(scene.material.clone());
        check_outputs(
            &scene_inputs(args.scene.as_deref(), scene, &material.heightfield),
            &[("--screenshot", p.clone())],
        )?;
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
