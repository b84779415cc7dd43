//! NMM against the f64 direct-sum reference at 1 nm and against FLSS at 5 nm, without a
//! GPU (the shader follows `brdf::nmm` sample for sample; tests/gpu_variants.rs holds the
//! two together): on a 1D grating and on the measured-like Elaphe field, at directions on
//! the orders, between them and off the plane of incidence, NMM's colour must be at least
//! as close to the reference as FLSS's at 5 nm, and within a stated bound.

use diffract::brdf::{direction, model, nmm, reference, Shading};
use diffract::colour::ColourTable;
use diffract::heightfield::HeightField;
use diffract::material::{Material, PreparedMaterial};

struct Errors {
    nmm: f64,
    flss5: f64,
}

fn rel_l2(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let (mut e, mut r) = (0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        for c in 0..3 {
            e += (x[c] - y[c]).powi(2);
            r += y[c] * y[c];
        }
    }
    (e / r).sqrt()
}

/// rel L2 of XYZ over `wrs` of NMM and of FLSS at 5 nm against the 1 nm reference.
fn errors(p: &PreparedMaterial, wi: [f64; 3], wrs: &[[f64; 3]]) -> Errors {
    let shading = Shading::default();
    let g = nmm::estimate_grating(&p.heightfield).unwrap();
    let density = nmm::Density::new();
    let t = p.terms();
    let five = ColourTable::new(5).unwrap();
    let one = ColourTable::new(1).unwrap();
    let reference = reference::xyz_many(
        &p.heightfield,
        p.material.coherence_um,
        &shading,
        &one,
        wi,
        wrs,
        &|| {},
    );
    let nmm: Vec<[f64; 3]> = wrs
        .iter()
        .map(|&wr| {
            nmm::xyz(
                p.stack.get().unwrap(),
                t,
                &p.window,
                &shading,
                &five,
                &g,
                &density,
                wi,
                wr,
                true,
            )
        })
        .collect();
    let flss5: Vec<[f64; 3]> = wrs
        .iter()
        .map(|&wr| {
            model::xyz(
                p.stack.get().unwrap(),
                t,
                &p.window,
                &shading,
                &five,
                wi,
                wr,
            )
        })
        .collect();
    Errors {
        nmm: rel_l2(&nmm, &reference),
        flss5: rel_l2(&flss5, &reference),
    }
}

/// Directions under a light at θi = 60° (the profile's): the plane of incidence every 3°
/// (orders and the gaps between them), and rays 2° and 6° off that plane.
fn directions() -> Vec<[f64; 3]> {
    let mut wrs = Vec::new();
    for k in 0..26 {
        let theta = 2.0 + 3.0 * k as f64;
        wrs.push(direction(theta, 180.0));
        if k % 3 == 0 {
            wrs.push(direction(theta, 0.0));
            wrs.push(direction(theta, 178.0));
            wrs.push(direction(theta, 174.0));
        }
    }
    wrs
}

fn prepared(heightfield: String) -> PreparedMaterial {
    Material {
        heightfield,
        ..Material::default()
    }
    .prepare(None, &diffract::report::Stderr)
    .unwrap()
}

/// A 1D sinusoidal grating of period 65/32 µm (≈ 2 µm) across x, 0.2 µm peak to valley,
/// on a 65 µm patch of 704² samples (dH = 92 nm, under λmin/4: no order aliases).
#[test]
fn nmm_beats_flss_at_5nm_on_a_1d_grating() {
    let n = 704;
    let dh = 65.0 / 704.0;
    let d = 65.0 / 32.0;
    let tau = 2.0 * std::f64::consts::PI;
    let h = (0..n * n)
        .map(|i| 0.1 * (1.0 + (tau * (i % n) as f64 * dh / d).sin()))
        .collect();
    let dir = std::env::temp_dir().join(format!("diffract-nmm-acc-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("grating.f32");
    HeightField::new(n, n, dh, h).unwrap().save(&path).unwrap();
    let p = prepared(path.to_string_lossy().into_owned());
    let e = errors(&p, direction(60.0, 0.0), &directions());
    println!(
        "1D grating: rel L2 vs 1 nm reference: nmm {:.3e}, flss 5 nm {:.3e}",
        e.nmm, e.flss5
    );
    // Measured 7.5e-4; 13 samples over ±4σν (before) gave 1.28e-3; FLSS at 5 nm 2.05e-3.
    assert!(
        e.nmm <= e.flss5,
        "nmm {:e} vs flss 5 nm {:e}",
        e.nmm,
        e.flss5
    );
    assert!(e.nmm < 1.0e-3, "nmm {:e}", e.nmm);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn nmm_beats_flss_at_5nm_on_the_elaphe_field() {
    let p = prepared("builtin:elaphe".into());
    let e = errors(&p, direction(60.0, 0.0), &directions());
    println!(
        "Elaphe: rel L2 vs 1 nm reference: nmm {:.3e}, flss 5 nm {:.3e}",
        e.nmm, e.flss5
    );
    // NMM sees only the light near the orders: 2.95e-2 (13 samples over ±4σν gave
    // 2.90e-2); FLSS at 5 nm misses lines between its wavelengths: 7.66e-2.
    assert!(
        e.nmm <= e.flss5,
        "nmm {:e} vs flss 5 nm {:e}",
        e.nmm,
        e.flss5
    );
    assert!(e.nmm < 3.0e-2, "nmm {:e}", e.nmm);
}
