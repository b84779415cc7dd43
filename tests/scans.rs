//! Gwyddion scans: `.gsf` and `.gwy` files written here by an independent writer (a minimal
//! GWY serialiser and GSF writer following the Gwyddion user guide) round-trip through the
//! one loader with their units; levelling recovers a tilted, row-offset grating's period and
//! its BRDF at the orders; a grating along the scan lines keeps its spectrum; the shipped
//! Elaphe crop's `.gsf` loads to the PNG's heights; bad files give one error line each.

use std::path::{Path, PathBuf};
use std::process::Command;

use diffract::brdf::{direction, model};
use diffract::heightfield::{HeightField, Source, Tile};
use diffract::material::Material;
use diffract::report::Collect;

/// The GWY serialiser and the GSF writer of the fixtures.
mod fixture {
    /// A component value (the types the tests write).
    pub enum V {
        B(bool),
        I(i32),
        Q(i64),
        D(f64),
        S(String),
        O(Obj),
        CArr(Vec<u8>),
        DArr(Vec<f64>),
        SArr(Vec<String>),
        OArr(Vec<Obj>),
    }

    pub struct Obj {
        pub name: String,
        pub comps: Vec<(String, V)>,
    }

    fn cstr(out: &mut Vec<u8>, s: &str) {
        out.extend(s.as_bytes());
        out.push(0);
    }

    pub fn object(o: &Obj) -> Vec<u8> {
        let mut body = Vec::new();
        for (name, v) in &o.comps {
            cstr(&mut body, name);
            match v {
                V::B(b) => body.extend([b'b', u8::from(*b)]),
                V::I(i) => {
                    body.push(b'i');
                    body.extend(i.to_le_bytes());
                }
                V::Q(q) => {
                    body.push(b'q');
                    body.extend(q.to_le_bytes());
                }
                V::D(d) => {
                    body.push(b'd');
                    body.extend(d.to_le_bytes());
                }
                V::S(s) => {
                    body.push(b's');
                    cstr(&mut body, s);
                }
                V::O(o) => {
                    body.push(b'o');
                    body.extend(object(o));
                }
                V::CArr(c) => {
                    body.push(b'C');
                    body.extend((c.len() as u32).to_le_bytes());
                    body.extend(c);
                }
                V::DArr(d) => {
                    body.push(b'D');
                    body.extend((d.len() as u32).to_le_bytes());
                    d.iter().for_each(|x| body.extend(x.to_le_bytes()));
                }
                V::SArr(s) => {
                    body.push(b'S');
                    body.extend((s.len() as u32).to_le_bytes());
                    s.iter().for_each(|x| cstr(&mut body, x));
                }
                V::OArr(o) => {
                    body.push(b'O');
                    body.extend((o.len() as u32).to_le_bytes());
                    o.iter().for_each(|x| body.extend(object(x)));
                }
            }
        }
        let mut out = Vec::new();
        cstr(&mut out, &o.name);
        out.extend((body.len() as u32).to_le_bytes());
        out.extend(body);
        out
    }

    pub fn unit(u: &str) -> Obj {
        Obj {
            name: "GwySIUnit".into(),
            comps: vec![("unitstr".into(), V::S(u.into()))],
        }
    }

