//! The device build of `G` (Vulkan compute) against the CPU f64 build, node by node: in
//! float64 within 1e-12 of each slice's peak (measured on lavapipe: below 1e-15), on fields
//! whose sizes exercise every radix path (96×80: 4,4,2,3 × 4,4,5; 105×102: 3,5,7 × 2,3,17),
//! on the shipped blazed and sinusoidal gratings (704²) and on the grown measured Elaphe
//! field (960²); in float32 within 5e-5 (measured: 6e-6 on the Elaphe field). The FFT
//! alone against rustfft. Validation on; every object and allocation released. Its own
//! test binary, because the leak counter is process-wide.

mod gpu_util;

use std::sync::Arc;

use diffract::brdf::table::{sample_g_kept, Region, Slices, TableSpec};
use diffract::gpu::context::leaked_allocations;
use diffract::gpu::Device;
use diffract::heightfield::HeightField;
use diffract::render::table_build::{fft_rows_device, sample_g_device, Precision};
use diffract::spectrum::num_complex::Complex64;
use gpu_util::device;

/// Largest |device − CPU| over a slice's nodes, relative to the slice's peak, that the
/// float64 build may show (measured on lavapipe: at most 8.4e-16).
const F64_TOLERANCE: f64 = 1e-12;
/// The same bound for the float32 build (measured on lavapipe: 6.0e-6 on the grown Elaphe
/// field, 8.6e-7 on the rough 105×102 field; docs/tables.md).
const F32_TOLERANCE: f64 = 5e-5;

/// Drops the device and checks that validation stayed silent and nothing leaked.
fn finish(dev: Arc<Device>) {
    let canary = dev.canary();
    drop(dev);
    assert_eq!(
        canary.count(),
        0,
        "validation messages: {:#?}",
        canary.messages()
    );
    assert_eq!(leaked_allocations(), 0);
}

/// A rough random-phase surface of `nx × ny` samples (a grating plus noise), so energy
/// spreads over many bins.
fn rough_field(nx: usize, ny: usize, dh: f64) -> HeightField {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let h = (0..nx * ny)
        .map(|i| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let noise = (state >> 11) as f64 / (1u64 << 53) as f64;
            let x = (i % nx) as f64 * dh;
            0.15 * (2.0 * std::f64::consts::PI * x / 1.1).sin() + 0.1 * noise
        })
        .collect();
    HeightField::new(nx, ny, dh, h).unwrap()
}

fn spec(region: Region, texel: f64, step_nm: u32) -> TableSpec {
    TableSpec {
        region,
        texel_uv: texel,
        w_nodes: 2,
        step_nm,
        response: diffract::brdf::table::Response::Relative,
    }
}

/// Largest |a − b| over each slice relative to that slice's largest |b|, over slices and
/// channels.
fn worst_relative(a: &Slices, b: &Slices) -> f64 {
    assert_eq!((a.nu, a.nv, a.w.len()), (b.nu, b.nv, b.w.len()));
    let mut worst: f64 = 0.0;
    for (sa, sb) in a.data.iter().zip(&b.data) {
        let peak = sb.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(peak > 0.0, "an all-zero reference slice proves nothing");
        for (x, y) in sa.iter().flatten().zip(sb.iter().flatten()) {
            assert!(x.is_finite(), "non-finite device value");
            worst = worst.max((x - y).abs() / peak);
        }
    }
    worst
}

/// Builds the same table on the CPU and on the device and returns the worst relative
/// difference.
fn compare(
    dev: &Arc<Device>,
    name: &str,
    hf: &HeightField,
    spec: &TableSpec,
    keep: Option<&[usize]>,
    precision: Precision,
) -> f64 {
    let w = [spec.region.lo[2], spec.region.hi[2]];
    let cpu = sample_g_kept(hf, 65.0, spec, &w, keep, &|| ()).unwrap();
    let gpu = sample_g_device(dev, hf, 65.0, spec, &w, keep, precision, &|| ()).unwrap();
    let err = worst_relative(&gpu, &cpu);
    println!(
        "{name} {}×{} field, {}×{}×{} nodes, {}: max |device − CPU| / slice peak = {err:.3e}",
        hf.nx(),
        hf.ny(),
        cpu.nu,
        cpu.nv,
        cpu.w.len(),
        precision.name()
    );
    err
}

/// A region around the specular peak and the first orders of a grating along x.
fn region() -> Region {
    Region {
        lo: [-0.45, -0.04, -1.9],
        hi: [0.25, 0.04, -1.6],
    }
}

