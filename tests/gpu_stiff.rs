//! A stiff case on the GPU (MODEL §4): a tall rough structure (0–2 µm) at 380 nm under
//! grazing light, where `a = k|w|·max|h − mean|` reaches ≈ 20. The Taylor series sums
//! terms far larger than its result, and float32 loses the difference to cancellation; the
//! Chebyshev (Jacobi–Anger) expansion has every factor bounded by 1 and stays at float32
//! accuracy. Both are compared with their own f64 model (the same algorithm in double
//! precision), so only arithmetic precision differs. Measured on lavapipe: max error / peak
//! Taylor 5.7e-4, Chebyshev 7.3e-6.

mod gpu_util;

use diffract::brdf;
use diffract::heightfield::HeightField;
use diffract::material::Material;
use diffract::spectrum::Expansion;
use gpu_util::*;

const SIZE: u32 = 24;
const LAMBDA_NM: f64 = 380.0;
const THETA_I: f64 = 85.0;

/// Max |GPU − f64 model| / max(model) of a spectral map, and whether everything was finite.
fn spectral_map_error(path: &str, expansion: Expansion, terms: usize) -> (f64, bool) {
    let Some(mut r) = renderer() else {
        return (0.0, true);
    };
    let m = Material {
        heightfield: path.into(),
        expansion,
        terms: diffract::material::Terms::Fixed(terms),
        window_radius: 1,
        ..Material::default()
    };
    let p = prepare(&m);
    let frame = r
        .render_brdf_map(&p, THETA_I, 0.0, SIZE, Some(LAMBDA_NM))
        .expect("render");
    assert_no_validation(&r);
    let finite = frame
        .rgb
        .iter()
        .flatten()
        .all(|v| v.is_finite() && *v >= 0.0);
    let wi = uploaded_direction(THETA_I, 0.0);
    let (mut max_cpu, mut worst) = (0.0f64, 0.0f64);
    for j in 0..SIZE {
        for i in 0..SIZE {
            let Some(wr) = map_direction(i, j, SIZE) else {
                continue;
            };
            let cpu = brdf::model::rho(
                p.stack.get().unwrap(),
                terms,
                &p.window,
                &p.shading,
                wi,
                wr,
                LAMBDA_NM,
            );
            max_cpu = max_cpu.max(cpu);
            worst = worst.max((frame.at(i, j)[0] as f64 - cpu).abs());
        }
    }
    (worst / max_cpu, finite)
}

#[test]
fn chebyshev_stays_accurate_in_float32_where_taylor_cancels() {
    let dir = std::env::temp_dir().join(format!("diffract-stiff-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("tall.png");
    // A rough tall surface (seeded Gaussian bumps, 0–2 µm): its spectrum is broad, so every
    // map pixel sees many terms of the series, not only the pixels on diffraction lines.
    let (n, dh) = (130usize, 0.5);
    let mut state = 0x2545_F491_4F6C_DD1D_u64;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let bumps: Vec<(f64, f64, f64)> = (0..120)
        .map(|_| (rnd() * 65.0, rnd() * 65.0, rnd() - 0.5))
        .collect();
    let mut h: Vec<f64> = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f64 * dh, (i / n) as f64 * dh);
            bumps
                .iter()
                .map(|&(bx, by, a)| {
                    // Periodic distance on the 65 µm patch.
                    let dx = (x - bx + 32.5).rem_euclid(65.0) - 32.5;
                    let dy = (y - by + 32.5).rem_euclid(65.0) - 32.5;
                    a * (-(dx * dx + dy * dy) / (2.0 * 1.5 * 1.5)).exp()
                })
                .sum()
        })
        .collect();
    let (lo, hi) = h
        .iter()
        .fold((f64::MAX, f64::MIN), |(l, u), &v| (l.min(v), u.max(v)));
    for v in &mut h {
        *v = 2.0 * (*v - lo) / (hi - lo);
    }
    HeightField::new(n, n, dh, h).unwrap().save(&path).unwrap();
    let path = path.to_string_lossy().into_owned();

    // T chosen so both f64 models are converged (README: Chebyshev needs about half).
    let (taylor, taylor_finite) = spectral_map_error(&path, Expansion::Taylor, 60);
    let (cheb, cheb_finite) = spectral_map_error(&path, Expansion::Chebyshev, 40);
    println!("rough 0–2 µm at 380 nm, θi = 85°: float32 vs f64 model, max error / peak: Taylor {taylor:.3e}, Chebyshev {cheb:.3e}");
    assert!(
        taylor_finite && cheb_finite,
        "non-finite or negative output"
    );
    assert!(cheb < 1e-3, "Chebyshev in float32: {cheb}");
    assert!(
        taylor > 10.0 * cheb,
        "Taylor {taylor} vs Chebyshev {cheb}: no cancellation seen"
    );
    let _ = std::fs::remove_dir_all(dir);
}
