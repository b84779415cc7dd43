//! The environment-lit rows of a profile (`profile --env SOURCE`): the environment-lit BRDF
//! map ([`crate::render::env`]) at several samples per pixel, each timed like the other rows
//! and scored at a few pixels against the f64 quadrature of the same environment
//! ([`env_radiance`], refined until it settles). The radiance table and its sampling density are built once
//! and shared by every row; so are the scored pixels and their reference. The rows are lit
//! by the environment alone: the sun adds the same noiseless term at every sample count.

use std::sync::Arc;
use std::time::{Duration, Instant};

use super::budget::{FrameTimes, Frames};
use super::output::{row_name, EnvRow, EnvRun, EnvSkipped};
use super::plan::EnvProfile;
use super::score::pick_pixels;
use super::stats::{bootstrap, error_stats};
use crate::brdf::env_reference::{env_radiance, Frame, Quadrature};
use crate::budget::{Cost, Fits, Keeper};
use crate::heightfield::HeightField;
use crate::light::set::EnvLight;
use crate::material::Material;
use crate::render::env::{render_env_brdf_map, EnvLighting, EnvMapRequest, EnvPicture};
use crate::render::env_brdf::EnvBrdf;
use crate::render::map_direction;
use crate::render::variant::VariantKind;
use crate::{Error, Result};

/// The fewest pixels the reference scores, whatever the budget.
const REFERENCE_MIN_PIXELS: usize = 4;
/// Share of the environment rows' time the reference may take (at least its fewest pixels).
const REFERENCE_SHARE: f64 = 0.4;

/// A variant's environment map costs `overhead + samples · per_sample`: the overhead its
/// wall time beyond its dispatches, the rest its GPU time per sample.
fn map_cost(wall_ms: f64, gpu_ms: f64, samples: u32) -> Cost {
    Cost {
        fixed_s: (wall_ms - gpu_ms).max(0.0) / 1e3,
        per_unit_s: gpu_ms / f64::from(samples.max(1)) / 1e3,
    }
}

