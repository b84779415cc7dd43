//! Precompute benchmark (issue #2): 31 DFT terms (T = 30) of a 1024² height field, this
//! project's real-to-complex path against numpy's `ifft2` on the same field, measured side by
//! side in one run. Run with `cargo bench --bench precompute` (needs python3 with numpy:
//! `python3 -m pip install numpy`). Prints times and the ratio; no assertion on speed.

use std::process::Command;
use std::time::Instant;

use diffract::heightfield::HeightField;
use diffract::spectrum::{compute_terms, Expansion, TermRequest};

const N: usize = 1024;
const T: usize = 30;
const REPEATS: usize = 3;

fn field() -> HeightField {
    // A deterministic rough grating: ridges with a slow wobble and hashed noise.
    let tau = 2.0 * std::f64::consts::PI;
    let dh = 65.0 / N as f64;
    let h = (0..N * N)
        .map(|i| {
            let (c, r) = ((i % N) as f64 * dh, (i / N) as f64 * dh);
            let noise =
                ((i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as f64 / (1u64 << 24) as f64;
            0.2 * (1.0 + (tau * (c + 0.3 * (tau * r / 65.0).sin()) / 1.14).sin()) + 0.02 * noise
        })
        .collect();
    HeightField::new(N, N, dh, h).expect("benchmark field is valid")
}

fn best_of(threads: usize, hf: &HeightField, req: &TermRequest) -> (f64, Vec<f64>) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("thread pool");
    let mut best = f64::INFINITY;
    let mut check = Vec::new();
    for _ in 0..REPEATS {
        let start = Instant::now();
        let s = pool.install(|| compute_terms(hf, req)).expect("terms");
        best = best.min(start.elapsed().as_secs_f64());
        check = [0, 1, 2, T]
            .iter()
            .map(|&n| s.texel(n, (N / 2) as i64, (N / 2) as i64).norm())
            .collect();
    }
    (best, check)
}

fn main() {
    let hf = field();
    let req = TermRequest {
        expansion: Expansion::Taylor,
        max_term: T,
        lambda_min_um: 0.38,
        window_radius: 1,
        full_band: true,
    };
    let threads = rayon::current_num_threads();
    let (t_multi, check) = best_of(threads, &hf, &req);
    let (t_single, _) = best_of(1, &hf, &req);
    println!("diffract  {N}² × {} terms: {t_single:.3} s on 1 thread, {t_multi:.3} s on {threads} threads (best of {REPEATS})", T + 1);

    let path = std::env::temp_dir().join(format!("diffract-bench-{}.f64", std::process::id()));
    let bytes: Vec<u8> = hf
        .heights_um()
        .iter()
        .flat_map(|h| h.to_le_bytes())
        .collect();
    std::fs::write(&path, bytes).expect("write benchmark field");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/numpy_terms.py");
    let out = Command::new("python3")
        .args([
            script,
            path.to_str().unwrap_or_default(),
            &N.to_string(),
            &N.to_string(),
            &T.to_string(),
            &REPEATS.to_string(),
        ])
        .output();
    let _ = std::fs::remove_file(&path);
    match out {
        Ok(o) if o.status.success() => {
            let text = String::from_utf8_lossy(&o.stdout);
            let mut it = text
                .split_whitespace()
                .filter_map(|s| s.parse::<f64>().ok());
            let t_numpy = it.next().unwrap_or(f64::NAN);
            let np_check: Vec<f64> = it.collect();
            // Relative to the largest DC value (n = 0 is exactly 1), so terms near zero
            // compare on an absolute scale.
            let scale = np_check
                .iter()
                .chain(&check)
                .fold(1e-300_f64, |m, v| m.max(v.abs()));
            let agree = np_check.len() == check.len()
                && np_check
                    .iter()
                    .zip(&check)
                    .all(|(a, b)| (a - b).abs() <= 1e-9 * scale);
            println!(
                "numpy     {N}² × {} terms: {t_numpy:.3} s (ifft2 of (1j*h)**n, 1 thread)",
                T + 1
            );
            println!(
                "ratio numpy/diffract: {:.2}× (1 thread), {:.2}× ({threads} threads); DC terms agree: {agree}",
                t_numpy / t_single,
                t_numpy / t_multi
            );
        }
        Ok(o) => println!(
            "numpy comparison skipped: {} (install numpy: python3 -m pip install numpy)",
            String::from_utf8_lossy(&o.stderr)
                .lines()
                .last()
                .unwrap_or("python3 failed")
        ),
        Err(e) => println!("numpy comparison skipped: python3 not runnable ({e})"),
    }
}