    /// A channel: title, size, lateral extent and unit, value unit, values.
    pub struct Chan<'a> {
        pub title: &'a str,
        pub nx: usize,
        pub ny: usize,
        pub x_real: f64,
        pub y_real: f64,
        pub xy: &'a str,
        pub z: &'a str,
        pub data: Vec<f64>,
    }

    pub fn data_field(c: &Chan) -> Obj {
        Obj {
            name: "GwyDataField".into(),
            comps: vec![
                ("xres".into(), V::I(c.nx as i32)),
                ("yres".into(), V::I(c.ny as i32)),
                ("xreal".into(), V::D(c.x_real)),
                ("yreal".into(), V::D(c.y_real)),
                ("xoff".into(), V::D(1e-6)),
                ("yoff".into(), V::D(0.0)),
                ("si_unit_xy".into(), V::O(unit(c.xy))),
                ("si_unit_z".into(), V::O(unit(c.z))),
                ("data".into(), V::DArr(c.data.clone())),
            ],
        }
    }

    /// A `.gwy` file: the channels under the given numbers, plus components of every other
    /// type a reader must step over.
    pub fn gwy(chans: &[(u32, Chan)]) -> Vec<u8> {
        let mut comps = vec![
            ("/filename".into(), V::S("fixture.gwy".into())),
            ("/meta/count".into(), V::Q(-7)),
            ("/meta/flag".into(), V::B(true)),
            ("/meta/bytes".into(), V::CArr(b"abc".to_vec())),
            ("/meta/names".into(), V::SArr(vec!["a".into(), "bc".into()])),
            ("/meta/units".into(), V::OArr(vec![unit("m"), unit("s")])),
        ];
        for (n, c) in chans {
            comps.push((format!("/{n}/data/title"), V::S(c.title.into())));
            comps.push((format!("/{n}/data"), V::O(data_field(c))));
            comps.push((format!("/{n}/base/palette"), V::S("Gray".into())));
            if c.title == "Height" {
                // A mask over every fifth sample.
                let mask = Chan {
                    title: "mask",
                    z: "",
                    data: (0..c.nx * c.ny).map(|i| f64::from(i % 5 == 0)).collect(),
                    ..*c
                };
                comps.push((format!("/{n}/mask"), V::O(data_field(&mask))));
            }
        }
        let mut out = b"GWYP".to_vec();
        out.extend(object(&Obj {
            name: "GwyContainer".into(),
            comps,
        }));
        out
    }

    /// A `.gsf` file: the header lines as given, NUL padding to a multiple of 4, float32.
    pub fn gsf(header: &str, values: &[f32]) -> Vec<u8> {
        let mut b = format!("Gwyddion Simple Field 1.0\n{header}").into_bytes();
        let pad = 4 - b.len() % 4;
        b.extend(std::iter::repeat_n(0u8, pad));
        values.iter().for_each(|v| b.extend(v.to_le_bytes()));
        b
    }
}

use fixture::Chan;

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-scans-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn source(path: &Path, level: &str) -> Source {
    Source {
        level: Some(level.into()),
        ..Source::new(path.to_string_lossy())
    }
}

/// Values with some structure, different per channel, of size `amp`.
fn values(nx: usize, ny: usize, seed: f64, amp: f64) -> Vec<f64> {
    (0..nx * ny)
        .map(|i| {
            amp * (((i % nx) as f64 * 0.37 + seed).sin() + ((i / nx) as f64 * 0.21 * seed).cos())
        })
        .collect()
}

