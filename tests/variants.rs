//! The pre-integrated tables against the f64 direct-sum reference, without a GPU: at table
//! nodes `C·G` must equal the reference XYZ (same wavelengths) to f64 rounding, since both
//! are exact evaluations of the same windowed transform; between nodes the representations
//! interpolate as documented; the Chebyshev coefficients in `w` decay as a smooth `G` must.

use diffract::brdf::nmm;
use diffract::brdf::reference;
use diffract::brdf::table::{
    chebyshev_nodes, sample_g, ChebyshevW, Dhillon, GTable, Region, TableSpec, Volume,
};
use diffract::brdf::{direction, gain, uvw, Shading};
use diffract::colour::ColourTable;
use diffract::heightfield::HeightField;
use diffract::material::Material;

/// A 65 µm patch of 260² samples (σt ≈ 0.64 texels, as the shipped gratings): a 1.5 µm
/// grating along x plus a weak oblique wave, so both u and v carry structure.
fn field() -> HeightField {
    let n = 260;
    let dh = 0.25;
    let tau = 2.0 * std::f64::consts::PI;
    let h = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f64 * dh, (i / n) as f64 * dh);
            0.15 * (1.0 + (tau * x / 1.5).sin()) + 0.05 * (1.0 + (tau * (x + 2.0 * y) / 12.0).cos())
        })
        .collect();
    HeightField::new(n, n, dh, h).unwrap()
}

fn rel(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
    let n = (b[0] * b[0] + b[1] * b[1] + b[2] * b[2]).sqrt();
    d / n.max(1e-300)
}

#[test]
fn table_nodes_equal_the_direct_sum_reference() {
    let hf = field();
    let shading = Shading::default();
    let colour = ColourTable::new(10).unwrap();
    let wi = direction(50.0, 0.0);
    // Directions on the first order (u = λ/d for λ ≈ 500 nm), at specular, and off-peak.
    for wr in [
        direction(28.0, 180.0),
        direction(50.0, 180.0),
        direction(37.0, 200.0),
    ] {
        let d = uvw(wi, wr);
        // A tiny region whose lower corner is exactly this (u, v, w): node (0, 0, 0).
        let region = Region {
            lo: d,
            hi: [d[0] + 0.004, d[1] + 0.004, d[2] + 0.004],
        };
        let spec = TableSpec {
            region,
            texel_uv: 0.002,
            w_nodes: 2,
            step_nm: 10,
            response: diffract::brdf::table::Response::Relative,
        };
        let s = sample_g(&hf, 65.0, &spec, &[d[2], d[2] + 0.004], &|| ()).unwrap();
        let c = gain(wi, wr, &shading);
        let table = s.data[0][0].map(|g| g * c);
        let want = reference::xyz(&hf, 65.0, &shading, &colour, wi, wr);
        assert!(
            rel(table, want) < 1e-7,
            "wr {wr:?}: table {table:?} vs reference {want:?}"
        );
    }
}

#[test]
fn many_direction_reference_matches_the_single_direction_one() {
    let hf = field();
    let shading = Shading::default();
    let colour = ColourTable::new(20).unwrap();
    let wi = direction(40.0, 10.0);
    let wrs = [
        direction(20.0, 170.0),
        direction(40.0, 190.0),
        direction(70.0, 90.0),
    ];
    let many = reference::xyz_many(&hf, 65.0, &shading, &colour, wi, &wrs, &|| ());
    for (wr, m) in wrs.iter().zip(&many) {
        let one = reference::xyz(&hf, 65.0, &shading, &colour, wi, *wr);
        assert!(rel(*m, one) < 1e-12, "{m:?} vs {one:?}");
    }
}

