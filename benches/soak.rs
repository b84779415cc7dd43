//! Soak (issue #10): thousands of tiny offscreen BRDF maps through one `Renderer`, with the
//! Khronos validation layer on. Passes when resident memory after the last frame is within
//! 1 % of what it was after a warm-up, and validation reported nothing. Run with
//! `cargo bench --bench soak` (`SOAK_FRAMES`, default 10 000; `SOAK_SIZE`, default 16;
//! `SOAK_VALIDATION=0` to run without the layer and tell its memory from the renderer's;
//! `SOAK_REBUILD=1` alternates the map side between `SOAK_SIZE` and one more, so every frame
//! builds its pass and target anew, as every frame did before the renderer reused them).
//! Exits non-zero on failure.

use std::time::Instant;

use diffract::material::Material;
use diffract::render::Renderer;
use diffract::spectrum::Expansion;

/// Resident set size of this process (kB), from /proc.
fn rss_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

fn env_or(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let frames = env_or("SOAK_FRAMES", 10_000);
    let size = env_or("SOAK_SIZE", 16) as u32;
    let warmup = (frames / 20).clamp(1, 200);
    let every = (frames / 10).clamp(1, 1000);
    let material = Material {
        heightfield: "builtin:blazed".into(),
        expansion: Expansion::Chebyshev,
        terms: diffract::material::Terms::Fixed(3),
        window_radius: 1,
        lambda_step_nm: 20,
        ..Material::default()
    };
    let prepared = material
        .prepare(None, &diffract::report::Stderr)
        .expect("material");
    let validation = env_or("SOAK_VALIDATION", 1) != 0;
    let rebuild = env_or("SOAK_REBUILD", 0) != 0;
    let mut renderer = Renderer::new(validation).expect("Vulkan device");
    let start = Instant::now();
    let mut base = 0;
    let mut peak = 0;
    for i in 0..frames {
        let theta = (i % 80) as f64;
        let phi = (i % 360) as f64;
        let side = size + (rebuild && i % 2 == 1) as u32;
        let frame = renderer
            .render_brdf_map(&prepared, theta, phi, side, None)
            .expect("frame");
        assert_eq!(frame.rgb.len(), (side * side) as usize);
        if i + 1 == warmup {
            base = rss_kb();
        }
        if i + 1 >= warmup {
            peak = peak.max(rss_kb());
        }
        if (i + 1) % every == 0 {
            eprintln!(
                "{} frames, RSS {} kB, {:.1} s",
                i + 1,
                rss_kb(),
                start.elapsed().as_secs_f64()
            );
        }
    }
    let end = rss_kb();
    let messages = renderer.validation_messages();
    let growth = (end as f64 - base as f64) / base.max(1) as f64 * 100.0;
    let per_frame = (end as f64 - base as f64) / (frames - warmup).max(1) as f64;
    println!(
        "soak: {frames} BRDF maps {size}²{} on {} (validation {}) in {:.1} s ({:.2} ms/frame); \
         RSS after {warmup} frames {base} kB, at the end {end} kB (peak {peak} kB): growth \
         {growth:+.2} % ({per_frame:+.3} kB/frame); validation messages: {messages}",
        if rebuild {
            " (rebuilt every frame)"
        } else {
            ""
        },
        renderer.device_name(),
        if validation { "on" } else { "off" },
        start.elapsed().as_secs_f64(),
        start.elapsed().as_secs_f64() * 1e3 / frames as f64
    );
    // Objects left alive are reported when the device is destroyed: count those too.
    let canary = renderer.canary();
    drop(renderer);
    let messages = messages.max(canary.count());
    let leaked = diffract::gpu::context::leaked_allocations();
    println!("soak: after teardown: validation messages {messages}, leaked allocations {leaked}");
    if growth >= 1.0 || messages > 0 || leaked > 0 {
        eprintln!(
            "soak: FAILED (growth must stay under 1 %, no validation message, no leaked allocation)"
        );
        std::process::exit(1);
    }
}
