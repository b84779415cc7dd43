//! BRDF maps lit by environment maps on the device (lavapipe, validation on): the white
//! furnace, environment-lit pixels against the f64 quadrature reference under the sky and
//! the studio, and the error falling with the samples.

mod gpu_util;

use diffract::brdf::env_reference::{env_radiance_converged, Frame, Quadrature};
use diffract::brdf::table::{Region, TableSpec};
use diffract::brdf::{schlick_r0, Shading};
use diffract::colour::{delta_e2000, xyz_to_lab, xyz_to_linear_srgb};
use diffract::heightfield::HeightField;
use diffract::light::env::{EnvMap, EnvSource};
use diffract::light::set::EnvLight;
use diffract::render::env::{map_direction, render_env_brdf_map, EnvLighting, EnvMapRequest};

const SHADING_OFF: Shading = Shading {
    fresnel: false,
    shadowing: false,
    ior: 1.5,
};

/// The white furnace on the device, every channel: a flat patch under a uniform white
/// environment of radiance 1, shadowing off, reflects the environment's white (X, Y and Z
/// each, relative to D65's) at every pixel with θr ≤ 60°; with Fresnel on, Schlick's
/// `R(θr)` times it. The table's spacing is the environment table's default (the
/// narrowest lobe's width): a coarser one rings below zero beside the blue lobes and the
/// clamp to `G ≥ 0` adds that energy back, in Z most.
#[test]
fn white_furnace_on_the_gpu() {
    let Some(dev) = gpu_util::device() else {
        return;
    };
    // A flat patch: its lobe lies within 0.04 of (u, v) = 0 for every view direction.
    let hf = HeightField::new(64, 64, 65.0 / 64.0, vec![0.0; 64 * 64]).unwrap();
    let default = diffract::cli::env::map_table_spec(None, Some(4), None, 65.0).unwrap();
    let spec = TableSpec {
        region: Region {
            lo: [-0.06, -0.06, -2.0],
            hi: [0.06, 0.06, -0.9],
        },
        ..default
    };
    let env = EnvMap::load(&EnvSource::White, 1.0, 0.0).unwrap();
    for fresnel in [false, true] {
        let shading = Shading {
            fresnel,
            ..SHADING_OFF
        };
        let lighting = EnvLighting::build(&hf, 65.0, &shading, &spec).unwrap();
        let size = 24;
        let req = EnvMapRequest {
            env: &env,
            shading,
            // The mean over the pixels is within 3e-4 of 1 at any count; a single pixel's
            // sampling noise is within 1 % from 256 samples (4 % at 16, 2.3 % at 64).
            samples: 4096,
            size,
            sun: None,
            seed: 0,
            brdf: None,
            per_dispatch: None,
        };
        let pic = render_env_brdf_map(&dev, &lighting, &req).unwrap();
        let (mut worst, mut n, mut mean) = ([0.0f64; 3], 0, [0.0f64; 3]);
        // And as the picture's R, G, B (linear sRGB), against white's.
        let white_rgb = xyz_to_linear_srgb(lighting.white);
        let mut worst_rgb = [0.0f64; 3];
        for j in 0..size {
            for i in 0..size {
                let Some(wr) = map_direction(i, j, size) else {
                    continue;
                };
                if wr[2] < 0.5 {
                    continue; // θr > 60°
                }
                let r0 = schlick_r0(1.5);
                let want = if fresnel {
                    r0 + (1.0 - r0) * (1.0 - wr[2]).powi(5)
                } else {
                    1.0
                };
                let px = pic.xyz[(j * size + i) as usize];
                let rgb = xyz_to_linear_srgb(px.map(f64::from));
                for c in 0..3 {
                    let r = f64::from(px[c]) / lighting.white[c] / want - 1.0;
                    worst[c] = worst[c].max(r.abs());
                    mean[c] += r;
                    let r = rgb[c] / white_rgb[c] / want - 1.0;
                    worst_rgb[c] = worst_rgb[c].max(r.abs());
                }
                n += 1;
            }
        }
        let mean = mean.map(|m| m / n as f64);
        eprintln!(
            "white furnace, Fresnel {fresnel}, texel {}: {n} pixels with θr ≤ 60°, mean X, Y, Z/white − 1 = {mean:?}, worst {worst:?}; worst R, G, B/white − 1 {worst_rgb:?}",
            spec.texel_uv
        );
        for c in 0..3 {
            assert!(
                worst_rgb[c] < 0.01,
                "Fresnel {fresnel}, R, G, B channel {c}: worst {}",
                worst_rgb[c]
            );
            assert!(
                worst[c] < 0.01 && mean[c].abs() < 2e-3,
                "Fresnel {fresnel}, channel {c}: worst {}, mean {}",
                worst[c],
                mean[c]
            );
        }
    }
    assert_eq!(dev.validation_messages(), 0);
}

/// A 1-D sinusoidal grating, period 2 µm, heights ±0.1 µm, 4 periods tiled.
fn grating() -> HeightField {
    let (nx, ny) = (128usize, 4usize);
    let dh = 8.0 / nx as f64;
    let h: Vec<f64> = (0..nx * ny)
        .map(|p| 0.1 * (2.0 * std::f64::consts::PI * (p % nx) as f64 * dh / 2.0).sin())
        .collect();
    HeightField::new(nx, ny, dh, h).unwrap()
}

fn grating_spec(texel: f64, w_nodes: usize) -> TableSpec {
    TableSpec {
        region: Region {
            lo: [-1.95, -0.03, -2.0],
            hi: [1.95, 0.03, -0.45],
        },
        texel_uv: texel,
        w_nodes,
        step_nm: 10,
        response: diffract::brdf::table::Response::Relative,
    }
}

