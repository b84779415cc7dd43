//! Whole-picture rows (`profile --picture`): what a user sees, scored. A scene is drawn by
//! each row's variant at each anti-aliasing mode (`N×N` samples a pixel, box-filtered, as
//! `[output] supersample` draws them) and compared with the same scene drawn by the
//! default variant at [`REFERENCE_SS`]² samples a pixel. The error of a picture is mostly
//! what a pixel's footprint leaves out (the lobes are 0.005 wide in `(u, v)`, a pixel of a
//! curved scale spans many), which the BRDF-map rows, one direction a pixel, cannot show.
//!
//! Scores, as graphics engineers compare renders, over the scene's pixels (those whose
//! reference is not the background): the relative L2 of the linear picture (exposed,
//! before the tone curve, every channel), CIEDE2000 (mean, p95, p99) and ꟻLIP (NVIDIA's
//! image-difference evaluator, LDR, at its default 67 pixels a degree; the `nv-flip`
//! crate) of the pictures as written (tone-mapped, 8-bit sRGB). The reference states its
//! own convergence: the same scores of its picture at half the rate against it.

use std::path::{Path, PathBuf};

use crate::brdf::table::MAX_LEVELS;
use crate::colour::{delta_e2000, linear_srgb_to_xyz, linear_to_srgb8, xyz_to_lab};
use crate::material::{Material, PreparedMaterial};
use crate::render::{Renderer, SceneInputs, TableOptions, VariantKind};
use crate::scene::Scene;
use crate::Result;

use super::plan::Variant;

/// Anti-aliasing modes of the picture rows unless `--picture-aa` says otherwise.
pub const DEFAULT_AA: [u32; 4] = [1, 2, 3, 4];
/// Samples a pixel (per side) of the reference picture unless `--picture-reference-ss`.
pub const REFERENCE_SS: u32 = 16;
/// Side of the pictures unless `--picture-size` says otherwise: the size CI renders at.
pub const DEFAULT_SIZE: u32 = 128;

/// What the picture rows draw.
#[derive(Debug, Clone)]
pub struct PictureSetup {
    pub scene: Scene,
    /// What the scene is, for the table's line: "the default scene" or its file.
    pub label: String,
    /// Samples a pixel per side of each row's pictures.
    pub aa: Vec<u32>,
    /// Samples a pixel per side of the reference.
    pub reference_ss: u32,
    /// Where each row's ꟻLIP error map (magma) and picture, and the reference, are written
    /// as PNG, when asked.
    pub error_maps: Option<PathBuf>,
}

/// A picture against the reference.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PictureError {
    pub rel_l2: f64,
    pub de_mean: f64,
    pub de_p95: f64,
    pub de_p99: f64,
    pub flip_mean: f64,
}

/// One row: a variant's picture at one anti-aliasing mode.
#[derive(Debug, Clone, PartialEq)]
pub struct PictureRow {
    /// The profile row's name and the mode: `chebyshev-w 2×2`.
    pub name: String,
    pub kind: VariantKind,
    pub aa: u32,
    /// Median GPU time of the draw (all `aa²` samples a pixel).
    pub gpu_ms: Option<f64>,
    pub error: PictureError,
}

/// The picture rows of a profile.
#[derive(Debug, Clone, PartialEq)]
pub struct PictureRun {
    /// The scene ([`PictureSetup::label`]).
    pub label: String,
    /// The height field of the material it is drawn with.
    pub surface: String,
    pub width: u32,
    pub height: u32,
    pub reference_ss: u32,
    pub reference_gpu_ms: Option<f64>,
    /// The reference at half its rate against itself: how far it is from converged.
    pub convergence: PictureError,
    /// Pixels scored (the scene's).
    pub pixels: usize,
    pub rows: Vec<PictureRow>,
    /// Rows that could not be drawn, with why.
    pub skipped: Vec<(String, String)>,
}

