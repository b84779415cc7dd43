//! Every shader variant on lavapipe with validation on: its BRDF map agrees with its own
//! f64 CPU model (the same table, interpolated as the GPU does) within a float32 bound,
//! the table variants agree with the f64 reference where their tables resolve `G`, a
//! spectral map is refused by variants that integrate offline, and resources are reused
//! between frames of the same material.

mod gpu_util;

use diffract::brdf::{direction, reference, Shading};
use diffract::colour::ColourTable;
use diffract::heightfield::HeightField;
use diffract::material::Material;
use diffract::render::variant::Family;
use diffract::render::{TableOptions, VariantKind};
use gpu_util::*;

/// A small fast material: a 65 µm patch of 130² samples (dH = 0.5 µm: only |u| ≲ 0.4 is
/// inside the spectrum at 380 nm, which is all a 30°-light map near specular needs).
fn material(dir: &std::path::Path) -> Material {
    let n = 130;
    let dh = 0.5;
    let tau = 2.0 * std::f64::consts::PI;
    let h = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f64 * dh, (i / n) as f64 * dh);
            0.1 * (1.0 + (tau * x / 5.0).sin()) + 0.03 * (1.0 + (tau * (x + y) / 13.0).cos())
        })
        .collect();
    let path = dir.join("field.png");
    HeightField::new(n, n, dh, h).unwrap().save(&path).unwrap();
    Material {
        heightfield: path.to_string_lossy().into_owned(),
        terms: diffract::material::Terms::Fixed(12),
        lambda_step_nm: 10,
        ..Material::default()
    }
}

