//! Leaving out what a scene does not need, through the real render path:
//! the renderer with leaving out on draws what it draws with everything kept, within the
//! stated bound — per pixel `|ΔXYZ| ≤ C(ωi, ωr) · (left-out weight)` (plus float32 noise),
//! since `|P̂|² ≤ 1` at every left-out wavelength — while it loops over fewer wavelengths,
//! uploads fewer DFT texels or builds its table from fewer wavelengths; and `diffract
//! render` prints the one line of what it left out with the right numbers.

mod gpu_util;

use std::path::{Path, PathBuf};
use std::process::Command;

use diffract::brdf::table::Region;
use diffract::leave_out::{intersect, texel_fraction, wavelengths_needed, UvBox};
use diffract::material::{Material, Terms};
use diffract::render::{TableOptions, VariantKind};
use diffract::spectrum::Expansion;
use gpu_util::*;

const SIZE: u32 = 33;

fn out_dir() -> PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-output/leave_out");
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Auto terms at the default tolerance, 10 nm, R = 1: a few seconds on lavapipe.
fn material(heightfield: &str) -> Material {
    Material {
        heightfield: heightfield.into(),
        expansion: Expansion::Chebyshev,
        terms: Terms::Auto,
        window_radius: 1,
        lambda_step_nm: 10,
        ..Material::default()
    }
}

