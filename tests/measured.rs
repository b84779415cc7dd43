//! The measured Elaphe crop and what is built from it: grey stored the ways tools write it
//! (RGB/RGBA with R = G = B, palette, 16-bit) loads like the grey PNG; a colour image is a
//! clear error; `--from-sample` grows a crop into a field with the crop's height histogram
//! and ridge period and no line at the crop's own period.

use std::path::{Path, PathBuf};

use diffract::cli::heightfield::{run_heightfield, HeightfieldArgs};
use diffract::heightfield::{
    grow, HeightField, GROWN_SAMPLES, MEASURED_ELAPHE_DH_UM, MEASURED_ELAPHE_H_MAX_UM,
};
use diffract::Error;
use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;

fn tmpdir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-measured-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

fn crop_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/measured/elaphe_afm_100x100.png")
}

fn crop() -> HeightField {
    HeightField::load(&crop_path(), None, None).expect("shipped crop with its sidecar")
}

// ---------------------------------------------------------------------------------------
// A minimal indexed-colour PNG writer (the image crate cannot write palettes): stored
// (uncompressed) deflate blocks, so it needs only CRC-32 and Adler-32.

fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

fn write_palette_png(path: &Path, w: u32, h: u32, palette: &[[u8; 3]], index: &[u8]) {
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&w.to_be_bytes());
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[8, 3, 0, 0, 0]);
    chunk(&mut png, b"IHDR", &ihdr);
    chunk(&mut png, b"PLTE", &palette.concat());
    let mut raw = Vec::new();
    for row in index.chunks_exact(w as usize) {
        raw.push(0); // filter: none
        raw.extend_from_slice(row);
    }
    let mut z = vec![0x78, 0x01];
    let blocks: Vec<&[u8]> = raw.chunks(65535).collect();
    for (i, b) in blocks.iter().enumerate() {
        z.push(u8::from(i + 1 == blocks.len()));
        z.extend_from_slice(&(b.len() as u16).to_le_bytes());
        z.extend_from_slice(&(!(b.len() as u16)).to_le_bytes());
        z.extend_from_slice(b);
    }
    let (mut a, mut b) = (1u32, 0u32);
    for &x in &raw {
        a = (a + u32::from(x)) % 65521;
        b = (b + a) % 65521;
    }
    z.extend_from_slice(&((b << 16) | a).to_be_bytes());
    chunk(&mut png, b"IDAT", &z);
    chunk(&mut png, b"IEND", &[]);
    std::fs::write(path, png).unwrap();
}

// ---------------------------------------------------------------------------------------
// Loading grey stored as colour