#[test]
fn representations_interpolate_g_within_their_stated_accuracy() {
    let hf = field();
    let wi = direction(50.0, 0.0);
    // A small box around the first order so the test stays fast; u/v texel at a quarter
    // of the coherence lobe.
    let d = uvw(wi, direction(30.0, 180.0));
    let region = Region {
        lo: [d[0] - 0.05, d[1] - 0.03, d[2] - 0.1],
        hi: [d[0] + 0.05, d[1] + 0.03, d[2] + 0.1],
    };
    let spec = |w_nodes| TableSpec {
        region,
        texel_uv: 0.0015,
        w_nodes,
        step_nm: 10,
        response: diffract::brdf::table::Response::Relative,
    };
    let cheb = ChebyshevW::build(&hf, 65.0, &spec(10), &|| ()).unwrap();
    let dh = Dhillon::from_chebyshev(&cheb, 0.0);
    let vol = Volume::build(&hf, 65.0, &spec(24), &|| ()).unwrap();
    // Points at (u, v) nodes (no u/v interpolation error) but between w nodes: the
    // error in w alone, against the exact G at that w.
    let (nu, nv) = cheb.nodes_uv();
    let w = d[2] + 0.037;
    let nodes_spec = TableSpec {
        w_nodes: 2,
        ..spec(2)
    };
    let exact = sample_g(&hf, 65.0, &nodes_spec, &[w, w + 0.01], &|| ()).unwrap();
    let peak = exact.data[0].iter().map(|x| x[1]).fold(0.0, f64::max);
    assert!(peak > 1e-3, "the box must hold the order: peak {peak}");
    let (mut e_cheb, mut e_dh, mut e_vol) = (0.0f64, 0.0f64, 0.0f64);
    for j in (0..nv).step_by(3) {
        for i in (0..nu).step_by(3) {
            let u = region.lo[0] + region.extent()[0] * i as f64 / (nu - 1) as f64;
            let v = region.lo[1] + region.extent()[1] * j as f64 / (nv - 1) as f64;
            let g = exact.data[0][j * nu + i][1];
            e_cheb = e_cheb.max((cheb.g([u, v, w]).unwrap()[1] - g).abs() / peak);
            e_dh = e_dh.max((dh.g([u, v, w]).unwrap()[1] - g).abs() / peak);
            e_vol = e_vol.max((vol.g([u, v, w]).unwrap()[1] - g).abs() / peak);
        }
    }
    // Chebyshev in w converges spectrally: 10 nodes over Δw = 0.2 are exact to 1e-6 here;
    // the same polynomial in powers of w agrees in f64 (the conditioning bites in f32).
    assert!(e_cheb < 1e-6, "chebyshev-w in w: {e_cheb:e}");
    assert!(e_dh < 1e-6, "dhillon in w (f64): {e_dh:e}");
    // Linear in w with 24 slices: second-order error, well under 1e-2 of the peak.
    assert!(e_vol < 1e-2 && e_vol > e_cheb, "volume in w: {e_vol:e}");
    // Outside the box: no value (the GPU draws black).
    assert!(cheb.g([region.hi[0] + 0.01, d[1], d[2]]).is_none());
    assert!(vol.g([d[0], d[1], region.lo[2] - 0.01]).is_none());
}

#[test]
fn chebyshev_coefficients_decay_to_the_tolerance_with_the_default_count() {
    // Over a BRDF map's whole w range at 60° (Δw = 1), the default K = 16 must bring the
    // last coefficient under 1e-4 of c0: the series is then converged to that tolerance.
    let hf = field();
    let wi = direction(60.0, 0.0);
    let full = Region::brdf_map(wi);
    let d = uvw(wi, direction(35.0, 180.0));
    let region = Region {
        lo: [d[0] - 0.02, d[1] - 0.02, full.lo[2]],
        hi: [d[0] + 0.02, d[1] + 0.02, full.hi[2]],
    };
    let spec = TableSpec {
        region,
        texel_uv: 0.004,
        w_nodes: 16,
        step_nm: 20,
        response: diffract::brdf::table::Response::Relative,
    };
    let cheb = ChebyshevW::build(&hf, 65.0, &spec, &|| ()).unwrap();
    let decay = cheb.decay();
    assert_eq!(decay.len(), 16);
    assert!(decay[15] < 1e-4, "decay {decay:?}");
    assert!(decay[15] < decay[2], "decay {decay:?}");
    // The nodes are where G was sampled: reproduce it there exactly (interpolation).
    let nodes = chebyshev_nodes(region.lo[2], region.hi[2], 16);
    let exact = sample_g(&hf, 65.0, &spec, &nodes, &|| ()).unwrap();
    for (k, w) in nodes.iter().enumerate() {
        let g = cheb.g([region.lo[0], region.lo[1], *w]).unwrap();
        let e = exact.data[k][0];
        assert!(
            (g[1] - e[1]).abs() <= 1e-9 * e[1].abs().max(1e-12),
            "{g:?} vs {e:?}"
        );
    }
}