fn scratch(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-variants-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

const SIZE: u32 = 24;
const THETA: f64 = 30.0;

fn options() -> TableOptions {
    TableOptions {
        texel_uv: Some(0.01),
        step_nm: Some(10),
        ..TableOptions::default()
    }
}

#[test]
fn every_variant_matches_its_own_f64_model() {
    let Some(mut r) = renderer() else { return };
    let dir = scratch("model");
    let prepared = prepare(&material(&dir));
    let wi = uploaded_direction(THETA, 0.0);
    r.set_keep_models(true);
    r.set_table_options(options());
    // pq needs whole copies of one period, which this field (two incommensurate waves) is
    // not: it is refused here and checked against its own model in tests/gpu_pq.rs. The
    // debug views draw no BRDF (tests/gpu_registry.rs checks them).
    for kind in VariantKind::ALL
        .into_iter()
        .filter(|k| *k != VariantKind::Pq && k.family() != Family::Debug)
    {
        r.set_variant(kind);
        let frame = r
            .render_brdf_map(&prepared, THETA, 0.0, SIZE, None)
            .unwrap_or_else(|e| panic!("{kind}: {e}"));
        assert_eq!(frame.variant.name.split(' ').next(), Some(kind.name()));
        if kind == VariantKind::Nmm {
            // 5 µm ridges along x: 13 periods in the 65 µm patch.
            let g = diffract::brdf::nmm::estimate_grating(&prepared.heightfield).unwrap();
            let d = g.period_um[0].unwrap();
            assert!((d - 5.0).abs() < 0.025, "estimated period {d}");
        }
        // Every variant is scored against its own CPU model.
        let model = |wr: [f64; 3]| {
            r.model()
                .unwrap_or_else(|| panic!("{kind} has a model"))
                .xyz(&prepared, &prepared.colour, wi, wr)
                .unwrap()
        };
        let mut peak = 0.0f64;
        let mut worst = 0.0f64;
        let mut gain_max = 0.0f64;
        for j in 0..SIZE {
            for i in 0..SIZE {
                let Some(wr) = map_direction(i, j, SIZE) else {
                    continue;
                };
                let m = model(wr);
                let g = frame.at(i, j);
                peak = peak.max(m[1]);
                gain_max = gain_max.max(diffract::brdf::gain(wi, wr, &prepared.shading));
                for c in 0..3 {
                    worst = worst.max((g[c] as f64 - m[c]).abs());
                }
            }
        }
        // float32 arithmetic and filtering weights: 1e-3 of the map's peak for the stable
        // representations. `dhillon` sums powers of ŵ that may exceed G: its table states a
        // bound on the float32 rounding of G (absolute, times the gain here), which the
        // build held under the material's tolerance, else it would have refused.
        let mut bound = 1e-3 * peak;
        if kind == VariantKind::Dhillon {
            let table = r.table_model().expect("kept model");
            let rounding = table.f32_error().expect("dhillon states its rounding");
            assert!(
                rounding <= prepared.material.tolerance,
                "dhillon drew a table whose bound {rounding:e} exceeds the tolerance"
            );
            bound += rounding * gain_max;
        }
        assert!(
            worst <= bound,
            "{kind}: GPU vs f64 model {worst:e} (peak {peak:e}, bound {bound:e})"
        );
    }
    assert_no_validation(&r);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn table_variants_agree_with_the_reference_where_the_table_resolves_g() {
    let Some(mut r) = renderer() else { return };
    let dir = scratch("reference");
    let prepared = prepare(&material(&dir));
    let wi = direction(THETA, 0.0);
    r.set_table_options(TableOptions {
        texel_uv: Some(0.004),
        step_nm: Some(10),
        w_nodes: Some(24),
        ..TableOptions::default()
    });
    let colour = ColourTable::new(10).unwrap();
    // Pixels along the plane of incidence, where this grating diffracts.
    let px: Vec<(u32, u32)> = (2..SIZE - 2).step_by(3).map(|i| (i, SIZE / 2)).collect();
    let wrs: Vec<[f64; 3]> = px
        .iter()
        .filter_map(|&(i, j)| map_direction(i, j, SIZE))
        .collect();
    let want = reference::xyz_many(
        &prepared.heightfield,
        65.0,
        &Shading::default(),
        &colour,
        wi,
        &wrs,
        &|| (),
    );
    let peak = want.iter().map(|x| x[1]).fold(0.0, f64::max);
    // Every registered table variant, so that a new one is held to the reference too.
    for kind in VariantKind::ALL.into_iter().filter(|k| k.is_table()) {
        r.set_variant(kind);
        let frame = r
            .render_brdf_map(&prepared, THETA, 0.0, SIZE, None)
            .unwrap();
        let mut worst = 0.0f64;
        for (&(i, j), w) in px.iter().zip(&want) {
            worst = worst.max((frame.at(i, j)[1] as f64 - w[1]).abs());
        }
        // The table integrates the same 10 nm spectrum as the reference here, so what is
        // left is the (u, v) interpolation of lobes ~0.005 wide on a 0.004 grid: 5% of the
        // peak bounds it (the profile reports the full distribution on the real gratings).
        assert!(worst < 0.05 * peak, "{kind}: {worst:e} vs peak {peak:e}");
    }
    assert_no_validation(&r);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn spectral_maps_need_flss_and_frames_reuse_prepared_tables() {
    let Some(mut r) = renderer() else { return };
    let dir = scratch("spectral");
    let prepared = prepare(&material(&dir));
    r.set_table_options(options());
    r.set_variant(VariantKind::Volume);
    let err = r
        .render_brdf_map(&prepared, THETA, 0.0, SIZE, Some(550.0))
        .unwrap_err()
        .to_string();
    assert!(err.contains("flss"), "{err}");
    let a = r
        .render_brdf_map(&prepared, THETA, 0.0, SIZE, None)
        .unwrap();
    let b = r
        .render_brdf_map(&prepared, THETA, 0.0, SIZE, None)
        .unwrap();
    assert_eq!(a.rgb, b.rgb);
    // The second frame reused the table: it reports the first build's time (a rebuild would
    // measure its own).
    assert_eq!(a.variant.build_ms, b.variant.build_ms);
    // `default` resolves to a real variant.
    r.set_variant(VariantKind::Default);
    assert_eq!(r.variant(), VariantKind::DEFAULT);
    assert_no_validation(&r);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn render_reports_gpu_time_for_every_variant_and_variants_lists_them() {
    if renderer().is_none() {
        return;
    }
    let dir = scratch("cli");
    let m = material(&dir);
    let run = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_diffract"))
            .args(args)
            .env("DIFFRACT_CACHE", "")
            .env("DIFFRACT_VALIDATION", "1")
            .output()
            .expect("run diffract")
    };
    let list = run(&["variants"]);
    let text = String::from_utf8_lossy(&list.stdout);
    assert!(list.status.success());
    for kind in VariantKind::ALL {
        assert!(text.contains(kind.name()), "{text}");
    }
    assert!(text.contains("(default)"), "{text}");
    // pq refuses this aperiodic field (tests/gpu_pq.rs renders it on a periodic one).
    for kind in VariantKind::ALL
        .into_iter()
        .filter(|k| *k != VariantKind::Pq)
    {
        let out = dir.join(format!("{}.exr", kind.name()));
        let o = run(&[
            "render",
            "--brdf-map",
            "--size",
            "16",
            "--theta-i",
            "30",
            "--heightfield",
            &m.heightfield,
            "--terms",
            "8",
            "--lambda-step-nm",
            "20",
            "--table-texel",
            "0.02",
            "--table-step-nm",
            "20",
            "--variant",
            kind.name(),
            "-o",
            out.to_str().unwrap(),
        ]);
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(
            o.status.success(),
            "{kind}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(
            stdout.contains(&format!("variant {}", kind.name())) && stdout.contains(": GPU "),
            "{kind}: {stdout}"
        );
        let gpu: f64 = stdout
            .split(": GPU ")
            .nth(1)
            .and_then(|s| s.split(" ms").next())
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("no GPU time in: {stdout}"));
        assert!(gpu > 0.0);
    }
    let o = run(&[
        "render",
        "--brdf-map",
        "--size",
        "8",
        "--variant",
        "volume",
        "--lambda-nm",
        "500",
        "-o",
        dir.join("x.exr").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--variant flss"));
    assert!(!dir.join("x.exr").exists());
    // `default` is the best variant that can draw the request: flss for one wavelength,
    // said in one note line.
    let o = run(&[
        "render",
        "--brdf-map",
        "--size",
        "8",
        "--heightfield",
        &m.heightfield,
        "--terms",
        "4",
        "--lambda-nm",
        "550",
        "-o",
        dir.join("y.exr").to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let notes: Vec<&str> = stderr.lines().filter(|l| l.starts_with("note:")).collect();
    assert_eq!(notes.len(), 1, "{stderr}");
    assert!(notes[0].contains("flss"), "{stderr}");
    assert!(String::from_utf8_lossy(&o.stdout).contains("variant flss"));
    assert!(dir.join("y.exr").exists());
    let _ = std::fs::remove_dir_all(dir);
}