#[test]
fn gwy_channels_round_trip_with_their_units_odd_and_non_square() {
    let d = tmpdir("gwy");
    let (nx, ny, dx) = (37, 23, 40e-9);
    // Each channel's values are about 0.1 µm in its own unit.
    let chan = |title, xy, xy_scale: f64, z, z_to_um: f64, seed| Chan {
        title,
        nx,
        ny,
        x_real: nx as f64 * dx / xy_scale,
        y_real: ny as f64 * dx / xy_scale,
        xy,
        z,
        data: values(nx, ny, seed, 0.1 / z_to_um),
    };
    let file = d.join("multi.gwy");
    std::fs::write(
        &file,
        fixture::gwy(&[
            (0, chan("Phase", "m", 1.0, "deg", 1.0, 1.0)),
            (1, chan("Height", "µm", 1e-6, "nm", 1e-3, 2.0)),
            (4, chan("ZSensor", "m", 1.0, "µm", 1.0, 3.0)),
            (2, chan("Amplitude", "nm", 1e-9, "m", 1e6, 4.0)),
        ]),
    )
    .unwrap();
    let check = |hf: &HeightField, seed: f64, z_to_um: f64| {
        assert_eq!((hf.nx(), hf.ny()), (nx, ny));
        assert!((hf.dh_um() - 0.04).abs() < 1e-12, "{}", hf.dh_um());
        for (a, b) in hf
            .heights_um()
            .iter()
            .zip(values(nx, ny, seed, 0.1 / z_to_um))
        {
            assert!((a - b * z_to_um).abs() <= 1e-12, "{a} {b}");
        }
    };
    // Default: the first channel titled as a height with a length unit, "Height" in nm.
    let report = Collect::default();
    let hf = source(&file, "none").load(&report).unwrap();
    check(&hf, 2.0, 1e-3);
    let notes = report.notes();
    assert!(notes[0].contains("mask marks 171 samples"), "{notes:?}");
    assert!(notes[1].contains("\"Height\" (nm), 37×23"), "{notes:?}");
    // By title and by index (channel order: /0, /1, /2, /4).
    let pick = |c: &str| Source {
        channel: Some(c.into()),
        ..source(&file, "none")
    };
    check(&pick("zsensor").load(&report).unwrap(), 3.0, 1.0);
    check(&pick("2").load(&report).unwrap(), 4.0, 1e6);
    check(&pick("3").load(&report).unwrap(), 3.0, 1.0);
    // A channel without a length unit needs --hmax-um, and then spans it.
    let e = pick("Phase").load(&report).unwrap_err().to_string();
    assert!(e.contains("not a length") && e.contains("--hmax-um"), "{e}");
    let phase = Source {
        h_max_um: Some(0.3),
        ..pick("Phase")
    }
    .load(&report)
    .unwrap();
    let (lo, hi) = phase.range();
    assert!(lo.abs() < 1e-12 && (hi - 0.3).abs() < 1e-12);
    let e = pick("Current").load(&report).unwrap_err().to_string();
    assert!(
        e.contains("\"Phase\"") && e.contains("\"Amplitude\""),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn gsf_round_trips_in_metres_nanometres_and_micrometres() {
    let d = tmpdir("gsf");
    for (nx, ny, xy, xy_scale, z, z_to_um) in [
        (31, 17, "m", 1.0, "m", 1e6),
        (8, 45, "µm", 1e-6, "nm", 1e-3),
        (1, 3, "nm", 1e-9, "µm", 1.0),
    ] {
        let dx = 25e-9;
        let v: Vec<f32> = values(nx, ny, 1.5, 0.1 / z_to_um)
            .iter()
            .map(|&x| x as f32)
            .collect();
        let header = format!(
            "XRes = {nx}\nYRes = {ny}\nXReal = {}\nYReal = {}\nXOffset = 0\nXYUnits = {xy}\n\
             ZUnits = {z}\nTitle = Topography\nCustomKey = 33\n",
            nx as f64 * dx / xy_scale,
            ny as f64 * dx / xy_scale
        );
        let p = d.join(format!("f{nx}x{ny}.gsf"));
        std::fs::write(&p, fixture::gsf(&header, &v)).unwrap();
        let hf = source(&p, "none").load(&Collect::default()).unwrap();
        assert_eq!((hf.nx(), hf.ny()), (nx, ny));
        assert!((hf.dh_um() - 0.025).abs() < 1e-12, "{}", hf.dh_um());
        for (a, b) in hf.heights_um().iter().zip(&v) {
            assert!((a - f64::from(*b) * z_to_um).abs() <= 1e-12, "{a} {b}");
        }
    }
    let _ = std::fs::remove_dir_all(&d);
}

fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets")
}

#[test]
fn the_shipped_elaphe_gsf_loads_to_the_png_heights_and_keeps_its_ridges() {
    let gsf = assets().join("measured/elaphe_afm_crop.gsf");
    let from_gsf = source(&gsf, "none").load(&Collect::default()).unwrap();
    let from_png = HeightField::load_source("builtin:elaphe-measured", None, None).unwrap();
    assert_eq!((from_gsf.nx(), from_gsf.ny()), (100, 100));
    assert!((from_gsf.dh_um() - from_png.dh_um()).abs() < 1e-12);
    let worst = from_gsf
        .heights_um()
        .iter()
        .zip(from_png.heights_um())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    // float32 rounding of heights below 0.44 µm: 2⁻²⁴·0.44 µm ≈ 2.6e-8 µm.
    assert!(worst <= 3e-8, "{worst}");
    assert_eq!(HeightField::load(&gsf, None, None).unwrap(), from_gsf);
    // Images keep their heights as stored: no levelling unless asked, nothing reported.
    let png = assets().join("measured/elaphe_afm_100x100.png");
    let report = Collect::default();
    let via_source = Source::new(png.to_string_lossy()).load(&report).unwrap();
    assert_eq!(via_source, HeightField::load(&png, None, None).unwrap());
    assert!(report.notes().is_empty() && report.warnings().is_empty());
    // The default levelling: its ridges run along the scan lines (6 periods over the rows),
    // so `rows` is skipped with the warning and the row-mean spectrum keeps its peak.
    let report = Collect::default();
    let levelled = Source::new(gsf.to_string_lossy()).load(&report).unwrap();
    let w = report.warnings();
    assert!(
        w.iter()
            .any(|w| w.contains("along the scan lines") && w.contains("6 periods")),
        "{w:?}"
    );
    let (share, k) = diffract::heightfield::level::scan_line_peak(levelled.heights_um(), 100, 100);
    assert_eq!(k, 6);
    assert!(share > 0.5, "{share}");
    let notes = report.notes();
    assert!(
        notes
            .iter()
            .any(|n| n.starts_with("levelling plane,rows: tilt")),
        "{notes:?}"
    );
    assert!(notes.iter().any(|n| n.starts_with("seam: ")), "{notes:?}");
}

/// A sinusoidal grating across x (ridges along y, the scan lines' normal), period 1.28 µm,
/// 200 nm peak to valley, 10 periods over 256 samples of 50 nm, with a generic phase.
fn clean_grating(x: f64) -> f64 {
    0.1 * (1.0 + (std::f64::consts::TAU * (x / 1.28 + 0.3)).cos())
}

const N: usize = 256;
const DH: f64 = 0.05;

/// The clean grating as a field, and as a scan: tilted by 2° (rising towards azimuth 30°)
/// with scan-line offsets of tens of nm (uniform in ±50 nm, seeded), written as a `.gsf` in
/// metres.
fn tilted_scan(d: &Path) -> (HeightField, PathBuf) {
    let clean: Vec<f64> = (0..N * N)
        .map(|i| clean_grating((i % N) as f64 * DH))
        .collect();
    let slope = 2f64.to_radians().tan();
    let (sx, sy) = (
        slope * 30f64.to_radians().cos(),
        slope * 30f64.to_radians().sin(),
    );
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let offsets: Vec<f64> = (0..N)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            0.05 * (2.0 * (state >> 11) as f64 / (1u64 << 53) as f64 - 1.0)
        })
        .collect();
    let dirty: Vec<f32> = clean
        .iter()
        .enumerate()
        .map(|(i, h)| {
            let (x, y) = ((i % N) as f64 * DH, (i / N) as f64 * DH);
            ((h + sx * x + sy * y + offsets[i / N]) * 1e-6) as f32
        })
        .collect();
    let side = N as f64 * DH * 1e-6;
    let header = format!(
        "XRes = {N}\nYRes = {N}\nXReal = {side}\nYReal = {side}\nXYUnits = m\nZUnits = m\n\
         Title = Height\n"
    );
    let p = d.join("tilted.gsf");
    std::fs::write(&p, fixture::gsf(&header, &dirty)).unwrap();
    (HeightField::new(N, N, DH, clean).unwrap(), p)
}

