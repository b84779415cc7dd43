//! `profile --env`: the environment-lit rows on lavapipe (validation on), on a small 1-D
//! grating with a small table: a row per sample count, their error against the f64
//! quadrature falling from the fewest samples to the most, rows over the budget skipped
//! with their estimates, the rows in the table, the CSV and the plot, and one error line
//! for a bad map.

mod gpu_util;

use diffract::brdf::table::{Region, TableSpec};
use diffract::heightfield::HeightField;
use diffract::light::env::{EnvMap, EnvSource};
use diffract::material::Material;
use diffract::profile::{
    flss_variants, format_csv, format_table, profile_with_env, Budget, EnvProfile, Frames,
    ProfileSetup,
};
use diffract::render::variant::VariantKind;

fn scratch(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!(
        "diffract-profile-env-{}-{name}",
        std::process::id()
    ));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A 1-D sinusoidal grating, period 2 µm, heights ±0.1 µm, 4 periods tiled.
fn grating(dir: &std::path::Path) -> String {
    let path = dir.join("grating.png");
    let (nx, ny) = (128usize, 4usize);
    let dh = 8.0 / nx as f64;
    let h: Vec<f64> = (0..nx * ny)
        .map(|p| 0.1 * (1.0 + (2.0 * std::f64::consts::PI * (p % nx) as f64 * dh / 2.0).sin()))
        .collect();
    HeightField::new(nx, ny, dh, h)
        .unwrap()
        .save(&path)
        .unwrap();
    path.to_string_lossy().into_owned()
}

/// Coherence 10 µm: lobes about 0.035 wide in `(u, v)`, so a coarse table over the whole
/// reachable disc (`render --env`'s region) stays small.
const COHERENCE_UM: f64 = 10.0;

fn setup(heightfield: &str, frames: Frames) -> ProfileSetup {
    ProfileSetup {
        base: Material {
            heightfield: heightfield.into(),
            coherence_um: COHERENCE_UM,
            ..Material::default()
        },
        variants: Vec::new(),
        theta_i_deg: 60.0,
        phi_i_deg: 0.0,
        size: 15,
        pixels: 4,
        brightest: 0,
        frames,
        mesh: None,
        per_vertex: false,
        cache_dir: None,
    }
}

fn env(samples: &[u32]) -> EnvProfile {
    EnvProfile {
        map: EnvMap::load(&EnvSource::Sky, 1.0, 0.0).unwrap(),
        samples: samples.to_vec(),
        spec: TableSpec {
            region: Region {
                lo: [-2.0, -2.0, -2.0],
                hi: [2.0, 2.0, 0.0],
            },
            texel_uv: 0.035,
            w_nodes: 4,
            step_nm: 10,
            response: diffract::brdf::table::Response::Relative,
        },
        pixels: 6,
        variants: vec![VariantKind::ChebyshevW],
    }
}