/// A picture as scored: linear (exposed), the same tone-mapped and clamped, and as 8-bit
/// sRGB bytes.
struct Drawn {
    linear: Vec<[f32; 3]>,
    toned: Vec<[f64; 3]>,
    srgb: Vec<u8>,
    gpu_ms: Option<f64>,
}

/// `scene` drawn at `ss²` samples a pixel: a first draw (it pays the pipeline's first-use
/// work in the driver), then `frames` timed draws.
fn draw(
    r: &mut Renderer,
    scene: &Scene,
    inputs: &SceneInputs,
    prepared: &PreparedMaterial,
    ss: u32,
    frames: usize,
) -> Result<Drawn> {
    let mut s = scene.clone();
    s.output.supersample = ss;
    let mut last = r.render_output(&s, Some(inputs), prepared, false)?;
    let mut times = Vec::new();
    for _ in 0..frames {
        last = r.render_output(&s, Some(inputs), prepared, false)?;
        times.extend(last.gpu_ms);
    }
    let mut toned = last.rgb.clone();
    crate::image_io::apply_tone(&mut toned, 1.0, s.output.tone, s.output.white)?;
    let toned: Vec<[f64; 3]> = toned
        .iter()
        .map(|p| p.map(|c| f64::from(c).clamp(0.0, 1.0)))
        .collect();
    let srgb = toned
        .iter()
        .flat_map(|&p| linear_to_srgb8(p, 1.0))
        .collect();
    Ok(Drawn {
        linear: last.rgb,
        toned,
        srgb,
        gpu_ms: crate::render::median(times),
    })
}

/// `test` against `reference` over `mask`'s pixels; the ꟻLIP error map as a side result.
fn score(
    reference: &Drawn,
    test: &Drawn,
    mask: &[bool],
    (w, h): (u32, u32),
) -> (PictureError, nv_flip::FlipImageFloat) {
    let (mut d2, mut r2) = (0.0f64, 0.0f64);
    let mut de = Vec::new();
    for (i, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
        for c in 0..3 {
            let (a, b) = (
                f64::from(test.linear[i][c]),
                f64::from(reference.linear[i][c]),
            );
            d2 += (a - b) * (a - b);
            r2 += b * b;
        }
        let lab = |p: [f64; 3]| xyz_to_lab(linear_srgb_to_xyz(p));
        de.push(delta_e2000(lab(test.toned[i]), lab(reference.toned[i])));
    }
    let map = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, &reference.srgb),
        nv_flip::FlipImageRgb8::with_data(w, h, &test.srgb),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    let flip = map.to_vec();
    let n = de.len().max(1) as f64;
    let flip_mean = mask
        .iter()
        .zip(&flip)
        .filter(|(m, _)| **m)
        .map(|(_, &f)| f64::from(f))
        .sum::<f64>()
        / n;
    de.sort_by(f64::total_cmp);
    let at = |q: f64| de.get(((q * de.len() as f64) as usize).min(de.len().saturating_sub(1)));
    let error = PictureError {
        rel_l2: if r2 > 0.0 { (d2 / r2).sqrt() } else { 0.0 },
        de_mean: de.iter().sum::<f64>() / n,
        de_p95: at(0.95).copied().unwrap_or(0.0),
        de_p99: at(0.99).copied().unwrap_or(0.0),
        flip_mean,
    };
    (error, map)
}

/// `material` prepared as the profile's rows prepare it (the planner's words on stderr).
fn prepare(material: &Material, cache_dir: Option<&Path>) -> Result<PreparedMaterial> {
    let hf = material.load_heightfield(&crate::report::Stderr)?;
    material.prepare_anywhere(hf, cache_dir, &crate::report::Stderr)
}