/// Renders a BRDF map with everything kept and with leaving out; checks the per-pixel bound,
/// what was left out, and returns the record.
fn map_both_ways(kind: VariantKind, heightfield: &str, theta: f64, table: Option<TableOptions>) {
    let Some(mut r) = renderer() else { return };
    r.set_variant(kind);
    if let Some(t) = table {
        r.set_table_options(t);
    }
    let m = material(heightfield);
    let p = prepare(&m);
    let full = r
        .render_brdf_map(&p, theta, 0.0, SIZE, None)
        .expect("keep-all map");
    let all = r.left_out();
    r.set_leave_out(true);
    let left = r
        .render_brdf_map(&p, theta, 0.0, SIZE, None)
        .expect("left-out map");
    let rec = r.left_out().expect("a record of what was left out");
    assert_no_validation(&r);
    drop(r);

    // Keeping all leaves nothing out.
    if let Some(all) = &all {
        let w = all.wavelengths.as_ref().unwrap();
        assert!(w.dropped_nm.is_empty() && w.dropped_weight == [0.0; 3]);
        if let Some(t) = &all.texels {
            assert_eq!(t.kept, t.stored);
        }
        assert!(all.terms.is_none(), "{kind}: keeping all left terms out");
    }
    // chebyshev-w leaves out the terms in w whose sum stays within the tolerance of the
    // peak, and says so; no other variant has such terms.
    let series = match &rec.terms {
        Some(t) => {
            assert_eq!(kind, VariantKind::ChebyshevW);
            let t = t.truncation;
            assert!(
                t.kept < t.of && t.tail > 0.0 && t.tail <= m.tolerance,
                "{t:?}"
            );
            assert!(left.variant.name.contains(&format!(" of {}", t.of)));
            t.tail * t.peak
        }
        None => {
            assert_ne!(kind, VariantKind::ChebyshevW, "no record of its terms");
            0.0
        }
    };
    // The wavelengths are leave_out::wavelengths_needed's, for the colour table it loops
    // over (the material's per pixel, the table step's in a build).
    let w = rec.wavelengths.as_ref().unwrap();
    let step = table.map_or(m.lambda_step_nm, |t| {
        t.step_nm.unwrap_or(TableOptions::DEFAULT_STEP_NM)
    });
    let colour = diffract::colour::ColourTable::new(step).unwrap();
    let sel = wavelengths_needed(&colour, m.tolerance);
    assert_eq!(w.kept_nm.len(), sel.keep.len());
    assert!(!w.dropped_nm.is_empty(), "{kind}: no wavelength left out");
    assert_eq!(w.dropped_weight, sel.dropped_weight);
    // The texels are the band of the map's (u, v) at the kept wavelengths.
    let wi = uploaded_direction(theta, 0.0);
    if let Some(t) = &rec.texels {
        let s = p.stack.get().unwrap();
        let (lo, hi) = w.kept_range_nm();
        let region = Region::brdf_map(wi).widened(1e-5);
        let band = intersect(
            &UvBox::of_region(&region).band(
                s.nx,
                s.ny,
                s.dh_um,
                lo * 1e-3,
                hi * 1e-3,
                p.window.radius,
            ),
            &s.band,
        );
        assert_eq!(t.kept, band);
        assert_eq!(t.stored, s.band);
        let f = texel_fraction(&t.kept, &t.stored);
        assert!(f < 0.5, "{kind}: kept {f} of the texels");
        assert!(rec.gpu_bytes < rec.gpu_bytes_keep_all);
        assert_eq!(left.variant.gpu_bytes, rec.gpu_bytes);
        assert_eq!(full.variant.gpu_bytes, rec.gpu_bytes_keep_all);
    }

    // Per pixel: the difference is the left-out wavelengths' share, at most C · weight, and
    // the left-out terms' (|T_j| ≤ 1), at most C · tail · peak. A table interpolates those
    // between its nodes with a cubic B-spline in (u, v) and a Chebyshev series in w, which
    // can overshoot the nodes' values a little.
    let overshoot = if rec.texels.is_some() { 1.01 } else { 1.5 };
    let max = full.rgb.iter().map(|p| p[1]).fold(0.0f32, f32::max) as f64;
    assert!(max > 1e-3, "{kind}: an empty map tests nothing");
    let mut worst = 0.0f64;
    let mut differ = 0;
    let (mut negative_all, mut negative_left) = (0, 0);
    for j in 0..SIZE {
        for i in 0..SIZE {
            let (a, b) = (full.at(i, j), left.at(i, j));
            // (A table's spline can ring slightly below zero beside a sharp lobe, with
            // everything kept too: only the series variants are checked for sign.)
            assert!(b.iter().all(|v| v.is_finite()));
            if rec.texels.is_some() {
                assert!(b.iter().all(|v| *v >= 0.0));
            } else {
                negative_all += a.iter().filter(|v| **v < 0.0).count();
                negative_left += b.iter().filter(|v| **v < 0.0).count();
            }
            let Some(wr) = map_direction(i, j, SIZE) else {
                assert_eq!(b, [0.0; 3]);
                continue;
            };
            let c = diffract::brdf::gain(wi, wr, &p.shading);
            for ch in 0..3 {
                let d = (a[ch] as f64 - b[ch] as f64).abs();
                let bound = c * (w.dropped_weight[ch] + series) * overshoot + 2e-6 * max;
                assert!(
                    d <= bound,
                    "{kind}: pixel ({i},{j}) channel {ch}: {} vs {} (bound {bound:.2e})",
                    a[ch],
                    b[ch]
                );
                worst = worst.max(d / max);
                differ += (d > 0.0) as usize;
            }
        }
    }
    eprintln!(
        "{kind} {heightfield}: {} of {} wavelengths kept, worst |Δ| {worst:.2e} of max Y {max:.3e} ({differ} channels differ, negative: {negative_all} keeping all, {negative_left} leaving out); GPU memory {:.2} MB against {:.2} MB",
        w.kept_nm.len(),
        w.kept_nm.len() + w.dropped_nm.len(),
        rec.gpu_bytes as f64 / 1e6,
        rec.gpu_bytes_keep_all as f64 / 1e6
    );
}

#[test]
fn flss_map_left_out_equals_keep_all_within_the_bound() {
    map_both_ways(VariantKind::Flss, "builtin:elaphe", 60.0, None);
}

#[test]
fn nmm_map_left_out_equals_keep_all_within_the_bound() {
    map_both_ways(VariantKind::Nmm, "builtin:blazed", 30.0, None);
}

/// pq loops over the colour table the variant keeps: it once looped over every wavelength of
/// the step, read past the kept ones and drew a black map whenever leaving out was on.
#[test]
fn pq_map_left_out_equals_keep_all_within_the_bound() {
    map_both_ways(VariantKind::Pq, "builtin:blazed", 30.0, None);
}