#[test]
fn env_rows_fall_with_samples_and_appear_in_the_outputs() {
    let Some(mut renderer) = gpu_util::renderer() else {
        return;
    };
    let dir = scratch("rows");
    let hf = grating(&dir);
    let setup = setup(&hf, Frames::Fixed(2));
    let run = profile_with_env(&mut renderer, &setup, Some(&env(&[1, 16, 256]))).unwrap();
    let e = run.env.as_ref().expect("the environment rows");
    assert!(
        run.reports.is_empty() && run.skipped.is_empty(),
        "env rows alone"
    );
    assert_eq!(
        e.rows.iter().map(|r| r.samples).collect::<Vec<_>>(),
        [1, 16, 256]
    );
    assert!(e.skipped.is_empty(), "no budget: every row measured");
    assert_eq!((e.scored, e.asked), (6, 6));
    assert!(
        e.reference_error < 1e-2,
        "the quadrature converged: {}",
        e.reference_error
    );
    for r in &e.rows {
        eprintln!(
            "{}: {} frames, {:.2} ms, rel L2 {:.3e} [{:.3e}, {:.3e}], ΔE p99 {:.2}",
            r.name(),
            r.frames,
            r.gpu_ms,
            r.vs_reference.rel_l2,
            r.intervals.rel_l2.lo,
            r.intervals.rel_l2.hi,
            r.vs_reference.p99_de
        );
        assert_eq!(r.frames, 2);
        assert!(r.gpu_ms > 0.0 && r.wall_ms >= r.gpu_ms);
        let i = r.intervals.rel_l2;
        assert!(i.lo <= r.vs_reference.rel_l2 && r.vs_reference.rel_l2 <= i.hi);
    }
    // Monte Carlo promises N^(−1/2): a factor of 16 from 1 to 256 samples. Asked: at
    // least 4, and each count below the one before.
    let l2: Vec<f64> = e.rows.iter().map(|r| r.vs_reference.rel_l2).collect();
    assert!(l2[1] < l2[0] && l2[2] < l2[1], "{l2:?}");
    assert!(l2[0] / l2[2] > 4.0, "{l2:?}");
    let table = format_table("lavapipe", &setup, &run);
    for name in [
        "env chebyshev-w 1 spp",
        "env chebyshev-w 16 spp",
        "env chebyshev-w 256 spp",
        "builtin:sky",
    ] {
        assert!(table.contains(name), "{table}");
    }
    let csv = format_csv(&run);
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let spp = header.iter().position(|h| *h == "env_spp").unwrap();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 3);
    for (row, n) in rows.iter().zip(["1", "16", "256"]) {
        assert_eq!(row.len(), header.len(), "{row:?}");
        assert_eq!(row[spp], n);
    }
    assert_eq!(renderer.validation_messages(), 0);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn env_rows_over_the_budget_are_skipped_with_their_estimates() {
    let Some(mut renderer) = gpu_util::renderer() else {
        return;
    };
    let dir = scratch("skip");
    let hf = grating(&dir);
    // A budget spent before the first row: the first is measured (it sets the pace), the
    // rest are skipped with the cost that pace estimates.
    let setup = setup(&hf, Frames::Budget(Budget::seconds(1e-3)));
    let run = profile_with_env(&mut renderer, &setup, Some(&env(&[1, 64, 1024]))).unwrap();
    let e = run.env.as_ref().unwrap();
    assert_eq!(e.rows.len(), 1);
    assert_eq!(e.rows[0].samples, 1);
    assert_eq!(
        e.skipped.iter().map(|k| k.samples).collect::<Vec<_>>(),
        [64, 1024]
    );
    for k in &e.skipped {
        assert!(k.estimated_s > 0.0 && k.reason.contains("budget"), "{k:?}");
    }
    // More samples, a larger estimate.
    assert!(e.skipped[1].estimated_s > e.skipped[0].estimated_s);
    let table = format_table("lavapipe", &setup, &run);
    assert!(
        table.contains("skipped: env chebyshev-w 64 spp: estimated"),
        "{table}"
    );
    let csv = format_csv(&run);
    assert!(csv
        .lines()
        .any(|l| l.starts_with("env chebyshev-w 1024 spp,") && l.contains(",true,")));
    assert_eq!(renderer.validation_messages(), 0);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn env_rows_beside_variant_rows() {
    let Some(mut renderer) = gpu_util::renderer() else {
        return;
    };
    let dir = scratch("mixed");
    let hf = grating(&dir);
    let mut setup = setup(&hf, Frames::Fixed(1));
    setup.variants = flss_variants(8)
        .into_iter()
        .filter(|v| v.name == "taylor R=2")
        .collect();
    assert_eq!(setup.variants.len(), 1);
    let run = profile_with_env(&mut renderer, &setup, Some(&env(&[1, 16]))).unwrap();
    assert_eq!(run.reports.len(), 1, "the variant row");
    assert_eq!(run.env.as_ref().unwrap().rows.len(), 2, "the env rows");
    let table = format_table("lavapipe", &setup, &run);
    let variant = table.find("| taylor R=2 |").expect("the variant's table");
    let env = table
        .find("| env chebyshev-w 16 spp |")
        .expect("the env table");
    assert!(variant < env, "the variants' table first: {table}");
    let csv = format_csv(&run);
    assert_eq!(
        csv.lines().count(),
        4,
        "header, the variant, two env rows: {csv}"
    );
    assert_eq!(renderer.validation_messages(), 0);
    let _ = std::fs::remove_dir_all(dir);
}

/// Rows per variant and sample count: each variant draws through its own shader with the
/// same samples, its rows named after it in the table and the CSV.
#[test]
fn env_rows_per_variant() {
    let Some(mut renderer) = gpu_util::renderer() else {
        return;
    };
    let dir = scratch("variants");
    let hf = grating(&dir);
    let mut setup = setup(&hf, Frames::Fixed(1));
    // This small patch's float32 lookup is good to 2e-3 (the planner's figure): flss is
    // drawn at that tolerance.
    setup.base.tolerance = 1e-2;
    let kinds = [
        VariantKind::ChebyshevW,
        VariantKind::Volume,
        VariantKind::Flss,
    ];
    let profile = EnvProfile {
        variants: kinds.to_vec(),
        ..env(&[4, 16])
    };
    let run = profile_with_env(&mut renderer, &setup, Some(&profile)).unwrap();
    let e = run.env.as_ref().unwrap();
    assert!(e.skipped.is_empty(), "{:?}", e.skipped);
    let names: Vec<String> = e.rows.iter().map(|r| r.name()).collect();
    let want: Vec<String> = kinds
        .iter()
        .flat_map(|k| [4, 16].map(|n| format!("env {} {n} spp", k.name())))
        .collect();
    assert_eq!(names, want);
    for r in &e.rows {
        eprintln!("{}: rel L2 {:.3e}", r.name(), r.vs_reference.rel_l2);
        assert!(r.vs_reference.rel_l2.is_finite() && r.vs_reference.rel_l2 < 1.0);
    }
    let table = format_table("lavapipe", &setup, &run);
    let csv = format_csv(&run);
    for name in &want {
        assert!(table.contains(&format!("| {name} |")), "{table}");
        assert!(
            csv.lines().any(|l| l.starts_with(&format!("{name},"))),
            "{csv}"
        );
    }
    assert_eq!(renderer.validation_messages(), 0);
    let _ = std::fs::remove_dir_all(dir);
}

fn profile_cli(args: &[&str], cwd: &std::path::Path) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_diffract"))
        .arg("profile")
        .args(args)
        .current_dir(cwd)
        .env("DIFFRACT_VALIDATION", "1")
        .output()
        .unwrap()
}