/// Draws and scores the environment rows with `renderer`'s device: the table, the first
/// map, the reference, then per variant of `env` (its first map at 1 sample for its pace)
/// the rows by ascending samples; with a budget (`end`), a row whose estimate exceeds the
/// time left is skipped with it (the default variant's first row is always measured).
/// Every variant draws the same samples (the same sequence and densities), so their
/// rows differ by their BRDFs and the noise they share.
pub(super) fn env_rows(
    renderer: &mut crate::render::Renderer,
    hf: &HeightField,
    base: &Material,
    size: u32,
    frames: Frames,
    env: &EnvProfile,
    end: Option<Instant>,
) -> Result<EnvRun> {
    if env.samples.is_empty() || env.pixels == 0 || env.variants.is_empty() {
        return Err(Error::invalid(
            "env",
            "at least one sample count, one variant and one scored pixel are needed",
        ));
    }
    let dev = Arc::clone(renderer.device());
    let shading = base.shading();
    let lighting = EnvLighting::build(hf, base.coherence_um, &shading, &env.spec)?;
    let table = lighting.report_line(false);
    eprintln!("profile: {table}");
    let draw = |brdf: Option<&Arc<EnvBrdf>>, samples: u32| {
        let req = EnvMapRequest {
            env: &env.map,
            shading,
            samples,
            size,
            sun: None,
            seed: 0,
            brdf,
            per_dispatch: None,
        };
        let t = Instant::now();
        render_env_brdf_map(&dev, &lighting, &req).map(|p| (p, t.elapsed().as_secs_f64() * 1e3))
    };
    // chebyshev-w draws from the environment table itself: uploaded once for every row.
    let own = Arc::new(lighting.brdf(&dev, &shading)?);
    let (first, first_wall_ms) = draw(Some(&own), 1)?;
    let pixels = pick_pixels(&first.xyz, size, 0, env.pixels);
    let ref_end = end.map(|e| {
        let left = e.saturating_duration_since(Instant::now());
        Instant::now() + left.mul_f64(REFERENCE_SHARE)
    });
    let reference = reference(&lighting, env, &shading, size, &pixels, ref_end);
    let mut run = EnvRun {
        source: env.map.name.clone(),
        table,
        build_ms: lighting.build_ms,
        first_wall_ms,
        first_gpu_ms: first.gpu_ms,
        reference_ms: reference.ms,
        reference_h: reference.h,
        reference_error: reference.error,
        scored: reference.xyz.len(),
        asked: pixels.len(),
        rows: Vec::new(),
        skipped: Vec::new(),
    };
    let pixels = &pixels[..reference.xyz.len()];
    let rows_in_all = env.variants.len() * env.samples.len();
    let now = Instant::now();
    let mut keeper = Keeper::new(
        now,
        end.map(|e| e.saturating_duration_since(now).as_secs_f64()),
    );
    // A material the planner refuses refuses every variant but chebyshev-w, whose table
    // is the environment table itself.
    let prepared = prepared_for(base, hf, &env.variants).map_err(|e| e.to_string());
    for (v, &kind) in env.variants.iter().enumerate() {
        let name = kind.name().to_string();
        let skipped = |k: usize, reason: String, estimated_s: f64| EnvSkipped {
            variant: name.clone(),
            samples: env.samples[k],
            estimated_s,
            reason,
        };
        let built = match &prepared {
            Ok(Some(p)) if kind != VariantKind::ChebyshevW => {
                renderer.set_variant(kind);
                renderer
                    .env_brdf(p, &lighting, &shading)
                    .map(Some)
                    .map_err(|e| e.to_string())
            }
            Err(e) if kind != VariantKind::ChebyshevW => Err(e.clone()),
            _ => Ok(Some(Arc::clone(&own))),
        };
        let brdf = match built {
            Ok(b) => b,
            Err(e) => {
                let reason = format!("refused: {e}");
                eprintln!("profile: env {name}: {reason}");
                for k in 0..env.samples.len() {
                    run.skipped.push(skipped(k, reason.clone(), 0.0));
                }
                continue;
            }
        };
        let (pic, wall) = draw(brdf.as_ref(), 1)?;
        keeper.split(&kind, map_cost(wall, pic.gpu_ms, 1));
        for (k, &samples) in env.samples.iter().enumerate() {
            let est = keeper.estimate_s(&kind, f64::from(samples)).unwrap_or(0.0);
            // The default variant's first row is measured whatever its estimate.
            if let (Fits::No { left_s, .. }, false) = (keeper.fits(Some(est)), k == 0 && v == 0) {
                let reason =
                    format!("estimated {est:.1} s, over the {left_s:.1} s left of the budget");
                eprintln!("profile: {}: skipped, {reason}", row_name(&name, samples));
                run.skipped.push(skipped(k, reason, est));
                continue;
            }
            let left_s = keeper.left_s();
            let rows_left = (rows_in_all - v * env.samples.len() - k) as f64;
            let row_end = left_s.map(|l| Instant::now() + Duration::from_secs_f64(l / rows_left));
            let (times, walls, last) =
                timed(&|n| draw(brdf.as_ref(), n), samples, frames, row_end)?;
            let row = score(
                &last,
                &name,
                samples,
                pixels,
                &reference.xyz,
                &times,
                &walls,
            );
            keeper.split(&kind, map_cost(row.wall_ms, row.gpu_ms, samples));
            eprintln!(
                "profile: {}: {} frames, median {:.2} ms (wall {:.2} ms), rel L2 {:.2e} [{:.2e}, {:.2e}]",
                row.name(),
                row.frames,
                row.gpu_ms,
                row.wall_ms,
                row.vs_reference.rel_l2,
                row.intervals.rel_l2.lo,
                row.intervals.rel_l2.hi
            );
            run.rows.push(row);
        }
    }
    Ok(run)
}

/// The material the variants other than `chebyshev-w` are built from (`None` when no
/// other is drawn: `chebyshev-w` draws from the environment table itself).
fn prepared_for(
    base: &Material,
    hf: &HeightField,
    variants: &[VariantKind],
) -> Result<Option<crate::material::PreparedMaterial>> {
    if variants.iter().all(|&k| k == VariantKind::ChebyshevW) {
        return Ok(None);
    }
    base.prepare_anywhere(hf.clone(), None, &crate::report::Stderr)
        .map(Some)
}

/// A row's frames: a fixed count, or until the median is known to the budget's precision,
/// its frames are spent or the next would end past `end`. Returns the dispatch times, the
/// wall times and the last map.
fn timed(
    draw: &dyn Fn(u32) -> Result<(EnvPicture, f64)>,
    samples: u32,
    frames: Frames,
    end: Option<Instant>,
) -> Result<(FrameTimes, Vec<f64>, EnvPicture)> {
    let mut times = FrameTimes::default();
    let mut walls: Vec<f64> = Vec::new();
    let mut last = None;
    while frames.more(&times, walls.last().copied(), end) {
        let (pic, wall) = draw(samples)?;
        times.0.push(pic.gpu_ms);
        walls.push(wall);
        last = Some(pic);
    }
    let last = last.ok_or_else(|| Error::invalid("profile", "no timed frame"))?;
    Ok((times, walls, last))
}

