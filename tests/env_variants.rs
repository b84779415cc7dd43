//! Every variant under an environment (lavapipe, validation on): each variant that draws a
//! BRDF draws an environment-lit BRDF map through its own shader, in the same radiance
//! units as every other, and differs from `flss`'s map (the variant exact to its own
//! terms, window and step) with the same samples by no more than it differs from `flss`
//! under the sun; a debug view is refused with the reason.

mod gpu_util;

use diffract::brdf::table::{Region, Response, TableSpec};
use diffract::heightfield::HeightField;
use diffract::light::env::{EnvMap, EnvSource};
use diffract::material::Material;
use diffract::render::env::{render_env_brdf_map, EnvLighting, EnvMapRequest};
use diffract::render::variant::{Family, TableOptions, VariantKind};
use gpu_util::*;

/// A 1.92 µm grating, 0.1 µm amplitude, twelve periods along x and constant along y on a
/// 23 µm patch, sampled finely enough (dH = 90 nm) that the spectrum holds every reachable
/// `|u| ≤ 2` at 380 nm: the DFT-term variants see no alias the tables do not.
fn material(dir: &std::path::Path) -> Material {
    let n = 256usize;
    let dh = 0.09;
    let period = n as f64 * dh / 12.0;
    let h: Vec<f64> = (0..n * n)
        .map(|p| {
            let x = (p % n) as f64 * dh;
            0.1 * (1.0 + (2.0 * std::f64::consts::PI * x / period).sin())
        })
        .collect();
    let path = dir.join("grating.png");
    HeightField::new(n, n, dh, h).unwrap().save(&path).unwrap();
    Material {
        heightfield: path.to_string_lossy().into_owned(),
        lambda_step_nm: 10,
        ..Material::default()
    }
}

/// The environment table's region and spacing (what the map reaches, but grazing `w`).
fn spec() -> TableSpec {
    TableSpec {
        region: Region {
            lo: [-1.95, -0.03, -2.0],
            hi: [1.95, 0.03, -0.45],
        },
        texel_uv: 0.002,
        w_nodes: 16,
        step_nm: 10,
        response: Response::Relative,
    }
}

/// The environment-lit maps: every pixel integrates the sky, so a coarse map sees every
/// order.
const SIZE: u32 = 12;
const SAMPLES: u32 = 256;
/// The sun-lit maps: one direction a pixel, so the map must be fine enough that a row of
/// pixel centres lies inside the orders' lobes (0.005 wide in v, at v = 0 here).
const SUN_SIZE: u32 = 256;
/// The sun's directions: the sky lights the patch from every one.
const THETAS: [f64; 3] = [0.0, 40.0, 70.0];

/// Relative L2 of `a` against `b` over every channel.
fn rel_l2(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let (mut d, mut n) = (0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        for c in 0..3 {
            d += (x[c] - y[c]).powi(2);
            n += y[c] * y[c];
        }
    }
    (d / n).sqrt()
}