/// ρ at the grating's orders m = −2, −1, 1 for light at 30° from −x, λ = 500 nm.
fn order_rhos(m: &Material, hf: HeightField) -> Vec<f64> {
    let report = Collect::default();
    let plan = m
        .plan_loaded(
            &hf,
            &diffract::brdf::truncation::Reach::ALL,
            diffract::brdf::truncation::Precision::F64,
            &report,
        )
        .unwrap();
    let p = m.prepare_planned(hf, plan, None, &report).unwrap();
    let wi = direction(30.0, 180.0);
    let lambda = 500.0;
    [-2.0, -1.0, 1.0]
        .iter()
        .map(|order| {
            let x: f64 = 0.5 + order * lambda * 1e-3 / 1.28;
            let wr = direction(
                x.abs().asin().to_degrees(),
                if x < 0.0 { 180.0 } else { 0.0 },
            );
            model::rho(
                p.stack.get().unwrap(),
                p.terms(),
                &p.window,
                &p.shading,
                wi,
                wr,
                lambda,
            )
        })
        .collect()
}

#[test]
fn levelling_a_tilted_row_offset_grating_restores_its_period_and_orders() {
    let d = tmpdir("tilted");
    let (clean, scan) = tilted_scan(&d);
    let report = Collect::default();
    let levelled = Source::new(scan.to_string_lossy()).load(&report).unwrap();
    let line = report
        .notes()
        .into_iter()
        .find(|n| n.starts_with("levelling"))
        .unwrap();
    eprintln!("{line}");
    assert!(line.contains("tilt 2.0"), "{line}");
    assert!(report.warnings().is_empty(), "{:?}", report.warnings());
    let raw = source(&scan, "none").load(&Collect::default()).unwrap();
    let material = Material {
        heightfield: scan.to_string_lossy().into_owned(),
        lambda_step_nm: 50,
        ..Material::default()
    };
    // The period from the grating equation (the f64 model over angle and wavelength).
    let period = |hf: &HeightField| {
        let report = Collect::default();
        let plan = material
            .plan_loaded(
                hf,
                &diffract::brdf::truncation::Reach::ALL,
                diffract::brdf::truncation::Precision::F64,
                &report,
            )
            .unwrap();
        let p = material
            .prepare_planned(hf.clone(), plan, None, &report)
            .unwrap();
        diffract::eval::grating_equation(&p, 75.0, 0.0, &[450.0, 550.0, 650.0], 0.02)
            .unwrap()
            .mean_nm
    };
    let (p_clean, p_level) = (period(&clean), period(&levelled));
    eprintln!("period: clean {p_clean:.2} nm, levelled {p_level:.2} nm");
    assert!(
        (p_level / p_clean - 1.0).abs() < 0.005,
        "{p_level} vs {p_clean}"
    );
    assert!((p_clean / 1280.0 - 1.0).abs() < 0.005, "{p_clean}");
    let (r_clean, r_level, r_raw) = (
        order_rhos(&material, clean),
        order_rhos(&material, levelled),
        order_rhos(&material, raw),
    );
    for ((c, l), r) in r_clean.iter().zip(&r_level).zip(&r_raw) {
        eprintln!(
            "order ρ: clean {c:.4e}, levelled {l:.4e} ({:+.2} %), raw {r:.4e} ({:.1} %)",
            (l / c - 1.0) * 100.0,
            r / c * 100.0
        );
        assert!((l / c - 1.0).abs() < 0.05, "levelled {l} vs clean {c}");
    }
    // Unlevelled, the orders are mostly gone: the test can tell.
    assert!(
        r_raw.iter().zip(&r_clean).any(|(r, c)| r / c < 0.5),
        "{r_raw:?} vs {r_clean:?}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_grating_along_the_scan_lines_gets_the_warning_not_a_flattened_spectrum() {
    let d = tmpdir("along");
    // Ridges along x: heights vary with the row only (8 periods over 128 rows), plus a tilt.
    let n = 128;
    let v: Vec<f32> = (0..n * n)
        .map(|i| {
            let (c, r) = ((i % n) as f64, (i / n) as f64);
            let g = 0.1 * (1.0 + (std::f64::consts::TAU * r / 16.0).cos());
            ((g + 0.01 * c * 0.05) * 1e-6) as f32
        })
        .collect();
    let header = format!(
        "XRes = {n}\nYRes = {n}\nXReal = {0}\nYReal = {0}\nXYUnits = m\nZUnits = m\nTitle = Height\n",
        n as f64 * 50e-9
    );
    let p = d.join("along.gsf");
    std::fs::write(&p, fixture::gsf(&header, &v)).unwrap();
    let report = Collect::default();
    let hf = Source::new(p.to_string_lossy()).load(&report).unwrap();
    let w = report.warnings();
    assert!(
        w.len() == 1 && w[0].contains("rows not aligned") && w[0].contains("8 periods"),
        "{w:?}"
    );
    // The structure is intact: peak-to-valley 0.2 µm, all of it in the row means' peak.
    let (lo, hi) = hf.range();
    assert!((hi - lo - 0.2).abs() < 0.01, "{}", hi - lo);
    let (share, k) = diffract::heightfield::level::scan_line_peak(hf.heights_um(), n, n);
    assert_eq!(k, 8);
    assert!(share > 0.95, "{share}");
    // Aligned by the median of row differences regardless, it would be flat: every row is
    // the one before plus a constant.
    let raw = source(&p, "none").load(&Collect::default()).unwrap();
    let rows: Vec<&[f64]> = raw.heights_um().chunks_exact(n).collect();
    let flat = rows.windows(2).all(|w| {
        let d0 = w[1][0] - w[0][0];
        w[1].iter()
            .zip(w[0])
            .all(|(a, b)| (a - b - d0).abs() < 1e-6)
    });
    assert!(flat);
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn caches_key_on_the_levelled_samples_and_scenes_carry_the_scan_keys() {
    let d = tmpdir("keys");
    let (_, scan) = tilted_scan(&d);
    let m = Material::default();
    let req = m.term_request(diffract::spectrum::Expansion::Chebyshev, 4);
    let key = |level: &str| {
        let hf = source(&scan, level).load(&Collect::default()).unwrap();
        diffract::spectrum::cache::cache_key(&hf, &req)
    };
    let (none, plane, both) = (key("none"), key("plane"), key("plane,rows"));
    assert!(none != plane && plane != both && none != both);
    assert_eq!(both, key("plane,rows"));
    // A scene names the scan with its channel, levelling and tiling.
    let scene = d.join("scene.toml");
    std::fs::write(
        &scene,
        "[material]\nheightfield = \"tilted.gsf\"\nchannel = \"Height\"\nlevel = \"plane\"\ntile = \"mirror\"\n",
    )
    .unwrap();
    let s = diffract::scene::Scene::load(&scene).unwrap();
    assert_eq!(s.material.level.as_deref(), Some("plane"));
    assert_eq!(s.material.tile, Some(Tile::Mirror));
    let report = Collect::default();
    let hf = s.material.load_heightfield(&report).unwrap();
    assert_eq!((hf.nx(), hf.ny()), (2 * N, 2 * N));
    assert!(
        report.notes().iter().any(|n| n.contains("--tile mirror")),
        "{:?}",
        report.notes()
    );
    let bad = d.join("bad.toml");
    std::fs::write(
        &bad,
        "[material]\nheightfield = \"tilted.gsf\"\nlevel = \"plain\"\n",
    )
    .unwrap();
    let e = diffract::scene::Scene::load(&bad).unwrap_err().to_string();
    assert!(e.contains("plain"), "{e}");
    let _ = std::fs::remove_dir_all(&d);
}

// ---- bad files through the command line ----------------------------------------------------

fn gwy_with(chans: Vec<(u32, Chan<'static>)>) -> Vec<u8> {
    fixture::gwy(&chans)
}

fn chan(title: &'static str, z: &'static str, nx: usize, ny: usize) -> Chan<'static> {
    Chan {
        title,
        nx,
        ny,
        x_real: 1e-6,
        y_real: 1e-6 * ny as f64 / nx as f64,
        xy: "m",
        z,
        data: vec![1e-9; nx * ny],
    }
}

fn good_gsf() -> Vec<u8> {
    fixture::gsf(
        "XRes = 4\nYRes = 4\nXReal = 2e-7\nYReal = 2e-7\nXYUnits = m\nZUnits = m\n",
        &[1e-8; 16],
    )
}

#[test]
fn bad_scan_files_give_one_error_line_each() {
    let d = tmpdir("bad");
    let mut truncated_gwy = gwy_with(vec![(0, chan("Height", "m", 8, 8))]);
    truncated_gwy.truncate(truncated_gwy.len() - 20);
    let mut huge_gwy = gwy_with(vec![(0, chan("Height", "m", 4, 4))]);
    // xres is the first component of the data field: "xres\0i" then the i32.
    let at = huge_gwy.windows(6).position(|w| w == b"xres\0i").unwrap() + 6;
    huge_gwy[at..at + 4].copy_from_slice(&1_000_000i32.to_le_bytes());
    let mut nan = good_gsf();
    let l = nan.len();
    nan[l - 4..].copy_from_slice(&f32::NAN.to_le_bytes());
    let mut short = good_gsf();
    short.truncate(short.len() - 6);
    let cases: Vec<(&str, Vec<u8>, &[&str], &str)> = vec![
        ("truncated.gsf", short, &[], "truncated"),
        ("truncated.gwy", truncated_gwy, &[], "truncated"),
        (
            "magic.gsf",
            b"Gwyddion Simple Field 9\nXRes = 1\n\0\0\0".to_vec(),
            &[],
            "not a Gwyddion Simple Field",
        ),
        (
            "magic.gwy",
            b"GWYQ\0\0\0\0".to_vec(),
            &[],
            "not a Gwyddion file",
        ),
        (
            "huge.gsf",
            fixture::gsf("XRes = 100000\nYRes = 100000\n", &[0.0; 4]),
            &[],
            "exceeds the limit",
        ),
        ("huge.gwy", huge_gwy, &[], "exceeds the limit"),
        ("nan.gsf", nan, &[], "not finite"),
        (
            "zero.gsf",
            fixture::gsf("XRes = 0\nYRes = 4\n", &[]),
            &[],
            "empty",
        ),
        (
            "noheight.gwy",
            gwy_with(vec![
                (0, chan("Phase", "deg", 4, 4)),
                (1, chan("Current", "A", 4, 4)),
            ]),
            &[],
            "no height channel",
        ),
        ("nochannel.gwy", gwy_with(vec![]), &[], "no image channel"),
        (
            "badpixels.gsf",
            fixture::gsf(
                "XRes = 4\nYRes = 4\nXReal = 2e-7\nYReal = 4e-7\nXYUnits = m\nZUnits = m\n",
                &[1e-8; 16],
            ),
            &[],
            "not square",
        ),
        (
            "channel.gwy",
            gwy_with(vec![(0, chan("Height", "m", 4, 4))]),
            &["--channel", "Phase"],
            "no channel \"Phase\"",
        ),
        ("level.gsf", good_gsf(), &["--level", "poly:99"], "poly:99"),
    ];
    let mut failures = Vec::new();
    for (name, bytes, extra, phrase) in &cases {
        let p = d.join(name);
        std::fs::write(&p, bytes).unwrap();
        let out = d.join(format!("{name}.png"));
        let o = Command::new(env!("CARGO_BIN_EXE_diffract"))
            .args(["heightfield", "--from-sample", p.to_str().unwrap()])
            .args(extra.iter().copied())
            .args(["--samples", "64", "-o", out.to_str().unwrap()])
            .env("DIFFRACT_CACHE", "")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
        let last_is_error = err.lines().last().is_some_and(|l| l.starts_with("error:"));
        if o.status.code() != Some(1)
            || errors.len() != 1
            || !last_is_error
            || !errors[0].contains(phrase)
            || out.exists()
        {
            failures.push(format!(
                "{name}: status {:?}, stderr:\n{err}",
                o.status.code()
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!("twice".parse::<Tile>().is_err());
    // --channel on a PNG is refused before anything is read.
    let o = Command::new(env!("CARGO_BIN_EXE_diffract"))
        .args([
            "heightfield",
            "--from-sample",
            "builtin:elaphe-measured",
            "--channel",
            "1",
        ])
        .args(["-o", d.join("x.png").to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.code() == Some(1) && err.contains("error: invalid channel"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// `--tile` on a scan that does not tile (10.5 periods of a 1.219 µm grating over 12.8 µm):
/// the seam's share, the grating-equation period and ρ at the orders against a grating of
/// the same profile that tiles (10 whole periods of 1.28 µm, its own orders). The numbers
/// are the ones docs/scans.md quotes.
#[test]
fn tile_modes_measured_on_the_orders() {
    let d = tmpdir("tile");
    let period_um = 12.8 / 10.5;
    let n = 256;
    let v: Vec<f32> = (0..n * n)
        .map(|i| {
            let x = (i % n) as f64 * DH;
            (0.1 * (1.0 + (std::f64::consts::TAU * x / period_um).cos()) * 1e-6) as f32
        })
        .collect();
    let header = format!(
        "XRes = {n}\nYRes = {n}\nXReal = {0}\nYReal = {0}\nXYUnits = m\nZUnits = m\nTitle = Height\n",
        n as f64 * DH * 1e-6
    );
    let p = d.join("cut.gsf");
    std::fs::write(&p, fixture::gsf(&header, &v)).unwrap();
    let material = Material {
        lambda_step_nm: 50,
        ..Material::default()
    };
    let measure = |hf: HeightField, period_um: f64| {
        let report = Collect::default();
        let reach = diffract::brdf::truncation::Reach::ALL;
        let f64p = diffract::brdf::truncation::Precision::F64;
        let plan = material.plan_loaded(&hf, &reach, f64p, &report).unwrap();
        let prep = material.prepare_planned(hf, plan, None, &report).unwrap();
        let g = diffract::eval::grating_equation(&prep, 75.0, 0.0, &[450.0, 550.0, 650.0], 0.02)
            .unwrap()
            .mean_nm;
        let wi = direction(30.0, 180.0);
        let rho: Vec<f64> = [-2.0, -1.0, 1.0]
            .iter()
            .map(|order| {
                let x: f64 = 0.5 + order * 0.5 / period_um;
                let wr = direction(
                    x.abs().asin().to_degrees(),
                    if x < 0.0 { 180.0 } else { 0.0 },
                );
                model::rho(
                    prep.stack.get().unwrap(),
                    prep.terms(),
                    &prep.window,
                    &prep.shading,
                    wi,
                    wr,
                    500.0,
                )
            })
            .collect();
        (g, rho)
    };
    let tiling: Vec<f64> = (0..n * n)
        .map(|i| 0.1 * (1.0 + (std::f64::consts::TAU * (i % n) as f64 * DH / 1.28).cos()))
        .collect();
    let (_, rho_ref) = measure(HeightField::new(n, n, DH, tiling).unwrap(), 1.28);
    let mut shares = Vec::new();
    for tile in [Tile::None, Tile::Mirror, Tile::Window, Tile::Grow] {
        let src = Source {
            level: Some("none".into()),
            tile: Some(tile),
            ..Source::new(p.to_string_lossy())
        };
        let hf = src.load(&Collect::default()).unwrap();
        let share = diffract::heightfield::seam::seam_share(&hf);
        let (g, rho) = measure(hf, period_um);
        let rel: Vec<String> = rho
            .iter()
            .zip(&rho_ref)
            .map(|(r, c)| format!("{:.1} %", r / c * 100.0))
            .collect();
        eprintln!(
            "tile {tile}: seam {:.2} %, period {g:.1} nm ({:+.2} %), ρ at orders −2, −1, 1: {}",
            share * 100.0,
            (g / (period_um * 1e3) - 1.0) * 100.0,
            rel.join(", ")
        );
        shares.push(share);
        if tile == Tile::Mirror {
            // 21 whole periods over the doubled side: the orders come back.
            assert!((g / (period_um * 1e3) - 1.0).abs() < 1e-3, "{g}");
            for (r, c) in rho.iter().zip(&rho_ref) {
                assert!((r / c - 1.0).abs() < 0.1, "{r} vs {c}");
            }
        }
    }
    assert!(shares[0] > 0.01, "{shares:?}");
    assert!(
        shares[1] < 1e-6 && shares[2] < 0.1 * shares[0],
        "{shares:?}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// Mutated and truncated files (seeded): the readers answer with an error or a channel,
/// never a panic and never an allocation beyond the file.
#[test]
fn mutated_scan_files_never_panic() {
    use diffract::heightfield::{gsf, gwy};
    let p = Path::new("fuzz");
    let gwy_good = gwy_with(vec![
        (0, chan("Height", "m", 6, 5)),
        (3, chan("Phase", "deg", 2, 2)),
    ]);
    let gsf_good = good_gsf();
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let (mut errors, mut reads) = (0, 0);
    for i in 0..4000 {
        let mut b = if i % 2 == 0 {
            gwy_good.clone()
        } else {
            gsf_good.clone()
        };
        match next() % 4 {
            0 => b.truncate((next() % b.len() as u64) as usize),
            1 => {
                let at = (next() % b.len() as u64) as usize;
                b[at] = next() as u8;
            }
            2 => {
                let at = (next() % (b.len() as u64 - 4)) as usize;
                b[at..at + 4].copy_from_slice(&(next() as u32).to_le_bytes());
            }
            _ => {
                let at = (next() % b.len() as u64) as usize;
                b[at] = [0u8, 0xff, b'D', b'O', b'o'][(next() % 5) as usize];
            }
        }
        let ok = if i % 2 == 0 {
            let f = gwy::GwyFile::from_bytes(b);
            f.channels(p)
                .and_then(|c| (0..c.len()).try_for_each(|k| f.channel(p, k).map(|_| ())))
        } else {
            gsf::parse(p, &b).map(|_| ())
        };
        match ok {
            Ok(()) => reads += 1,
            Err(e) => {
                assert!(!e.to_string().contains('\n'), "{e}");
                errors += 1;
            }
        }
    }
    eprintln!("mutated files: {reads} read, {errors} refused");
    assert!(
        errors > 1000 && reads > 100,
        "{reads} read, {errors} refused"
    );
}