/// Draws and scores the picture rows of `rows` (each at every mode of `setup.aa`) on `r`,
/// the scene's surface of `base` (`diffract profile` passes the scene's own material with
/// its material flags applied); the reference is the default variant with `render`'s table
/// options.
pub fn run(
    r: &mut Renderer,
    setup: &PictureSetup,
    rows: &[Variant],
    base: &Material,
    frames: usize,
    cache_dir: Option<&Path>,
) -> Result<PictureRun> {
    let scene = &setup.scene;
    let (w, h) = (scene.output.width, scene.output.height);
    let inputs = SceneInputs::load(scene, true)?;
    let prepared = prepare(base, cache_dir)?;
    r.set_variant(VariantKind::DEFAULT);
    // Unfiltered: at that rate the samples themselves average each pixel's footprint. With
    // every term and wavelength kept, so that the rows' error includes what they leave out.
    r.set_table_options(TableOptions {
        levels: 1,
        ..TableOptions::RENDER
    });
    r.set_leave_out(false);
    eprintln!(
        "profile: picture reference: {} at {}×{} samples a pixel",
        VariantKind::DEFAULT.resolve().name(),
        setup.reference_ss,
        setup.reference_ss
    );
    let reference = draw(r, scene, &inputs, &prepared, setup.reference_ss, 1)?;
    let half = draw(
        r,
        scene,
        &inputs,
        &prepared,
        (setup.reference_ss / 2).max(1),
        0,
    )?;
    let bg = scene.output.background;
    let mask: Vec<bool> = reference
        .linear
        .iter()
        .map(|p| (0..3).any(|c| (p[c] - bg[c]).abs() > 1e-6))
        .collect();
    let (convergence, _) = score(&reference, &half, &mask, (w, h));
    if let Some(dir) = &setup.error_maps {
        let file = dir.join("reference.png");
        crate::image_io::write_png_rgb8(&file, w, h, reference.srgb.clone())?;
    }
    let mut out = PictureRun {
        label: setup.label.clone(),
        surface: base.heightfield.clone(),
        width: w,
        height: h,
        reference_ss: setup.reference_ss,
        reference_gpu_ms: reference.gpu_ms,
        convergence,
        pixels: mask.iter().filter(|m| **m).count(),
        rows: Vec::new(),
        skipped: Vec::new(),
    };
    for row in rows {
        r.set_variant(row.kind);
        r.set_storage_format(row.storage);
        r.set_leave_out(row.leave_out);
        let prepared = match prepare(&row.material(base), cache_dir) {
            Ok(p) => p,
            Err(e) => {
                out.skipped.push((row.name.clone(), e.to_string()));
                continue;
            }
        };
        // Each mode as asked; a table that can be filtered to the pixel's footprint also
        // the other way, at the two smallest modes.
        let mut modes: Vec<(u32, usize)> =
            setup.aa.iter().map(|&a| (a, row.table.levels)).collect();
        if row.kind.resolve() == VariantKind::ChebyshevW {
            let other = if row.table.levels > 1 { 1 } else { MAX_LEVELS };
            modes.extend(setup.aa.iter().take(2).map(|&a| (a, other)));
        }
        for (aa, levels) in modes {
            r.set_table_options(TableOptions {
                format: row.table.format,
                step_nm: row.table.step_nm,
                levels,
                ..TableOptions::RENDER
            });
            let filters = row.kind.resolve() == VariantKind::ChebyshevW;
            let (filtered, by_default) = (filters && levels > 1, filters && row.table.levels > 1);
            let name = match (filtered, by_default) {
                (true, false) => format!("{} filtered {aa}×{aa}", row.name),
                (false, true) => format!("{} unfiltered {aa}×{aa}", row.name),
                _ => format!("{} {aa}×{aa}", row.name),
            };
            eprintln!("profile: picture {name}");
            let drawn = match draw(r, scene, &inputs, &prepared, aa, frames.max(1)) {
                Ok(d) => d,
                Err(e) => {
                    out.skipped.push((name, e.to_string()));
                    continue;
                }
            };
            let (error, map) = score(&reference, &drawn, &mask, (w, h));
            if let Some(dir) = &setup.error_maps {
                let file =
                    |what: &str| dir.join(format!("{what} {name}.png").replace([' ', '×'], "_"));
                let rgb = map.apply_color_lut(&nv_flip::magma_lut()).to_vec();
                crate::image_io::write_png_rgb8(&file("flip"), w, h, rgb)?;
                crate::image_io::write_png_rgb8(&file("picture"), w, h, drawn.srgb.clone())?;
            }
            out.rows.push(PictureRow {
                name,
                kind: row.kind,
                aa,
                gpu_ms: drawn.gpu_ms,
                error,
            });
        }
    }
    r.set_table_options(TableOptions::default());
    Ok(out)
}