#[test]
fn the_command_writes_env_rows_and_refuses_bad_maps_in_one_line() {
    let dir = scratch("cli");
    std::fs::write(dir.join("garbage.hdr"), b"not a radiance file").unwrap();
    let cases: &[(&[&str], &str)] = &[
        (&["--env", "missing.hdr"], "missing.hdr"),
        (&["--env", "garbage.hdr"], "header"),
        (&["--env", "builtin:moon"], "builtin:sky"),
        (&["--env", "builtin:sky", "--env-spp", "0"], "env-spp"),
        (&["--env", "builtin:sky", "--env-pixels", "0"], "env-pixels"),
        (
            &["--env", "builtin:sky", "--env-intensity", "-1"],
            "intensity",
        ),
        (&["--env-spp", "4"], "--env SOURCE"),
        (&["--only", "env"], "--env SOURCE"),
    ];
    for (args, want) in cases {
        let o = profile_cli(args, &dir);
        let err = String::from_utf8_lossy(&o.stderr);
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert_eq!(lines.len(), 1, "{args:?}: one line: {err}");
        assert!(
            lines[0].starts_with("error:") && lines[0].contains(want),
            "{args:?}: {err}"
        );
    }
    let Some(_) = gpu_util::renderer() else {
        return;
    };
    let hf = grating(&dir);
    let o = profile_cli(
        &[
            "--only",
            "env",
            "--env",
            "builtin:studio",
            "--env-rotate-deg",
            "30",
            "--heightfield",
            &hf,
            "--coherence-um",
            "10",
            "--size",
            "9",
            "--pixels",
            "4",
            "--brightest",
            "0",
            "--env-spp",
            "16,1",
            "--env-pixels",
            "3",
            "--frames",
            "1",
            "--table-w-nodes",
            "4",
            "--table-step-nm",
            "10",
            "--csv",
            "p.csv",
            "--plot",
            "p.png",
        ],
        &dir,
    );
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        out.contains("| env chebyshev-w 1 spp | 1 |")
            && out.contains("| env chebyshev-w 16 spp | 16 |"),
        "{out}"
    );
    let csv = std::fs::read_to_string(dir.join("p.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3, "{csv}");
    let png = image::open(dir.join("p.png")).unwrap();
    assert!(png.width() > 100);
    let _ = std::fs::remove_dir_all(dir);
}
