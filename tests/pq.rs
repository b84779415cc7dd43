//! The PQ variant's f64 model (thesis §1.5.3 done right, `brdf::pq`) against FLSS at 1 nm on
//! a grating whose period divides the patch, and against the thesis's `√(p² + q²)` form.
//! No GPU here (tests/gpu_pq.rs has the GPU side).

use diffract::brdf::pq::{self, Form};
use diffract::brdf::{direction, model, Shading};
use diffract::heightfield::HeightField;
use diffract::material::Material;

/// A 65 µm patch of 240² samples (dH = 0.2708 µm): 40 copies of a 1.625 µm sinusoidal
/// ridge along x (6 samples a period), constant along y.
fn grating() -> HeightField {
    let n = 240;
    let dh = 65.0 / n as f64;
    let tau = 2.0 * std::f64::consts::PI;
    let h = (0..n * n)
        .map(|i| 0.12 * (1.0 + (tau * (i % n) as f64 / 6.0).sin()))
        .collect();
    HeightField::new(n, n, dh, h).unwrap()
}

/// PQ against FLSS (same terms, 1 nm) over the plane of incidence, θi = 40°, θr = 5…83°.
///
/// The tolerance, derived (brdf::pq's module doc). Both are exact at a line's centre (the
/// 3-tap sinc interpolation is exact on the period's bins; within a main lobe, |s − m| ≤
/// 1/N, the dropped taps weigh ≲ 1/(2πN) of their bins). A spectral integral sees each
/// line's area: N = round(57.6/1.625) = 35 copies make PQ's 1.28% larger than the
/// Gaussian window's. The shapes differ: the box's Fejér kernel keeps 90.3% of a line's
/// energy in its main lobe and spreads the rest over side lobes decaying as 1/Δs², whose
/// share beyond |Δs| = δ (δ in order spacings) is ≈ 2/(π²Nδ); light moved by more than a
/// quarter of an order spacing (tens of nm at orders 4–6) lands where D65·CMF weigh it
/// differently, or in another pixel: 2/(π²·35·0.25) = 2.3%. Together ≈ 3.6%, so the test
/// takes 5% rel L2 (Y on the bright orders reads 2–3% low: the side-lobe loss exceeds the
/// area gain; between the orders the box leaves ~1e-4 where the Gaussian leaves nothing).
/// The thesis form √(p² + q²) (|F| instead of |F|²) has lobe area ~ ln N/N, several times
/// too large: it must miss by more than 5 times that tolerance.
#[test]
fn pq_matches_flss_at_1nm_on_a_grating_whose_period_divides_the_patch() {
    let hf = grating();
    let dir = std::env::temp_dir().join(format!("diffract-pq-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("grating.f32");
    hf.save(&path).unwrap();
    let material = Material {
        heightfield: path.to_string_lossy().into_owned(),
        lambda_step_nm: 1,
        ..Material::default()
    };
    let p = material.prepare(None, &diffract::report::Stderr).unwrap();
    let t = p.terms();
    let g = pq::estimate_periodicity(&p.heightfield, material.coherence_um).unwrap();
    assert_eq!(g.axes[0].copies_in_patch, 40);
    assert!((g.axes[0].period_um - 1.625).abs() < 1e-9);
    assert_eq!(g.axes[0].copies, 35);
    assert_eq!(g.axes[1].taps, 1, "constant along y");
    let area = g.axes[0].area_ratio();
    assert!((area - 1.0128).abs() < 1e-3, "area ratio {area}");
    let tolerance = 0.05;

    let shading = Shading::default();
    let wi = direction(40.0, 0.0);
    let (mut e2, mut r2, mut thesis_e2, mut ratio_sum, mut ratio_n) = (0.0, 0.0, 0.0, 0.0, 0);
    for k in 0..40 {
        let wr = direction(5.0 + 2.0 * k as f64, 180.0);
        let flss = model::xyz(
            p.stack.get().unwrap(),
            t,
            &p.window,
            &shading,
            &p.colour,
            wi,
            wr,
        );
        let fixed = pq::xyz(
            p.stack.get().unwrap(),
            t,
            &g,
            &shading,
            &p.colour,
            wi,
            wr,
            Form::Intensity,
        );
        let thesis = pq::xyz(
            p.stack.get().unwrap(),
            t,
            &g,
            &shading,
            &p.colour,
            wi,
            wr,
            Form::Thesis,
        );
        assert!(fixed.iter().all(|c| c.is_finite() && *c >= -1e-12));
        for c in 0..3 {
            e2 += (fixed[c] - flss[c]).powi(2);
            thesis_e2 += (thesis[c] - flss[c]).powi(2);
            r2 += flss[c] * flss[c];
        }
        if flss[1] > 1e-2 {
            ratio_sum += fixed[1] / flss[1];
            ratio_n += 1;
        }
    }
    let (rel, thesis) = ((e2 / r2).sqrt(), (thesis_e2 / r2).sqrt());
    println!(
        "pq vs flss at 1 nm: rel L2 {rel:.3e} (tolerance {tolerance:.3e}; lobe area ratio {area:.4}, mean Y ratio on lit directions {:.4} over {ratio_n}); thesis √(p²+q²): {thesis:.3e}",
        ratio_sum / ratio_n.max(1) as f64
    );
    assert!(rel < tolerance, "pq vs flss 1 nm: {rel:e}");
    assert!(
        thesis > 5.0 * tolerance,
        "√(p²+q²) should miss by far: {thesis:e}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

/// The shipped irregular and measured fields are refused with one clear reason, and the
/// synthetic blazed grating is accepted at its 2.5 µm period, with the 4.5% of its power
/// that its 92 nm sampling aliases off the lattice stated.
#[test]
fn pq_refuses_fields_without_a_period() {
    for name in [
        "builtin:elaphe-measured",
        "builtin:elaphe-grown",
        "builtin:elaphe",
        "builtin:xenopeltis",
    ] {
        let hf = HeightField::load_source(name, None, None).unwrap();
        let err = pq::estimate_periodicity(&hf, 65.0).unwrap_err().to_string();
        assert!(err.contains("not periodic"), "{name}: {err}");
        assert_eq!(err.lines().count(), 1);
    }
    let hf = HeightField::load_source("builtin:blazed", None, None).unwrap();
    let g = pq::estimate_periodicity(&hf, 65.0).unwrap();
    let l = g.axes[0].period_um;
    assert!((l - 2.5).abs() < 0.01, "blazed period {l}");
    assert_eq!((g.axes[0].copies_in_patch, g.axes[0].copies), (26, 23));
    assert!(
        g.off_lattice > 0.04 && g.off_lattice < 0.05,
        "{}",
        g.off_lattice
    );
    println!(
        "blazed: M = {}, L = {l:.4} µm, N = {}, area ratio {:.4}, off-lattice power {:.1e}",
        g.axes[0].copies_in_patch,
        g.axes[0].copies,
        g.axes[0].area_ratio(),
        g.off_lattice
    );
}