/// Pixels of a 16² map to check: near normal, along the grating and across it.
const PIXELS: [(u32, u32); 3] = [(8, 8), (4, 7), (9, 12)];

fn lab(xyz: [f64; 3], white_y: f64) -> [f64; 3] {
    xyz_to_lab(xyz.map(|x| x / white_y))
}

/// Samples per pixel of the comparison with the reference. This 0.2 µm grating sends most
/// of its light into orders, a hard case for the sampler: under the sky a pixel's ΔE2000
/// was up to 3.7 at the default 256 samples and 1.7 at 1024, under the studio 7.0 at 1024;
/// at 4096 all pixels are within 0.5 but the darkest (ΔE2000 1.2, Y 3 % off).
const SAMPLES: u32 = 4096;

#[test]
fn environment_lit_pixels_match_the_f64_reference() {
    let Some(dev) = gpu_util::device() else {
        return;
    };
    let hf = grating();
    let shading = Shading::default();
    let lighting = EnvLighting::build(&hf, 65.0, &shading, &grating_spec(0.002, 16)).unwrap();
    // The reference integrates the same f64 model of the BRDF (the table's own error
    // against the direct-sum reference is measured with the tables, docs/tables.md), so
    // what is compared is the integration: quadrature against Monte Carlo.
    let g = |d: [f64; 3]| lighting.g(d).unwrap_or([0.0; 3]);
    let size = 16;
    for (source, rotate) in [(EnvSource::Sky, 0.0), (EnvSource::Studio, 30.0)] {
        let env = EnvMap::load(&source, 1.0, rotate).unwrap();
        let req = EnvMapRequest {
            env: &env,
            shading,
            samples: SAMPLES,
            size,
            sun: None,
            seed: 0,
            brdf: None,
            per_dispatch: None,
        };
        let pic = render_env_brdf_map(&dev, &lighting, &req).unwrap();
        let refs: Vec<([f64; 3], f64)> = PIXELS
            .iter()
            .map(|&(i, j)| {
                let wr = map_direction(i, j, size).unwrap();
                let q = Quadrature {
                    lo: [-1.95, -0.03],
                    hi: [1.95, 0.03],
                    h: 0.001,
                };
                env_radiance_converged(&EnvLight::new(&env), &Frame::BRDF_MAP, wr, &shading, &g, &q)
            })
            .collect();
        let white_y = refs.iter().fold(0.0f64, |m, r| m.max(r.0[1]));
        for (&(i, j), (want, quad_err)) in PIXELS.iter().zip(&refs) {
            let got = pic.xyz[(j * size + i) as usize].map(f64::from);
            let rel = (got[1] - want[1]).abs() / want[1];
            let de = delta_e2000(lab(got, white_y), lab(*want, white_y));
            eprintln!(
                "{}: pixel ({i}, {j}) GPU {got:.4?} reference {want:.4?} (quadrature ±{quad_err:.1e}): Y {rel:.3}, ΔE2000 {de:.2}",
                source.name()
            );
            if want[1] < 0.01 * white_y {
                continue; // black: ΔE and relative errors of noise
            }
            assert!(*quad_err < 1e-3, "reference not converged: {quad_err}");
            assert!(
                de < 1.5 && rel < 0.05,
                "{}: pixel ({i}, {j}) ΔE {de}, Y {rel}",
                source.name()
            );
        }
    }
    assert_eq!(dev.validation_messages(), 0);
}

#[test]
fn the_error_falls_with_the_samples() {
    let Some(dev) = gpu_util::device() else {
        return;
    };
    let hf = grating();
    let shading = Shading::default();
    let lighting = EnvLighting::build(&hf, 65.0, &shading, &grating_spec(0.002, 12)).unwrap();
    let env = EnvMap::load(&EnvSource::Studio, 1.0, 30.0).unwrap();
    let size = 16;
    let draw = |samples: u32, seed: u32| {
        let req = EnvMapRequest {
            env: &env,
            shading,
            samples,
            size,
            sun: None,
            seed,
            brdf: None,
            per_dispatch: None,
        };
        render_env_brdf_map(&dev, &lighting, &req).unwrap()
    };
    let converged = draw(2048, 7);
    let norm: f64 = converged
        .xyz
        .iter()
        .map(|p| f64::from(p[1]).powi(2))
        .sum::<f64>()
        .sqrt();
    let mut errors = Vec::new();
    for n in [4u32, 16, 64, 256] {
        // Averaged over four scramblings: one picture's error is itself noisy.
        let e: f64 = (1..=4)
            .map(|seed| {
                let p = draw(n, seed);
                p.xyz
                    .iter()
                    .zip(&converged.xyz)
                    .map(|(a, b)| f64::from(a[1] - b[1]).powi(2))
                    .sum::<f64>()
                    .sqrt()
                    / norm
            })
            .sum::<f64>()
            / 4.0;
        eprintln!("{n} samples per pixel: relative L2 error of Y {e:.4}");
        errors.push((n, e));
    }
    // Monte Carlo promises N^(−1/2); over 4 → 256 samples that is a factor of 8.
    let (first, last) = (errors[0].1, errors[3].1);
    let rate = (first / last).ln() / (256f64 / 4.0).ln();
    eprintln!("observed rate N^−{rate:.2}");
    assert!(rate > 0.4, "error falls as N^−{rate:.2}");
    assert_eq!(dev.validation_messages(), 0);
}
