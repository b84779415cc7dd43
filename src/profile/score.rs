//! What a row is scored against and how: the pixels picked on the first measured map with
//! the f64 reference (direct sum, 1 nm) at each, the per-pixel mesh reference of
//! `--per-vertex`, and a row's errors against them and against its own CPU model.

use std::time::Instant;

use super::budget::Frames;
use super::plan::{ProfileSetup, Variant};
use super::stats::{bootstrap, error_stats, ErrorIntervals, ErrorStats};
use crate::brdf::{direction, reference};
use crate::colour::{linear_srgb_to_xyz, ColourTable};
use crate::gpu::StorageFormat;
use crate::material::{Material, PreparedMaterial};
use crate::render::variant::CpuModel;
use crate::render::Picture;
use crate::render::{map_direction, Renderer, TableOptions, VariantKind};
use crate::scene::Scene;
use crate::spectrum::Expansion;
use crate::{Error, Result};

/// Scored pixels and the reference XYZ at each.
pub(super) type Samples = (Vec<(u32, u32)>, Vec<[f64; 3]>);

/// Share of the budget the reference may take, and the fewest pixels it scores.
const REFERENCE_SHARE: f64 = 0.4;
const REFERENCE_MIN_PIXELS: usize = 8;

/// The scored pixels, picked on `frame` (the first measured row's map), and the reference
/// XYZ at each; with a budget the reference takes at most its share of it, counted from
/// `start`. `say`: print what the reference took even when it took every pixel.
pub(super) fn reference_samples(
    setup: &ProfileSetup,
    prepared: &PreparedMaterial,
    frame: &Picture,
    table_1nm: &ColourTable,
    start: Instant,
    say: bool,
) -> Samples {
    let mut pixels = pick_pixels(&frame.rgb, setup.size, setup.brightest, setup.pixels);
    // With a budget the reference takes at most its share of it: pixels in the order
    // picked (any prefix holds bright and spread ones, spread over the disk), at least
    // REFERENCE_MIN_PIXELS.
    let limit = match setup.frames {
        Frames::Budget(b) => {
            Some(start + std::time::Duration::from_secs_f64(REFERENCE_SHARE * b.total_s))
        }
        Frames::Fixed(_) => None,
    };
    let bar = crate::progress::bar(pixels.len() as u64, "f64 reference at 1 nm");
    let started = Instant::now();
    let mut refs: Vec<[f64; 3]> = Vec::with_capacity(pixels.len());
    for chunk in pixels.chunks(4) {
        if let Some(limit) = limit {
            let per_pixel = started.elapsed().as_secs_f64() / refs.len().max(1) as f64;
            let next = std::time::Duration::from_secs_f64(per_pixel * chunk.len() as f64);
            if refs.len() >= REFERENCE_MIN_PIXELS && Instant::now() + next > limit {
                break;
            }
        }
        let wrs: Vec<[f64; 3]> = chunk.iter().map(|p| wr_of(setup, p)).collect();
        refs.extend(reference::xyz_many(
            &prepared.heightfield,
            prepared.material.coherence_um,
            &prepared.shading,
            table_1nm,
            direction(setup.theta_i_deg, setup.phi_i_deg),
            &wrs,
            &|| bar.inc(1),
        ));
    }
    bar.finish_and_clear();
    let asked = pixels.len();
    pixels.truncate(refs.len());
    if say || pixels.len() < asked {
        eprintln!(
            "profile: f64 reference at 1 nm at {} of {asked} pixels: {:.1} s",
            pixels.len(),
            started.elapsed().as_secs_f64()
        );
    }
    (pixels, refs)
}

/// What a row's scoring found.
pub(super) struct Scores {
    pub(super) vs_reference: ErrorStats,
    pub(super) intervals: ErrorIntervals,
    pub(super) vs_model: ErrorStats,
    pub(super) reference_dark: bool,
    pub(super) conditioning: Option<f64>,
    pub(super) overshoot: Option<f64>,
}

