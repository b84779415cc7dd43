//! The fast CPU table build (float32 sums over the shared term band) against the float64
//! build, on three fields of different kinds: the default grown Elaphe field, a 1-D
//! sinusoidal grating and the measured AFM crop. Every sample of every slice must be within
//! `FAST_BUILD_TOLERANCE` of the f64 build's slice peak, and the build's own probe (the
//! figure its report line states) must agree with what the whole table shows.

use diffract::brdf::table::{sample_g_kept_in, Region, TableSpec, FAST_BUILD_TOLERANCE};
use diffract::brdf::truncation::Precision;
use diffract::heightfield::{HeightField, Source};
use diffract::report::Collect;

fn field(spec: &str) -> HeightField {
    Source::new(spec)
        .load(&Collect::default())
        .unwrap_or_else(|e| panic!("{spec}: {e}"))
}

fn check(name: &str, hf: &HeightField, region: Region) {
    let spec = TableSpec {
        region,
        texel_uv: TableSpec::default_texel(65.0),
        w_nodes: 4,
        step_nm: 10,
        response: diffract::brdf::table::Response::Relative,
    };
    let w: Vec<f64> = (0..spec.w_nodes)
        .map(|k| region.lo[2] + (region.hi[2] - region.lo[2]) * k as f64 / 3.0)
        .collect();
    let exact = sample_g_kept_in(hf, 65.0, &spec, &w, None, Precision::F64, &|| ()).unwrap();
    let fast = sample_g_kept_in(hf, 65.0, &spec, &w, None, Precision::F32, &|| ()).unwrap();
    assert_eq!(exact.precision, Precision::F64);
    assert_eq!(exact.probe, None);
    assert_eq!(
        fast.precision,
        Precision::F32,
        "{name}: the fast build must use the term band here"
    );
    let mut worst = 0.0f64;
    for (a, b) in exact.slices.data.iter().zip(&fast.slices.data) {
        let peak = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(peak > 0.0, "{name}: an empty slice proves nothing");
        for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
            worst = worst.max((x - y).abs() / peak);
        }
    }
    let probe = fast.probe.expect("an f32 build states its probe");
    eprintln!("{name}: f32 against f64: {worst:.2e} of the slice peak (probe {probe:.2e})");
    assert!(
        worst <= FAST_BUILD_TOLERANCE,
        "{name}: {worst:e} of the peak, over {FAST_BUILD_TOLERANCE:e}"
    );
    assert!(
        probe > 0.0 && probe <= FAST_BUILD_TOLERANCE,
        "{name}: probe {probe:e}"
    );
    // The probe is a sample of the same difference: not far below what the table shows.
    assert!(
        probe >= worst / 100.0,
        "{name}: probe {probe:e} hides the table's {worst:e}"
    );
}

#[test]
fn the_fast_build_is_within_its_tolerance_of_f64_on_three_fields() {
    // Around the specular peak at normal incidence and a first order of the ridges.
    let near_specular = Region {
        lo: [-0.12, -0.12, -2.0],
        hi: [0.12, 0.12, -1.8],
    };
    check(
        "builtin:elaphe-grown",
        &field("builtin:elaphe-grown"),
        near_specular,
    );
    let grating = field("builtin:sinusoidal");
    check(
        "builtin:sinusoidal",
        &grating,
        Region {
            lo: [-0.5, -0.05, -2.0],
            hi: [0.5, 0.05, -1.7],
        },
    );
    let crop = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/assets/measured/elaphe_afm_crop.gsf"
    );
    check("measured crop", &field(crop), near_specular);
}
