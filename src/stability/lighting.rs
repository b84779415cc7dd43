//! The matrix's lighting cases: environment maps that are hard on an importance sampler, on
//! a flat patch whose lobe has a closed form ([`FlatLobe`]), drawn as environment-lit BRDF
//! maps on the device by every variant that can be lit by an environment, and checked
//! pixel by pixel against the f64 quadrature of the same lighting (a second method:
//! midpoint rule over `(u, v)` against Monte Carlo with multiple importance sampling).
//!
//! - **A sun hidden in an HDR map**: a clear sky with a 1° disc of irradiance 5 in it, 1024×512:
//!   nearly all of the map's power in a few dozen pixels.
//! - **A grazing environment**: light only within 20° above the horizon, seen from 75° to
//!   90° (the mirror directions at least 5° inside the band), where the gain and Fresnel
//!   change fastest and `(u, v)` compresses the most.
//! - **A black map with one pixel**: all the light in one pixel (2.8° wide) of a 128×64
//!   map, which the BRDF sampler almost never finds, placed where one view of the map
//!   mirrors into it.

use std::f64::consts::PI;
use std::sync::Arc;

use super::Status;
use crate::brdf::env_reference::{env_radiance_converged, FlatLobe, Frame, Quadrature};
use crate::brdf::table::{Region, TableSpec};
use crate::brdf::Shading;
use crate::colour::ColourTable;
use crate::heightfield::HeightField;
use crate::light::env::{map_to_direction, sky, tabulate, EnvMap};
use crate::light::set::EnvLight;
use crate::render::env::{map_direction, render_env_brdf_map, EnvLighting, EnvMapRequest};
use crate::render::variant::VariantKind;
use crate::render::Renderer;
use crate::Result;

/// Samples per pixel of every case: the renderer's default.
pub const SAMPLES: u32 = 256;
/// Side of each case's BRDF map (pixels).
pub const MAP_SIZE: u32 = 16;
/// A lit pixel (reference `Y` at least [`LIT`] of the case's brightest) passes within this
/// relative error of `Y`.
pub const BOUND: f64 = 0.05;
/// Pixels darker than this share of the case's brightest are judged by their absolute error
/// relative to the brightest, against the same bound.
pub const LIT: f64 = 0.01;

/// One lighting case.
#[derive(Debug, Clone, PartialEq)]
pub struct LightingCell {
    pub case: &'static str,
    /// The variant that drew it.
    pub variant: &'static str,
    /// Pixels compared, and how many of them are lit.
    pub pixels: usize,
    pub lit: usize,
    /// Worst `|ΔY|/Y` over the lit pixels.
    pub worst_lit: f64,
    /// Worst `|ΔY|/Y_max` over the dark pixels.
    pub worst_dark: f64,
    /// The reference's own worst error (its spacing against half that).
    pub quadrature: f64,
    pub status: Status,
    pub message: String,
}

/// Which views (tangent-space `ωr`) of its BRDF map a case is judged at.
type Judged = fn([f64; 3]) -> bool;

/// The cases' maps and the views each one is judged at.
fn cases() -> Vec<(&'static str, EnvMap, Judged)> {
    vec![
        ("sun hidden in an HDR map", sun_in_sky(), |wr| wr[2] >= 0.2),
        ("grazing environment", horizon_band(), |wr| wr[2] <= 0.26),
        ("black map with one pixel", one_pixel(), |_| true),
    ]
}

/// The built-in sky with a sun of 1° diameter and irradiance 5, 40° above the horizon.
fn sun_in_sky() -> EnvMap {
    let sun = map_to_direction(0.55, 50.0 / 180.0);
    let radius = 0.5f64.to_radians();
    let radiance = 5.0 / (2.0 * PI * (1.0 - radius.cos()));
    let px = tabulate(1024, 512, |d| {
        let c = d[0] * sun[0] + d[1] * sun[1] + d[2] * sun[2];
        if c >= radius.cos() {
            [radiance; 3]
        } else {
            sky(d)
        }
    });
    EnvMap::from_pixels(1024, 512, px, "sky with a sun").expect("finite map")
}

/// Radiance 1 within 20° above the horizon, black elsewhere.
fn horizon_band() -> EnvMap {
    let px = tabulate(512, 256, |d| {
        if d[1] >= 0.0 && d[1] < 20f64.to_radians().sin() {
            [1.0; 3]
        } else {
            [0.0; 3]
        }
    });
    EnvMap::from_pixels(512, 256, px, "horizon band").expect("finite map")
}

/// A black 128×64 map with one pixel of radiance 100: the one that the view of the BRDF
/// map's pixel (10, 6) mirrors into.
fn one_pixel() -> EnvMap {
    let (w, h) = (128, 64);
    let mut map = EnvMap::from_pixels(w, h, vec![[0.0f32; 3]; (w * h) as usize], "one pixel")
        .expect("finite map");
    let wr = map_direction(10, 6, MAP_SIZE).expect("inside the map");
    let (c, r) = map.pixel_of(Frame::BRDF_MAP.to_world([-wr[0], -wr[1], wr[2]]));
    map.radiance[(r * w + c) as usize] = [100.0; 3];
    map
}