#[test]
fn device_fft_matches_rustfft() {
    let Some(dev) = device() else { return };
    let mut planner = rustfft::FftPlanner::<f64>::new();
    for n in [2usize, 3, 5, 7, 11, 13, 17, 64, 96, 704, 960] {
        let lines = 3;
        let input: Vec<Complex64> = (0..n * lines)
            .map(|i| Complex64::new((i as f64 * 0.37).sin(), (i as f64 * 1.3).cos() - 0.2))
            .collect();
        let mut want = input.clone();
        let fft = planner.plan_fft_inverse(n);
        for row in want.chunks_exact_mut(n) {
            fft.process(row);
        }
        let peak = want.iter().fold(0.0f64, |m, z| m.max(z.norm()));
        for (precision, tol) in [(Precision::F64, 1e-13), (Precision::F32, 1e-5)] {
            if precision == Precision::F64 && !dev.info.shader_float64 {
                continue;
            }
            let mut rows: Vec<f64> = input.iter().flat_map(|z| [z.re, z.im]).collect();
            fft_rows_device(&dev, n, &mut rows, precision).unwrap();
            let err = rows
                .chunks_exact(2)
                .zip(&want)
                .map(|(g, w)| (Complex64::new(g[0], g[1]) - w).norm())
                .fold(0.0f64, f64::max)
                / peak;
            println!(
                "FFT n = {n} {}: max error / peak = {err:.2e}",
                precision.name()
            );
            assert!(err < tol, "n = {n} {}: {err:.2e}", precision.name());
        }
    }
    finish(dev);
}

#[test]
fn device_table_equals_the_cpu_f64_table_on_odd_sizes() {
    let Some(dev) = device() else { return };
    assert!(
        dev.info.shader_float64,
        "{} lacks shaderFloat64; this test needs the float64 path",
        dev.info.name
    );
    // 96×80 (radices 4,4,2,3 and 4,4,5) and 105×102 (3,5,7 and 2,3,17), dH = 0.09 µm.
    for (nx, ny) in [(96usize, 80usize), (105, 102)] {
        let hf = rough_field(nx, ny, 0.09);
        let s = spec(region(), 0.01, 40);
        let err = compare(&dev, "rough", &hf, &s, None, Precision::F64);
        assert!(err < F64_TOLERANCE, "{nx}×{ny}: {err:.3e}");
    }
    finish(dev);
}

#[test]
fn device_table_equals_the_cpu_f64_table_on_the_shipped_fields() {
    let Some(dev) = device() else { return };
    assert!(
        dev.info.shader_float64,
        "{} lacks shaderFloat64",
        dev.info.name
    );
    // Three wavelengths across the spectrum (indices into the 10 nm colour table).
    let keep = [4usize, 17, 33];
    for name in [
        "builtin:blazed",
        "builtin:sinusoidal",
        "builtin:elaphe-grown",
    ] {
        let hf = HeightField::load_source(name, None, None).unwrap();
        let s = spec(region(), 0.005, 10);
        let err = compare(&dev, name, &hf, &s, Some(&keep), Precision::F64);
        assert!(err < F64_TOLERANCE, "{name}: {err:.3e}");
    }
    finish(dev);
}

#[test]
fn float32_device_table_stays_within_its_bound() {
    let Some(dev) = device() else { return };
    let keep = [4usize, 17, 33];
    let hf = HeightField::load_source("builtin:elaphe-grown", None, None).unwrap();
    let s = spec(region(), 0.005, 10);
    let err = compare(&dev, "elaphe-grown", &hf, &s, Some(&keep), Precision::F32);
    assert!(err < F32_TOLERANCE, "{err:.3e}");
    let hf = rough_field(105, 102, 0.09);
    let err = compare(
        &dev,
        "rough",
        &hf,
        &spec(region(), 0.01, 40),
        None,
        Precision::F32,
    );
    assert!(err < F32_TOLERANCE, "{err:.3e}");
    finish(dev);
}

/// `render --table-build` builds where it is told and says so on its `table:` line; the
/// builds give the same picture.
#[test]
fn render_says_where_the_table_was_built() {
    if device().is_none() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("diffract-table-build-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut pictures = Vec::new();
    for (build, want) in [
        ("cpu", "built on CPU (f32 sums, within "),
        ("cpu-f64", "built on CPU (f64) in "),
        ("device", "built on device ("),
    ] {
        let out = dir.join(format!("{build}.png"));
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_diffract"))
            .args([
                "render",
                "--brdf-map",
                "--size",
                "16",
                "--theta-i",
                "40",
                "--heightfield",
                "builtin:blazed",
                "--table-texel",
                "0.05",
                "--table-step-nm",
                "20",
                "--no-cache",
                "--table-build",
                build,
                "-o",
            ])
            .arg(&out)
            .env("DIFFRACT_VALIDATION", "1")
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(
            o.status.success(),
            "{build}: {stdout}{}",
            String::from_utf8_lossy(&o.stderr)
        );
        let line = stdout
            .lines()
            .find(|l| l.starts_with("table: chebyshev-w"))
            .unwrap_or_else(|| panic!("no table line: {stdout}"));
        assert!(line.contains(want) && line.ends_with(" MB"), "{line}");
        pictures.push(image::open(&out).unwrap().to_rgb8());
    }
    // The tables agree to float32 rounding, so the 8-bit pictures are the same.
    for other in &pictures[1..] {
        let differ = pictures[0]
            .pixels()
            .zip(other.pixels())
            .filter(|(a, b)| a.0.iter().zip(b.0).any(|(x, y)| x.abs_diff(y) > 1))
            .count();
        assert_eq!(differ, 0);
    }
    let bad = std::process::Command::new(env!("CARGO_BIN_EXE_diffract"))
        .args(["render", "--table-build", "gpu"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--table-build"));
    let _ = std::fs::remove_dir_all(&dir);
}