/// The map's errors at the scored pixels against the reference and against the row's
/// own CPU model, and what its table says about itself.
pub(super) fn score_map(
    renderer: &Renderer,
    setup: &ProfileSetup,
    prepared: &PreparedMaterial,
    material: &Material,
    frame: &Picture,
    (pixels, refs): &Samples,
) -> Result<Scores> {
    let gpu_xyz: Vec<[f64; 3]> = pixels
        .iter()
        .map(|&(i, j)| frame.at(i, j).map(f64::from))
        .collect();
    let wi = direction(setup.theta_i_deg, setup.phi_i_deg);
    // ωi as uploaded (float32), so the model sees what the shader saw.
    let wi32 = wi.map(|c| c as f32 as f64);
    let model: &dyn CpuModel = renderer.model().ok_or_else(|| {
        Error::invalid(
            "profile",
            format!("{} has no CPU model to score against", frame.variant.name),
        )
    })?;
    let colour = kept_colour(renderer, prepared);
    let modelled: Vec<[f64; 3]> = pixels
        .iter()
        .map(|p| model.xyz(prepared, &colour, wi32, wr_of(setup, p)))
        .collect::<Result<_>>()?;
    // Dark: every reference sample lies under the error the variants promise there,
    // the tolerance on ρ/C (relative to a mirror's specular value) times the gain C.
    let reference_dark = pixels.iter().zip(refs).all(|(p, r)| {
        let c = crate::brdf::gain(wi, wr_of(setup, p), &prepared.shading);
        c <= 0.0 || r[1] < material.tolerance * c
    });
    let table = model.table();
    Ok(Scores {
        vs_reference: error_stats(&gpu_xyz, refs),
        intervals: bootstrap(&gpu_xyz, refs),
        vs_model: error_stats(&gpu_xyz, &modelled),
        reference_dark,
        conditioning: table.and_then(|t| t.conditioning()),
        overshoot: table.map(|t| overshoot(t, setup, wi32)),
    })
}

/// `ωr` of map pixel `(i, j)`.
fn wr_of(setup: &ProfileSetup, &(i, j): &(u32, u32)) -> [f64; 3] {
    map_direction(i, j, setup.size).unwrap_or([0.0, 0.0, 1.0])
}

/// The material's colour table with the wavelengths the row left out at weight 0 (its
/// model integrates the kept ones only).
fn kept_colour(renderer: &Renderer, prepared: &PreparedMaterial) -> ColourTable {
    let mut c = prepared.colour.clone();
    if let Some(w) = renderer.left_out().and_then(|l| l.wavelengths) {
        if w.place == "per pixel" {
            for (l, wt) in c.lambdas_nm.iter().zip(c.weights.iter_mut()) {
                if !w.kept_nm.iter().any(|k| (k - l).abs() < 1e-9) {
                    *wt = [0.0; 3];
                }
            }
        }
    }
    c
}

/// The most negative `G` of `table`'s interpolant over the map before the clamp, relative
/// to the map's largest `G_Y`.
fn overshoot(table: &dyn crate::brdf::table::GTable, setup: &ProfileSetup, wi32: [f64; 3]) -> f64 {
    let (mut lowest, mut peak) = (0.0f64, 0.0f64);
    for k in 0..setup.size * setup.size {
        let Some(wr) = map_direction(k % setup.size, k / setup.size, setup.size) else {
            continue;
        };
        if let Some(g) = table.g_unclamped(crate::brdf::uvw(wi32, wr)) {
            peak = peak.max(g[1]);
            lowest = g.iter().fold(lowest, |m, x| m.min(*x));
        }
    }
    if peak > 0.0 {
        lowest / peak
    } else {
        0.0
    }
}

/// The mesh view of `scene` by [`VariantKind::REFERENCE`] per pixel at 1 nm, keeping
/// everything (on the map it matches the f64 direct sum to 9e-5 rel L2, README).
pub(super) fn mesh_reference(
    renderer: &mut Renderer,
    setup: &ProfileSetup,
    scene: &Scene,
) -> Result<Vec<[f64; 3]>> {
    let kind = VariantKind::REFERENCE;
    let reference = Variant {
        name: "mesh reference".into(),
        kind,
        expansion: Expansion::Taylor,
        terms: setup
            .variants
            .iter()
            .map(|v| v.terms)
            .max()
            .unwrap_or(30)
            .max(1),
        window_radius: 2,
        lambda_step_nm: 1,
        storage: StorageFormat::Rg32f,
        table: TableOptions::default(),
        leave_out: false,
    };
    renderer.set_leave_out(false);
    let prepared = reference
        .material(&setup.base)
        .prepare(setup.cache_dir.as_deref(), &crate::report::Stderr)?;
    renderer.set_variant(kind);
    renderer.set_storage_format(StorageFormat::Rg32f);
    renderer.set_per_vertex(false);
    let f = renderer.render_scene(scene, &prepared)?;
    Ok(f.rgb.iter().map(|c| c.map(f64::from)).collect())
}

