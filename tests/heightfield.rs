//! Height-field files, sidecars, bad inputs, the test-grating generators and the shipped
//! assets.

use std::path::{Path, PathBuf};

use diffract::cli::heightfield::{run_heightfield, HeightfieldArgs};
use diffract::heightfield::{generate, GratingKind, GratingSpec, HeightField};
use diffract::Error;
use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;

/// A fresh empty directory per test (tests run in parallel).
fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-hf-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets")
}

fn small(kind: GratingKind) -> GratingSpec {
    GratingSpec {
        size_um: 12.0,
        ..GratingSpec::default_for(kind)
    }
}

fn write_gray8(path: &Path, w: u32, h: u32, f: impl Fn(u32, u32) -> u8) {
    image::GrayImage::from_fn(w, h, |x, y| image::Luma([f(x, y)]))
        .save(path)
        .expect("write test PNG");
}

#[test]
fn png16_round_trip_within_one_step() {
    let dir = tmpdir("png16");
    let hf = generate(&small(GratingKind::Xenopeltis)).unwrap();
    let p = dir.join("x.png");
    hf.save(&p).unwrap();
    let side = std::fs::read_to_string(dir.join("x.toml")).unwrap();
    assert!(
        side.contains("dh_um") && side.contains("h_max_um"),
        "{side}"
    );
    let back = HeightField::load(&p, None, None).unwrap();
    assert_eq!((back.nx(), back.ny()), (hf.nx(), hf.ny()));
    assert_eq!(back.dh_um(), hf.dh_um());
    let (lo, hi) = hf.range();
    let step = (hi - lo) / 65535.0;
    for (a, b) in hf.heights_um().iter().zip(back.heights_um()) {
        assert!((a - lo - b).abs() <= 0.5 * step + 1e-15, "{a} vs {b}");
    }
    // No temporaries left next to the outputs.
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(names, ["x.png", "x.toml"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn png16_keeps_offset_heights_relative() {
    // Saving shifts the minimum to 0; a field with a nonzero floor comes back shifted.
    let dir = tmpdir("offset");
    let hf = HeightField::new(4, 2, 0.05, vec![1.0, 1.5, 2.0, 1.25, 1.0, 1.0, 2.0, 1.75]).unwrap();
    let p = dir.join("o.png");
    hf.save(&p).unwrap();
    let back = HeightField::load(&p, None, None).unwrap();
    for (a, b) in hf.heights_um().iter().zip(back.heights_um()) {
        assert!((a - 1.0 - b).abs() < 1e-4, "{a} vs {b}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn png8_maps_grey_to_height_and_flags_override_sidecar() {
    let dir = tmpdir("png8");
    let p = dir.join("g.png");
    write_gray8(&p, 5, 3, |x, y| (x * 50 + y) as u8);
    std::fs::write(dir.join("g.toml"), "dh_um = 0.08\nh_max_um = 0.5\n").unwrap();
    let hf = HeightField::load(&p, None, None).unwrap();
    assert_eq!((hf.nx(), hf.ny(), hf.dh_um()), (5, 3, 0.08));
    assert!((hf.at(4, 2) - (202.0 / 255.0) * 0.5).abs() < 1e-12);
    assert!((hf.at(1, 0) - (50.0 / 255.0) * 0.5).abs() < 1e-12);
    let o = HeightField::load(&p, Some(0.02), Some(1.0)).unwrap();
    assert_eq!(o.dh_um(), 0.02);
    assert!((o.at(4, 2) - 202.0 / 255.0).abs() < 1e-12);
    // A flag alone suffices when the sidecar lacks the key.
    std::fs::write(dir.join("g.toml"), "dh_um = 0.08\n").unwrap();
    let f = HeightField::load(&p, None, Some(2.0)).unwrap();
    assert!((f.at(1, 0) - (50.0 / 255.0) * 2.0).abs() < 1e-12);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn grey_alpha_is_accepted_alpha_ignored() {
    let dir = tmpdir("la");
    let p = dir.join("la.png");
    image::GrayAlphaImage::from_fn(3, 2, |x, _| image::LumaA([(x * 100) as u8, 7]))
        .save(&p)
        .unwrap();
    let hf = HeightField::load(&p, Some(0.05), Some(1.0)).unwrap();
    assert!((hf.at(2, 1) - 200.0 / 255.0).abs() < 1e-12);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn f32_round_trip_and_size_check() {
    let dir = tmpdir("f32");
    let hf = generate(&small(GratingKind::Elaphe)).unwrap();
    let p = dir.join("e.f32");
    hf.save(&p).unwrap();
    let side = std::fs::read_to_string(dir.join("e.toml")).unwrap();
    assert!(
        side.contains("nx") && side.contains("ny") && side.contains("dh_um"),
        "{side}"
    );
    let back = HeightField::load(&p, None, None).unwrap();
    assert_eq!(
        (back.nx(), back.ny(), back.dh_um()),
        (hf.nx(), hf.ny(), hf.dh_um())
    );
    for (a, b) in hf.heights_um().iter().zip(back.heights_um()) {
        assert_eq!(*b, f64::from(*a as f32));
    }
    // h_max makes no sense for µm heights.
    assert!(HeightField::load(&p, None, Some(1.0)).is_err());
    // Truncated raw file: clear error, no panic.
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() - 3]).unwrap();
    let e = HeightField::load(&p, None, None).unwrap_err();
    assert!(
        matches!(e, Error::Image { .. }) && e.to_string().contains("truncated"),
        "{e}"
    );
    // Missing nx/ny.
    std::fs::write(dir.join("e.toml"), "dh_um = 0.05\n").unwrap();
    let e = HeightField::load(&p, None, None).unwrap_err();
    assert!(e.to_string().contains("nx"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_scale_names_both_options() {
    let dir = tmpdir("scale");
    let p = dir.join("s.png");
    write_gray8(&p, 4, 4, |x, _| x as u8);
    let e = HeightField::load(&p, None, Some(1.0))
        .unwrap_err()
        .to_string();
    assert!(e.contains("--dh-um") && e.contains("s.toml"), "{e}");
    let e = HeightField::load(&p, Some(0.05), None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("--hmax-um") && e.contains("h_max_um"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_inputs_are_clear_errors() {
    let dir = tmpdir("bad");
    // Missing file: Io with the path.
    let missing = dir.join("nope.png");
    let e = HeightField::load(&missing, Some(0.05), Some(1.0)).unwrap_err();
    assert!(
        matches!(e, Error::Io { .. }) && e.to_string().contains("nope.png"),
        "{e}"
    );

    // Colour image: names the first pixel and channel that differ from R.
    let rgb = dir.join("rgb.png");
    image::RgbImage::from_pixel(4, 4, image::Rgb([1, 2, 3]))
        .save(&rgb)
        .unwrap();
    let e = HeightField::load(&rgb, Some(0.05), Some(1.0)).unwrap_err();
    assert!(
        matches!(e, Error::Image { .. })
            && e.to_string().contains("not grey")
            && e.to_string()
                .contains("(column 0, row 0) has R = 1 but G = 2"),
        "{e}"
    );

    // Truncated PNG and garbage: Image errors, never a panic.
    let good = dir.join("good.png");
    write_gray8(&good, 32, 32, |x, y| (x ^ y) as u8);
    let bytes = std::fs::read(&good).unwrap();
    for (name, data) in [
        ("trunc.png", &bytes[..bytes.len() / 2]),
        ("head.png", &bytes[..20]),
        ("junk.png", b"this is not a png at all".as_slice()),
        ("empty.png", b"".as_slice()),
    ] {
        let p = dir.join(name);
        std::fs::write(&p, data).unwrap();
        let e = HeightField::load(&p, Some(0.05), Some(1.0)).unwrap_err();
        assert!(
            matches!(e, Error::Image { .. } | Error::Io { .. }),
            "{name}: {e}"
        );
        assert!(e.to_string().contains(name), "{e}");
    }

    // Bad sidecar TOML: the message carries the line.
    std::fs::write(dir.join("good.toml"), "dh_um = 0.05\nh_max_um = = 1\n").unwrap();
    let e = HeightField::load(&good, None, None).unwrap_err();
    assert!(matches!(e, Error::Parse { .. }), "{e}");
    assert!(e.to_string().contains("line 2"), "{e}");
    assert!(!e.to_string().contains('\n'), "{e}");

    // Unknown key.
    std::fs::write(dir.join("good.toml"), "dh_um = 0.05\nhmax = 1\n").unwrap();
    let e = HeightField::load(&good, None, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("hmax") && e.contains("line 2"), "{e}");

    // Sidecar size disagreeing with the image.
    std::fs::write(
        dir.join("good.toml"),
        "dh_um = 0.05\nh_max_um = 1\nnx = 31\n",
    )
    .unwrap();
    assert!(HeightField::load(&good, None, None).is_err());

    // dH ≤ 0, NaN, h_max < 0: rejected whether from flags or sidecar.
    std::fs::write(dir.join("good.toml"), "h_max_um = 1\n").unwrap();
    for dh in [0.0, -0.1, f64::NAN, f64::INFINITY] {
        let e = HeightField::load(&good, Some(dh), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("good.png"), "{e}");
    }
    std::fs::write(dir.join("good.toml"), "dh_um = -0.05\nh_max_um = 1\n").unwrap();
    assert!(HeightField::load(&good, None, None).is_err());
    std::fs::write(dir.join("good.toml"), "dh_um = 0.05\nh_max_um = -1\n").unwrap();
    assert!(HeightField::load(&good, None, None).is_err());

    // Unknown extension.
    assert!(HeightField::load(&dir.join("a.bmp"), Some(0.05), Some(1.0)).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn failed_save_leaves_nothing() {
    let dir = tmpdir("failsave");
    let hf = generate(&small(GratingKind::Blazed)).unwrap();
    let e = hf.save(&dir.join("no/such/dir/x.png")).unwrap_err();
    assert!(matches!(e, Error::Io { .. }), "{e}");
    assert!(hf.save(&dir.join("x.jpg")).is_err());
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn generators_are_deterministic_per_seed() {
    for kind in GratingKind::ALL {
        let s = small(kind);
        let a = generate(&s).unwrap();
        assert_eq!(a, generate(&s).unwrap(), "{kind}");
        let other = generate(&GratingSpec { seed: 2, ..s }).unwrap();
        match kind {
            // The irregular kinds depend on the seed ...
            GratingKind::Elaphe | GratingKind::Xenopeltis => assert_ne!(a, other, "{kind}"),
            // ... the regular ones do not.
            _ => assert_eq!(a, other, "{kind}"),
        }
    }
}

/// Index of the strongest non-DC frequency (0..n/2) of the power spectrum summed over
/// `rows` (x direction) of the field.
fn dominant_x_frequency(hf: &HeightField, rows: impl Iterator<Item = usize>) -> usize {
    let n = hf.nx();
    let fft = FftPlanner::new().plan_fft_forward(n);
    let mut power = vec![0.0; n / 2 + 1];
    for r in rows {
        let row = &hf.heights_um()[r * n..(r + 1) * n];
        let mean = row.iter().sum::<f64>() / n as f64;
        let mut buf: Vec<Complex64> = row.iter().map(|h| Complex64::new(h - mean, 0.0)).collect();
        fft.process(&mut buf);
        for (p, v) in power.iter_mut().zip(&buf) {
            *p += v.norm_sqr();
        }
    }
    (1..power.len())
        .max_by(|&a, &b| power[a].total_cmp(&power[b]))
        .unwrap()
}

#[test]
fn dominant_frequency_matches_the_period() {
    // Defaults: 26 blazed/sinusoidal periods, 57 Elaphe periods over 65 µm.
    for (kind, periods) in [
        (GratingKind::Blazed, 26),
        (GratingKind::Sinusoidal, 26),
        (GratingKind::Elaphe, 57),
    ] {
        let s = GratingSpec::default_for(kind);
        let hf = generate(&s).unwrap();
        let got = dominant_x_frequency(&hf, 0..hf.ny());
        assert_eq!(got, periods, "{kind}");
        let expected = s.extent_um().unwrap() / s.waves().unwrap().0.period_um;
        assert!((got as f64 - expected).abs() < 1e-9, "{kind}");
        // Nominal period within 1 %.
        let d = s.extent_um().unwrap() / got as f64;
        assert!((d / s.period_um - 1.0).abs() < 0.01, "{kind}: {d}");
    }
    // Xenopeltis: rows near y = 0 are domain a (≈1.55 µm), rows near y = L/2 domain b
    // (≈1.60 µm, tilted).
    let s = GratingSpec::default_for(GratingKind::Xenopeltis);
    let (a, b) = s.waves().unwrap();
    let b = b.unwrap();
    let hf = generate(&s).unwrap();
    let n = hf.ny();
    assert_eq!(dominant_x_frequency(&hf, 0..n / 16), a.mx as usize);
    assert_eq!(
        dominant_x_frequency(&hf, n / 2 - n / 16..n / 2 + n / 16),
        b.mx as usize
    );
    assert_ne!(a.mx, b.mx);
    // A rotated sinusoid: row spectrum peaks at m_x, column spectrum at m_y.
    let s = GratingSpec {
        period_um: 3.0,
        angle_deg: 30.0,
        ..GratingSpec::default_for(GratingKind::Sinusoidal)
    };
    let w = s.waves().unwrap().0;
    let hf = generate(&s).unwrap();
    assert_eq!(dominant_x_frequency(&hf, 0..hf.ny()), w.mx as usize);
    let t = HeightField::new(
        hf.ny(),
        hf.nx(),
        hf.dh_um(),
        (0..hf.nx() * hf.ny())
            .map(|i| hf.at((i / hf.ny()) as i64, (i % hf.ny()) as i64))
            .collect(),
    )
    .unwrap();
    assert_eq!(dominant_x_frequency(&t, 0..t.ny()), w.my as usize);
    // Snapping to the 65 µm lattice moves period and angle only slightly.
    assert!(
        (w.angle_deg - 30.0).abs() < 0.5 && (w.period_um - 3.0).abs() < 0.05,
        "{w:?}"
    );
}

#[test]
fn shipped_assets_equal_the_default_generators() {
    for kind in GratingKind::ALL {
        let expected = generate(&GratingSpec::default_for(kind)).unwrap();
        let builtin = HeightField::load_source(&format!("builtin:{kind}"), None, None).unwrap();
        assert_eq!(builtin, expected, "{kind}");
        let asset = HeightField::load(&assets().join(format!("{kind}.png")), None, None).unwrap();
        assert_eq!(
            (asset.nx(), asset.ny()),
            (expected.nx(), expected.ny()),
            "{kind}"
        );
        assert_eq!(asset.dh_um(), expected.dh_um(), "{kind}");
        let (lo, hi) = expected.range();
        let tol = (hi - lo) / 65535.0;
        let worst = expected
            .heights_um()
            .iter()
            .zip(asset.heights_um())
            .fold(0.0f64, |m, (a, b)| m.max((a - lo - b).abs()));
        assert!(worst <= tol, "{kind}: off by {worst} µm (step {tol})");
    }
}

#[test]
fn builtin_sources() {
    let e = HeightField::load_source("builtin:elaphe", None, Some(0.5)).unwrap();
    let (lo, hi) = e.range();
    assert!(lo == 0.0 && (hi - 0.5).abs() < 1e-12);
    let coarse = HeightField::load_source("builtin:blazed", Some(0.0812), None).unwrap();
    assert_eq!(coarse.dh_um(), 0.0812);
    assert_eq!(coarse.nx(), 800);
    assert!(HeightField::load_source("builtin:boa", None, None).is_err());
    assert!(HeightField::load_source("builtin:elaphe", Some(0.5), None).is_err());
    assert!(matches!(
        HeightField::load_source("/no/such/file.png", Some(0.1), Some(1.0)),
        Err(Error::Io { .. })
    ));
}

fn args(kind: GratingKind, out: PathBuf) -> HeightfieldArgs {
    HeightfieldArgs {
        kind: Some(kind),
        from_sample: None,
        samples: None,
        h_max_um: None,
        channel: None,
        level: None,
        out,
        size_um: Some(10.0),
        dh_um: None,
        period_um: None,
        height_um: None,
        angle_deg: None,
        seed: None,
    }
}

#[test]
fn cli_generates_and_rejects_nonsense() {
    let dir = tmpdir("cli");
    let out = dir.join("s.f32");
    run_heightfield(&args(GratingKind::Sinusoidal, out.clone())).unwrap();
    let hf = HeightField::load(&out, None, None).unwrap();
    assert_eq!(hf.nx(), (10.0f64 / (65.0 / 704.0)).round() as usize);
    let bad = [
        HeightfieldArgs {
            period_um: Some(-2.0),
            ..args(GratingKind::Blazed, dir.join("a.png"))
        },
        HeightfieldArgs {
            period_um: Some(0.15),
            ..args(GratingKind::Blazed, dir.join("a.png"))
        },
        HeightfieldArgs {
            dh_um: Some(f64::NAN),
            ..args(GratingKind::Blazed, dir.join("a.png"))
        },
        HeightfieldArgs {
            size_um: Some(1000.0),
            ..args(GratingKind::Blazed, dir.join("a.png"))
        },
        HeightfieldArgs {
            height_um: Some(f64::INFINITY),
            ..args(GratingKind::Blazed, dir.join("a.png"))
        },
    ];
    for a in bad {
        let e = run_heightfield(&a).unwrap_err();
        assert!(matches!(e, Error::Invalid { .. }), "{a:?}: {e}");
    }
    assert!(!dir.join("a.png").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