#[test]
fn table_specs_refuse_nonsense_and_oversized_builds() {
    let r = Region::brdf_map(direction(30.0, 0.0));
    let bad = |texel_uv: f64, w_nodes: usize| TableSpec {
        region: r,
        texel_uv,
        w_nodes,
        step_nm: 5,
        response: diffract::brdf::table::Response::Relative,
    };
    assert!(bad(0.0, 16).validate().is_err());
    assert!(bad(f64::NAN, 16).validate().is_err());
    assert!(bad(0.0001, 16).validate().is_err(), "20000² nodes");
    assert!(bad(0.003, 1).validate().is_err());
    assert!(bad(0.003, 65).validate().is_err());
    assert!(bad(0.003, 16).validate().is_ok());
}

/// NMM on a 1D grating whose period divides the patch (1.625 µm: 40 periods in 65 µm)
/// against FLSS with the same terms and taps at 1 nm. All the light off specular sits on
/// the orders, and NMM integrates each line over ±2.5σ of the window (it drops 4e-4 of it)
/// with 9 samples where FLSS takes a 1 nm trapezoid: the two agree to 1%, so the stated
/// tolerance is 1% rel L2 over the plane of incidence. Without the Jacobian λ²/(|u|d)
/// (the thesis's code, which normalised per pixel instead) the same comparison fails by far.
#[test]
fn nmm_matches_flss_at_1nm_on_a_grating_and_needs_its_jacobian() {
    let n = 260;
    let dh = 0.25;
    let tau = 2.0 * std::f64::consts::PI;
    let h = (0..n * n)
        .map(|i| 0.12 * (1.0 + (tau * (i % n) as f64 * dh / 1.625).sin()))
        .collect();
    let hf = HeightField::new(n, n, dh, h).unwrap();
    let dir = std::env::temp_dir().join(format!("diffract-nmm-{}", std::process::id()));
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
    let g = nmm::estimate_grating(&p.heightfield).unwrap();
    let d = g.period_um[0].unwrap();
    assert!((d - 1.625).abs() / 1.625 < 5e-3, "period {d}");
    let density = nmm::Density::new();
    let shading = Shading::default();
    let wi = direction(40.0, 0.0);
    let (mut e2, mut r2, mut thesis_e2) = (0.0, 0.0, 0.0);
    for k in 0..40 {
        let wr = direction(5.0 + 2.0 * k as f64, 180.0);
        let flss = diffract::brdf::model::xyz(
            p.stack.get().unwrap(),
            t,
            &p.window,
            &shading,
            &p.colour,
            wi,
            wr,
        );
        let with = nmm::xyz(
            p.stack.get().unwrap(),
            t,
            &p.window,
            &shading,
            &p.colour,
            &g,
            &density,
            wi,
            wr,
            true,
        );
        let without = nmm::xyz(
            p.stack.get().unwrap(),
            t,
            &p.window,
            &shading,
            &p.colour,
            &g,
            &density,
            wi,
            wr,
            false,
        );
        for c in 0..3 {
            e2 += (with[c] - flss[c]).powi(2);
            thesis_e2 += (without[c] - flss[c]).powi(2);
            r2 += flss[c] * flss[c];
        }
    }
    let (rel, thesis) = ((e2 / r2).sqrt(), (thesis_e2 / r2).sqrt());
    println!("nmm vs flss at 1 nm: rel L2 {rel:.2e}; without the Jacobian: {thesis:.2e}");
    assert!(rel < 1e-2, "nmm vs flss 1 nm: {rel:e}");
    assert!(thesis > 0.2, "without the Jacobian: {thesis:e}");
    let _ = std::fs::remove_dir_all(dir);
}
