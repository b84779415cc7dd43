//! A procedural skin texture for the snake meshes (thesis Algorithm 4 blends a texture with
//! the diffraction colour): the pattern of a corn snake, *Elaphe guttata* — the species of
//! the measured height field — with red-brown dorsal saddles edged in black on a tan ground,
//! smaller lateral blotches and a cream belly with dark checks, darkened a little so the
//! iridescence stands out as on a real skin. Deterministic; pure pixels, no I/O.
//!
//! Coordinates follow [`crate::mesh::Mesh::scaly_snake`]: texture `u` along the body (tail →
//! head), `v` around it with the belly at `v = 0.25` and the spine at `v = 0.75`. Images are
//! stored top row first and the shader samples row `(1 − v)·height`.

/// `[texture] path` value that selects this texture instead of a PNG file.
pub const ELAPHE_SKIN_BUILTIN: &str = "builtin:elaphe-skin";

/// Size of the built-in texture: 4:1 like the body (2 long, 2π·0.08 ≈ 0.5 around). The
/// close-up default camera spans about 0.3 of the body's length over 512 pixels (1024
/// supersampled): 4096 texels along the body keep the pattern's edges about a texel per
/// rendered sample (1024 made them stair-steps 3–4 pixels wide).
pub const ELAPHE_SKIN_SIZE: (u32, u32) = (4096, 1024);

/// Saddles along the body.
const SADDLES: f64 = 30.0;

fn mix(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    let t = t.clamp(0.0, 1.0);
    [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * t)
}

/// Smooth value noise in [0, 1] on an integer lattice (hash of the corners, smoothstep).
fn value_noise(x: f64, y: f64, seed: u64) -> f64 {
    let hash = |i: i64, j: i64| {
        let mut z = (i as u64)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add((j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F))
            ^ seed;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let (i, j) = (x.floor() as i64, y.floor() as i64);
    let (fx, fy) = (x - x.floor(), y - y.floor());
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (sx, sy) = (s(fx), s(fy));
    let top = hash(i, j) * (1.0 - sx) + hash(i + 1, j) * sx;
    let bottom = hash(i, j + 1) * (1.0 - sx) + hash(i + 1, j + 1) * sx;
    top * (1.0 - sy) + bottom * sy
}

/// Linear-light colour of the skin at body coordinates `(u, v)`.
fn skin_linear(u: f64, v: f64) -> [f64; 3] {
    let ground = [0.30, 0.13, 0.055];
    let saddle = [0.26, 0.045, 0.018];
    let edge = [0.012, 0.008, 0.006];
    let belly = [0.55, 0.48, 0.36];
    // Angular distance from the spine: 0 on the spine, 0.5 on the belly.
    let d = {
        let x = (v - 0.75).rem_euclid(1.0);
        x.min(1.0 - x)
    };
    // Wobbly outlines: the pattern of a real animal is not a lattice.
    let wobble = 0.35 * (value_noise(u * 90.0, v * 12.0, 7) - 0.5);
    let mut c = mix(ground, belly, (d - 0.36) / 0.06);
    // Dorsal saddles: ellipses on the spine, edged in black.
    let k = (u * SADDLES).round();
    let du = (u * SADDLES - k) / 0.3;
    let r = (du * du + (d / 0.17) * (d / 0.17)).sqrt() + wobble;
    if r < 1.25 {
        c = if r < 1.0 { saddle } else { edge };
    }
    // Lateral blotches between the saddles.
    let du = (u * SADDLES - k - 0.5).rem_euclid(1.0) - 0.5;
    let r = ((du / 0.22).powi(2) + ((d - 0.3) / 0.05).powi(2)).sqrt() + wobble;
    if r < 1.2 {
        c = if r < 0.9 { saddle } else { edge };
    }
    // Belly checks.
    if d > 0.4 {
        let check = ((u * SADDLES * 2.0).floor() as i64 + if v < 0.25 { 0 } else { 1 }) % 2 == 0;
        if check && (d - 0.4) > 0.02 + 0.03 * value_noise(u * 200.0, v * 40.0, 3) {
            c = edge;
        }
    }
    // Fine mottling, ±15 % in brightness; the head end plainer.
    let m = 0.85 + 0.3 * value_noise(u * 400.0, v * 100.0, 11);
    let c = c.map(|x| x * m);
    if u > 0.93 {
        mix(c, ground, (u - 0.93) / 0.03)
    } else {
        c
    }
}

/// The built-in corn-snake skin as sRGB bytes, `width × height`, top row first.
/// Rows in parallel (4 M texels at the built-in size).
pub fn elaphe_skin(width: u32, height: u32) -> Vec<[u8; 3]> {
    use rayon::prelude::*;
    let (w, h) = (width.max(1), height.max(1));
    (0..h)
        .into_par_iter()
        .flat_map_iter(|y| {
            (0..w).map(move |x| {
                let u = (x as f64 + 0.5) / w as f64;
                let v = 1.0 - (y as f64 + 0.5) / h as f64;
                crate::colour::linear_to_srgb8(skin_linear(u, v), 1.0)
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skin_is_deterministic_dark_on_the_back_and_light_on_the_belly() {
        let (w, h) = (256, 64);
        let a = elaphe_skin(w, h);
        assert_eq!(a.len(), (w * h) as usize);
        assert_eq!(a, elaphe_skin(w, h));
        let lum = |row: u32| {
            (0..w)
                .map(|x| {
                    a[(row * w + x) as usize]
                        .iter()
                        .map(|&c| c as f64)
                        .sum::<f64>()
                })
                .sum::<f64>()
                / w as f64
        };
        // Spine v = 0.75 → row (1 − 0.75)·h; belly v = 0.25 → row 0.75·h.
        let (spine, belly) = (lum(h / 4), lum(3 * h / 4));
        assert!(belly > 1.2 * spine, "{belly} vs {spine}");
        // A pattern, not a flat colour: dark edges and reddish saddles both occur.
        assert!(a.iter().any(|p| p.iter().all(|&c| c < 40)));
        assert!(a.iter().any(|p| p[0] > 2 * p[2] && p[0] > 80));
    }
}