/// The row of `samples` from its last map and its frame times.
fn score(
    last: &EnvPicture,
    variant: &str,
    samples: u32,
    pixels: &[(u32, u32)],
    reference: &[[f64; 3]],
    times: &FrameTimes,
    walls: &[f64],
) -> EnvRow {
    let got: Vec<[f64; 3]> = pixels
        .iter()
        .map(|&(i, j)| last.xyz[(j * last.size + i) as usize].map(f64::from))
        .collect();
    EnvRow {
        variant: variant.to_string(),
        samples,
        gpu_ms: times.median().unwrap_or(0.0),
        spread_ms: times.quantile(0.1).zip(times.quantile(0.9)),
        frames: walls.len(),
        wall_ms: crate::render::median(walls.to_vec()).unwrap_or(0.0),
        vs_reference: error_stats(&got, reference),
        intervals: bootstrap(&got, reference),
    }
}

/// The reference at the scored pixels.
struct Reference {
    xyz: Vec<[f64; 3]>,
    ms: f64,
    /// The finest cell side any pixel reached.
    h: f64,
    error: f64,
}

/// A pixel's quadrature is refined (its cell side halved) until two successive values
/// differ by less than this, relative to the pixel's Y, ...
const REFERENCE_TOLERANCE: f64 = 2e-3;
/// ... or the next would take more cells than this (about 3 s on a 2-core VM).
const REFERENCE_MAX_CELLS: f64 = 8.4e6;

/// The f64 quadrature of the same table and environment at `pixels`, in their order,
/// over each pixel's reachable disc ([`env_radiance`] at cell sides `h`, `h/2`, ... from
/// half a table texel, the table being a cubic spline over its texels: the value of the
/// finest, and the difference from the one before as its error); with `end`, it stops
/// past it once [`REFERENCE_MIN_PIXELS`] are done.
fn reference(
    lighting: &EnvLighting,
    env: &EnvProfile,
    shading: &crate::brdf::Shading,
    size: u32,
    pixels: &[(u32, u32)],
    end: Option<Instant>,
) -> Reference {
    let start = Instant::now();
    let g = |d: [f64; 3]| lighting.g(d).unwrap_or([0.0; 3]);
    let (mut xyz, mut diff) = (Vec::with_capacity(pixels.len()), 0.0f64);
    let mut finest = env.spec.texel_uv;
    for &(i, j) in pixels {
        if let Some(end) = end {
            let per_pixel = start.elapsed().as_secs_f64() / xyz.len().max(1) as f64;
            let next = Instant::now() + Duration::from_secs_f64(per_pixel);
            if xyz.len() >= REFERENCE_MIN_PIXELS && next > end {
                break;
            }
        }
        let wr = map_direction(i, j, size).unwrap_or([0.0, 0.0, 1.0]);
        let at = |h: f64| {
            env_radiance(
                &EnvLight::new(&env.map),
                &Frame::BRDF_MAP,
                wr,
                shading,
                &g,
                &Quadrature::reachable(wr, h),
            )
        };
        let mut h = env.spec.texel_uv / 2.0;
        let mut coarse = at(h);
        let (fine, d) = loop {
            h /= 2.0;
            let fine = at(h);
            let d = (0..3).fold(0.0f64, |m, k| m.max((fine[k] - coarse[k]).abs()));
            let cells = 4.0 / (h * h);
            if d <= REFERENCE_TOLERANCE * fine[1].abs() || cells > REFERENCE_MAX_CELLS {
                break (fine, d);
            }
            coarse = fine;
        };
        finest = finest.min(h);
        xyz.push(fine);
        diff = diff.max(d);
    }
    // Relative to the brightest scored pixel, as the rows' errors are scaled: a dark
    // pixel's own relative difference says little about the figures.
    let y_max = xyz.iter().fold(0.0f64, |m, v| m.max(v[1]));
    let error = if y_max > 0.0 { diff / y_max } else { diff };
    let ms = start.elapsed().as_secs_f64() * 1e3;
    eprintln!(
        "profile: f64 environment quadrature at {} of {} pixels (cells down to {finest:.5}, largest difference between the last two {error:.1e} of the brightest pixel's Y): {:.1} s",
        xyz.len(),
        pixels.len(),
        ms / 1e3
    );
    Reference {
        xyz,
        ms,
        h: finest,
        error,
    }
}