/// Draws and checks every case with every variant that can be lit by an environment, on
/// `r`'s device (the default variant first).
pub fn run(r: &mut Renderer) -> Result<Vec<LightingCell>> {
    let coherence = crate::material::DEFAULT_COHERENCE_UM;
    let shading = Shading::default();
    // A flat patch: its lobe lies within 0.04 of (u, v) = 0 for every view. Sampled at
    // 90 nm, so that the discrete spectrum's first alias (at u = λ/dH) lies beyond every
    // reachable |u| ≤ 2 at 380 nm: the variants that evaluate the DFT terms wherever a
    // direction falls (flss) see the lobe alone, as the tables over the lobe's region do.
    let n = 256;
    let hf = HeightField::new(n, n, 0.09, vec![0.0; n * n])?;
    let spec = TableSpec {
        region: Region {
            lo: [-0.04, -0.04, -2.0],
            hi: [0.04, 0.04, -0.01],
        },
        texel_uv: 0.001,
        w_nodes: 4,
        step_nm: 10,
        response: crate::brdf::table::Response::Relative,
    };
    let lighting = EnvLighting::build(&hf, coherence, &shading, &spec)?;
    let lobe = FlatLobe::new(&ColourTable::new(spec.step_nm)?, coherence, &shading);
    let g = |uvw: [f64; 3]| lobe.g(uvw);
    let material = crate::material::Material {
        lambda_step_nm: spec.step_nm,
        coherence_um: coherence,
        ..crate::material::Material::default()
    };
    let prepared = material.prepare_anywhere(hf.clone(), None, &crate::report::Stderr)?;
    // A variant that refuses the flat patch (nmm and pq find no period in it) is a
    // refused cell per case, with its reason.
    let mut brdfs = Vec::new();
    for kind in lit_variants() {
        let brdf = match kind {
            VariantKind::ChebyshevW => Ok(None),
            k => {
                r.set_variant(k);
                r.env_brdf(&prepared, &lighting, &shading)
                    .map(Some)
                    .map_err(|e| e.to_string())
            }
        };
        brdfs.push((kind.name(), brdf));
    }
    let dev = Arc::clone(r.device());
    let mut out = Vec::new();
    for (case, env, judged) in cases() {
        // The reference once per case, then every variant's map against it.
        let mut want = Vec::new();
        for j in 0..MAP_SIZE {
            for i in 0..MAP_SIZE {
                let Some(wr) = map_direction(i, j, MAP_SIZE).filter(|&wr| judged(wr)) else {
                    continue;
                };
                let q = Quadrature::around(0.0, 0.0, 0.04, 0.001);
                let (xyz, quad) = env_radiance_converged(
                    &EnvLight::new(&env),
                    &Frame::BRDF_MAP,
                    wr,
                    &shading,
                    &g,
                    &q,
                );
                want.push(((j * MAP_SIZE + i) as usize, xyz, quad));
            }
        }
        for (variant, brdf) in &brdfs {
            let brdf = match brdf {
                Ok(b) => b,
                Err(e) => {
                    out.push(LightingCell {
                        case,
                        variant,
                        pixels: 0,
                        lit: 0,
                        worst_lit: 0.0,
                        worst_dark: 0.0,
                        quadrature: 0.0,
                        status: Status::Refused,
                        message: e.clone(),
                    });
                    continue;
                }
            };
            let req = EnvMapRequest {
                env: &env,
                shading,
                samples: SAMPLES,
                size: MAP_SIZE,
                sun: None,
                seed: 0,
                brdf: brdf.as_ref(),
                per_dispatch: None,
            };
            let pic = render_env_brdf_map(&dev, &lighting, &req)?;
            let rows: Vec<_> = want
                .iter()
                .map(|&(p, xyz, quad)| (pic.xyz[p].map(f64::from), xyz, quad))
                .collect();
            out.push(judge(case, variant, &rows));
        }
    }
    Ok(out)
}

/// Every variant that can be lit by an environment, the default first.
pub fn lit_variants() -> Vec<VariantKind> {
    crate::render::env_brdf::lightable(&VariantKind::ALL)
}

/// The verdict of a case from `(device, reference, quadrature error)` per pixel.
fn judge(
    case: &'static str,
    variant: &'static str,
    rows: &[([f64; 3], [f64; 3], f64)],
) -> LightingCell {
    let y_max = rows.iter().fold(0.0f64, |m, r| m.max(r.1[1]));
    let (mut worst_lit, mut worst_dark, mut quadrature) = (0.0f64, 0.0f64, 0.0f64);
    let (mut bad, mut lit) = (0, 0);
    for (got, want, quad) in rows {
        if got.iter().any(|c| !c.is_finite() || *c < 0.0) {
            bad += 1;
            continue;
        }
        if want[1] > 0.0 && want[1] >= LIT * y_max {
            lit += 1;
            worst_lit = worst_lit.max((got[1] - want[1]).abs() / want[1]);
            quadrature = quadrature.max(*quad);
        } else {
            worst_dark = worst_dark.max((got[1] - want[1]).abs() / y_max.max(1e-300));
        }
    }
    let status = if bad == 0 && lit > 0 && worst_lit <= BOUND && worst_dark <= BOUND {
        Status::Pass
    } else {
        Status::Fail
    };
    LightingCell {
        case,
        variant,
        pixels: rows.len(),
        lit,
        worst_lit,
        worst_dark,
        quadrature,
        status,
        message: if bad > 0 {
            format!("{bad} pixel(s) not finite or negative")
        } else {
            String::new()
        },
    }
}