/// Grey 8-bit, RGB, RGBA (with a varying alpha, which is ignored) and palette encodings of
/// one pattern give bit-identical height fields; so do 16-bit grey and 16-bit RGB(A).
#[test]
fn rgb_rgba_and_palette_grey_load_identically_to_the_grey_png() {
    let dir = tmpdir("greys");
    let (w, h) = (13u32, 7u32);
    let g8 = |x: u32, y: u32| ((x * 37 + y * 11) % 256) as u8;
    let g16 = |x: u32, y: u32| ((x * 4099 + y * 977) % 65536) as u16;
    let load = |p: &Path| HeightField::load(p, Some(0.05), Some(0.4)).unwrap();

    let grey = dir.join("grey.png");
    image::GrayImage::from_fn(w, h, |x, y| image::Luma([g8(x, y)]))
        .save(&grey)
        .unwrap();
    let reference = load(&grey);
    let rgb = dir.join("rgb.png");
    image::RgbImage::from_fn(w, h, |x, y| image::Rgb([g8(x, y); 3]))
        .save(&rgb)
        .unwrap();
    let rgba = dir.join("rgba.png");
    image::RgbaImage::from_fn(w, h, |x, y| {
        let g = g8(x, y);
        image::Rgba([g, g, g, (x * 20) as u8])
    })
    .save(&rgba)
    .unwrap();
    let pal = dir.join("palette.png");
    let palette: Vec<[u8; 3]> = (0..=255u8).rev().map(|v| [v; 3]).collect();
    let index: Vec<u8> = (0..h)
        .flat_map(|y| (0..w).map(move |x| 255 - g8(x, y)))
        .collect();
    write_palette_png(&pal, w, h, &palette, &index);
    for p in [&rgb, &rgba, &pal] {
        assert_eq!(load(p), reference, "{}", p.display());
    }

    let grey16 = dir.join("grey16.png");
    image::ImageBuffer::<image::Luma<u16>, _>::from_fn(w, h, |x, y| image::Luma([g16(x, y)]))
        .save(&grey16)
        .unwrap();
    let reference16 = load(&grey16);
    let rgba16 = dir.join("rgba16.png");
    image::ImageBuffer::<image::Rgba<u16>, _>::from_fn(w, h, |x, y| {
        let g = g16(x, y);
        image::Rgba([g, g, g, 65535])
    })
    .save(&rgba16)
    .unwrap();
    assert_eq!(load(&rgba16), reference16);
    // 16-bit levels are not rounded to 8 bits on the way.
    assert!(reference16
        .heights_um()
        .iter()
        .any(|h| (h / 0.4 * 255.0).fract().abs() > 1e-3));

    // The shipped crop (8-bit RGBA) equals its own R channel stored as grey.
    let img = image::open(crop_path()).unwrap().to_rgba8();
    assert!(img.pixels().all(|p| p[0] == p[1] && p[1] == p[2]));
    let crop_grey = dir.join("crop_grey.png");
    image::GrayImage::from_fn(img.width(), img.height(), |x, y| {
        image::Luma([img.get_pixel(x, y)[0]])
    })
    .save(&crop_grey)
    .unwrap();
    let a = HeightField::load(&crop_grey, Some(MEASURED_ELAPHE_DH_UM), Some(0.4347)).unwrap();
    assert_eq!(a, crop());
    assert_eq!(
        HeightField::load_source("builtin:elaphe-measured", None, None).unwrap(),
        crop()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A colour RGBA image, and a palette with a non-grey colour, are one-line errors that name
/// the first pixel and the channel that differs.
#[test]
fn mixed_colour_images_are_clear_errors() {
    let dir = tmpdir("colour");
    let p = dir.join("mixed.png");
    image::RgbaImage::from_fn(6, 5, |x, y| {
        let g = (x * 10 + y) as u8;
        if (x, y) == (4, 2) {
            image::Rgba([g, g, g + 1, 255])
        } else if (x, y) == (5, 3) {
            image::Rgba([g, 0, g, 255])
        } else {
            image::Rgba([g, g, g, 255])
        }
    })
    .save(&p)
    .unwrap();
    let e = HeightField::load(&p, Some(0.05), Some(1.0)).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, Error::Image { .. }), "{msg}");
    assert!(
        msg.contains("mixed.png") && msg.contains("(column 4, row 2) has R = 42 but B = 43"),
        "{msg}"
    );
    assert!(!msg.contains('\n'));

    let pal = dir.join("pal.png");
    write_palette_png(&pal, 2, 2, &[[0, 0, 0], [9, 8, 9]], &[0, 0, 1, 0]);
    let msg = HeightField::load(&pal, Some(0.05), Some(1.0))
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("palette image") && msg.contains("(column 0, row 1) has R = 9 but G = 8"),
        "{msg}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

// ---------------------------------------------------------------------------------------
// Growing

/// Power spectrum `|DFT(h − mean)|²` of a square field, row-major `[ky][kx]`.
fn power(hf: &HeightField) -> Vec<f64> {
    let (nx, ny) = (hf.nx(), hf.ny());
    let m = hf.mean();
    let mut d: Vec<Complex64> = hf
        .heights_um()
        .iter()
        .map(|h| Complex64::new(h - m, 0.0))
        .collect();
    let mut planner = FftPlanner::new();
    let row = planner.plan_fft_forward(nx);
    for r in d.chunks_exact_mut(nx) {
        row.process(r);
    }
    let col = planner.plan_fft_forward(ny);
    let mut c = vec![Complex64::new(0.0, 0.0); ny];
    for x in 0..nx {
        for y in 0..ny {
            c[y] = d[y * nx + x];
        }
        col.process(&mut c);
        for y in 0..ny {
            d[y * nx + x] = c[y];
        }
    }
    d.iter().map(|z| z.norm_sqr()).collect()
}

/// Signed frequency (cycles per sample) of bin `k` of an `n`-point DFT.
fn freq(k: usize, n: usize) -> f64 {
    let k = if k > n / 2 {
        k as f64 - n as f64
    } else {
        k as f64
    };
    k / n as f64
}

/// The strongest non-DC spectral peak `(fx, fy)` in cycles per sample, folded to `fy ≥ 0`.
fn peak(hf: &HeightField) -> (f64, f64) {
    let p = power(hf);
    let (nx, ny) = (hf.nx(), hf.ny());
    let k = (1..p.len()).max_by(|&a, &b| p[a].total_cmp(&p[b])).unwrap();
    let (fx, fy) = (freq(k % nx, nx), freq(k / nx, ny));
    if fy < 0.0 || (fy == 0.0 && fx < 0.0) {
        (-fx, -fy)
    } else {
        (fx, fy)
    }
}

/// Kolmogorov–Smirnov distance between the empirical height distributions.
fn ks_distance(a: &[f64], b: &[f64]) -> f64 {
    let mut a = a.to_vec();
    let mut b = b.to_vec();
    a.sort_unstable_by(f64::total_cmp);
    b.sort_unstable_by(f64::total_cmp);
    let mut levels: Vec<f64> = a.iter().chain(&b).copied().collect();
    levels.sort_unstable_by(f64::total_cmp);
    levels.dedup();
    let cdf = |v: &[f64], x: f64| v.partition_point(|&y| y <= x) as f64 / v.len() as f64;
    levels
        .iter()
        .map(|&x| (cdf(&a, x) - cdf(&b, x)).abs())
        .fold(0.0, f64::max)
}

/// `Σ P(g) / Σ mean(P at the 8 neighbours of g)` over the bins `g ≠ 0` whose frequency is a
/// multiple of `1/period` cycles per sample (`n` a multiple of `period`): the lines a field
/// that repeats every `period` samples puts its whole spectrum on.
fn line_ratio(hf: &HeightField, period: usize) -> f64 {
    let n = hf.nx();
    assert_eq!(n % period, 0);
    let step = n / period;
    let p = power(hf);
    let at =
        |x: i64, y: i64| p[(y.rem_euclid(n as i64) as usize) * n + x.rem_euclid(n as i64) as usize];
    let (mut on, mut beside) = (0.0, 0.0);
    for gy in (0..n).step_by(step) {
        for gx in (0..n).step_by(step) {
            if gx == 0 && gy == 0 {
                continue;
            }
            let (x, y) = (gx as i64, gy as i64);
            on += at(x, y);
            let mut s = 0.0;
            for (dx, dy) in [
                (-1, -1),
                (0, -1),
                (1, -1),
                (-1, 0),
                (1, 0),
                (-1, 1),
                (0, 1),
                (1, 1),
            ] {
                s += at(x + dx, y + dy);
            }
            beside += s / 8.0;
        }
    }
    on / beside
}

/// The crop repeated `k × k` times.
fn tiled(crop: &HeightField, k: usize) -> HeightField {
    let n = crop.nx() * k;
    let h = (0..n * n)
        .map(|i| crop.at((i % n) as i64, (i / n) as i64))
        .collect();
    HeightField::new(n, n, crop.dh_um(), h).unwrap()
}

/// The grown field keeps the crop's statistics and period but not its repetition.
///
/// Tolerances and why:
/// - **Histogram:** KS distance ≤ 1e-4. Nearest-rank matching gives every crop sample
///   `N²/n² = 81` grown samples here (900²/100²), so the distributions are equal; in general
///   rounding the rank moves at most one crop rank, `1/n² = 1e-4` of the mass.
/// - **Ridge period:** the dominant peak lies within half a crop bin, `0.5/100` cycles per
///   sample, of the crop's, in both components: the crop only knows its period to its own
///   DFT resolution (6 ± 0.5 cycles per 100 samples, 15.4–18.2 samples). The grown spectrum
///   is the crop's tapered transform sampled 9× finer, so its peak may sit anywhere in
///   that bin, but not outside.
/// - **No line at the crop's period:** power on the multiples of 1/100 cycles per sample
///   over power on their 8 neighbours ≤ 1.5. The grown spectrum is smooth on the scale of
///   a crop bin (9 fine bins: the Hann taper's main lobe is 4 crop bins wide), so
///   neighbours one fine bin away carry nearly the same power (ratio ≈ 1); the tiled crop
///   has all its power on those bins and a ratio of ~1e20, checked here so the test can fail.
#[test]
fn grown_field_keeps_histogram_and_period_without_the_crop_period() {
    let crop = crop();
    assert_eq!((crop.nx(), crop.ny()), (100, 100));
    let n = 900;
    let grown = grow(&crop, n, 7).unwrap();
    assert_eq!((grown.nx(), grown.ny()), (n, n));
    assert_eq!(grown.dh_um(), crop.dh_um());

    let ks = ks_distance(grown.heights_um(), crop.heights_um());
    let (lo, hi) = crop.range();
    assert_eq!(grown.range(), (lo, hi));
    println!("KS distance of the height distributions: {ks:.2e}");
    assert!(ks <= 1e-4, "KS {ks}");

    let (cx, cy) = peak(&crop);
    let (gx, gy) = peak(&grown);
    println!(
        "ridge period: crop {:.2} samples (peak {cx:.4}, {cy:.4}), grown {:.2} samples (peak {gx:.4}, {gy:.4})",
        1.0 / cx.hypot(cy),
        1.0 / gx.hypot(gy)
    );
    assert_eq!(
        (cx, cy),
        (0.0, 0.06),
        "the crop's documented peak: 6 cycles per 100 samples along y"
    );
    assert!(
        (gx - cx).abs() <= 0.005 && (gy - cy).abs() <= 0.005,
        "{gx} {gy}"
    );

    let grown_ratio = line_ratio(&grown, 100);
    let tiled_ratio = line_ratio(&tiled(&crop, n / 100), 100);
    println!("line ratio at the crop period: grown {grown_ratio:.3}, tiled {tiled_ratio:.3e}");
    assert!(grown_ratio <= 1.5, "{grown_ratio}");
    assert!(
        tiled_ratio > 1e6,
        "the check must catch tiling: {tiled_ratio}"
    );
}

#[test]
fn growing_is_deterministic_per_seed_and_rejects_bad_sizes() {
    let crop = crop();
    let a = grow(&crop, 128, 1).unwrap();
    assert_eq!(a, grow(&crop, 128, 1).unwrap());
    assert_ne!(a, grow(&crop, 128, 2).unwrap());
    for n in [0, 99, 5000] {
        assert!(
            matches!(grow(&crop, n, 1), Err(Error::Invalid { .. })),
            "{n}"
        );
    }
    let tiny = HeightField::new(3, 3, 0.1, vec![0.0; 9]).unwrap();
    assert!(grow(&tiny, 16, 1).is_err());
}

/// `builtin:elaphe-grown` is the crop grown with seed 1 to the documented size; the CLI's
/// `--from-sample` writes the same field (within 16-bit quantisation) with its sidecar.
#[test]
fn builtin_and_cli_growing_agree() {
    let dir = tmpdir("cli");
    let out = dir.join("grown.png");
    let args = HeightfieldArgs {
        kind: None,
        from_sample: Some(crop_path().to_string_lossy().into_owned()),
        out: out.clone(),
        size_um: None,
        samples: Some(GROWN_SAMPLES),
        dh_um: None,
        h_max_um: None,
        channel: None,
        level: None,
        period_um: None,
        height_um: None,
        angle_deg: None,
        seed: Some(1),
    };
    run_heightfield(&args).unwrap();
    let file = HeightField::load(&out, None, None).unwrap();
    let builtin = HeightField::load_source("builtin:elaphe-grown", None, None).unwrap();
    assert_eq!((builtin.nx(), builtin.ny()), (GROWN_SAMPLES, GROWN_SAMPLES));
    assert_eq!(file.dh_um(), MEASURED_ELAPHE_DH_UM);
    let (lo, hi) = builtin.range();
    let step = (hi - lo) / 65535.0;
    for (a, b) in builtin.heights_um().iter().zip(file.heights_um()) {
        assert!((a - lo - b).abs() <= 0.5 * step + 1e-12);
    }
    // Default size: 65 µm at the crop's pixel size.
    let args65 = HeightfieldArgs {
        samples: None,
        out: dir.join("g65.f32"),
        ..args.clone()
    };
    assert_eq!(
        args65.grown_samples(MEASURED_ELAPHE_DH_UM).unwrap(),
        (65.0 / MEASURED_ELAPHE_DH_UM).round() as usize
    );
    // The calibration overrides reach the crop.
    let scaled = HeightField::load_source("builtin:elaphe-measured", None, Some(0.2)).unwrap();
    let ratio = MEASURED_ELAPHE_H_MAX_UM / 0.2;
    assert!((crop().range().1 - scaled.range().1 * ratio).abs() < 1e-12);
    // A grating option with --from-sample, or a colour sample, is an error, nothing written.
    let bad = HeightfieldArgs {
        samples: Some(10),
        out: dir.join("bad.png"),
        ..args
    };
    assert!(matches!(run_heightfield(&bad), Err(Error::Invalid { .. })));
    assert!(!dir.join("bad.png").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