#[test]
fn table_built_from_fewer_wavelengths_equals_keep_all_within_the_bound() {
    let table = TableOptions {
        texel_uv: Some(0.02),
        step_nm: Some(10),
        ..TableOptions::default()
    };
    // The light's mirror direction on a pixel, so the map holds the specular peak.
    map_both_ways(
        VariantKind::ChebyshevW,
        "builtin:elaphe-measured",
        theta_for_specular_pixel(10, SIZE),
        Some(table),
    );
}

/// Runs `diffract render ARGS` with validation on; returns the `left out:` line(s) of stderr,
/// or `None` when the machine has no Vulkan driver (a failure under
/// `DIFFRACT_REQUIRE_VULKAN=1`).
fn render(args: &[&str]) -> Option<Vec<String>> {
    let o = Command::new(env!("CARGO_BIN_EXE_diffract"))
        .arg("render")
        .args(args)
        .env("DIFFRACT_VALIDATION", "1")
        .output()
        .expect("run diffract");
    if binary_found_no_vulkan(&o) {
        return None;
    }
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "diffract render {args:?}: {err}");
    let lines: Vec<String> = err
        .lines()
        .filter(|l| l.starts_with("left out:"))
        .map(str::to_string)
        .collect();
    // The line is the subject of these tests: its absence is a failure.
    assert!(
        !lines.is_empty(),
        "diffract render {args:?} printed no 'left out:' line: {err}"
    );
    Some(lines)
}

#[test]
fn render_reports_what_it_left_out_on_one_line() {
    let dir = out_dir();
    let (a, b) = (dir.join("map_left.exr"), dir.join("map_all.exr"));
    let common = [
        "--brdf-map",
        "--theta-i",
        "60",
        "--size",
        "17",
        "--variant",
        "flss",
        "--heightfield",
        "builtin:elaphe",
        "--lambda-step-nm",
        "10",
        "--window-radius",
        "1",
        "--no-cache",
        "-o",
    ];
    let with = |out: &Path, extra: &[&str]| {
        let mut v: Vec<String> = common.iter().map(|s| s.to_string()).collect();
        v.push(out.display().to_string());
        v.extend(extra.iter().map(|s| s.to_string()));
        v
    };
    let left_args = with(&a, &["--verbose"]);
    let Some(lines) = render(&left_args.iter().map(String::as_str).collect::<Vec<_>>()) else {
        return;
    };
    // What the line must say, from the library.
    let m = Material {
        heightfield: "builtin:elaphe".into(),
        window_radius: 1,
        lambda_step_nm: 10,
        ..Material::default()
    };
    let p = prepare(&m);
    let sel = wavelengths_needed(&p.colour, m.tolerance);
    let kept = |i: usize| p.colour.lambdas_nm[sel.keep[i]];
    let (lo, hi) = (kept(0), kept(sel.keep.len() - 1));
    let s = p.stack.get().unwrap();
    let region = Region::brdf_map(uploaded_direction(60.0, 0.0)).widened(1e-5);
    let band = intersect(
        &UvBox::of_region(&region).band(s.nx, s.ny, s.dh_um, lo * 1e-3, hi * 1e-3, 1),
        &s.band,
    );
    let line = &lines[0];
    for want in [
        format!("left out: terms above T = {} (auto)", p.terms()),
        format!(
            "{} of {} wavelengths per pixel",
            p.colour.len() - sel.keep.len(),
            p.colour.len()
        ),
        format!("{lo}–{hi} nm kept"),
        format!(
            "{:.1}% of the DFT texels ({}×{} of {}×{} kept)",
            100.0 * (1.0 - texel_fraction(&band, &s.band)),
            band.width,
            band.height,
            s.band.width,
            s.band.height
        ),
        "features: texture blending;".to_string(),
        format!(
            "GPU memory {:.1} MB ({:.1} MB keeping all)",
            (s.term_count() * band.width * band.height * 8) as f64 / 1e6,
            (s.term_count() * s.band.width * s.band.height * 8) as f64 / 1e6
        ),
    ] {
        assert!(line.contains(&want), "'{line}' lacks '{want}'");
    }
    // --verbose: terms, wavelengths, texels and features, one line each.
    assert_eq!(lines.len(), 5, "{lines:#?}");
    assert!(lines[2].contains(&format!("kept {lo}–{hi} ({})", sel.keep.len())));
    assert!(lines[3].contains(&format!("columns {}..{}", band.x0, band.x0 + band.width)));

    // --keep-all: nothing left out, one line, the same image within the bound.
    let all_args = with(&b, &["--keep-all"]);
    let lines = render(&all_args.iter().map(String::as_str).collect::<Vec<_>>())
        .expect("the first render found Vulkan");
    assert_eq!(lines.len(), 1, "{lines:#?}");
    for want in [
        format!("0 of {} wavelengths per pixel", p.colour.len()),
        format!(
            "0.0% of the DFT texels ({0}×{1} of {0}×{1} kept)",
            s.band.width, s.band.height
        ),
        "(--keep-all)".to_string(),
    ] {
        assert!(lines[0].contains(&want), "'{}' lacks '{want}'", lines[0]);
    }
    let (_, _, left) = diffract::image_io::read_exr(&a).unwrap();
    let (_, _, all) = diffract::image_io::read_exr(&b).unwrap();
    let wi = uploaded_direction(60.0, 0.0);
    for (k, (x, y)) in left.iter().zip(&all).enumerate() {
        let (i, j) = (k as u32 % 17, k as u32 / 17);
        let c = map_direction(i, j, 17).map_or(0.0, |wr| diffract::brdf::gain(wi, wr, &p.shading));
        for ch in 0..3 {
            let d = (x[ch] - y[ch]).abs() as f64;
            assert!(
                d <= c * sel.dropped_weight[ch] * 1.01 + 1e-7,
                "pixel {k}: {x:?} vs {y:?}"
            );
        }
    }
}