/// The Markdown section.
pub fn to_markdown(cells: &[LightingCell]) -> String {
    let mut s = format!(
        "\n## Lighting\n\nEnvironment-lit BRDF maps ({MAP_SIZE}², {SAMPLES} samples per pixel) \
         of a flat patch against the f64 quadrature of the same lighting with the lobe's \
         closed form. A lit pixel (reference Y ≥ {LIT} of the brightest) passes within \
         {:.0} % of its Y, a dark one within {:.0} % of the brightest; every pixel must be \
         finite and ≥ 0. Every variant that can be lit by an environment draws every case \
         through its own shader.\n\n| case | variant | pixels (lit) | worst ΔY/Y, lit | \
         worst ΔY/Y_max, dark | quadrature error | status |\n|---|---|---|---|---|---|---|\n",
        100.0 * BOUND,
        100.0 * BOUND
    );
    for c in cells {
        s += &format!(
            "| {} | {} | {} ({}) | {:.2e} | {:.2e} | {:.1e} | {}{} |\n",
            c.case,
            c.variant,
            c.pixels,
            c.lit,
            c.worst_lit,
            c.worst_dark,
            c.quadrature,
            c.status,
            if c.message.is_empty() {
                String::new()
            } else {
                format!(": {}", c.message)
            }
        );
    }
    s
}

/// One line per case for stdout.
pub fn summary(cells: &[LightingCell]) -> Vec<String> {
    cells
        .iter()
        .map(|c| {
            format!(
                "lighting, {}, {}: {} over {} pixels ({} lit); worst ΔY/Y {:.1e} lit, {:.1e} of the brightest dark (bound {BOUND})",
                c.case, c.variant, c.status, c.pixels, c.lit, c.worst_lit, c.worst_dark
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_verdict_fails_noise_past_the_bound_and_bad_numbers() {
        let want = [0.5, 1.0, 0.8];
        let near = [0.5, 1.0 + 0.5 * BOUND, 0.8];
        let far = [0.5, 1.0 + 2.0 * BOUND, 0.8];
        let dark = [0.0, 0.0, 0.0];
        assert_eq!(
            judge("ok", "v", &[(near, want, 0.0), (dark, dark, 0.0)]).status,
            Status::Pass
        );
        let c = judge("ok", "v", &[(near, want, 0.0), (dark, dark, 0.0)]);
        assert_eq!((c.pixels, c.lit), (2, 1));
        assert_eq!(judge("far", "v", &[(far, want, 0.0)]).status, Status::Fail);
        // A dark pixel lit by the device beyond the bound of the brightest.
        let glow = [0.0, 2.0 * BOUND, 0.0];
        assert_eq!(
            judge("glow", "v", &[(want, want, 0.0), (glow, dark, 0.0)]).status,
            Status::Fail
        );
        for bad in [f64::NAN, f64::INFINITY, -1e-3] {
            let c = judge(
                "bad",
                "v",
                &[(want, want, 0.0), ([0.0, bad, 0.0], dark, 0.0)],
            );
            assert_eq!(c.status, Status::Fail, "{bad}");
            assert!(c.message.contains("not finite or negative"));
        }
        // Nothing lit: nothing was checked.
        assert_eq!(
            judge("black", "v", &[(dark, dark, 0.0)]).status,
            Status::Fail
        );
    }

    #[test]
    fn the_one_pixel_lies_where_its_view_mirrors() {
        let map = one_pixel();
        let lit: Vec<usize> = (0..map.radiance.len())
            .filter(|&i| map.radiance[i][1] > 0.0)
            .collect();
        assert_eq!(lit.len(), 1);
        let wr = map_direction(10, 6, MAP_SIZE).unwrap();
        let d = Frame::BRDF_MAP.to_world([-wr[0], -wr[1], wr[2]]);
        assert!(map.radiance(d)[1] == 100.0);
        // The sun's pixels hold 5 of its map's power, more than the whole sky.
        let total = sun_in_sky().integral()[1];
        let sky = EnvMap::from_pixels(1024, 512, tabulate(1024, 512, sky), "sky").unwrap();
        let sun = total - sky.integral()[1];
        assert!(
            (sun - 5.0).abs() < 0.5 && sun > 0.5 * total,
            "sun {sun} of {total}"
        );
    }
}