impl PictureRun {
    /// The picture rows as a table: the reference and its convergence, then a row a line.
    pub fn table(&self) -> String {
        let c = &self.convergence;
        let mut s = format!(
            "\nwhole picture: {} at {}×{}, its surface {} ({} of its pixels scored) against the same drawn by {} at {}×{} samples a pixel (GPU {}); the reference at half that rate is off by rel-L2 {:.2e}, ΔE2000 p99 {:.2}, ꟻLIP {:.4}\n",
            self.label,
            self.width,
            self.height,
            self.surface,
            self.pixels,
            VariantKind::DEFAULT.resolve().name(),
            self.reference_ss,
            self.reference_ss,
            self.reference_gpu_ms
                .map_or("untimed".to_string(), |t| format!("{t:.1} ms")),
            c.rel_l2,
            c.de_p99,
            c.flip_mean
        );
        s.push_str(&format!(
            "{:<28} {:>10} {:>9} {:>8} {:>8} {:>8} {:>8}\n",
            "picture", "GPU ms", "rel-L2", "ΔE mean", "ΔE p95", "ΔE p99", "ꟻLIP"
        ));
        for r in &self.rows {
            let e = &r.error;
            s.push_str(&format!(
                "{:<28} {:>10} {:>9.3} {:>8.3} {:>8.2} {:>8.2} {:>8.4}\n",
                r.name,
                r.gpu_ms.map_or("-".to_string(), |t| format!("{t:.2}")),
                e.rel_l2,
                e.de_mean,
                e.de_p95,
                e.de_p99,
                e.flip_mean
            ));
        }
        for (name, why) in &self.skipped {
            s.push_str(&format!("{name:<28} skipped: {why}\n"));
        }
        s
    }

    /// The picture rows' CSV lines, in the columns of [`super::format_csv`]: `picture` as
    /// their kind, the reference in their detail, the mode, ꟻLIP and ΔE2000 p95 in the
    /// last three columns.
    pub fn csv(&self) -> String {
        let detail = format!(
            "against {} at {}×{} samples a pixel; {}×{}",
            VariantKind::DEFAULT.resolve().name(),
            self.reference_ss,
            self.reference_ss,
            self.width,
            self.height
        );
        let mut csv = String::new();
        for r in &self.rows {
            let e = &r.error;
            let mut c = vec![String::new(); 42];
            c[0] = r.name.clone();
            c[6] = r.gpu_ms.map_or(String::new(), |t| t.to_string());
            c[8] = e.rel_l2.to_string();
            c[10] = e.de_mean.to_string();
            c[13] = "picture".into();
            c[14] = detail.clone();
            c[20] = e.de_p99.to_string();
            c[36] = "false".into();
            c[39] = r.aa.to_string();
            c[40] = e.flip_mean.to_string();
            c[41] = e.de_p95.to_string();
            csv.push_str(&(c.join(",") + "\n"));
        }
        for (name, why) in &self.skipped {
            let mut c = vec![String::new(); 42];
            c[0] = name.clone();
            c[13] = "picture".into();
            c[14] = why.replace(',', ";");
            c[36] = "true".into();
            csv.push_str(&(c.join(",") + "\n"));
        }
        csv
    }
}