#[test]
fn mesh_render_leaves_out_texels_its_directions_cannot_reach() {
    let dir = out_dir();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/examples/flat_scales.toml");
    let scene = scene.display().to_string();
    let (a, b) = (dir.join("mesh_left.exr"), dir.join("mesh_all.exr"));
    let (a_s, b_s) = (a.display().to_string(), b.display().to_string());
    let args = |out: &str| {
        vec![
            "--scene",
            &scene,
            "--variant",
            "flss",
            "--width",
            "24",
            "--height",
            "24",
            "--lambda-step-nm",
            "10",
            "--window-radius",
            "1",
            "--no-cache",
            "-o",
        ]
        .into_iter()
        .map(str::to_string)
        .chain([out.to_string()])
        .collect::<Vec<_>>()
    };
    let l = args(&a_s);
    let Some(lines) = render(&l.iter().map(String::as_str).collect::<Vec<_>>()) else {
        return;
    };
    let mut k = args(&b_s);
    k.push("--keep-all".into());
    let all_lines = render(&k.iter().map(String::as_str).collect::<Vec<_>>())
        .expect("the first render found Vulkan");
    // A distant camera and one light reach a small (u, v) box: most texels are left out.
    let pct: f64 = lines[0]
        .split("% of the DFT texels")
        .next()
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no texel fraction in '{}'", lines[0]));
    assert!(pct > 50.0, "{}", lines[0]);
    assert!(
        all_lines[0].contains("0.0% of the DFT texels"),
        "{}",
        all_lines[0]
    );
    // The images agree within the bound, measured against the specular highlight
    // (the brightest pixels are the mirror direction, ρ ≈ C).
    let (_, _, left) = diffract::image_io::read_exr(&a).unwrap();
    let (_, _, all) = diffract::image_io::read_exr(&b).unwrap();
    let max = all.iter().flatten().fold(0.0f32, |m, v| m.max(*v)) as f64;
    let worst = left
        .iter()
        .zip(&all)
        .flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs() as f64))
        .fold(0.0f64, f64::max);
    // XYZ → sRGB sums at most 5.3 times a channel's error.
    assert!(worst <= 5.3e-3 * max, "worst {worst:.3e} of max {max:.3e}");
    eprintln!(
        "{}\n{}\nworst |Δ| {worst:.2e} of max {max:.3e}",
        lines[0], all_lines[0]
    );
}