#[test]
fn every_variant_draws_under_an_environment_as_it_draws_under_the_sun() {
    let Some(mut r) = renderer() else { return };
    let dir = std::env::temp_dir().join(format!("diffract-env-variants-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let prepared = prepare(&material(&dir));
    let shading = prepared.shading;
    let lighting = EnvLighting::build(&prepared.heightfield, 65.0, &shading, &spec()).unwrap();
    let sky = EnvMap::load(&EnvSource::Sky, 1.0, 0.0).unwrap();
    r.set_table_options(TableOptions {
        texel_uv: Some(0.002),
        step_nm: Some(10),
        ..TableOptions::default()
    });
    let mut env_maps = Vec::new();
    let mut sun_maps = Vec::new();
    let kinds: Vec<VariantKind> = std::iter::once(VariantKind::ChebyshevW)
        .chain(
            VariantKind::ALL
                .into_iter()
                .filter(|k| *k != VariantKind::ChebyshevW),
        )
        .collect();
    for kind in kinds {
        r.set_variant(kind);
        let brdf = match r.env_brdf(&prepared, &lighting, &shading) {
            Ok(b) => b,
            Err(e) => {
                let msg = e.to_string();
                eprintln!("{kind}: refused: {msg}");
                assert_eq!(kind.family(), Family::Debug, "{kind} refused: {msg}");
                assert!(msg.contains("cannot be lit by an environment"), "{msg}");
                assert_eq!(msg.lines().count(), 1);
                continue;
            }
        };
        let pic = render_env_brdf_map(
            r.device(),
            &lighting,
            &EnvMapRequest {
                env: &sky,
                shading,
                samples: SAMPLES,
                size: SIZE,
                sun: None,
                seed: 0,
                brdf: Some(&brdf),
                per_dispatch: None,
            },
        )
        .unwrap_or_else(|e| panic!("{kind} under the sky: {e}"));
        assert_eq!(pic.dropped, 0, "{kind}: batches dropped");
        let inside = |s: u32| (0..s * s).filter(move |p| map_direction(p % s, p / s, s).is_some());
        let env: Vec<[f64; 3]> = inside(SIZE)
            .map(|p| pic.xyz[p as usize].map(f64::from))
            .collect();
        let sun: Vec<Vec<[f64; 3]>> = THETAS
            .iter()
            .map(|&theta| {
                let frame = r
                    .render_brdf_map(&prepared, theta, 0.0, SUN_SIZE, None)
                    .unwrap_or_else(|e| panic!("{kind} under the sun: {e}"));
                inside(SUN_SIZE)
                    .map(|p| frame.at(p % SUN_SIZE, p / SUN_SIZE).map(f64::from))
                    .collect()
            })
            .collect();
        env_maps.push((kind, env));
        sun_maps.push(sun);
    }
    let at = env_maps
        .iter()
        .position(|(k, _)| *k == VariantKind::Flss)
        .expect("flss drew");
    let (_, c_env) = &env_maps[at];
    let c_sun = &sun_maps[at];
    let y: f64 = c_env.iter().map(|p| p[1]).sum::<f64>() / c_env.len() as f64;
    assert!(y > 1e-3, "flss's map under the sky is lit: mean Y {y}");
    for (theta, map) in THETAS.iter().zip(c_sun) {
        let lit: f64 = map.iter().map(|p| p[1]).sum();
        assert!(lit > 0.0, "flss's map under the sun at {theta}° is lit");
    }
    for ((kind, env), sun) in env_maps.iter().zip(&sun_maps) {
        if *kind == VariantKind::Flss {
            continue;
        }
        // The variant's worst difference from flss over the sun's directions.
        let e_env = rel_l2(env, c_env);
        let e_sun = sun
            .iter()
            .zip(c_sun)
            .map(|(a, b)| rel_l2(a, b))
            .fold(0.0, f64::max);
        let mean: f64 = env.iter().map(|p| p[1]).sum::<f64>() / env.len() as f64;
        eprintln!(
            "{kind}: against flss, rel-L2 {e_env:.2e} under the sky, {e_sun:.2e} under the sun; mean Y under the sky {mean:.5} against {y:.5}"
        );
        // The same samples (the same directions, the same weights): what is left is the
        // variants' BRDFs, which differ under the sun by at most e_sun at 0°, 40° and 70°.
        assert!(
            e_env <= 2.0 * e_sun + 0.01,
            "{kind}: rel-L2 {e_env:e} under the sky against {e_sun:e} under the sun"
        );
    }
    assert_no_validation(&r);
    let _ = std::fs::remove_dir_all(dir);
}

/// What the samples per dispatch guard against, shown: llvmpipe ends every loop of a
/// shader invocation once its loops together have run 65 535 iterations
/// (`DeviceInfo::loop_iteration_limit`). One dispatch of 256 `flss` samples (about 7 000
/// iterations a sample here) passes it: every pixel takes fewer samples than asked, says
/// so in its count, and is exactly the mean of the samples it took (the sample the cut
/// fell in is left out). The default split takes every sample. A driver without the
/// limit takes every sample either way.
#[test]
fn a_dispatch_past_the_drivers_loop_limit_takes_fewer_samples_and_counts_them() {
    let Some(mut r) = renderer() else { return };
    let dir = std::env::temp_dir().join(format!("diffract-env-limit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let prepared = prepare(&material(&dir));
    let shading = prepared.shading;
    let lighting = EnvLighting::build(&prepared.heightfield, 65.0, &shading, &spec()).unwrap();
    let sky = EnvMap::load(&EnvSource::Sky, 1.0, 0.0).unwrap();
    r.set_variant(VariantKind::Flss);
    let brdf = r.env_brdf(&prepared, &lighting, &shading).unwrap();
    let size = 6;
    let draw = |per_dispatch, samples| {
        render_env_brdf_map(
            r.device(),
            &lighting,
            &EnvMapRequest {
                env: &sky,
                shading,
                samples,
                size,
                sun: None,
                seed: 0,
                brdf: Some(&brdf),
                per_dispatch,
            },
        )
        .unwrap()
    };
    let (split, whole) = (draw(None, SAMPLES), draw(Some(SAMPLES), SAMPLES));
    let inside: Vec<usize> = (0..size * size)
        .filter(|p| map_direction(p % size, p / size, size).is_some())
        .map(|p| p as usize)
        .collect();
    for &p in &inside {
        assert_eq!(
            split.taken[p], SAMPLES,
            "the default split takes every sample"
        );
    }
    let limited = r.device().info.loop_iteration_limit().is_some();
    let most = inside.iter().map(|&p| whole.taken[p]).max().unwrap();
    let least = inside.iter().map(|&p| whole.taken[p]).min().unwrap();
    eprintln!(
        "{}: one dispatch of {SAMPLES} flss samples took {least} to {most} a pixel",
        r.device_name()
    );
    if !limited {
        assert_eq!(least, SAMPLES);
        assert_no_validation(&r);
        return;
    }
    assert!(most < SAMPLES / 4, "llvmpipe's limit cut the loop: {most}");
    assert!(least > 0, "every pixel took a sample before the cut");
    // A cut pixel is the mean of the samples it took: the first `least` to `most` of the
    // sequence. Against the picture of the first `n` samples (n: `least` down to a
    // multiple of 8, so that the light samples fall where they fell in the cut run) it
    // differs by the last few samples only; against the whole picture by the noise of
    // the other ~220.
    let n = least / 8 * 8;
    let first = draw(None, n);
    let pick = |pic: &diffract::render::env::EnvPicture| -> Vec<[f64; 3]> {
        inside.iter().map(|&p| pic.xyz[p].map(f64::from)).collect()
    };
    let (to_first, to_all) = (
        rel_l2(&pick(&whole), &pick(&first)),
        rel_l2(&pick(&whole), &pick(&split)),
    );
    eprintln!("rel-L2 of the cut picture: {to_first:.3} to its first {n} samples' picture, {to_all:.3} to the whole one");
    assert!(to_first < to_all / 2.0);
    assert_no_validation(&r);
    let _ = std::fs::remove_dir_all(dir);
}