/// A mesh view against the reference variant's mesh render (with `--per-vertex`).
pub(super) fn mesh_error(reference: &[[f64; 3]], rgb: &[[f32; 3]]) -> ErrorStats {
    let xyz: Vec<[f64; 3]> = rgb
        .iter()
        .map(|c| linear_srgb_to_xyz(c.map(f64::from)))
        .collect();
    let refs: Vec<[f64; 3]> = reference.iter().map(|c| linear_srgb_to_xyz(*c)).collect();
    error_stats(&xyz, &refs)
}

/// Pixels to score: the `bright` brightest of `map` and `spread` more spread evenly over the
/// rest of the disk, each at most once; in an order whose every prefix holds bright and
/// spread pixels in proportion, the spread ones spread over the disk.
pub(super) fn pick_pixels(
    map: &[[f32; 3]],
    size: u32,
    bright: usize,
    spread: usize,
) -> Vec<(u32, u32)> {
    let mut inside: Vec<(u32, u32, f32)> = (0..size * size)
        .filter_map(|k| {
            let (i, j) = (k % size, k / size);
            map_direction(i, j, size).map(|_| (i, j, map[k as usize][1]))
        })
        .collect();
    inside.sort_by(|a, b| b.2.total_cmp(&a.2));
    let bright = bright.min(inside.len());
    let brightest: Vec<(u32, u32)> = inside[..bright].iter().map(|p| (p.0, p.1)).collect();
    let rest = &inside[bright..];
    let spread = spread.min(rest.len());
    let mut order: Vec<(u32, u32)> = rest.iter().map(|p| (p.0, p.1)).collect();
    order.sort_unstable_by_key(|&(i, j)| (j, i));
    // Strided picks, visited in bit-reversed order: a prefix samples the whole disk.
    let bits = usize::BITS - spread.max(1).leading_zeros();
    let spread: Vec<(u32, u32)> = (0..1usize << bits)
        .map(|s| s.reverse_bits() >> (usize::BITS - bits))
        .filter(|&s| s < spread)
        .map(|s| order[s * order.len() / spread])
        .collect();
    let (nb, n) = (brightest.len(), brightest.len() + spread.len());
    let (mut b, mut s) = (
        brightest.into_iter().peekable(),
        spread.into_iter().peekable(),
    );
    let mut picked = Vec::with_capacity(n);
    let mut taken_bright = 0;
    for k in 0..n {
        let from_bright = match (b.peek().is_some(), s.peek().is_some()) {
            (true, true) => taken_bright * n < (k + 1) * nb,
            (bright_left, _) => bright_left,
        };
        if from_bright {
            picked.extend(b.next());
            taken_bright += 1;
        } else {
            picked.extend(s.next());
        }
    }
    picked
}

#[cfg(test)]
mod pick_tests {
    use super::*;

    #[test]
    fn every_prefix_of_the_picked_pixels_mixes_bright_and_spread_ones() {
        let size = 33;
        let map: Vec<[f32; 3]> = (0..size * size).map(|k| [0.0, k as f32, 0.0]).collect();
        let picked = pick_pixels(&map, size as u32, 8, 16);
        assert_eq!(picked.len(), 24);
        let mut unique = picked.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), 24, "each pixel once");
        // The brightest are the last rows of this map (its Y grows with the index).
        let bright = |p: &(u32, u32)| p.1 >= 28;
        let first: Vec<_> = picked[..6].to_vec();
        assert!(first.iter().any(bright) && first.iter().any(|p| !bright(p)));
        // The spread ones among the first six lie in both halves of the disk.
        let spread: Vec<_> = first.iter().filter(|p| !bright(p)).collect();
        assert!(spread.iter().any(|p| p.1 < 16) && spread.iter().any(|p| p.1 >= 16));
    }
}
