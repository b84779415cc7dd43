//! Error-versus-time profiling of shader variants (MODEL §6–7): every variant renders the
//! same BRDF map (and, optionally, a mesh view) on the GPU, is timed with GPU timestamps
//! (median of several frames after a warm-up frame that also builds its tables), and is
//! scored at sampled pixels against the f64 reference (direct sum, 1 nm) and against the f64
//! model of the same variant (FLSS in f64, or the f64 table with the GPU's interpolation),
//! which separates approximation error from float32 and driver error.
//!
//! Metrics per variant (MODEL §6): relative L2 of linear XYZ over the sampled pixels, max
//! |ΔY|, and CIEDE2000 (p50, p99, mean, max) of the colours after scaling so the brightest
//! reference sample has `Y = 1`.

use std::path::PathBuf;

use indicatif::{ProgressBar, ProgressStyle};

use crate::brdf::{direction, model, reference};
use crate::cli::cache::CacheArgs;
use crate::cli::gpu::TableArgs;
use crate::cli::material::MaterialArgs;
use crate::colour::{delta_e2000, linear_srgb_to_xyz, xyz_to_lab, ColourTable};
use crate::gpu::StorageFormat;
use crate::material::Material;
use crate::render::variant::{Family, Preset};
use crate::render::{map_direction, Renderer, TableOptions, VariantKind};
use crate::scene::Scene;
use crate::spectrum::Expansion;
use crate::{Error, Result};

/// One profiled configuration: a variant with its numerical choices (FLSS: the material's
/// expansion, `T`, `R`, `Δλ` and term storage; tables: their sampling options).
#[derive(Debug, Clone, PartialEq)]
pub struct Variant {
    pub name: String,
    pub kind: VariantKind,
    pub expansion: Expansion,
    pub terms: usize,
    pub window_radius: usize,
    pub lambda_step_nm: u32,
    pub storage: StorageFormat,
    pub table: TableOptions,
    /// Leave out what the map cannot need, as `render` does (wavelengths whose weight is
    /// under the tolerance, DFT texels outside the reached band); false: keep everything.
    pub leave_out: bool,
}

impl Variant {
    /// `base` with this variant's numerical choices (the DFT-term variants read them; the
    /// table variants read only the height field and coherence length).
    pub fn material(&self, base: &Material) -> Material {
        match self.kind.family() {
            Family::Terms => Material {
                expansion: self.expansion,
                terms: crate::material::Terms::Fixed(self.terms),
                window_radius: self.window_radius,
                lambda_step_nm: self.lambda_step_nm,
                ..base.clone()
            },
            Family::Table | Family::Debug => base.clone(),
        }
    }

    /// The row of `kind` for `preset`, with the profile's Taylor `terms` and `table` options.
    fn from_preset(kind: VariantKind, preset: &Preset, terms: usize, table: &TableOptions) -> Self {
        let table = TableOptions {
            step_nm: preset.table_step_nm.or(table.step_nm),
            format: preset.table_format.unwrap_or(table.format),
            ..*table
        };
        let name = if preset.label.is_empty() {
            kind.name().to_string()
        } else {
            preset.label.to_string()
        };
        match kind.family() {
            Family::Terms => Variant {
                name,
                kind,
                expansion: preset.expansion,
                terms: preset.terms(terms),
                window_radius: preset.window_radius,
                lambda_step_nm: preset.lambda_step_nm,
                storage: preset.storage,
                table,
                leave_out: preset.leave_out,
            },
            Family::Table | Family::Debug => Variant {
                name,
                kind,
                expansion: Expansion::Taylor,
                terms: 0,
                window_radius: 0,
                lambda_step_nm: table.step_nm.unwrap_or(TableOptions::DEFAULT_STEP_NM),
                storage: StorageFormat::Rg32f,
                table,
                leave_out: preset.leave_out,
            },
        }
    }
}

/// The rows of every registered variant of `family`, from the presets each declares.
fn rows_of(family: Family, terms: usize, table: &TableOptions) -> Vec<Variant> {
    VariantKind::ALL
        .into_iter()
        .filter(|k| k.family() == family)
        .flat_map(|k| {
            k.profile_presets()
                .iter()
                .map(move |p| Variant::from_preset(k, p, terms, table))
        })
        .collect()
}

/// The DFT-term set (flss, nmm, pq): the rows each variant declares, e.g. FLSS's thesis
/// setting (Taylor, R = 1), the default, larger R, Chebyshev, the compact storage formats,
/// and coarser and finer wavelength steps. `terms` is T of the Taylor rows; Chebyshev gets
/// about two thirds of it (it converges faster, README).
pub fn flss_variants(terms: usize) -> Vec<Variant> {
    rows_of(Family::Terms, terms, &TableOptions::default())
}

/// The pre-integrated set with `table` as the base options: each table variant at its
/// defaults, plus the extra rows each declares (`chebyshev-w` with its spectrum integrated
/// at 5 nm as FLSS samples it, `volume` in float16).
pub fn table_variants(table: &TableOptions) -> Vec<Variant> {
    rows_of(Family::Table, 0, table)
}

/// Every variant: [`flss_variants`] then [`table_variants`].
pub fn standard_variants(terms: usize) -> Vec<Variant> {
    let mut v = flss_variants(terms);
    v.extend(table_variants(&TableOptions::default()));
    v
}

/// Errors of one set of XYZ samples against another (MODEL §6).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorStats {
    /// `‖xyz − ref‖₂ / ‖ref‖₂` over all samples and channels.
    pub rel_l2: f64,
    /// Largest `|Y − Y_ref|`.
    pub max_abs_y: f64,
    /// Mean and largest CIEDE2000 after scaling by `1 / max Y_ref`.
    pub mean_de: f64,
    pub max_de: f64,
    /// Median and 99th percentile of the same CIEDE2000 values.
    pub p50_de: f64,
    pub p99_de: f64,
}

/// Compares `xyz` with `reference` sample by sample.
pub fn error_stats(xyz: &[[f64; 3]], reference: &[[f64; 3]]) -> ErrorStats {
    let y_max = reference.iter().map(|r| r[1]).fold(0.0, f64::max);
    let scale = if y_max > 0.0 { 1.0 / y_max } else { 1.0 };
    let (mut diff2, mut ref2, mut max_abs_y) = (0.0, 0.0, 0.0);
    let mut des = Vec::with_capacity(xyz.len());
    for (a, r) in xyz.iter().zip(reference) {
        for c in 0..3 {
            diff2 += (a[c] - r[c]).powi(2);
            ref2 += r[c] * r[c];
        }
        max_abs_y = f64::max(max_abs_y, (a[1] - r[1]).abs());
        let de = delta_e2000(
            xyz_to_lab(a.map(|v| (v * scale).max(0.0))),
            xyz_to_lab(r.map(|v| (v * scale).max(0.0))),
        );
        des.push(de);
    }
    let n = xyz.len().max(1) as f64;
    des.sort_by(f64::total_cmp);
    let pct = |p: f64| {
        if des.is_empty() {
            0.0
        } else {
            des[((p * (des.len() - 1) as f64).round() as usize).min(des.len() - 1)]
        }
    };
    ErrorStats {
        rel_l2: if ref2 > 0.0 {
            (diff2 / ref2).sqrt()
        } else {
            diff2.sqrt()
        },
        max_abs_y,
        mean_de: des.iter().sum::<f64>() / n,
        max_de: des.last().copied().unwrap_or(0.0),
        p50_de: pct(0.5),
        p99_de: pct(0.99),
    }
}

/// One row of the profile.
#[derive(Debug, Clone, PartialEq)]
pub struct VariantReport {
    pub variant: Variant,
    /// Median GPU time of the map frames after the warm-up (ms); `None` without timestamps.
    pub gpu_ms: Option<f64>,
    /// Median wall time of a map frame after the warm-up (ms), upload and readback included.
    pub wall_ms: f64,
    /// Building and uploading the variant's resources (ms): table build or term upload.
    pub build_ms: f64,
    /// GPU memory of the variant's resources (bytes).
    pub gpu_bytes: usize,
    /// Texel fetches per pixel.
    pub fetches: usize,
    /// The variant's own description of its settings.
    pub detail: String,
    /// Median GPU time of the mesh view (ms), when profiled.
    pub mesh_gpu_ms: Option<f64>,
    /// Condition number of the representation's sum, where float32 rounding limits it.
    pub conditioning: Option<f64>,
    /// Table variants: the most negative `G` (any channel) of the interpolant over the map
    /// before the clamp to `G ≥ 0`, relative to the map's largest `G_Y` (0: none).
    pub overshoot: Option<f64>,
    /// The reference is dark: every scored sample is below what the variants may err by
    /// there (the tolerance times the gain `C`: `ρ/C` under the tolerance of a mirror's
    /// specular value), so ratios to it measure noise and the table says `reference dark`.
    pub reference_dark: bool,
    /// GPU against the f64 reference.
    pub vs_reference: ErrorStats,
    /// GPU against the f64 model of the same variant (float32 and driver error only).
    pub vs_model: ErrorStats,
    /// With `--per-vertex`: the mesh view against the per-pixel FLSS 1 nm mesh reference.
    pub mesh_vs_reference: Option<ErrorStats>,
    /// A per-vertex row (thesis §1.5.1): only its mesh columns are measured (a BRDF map has
    /// no vertices; its map columns repeat the per-pixel variant's).
    pub per_vertex: bool,
}

/// What to profile.
#[derive(Debug, Clone)]
pub struct ProfileSetup {
    pub base: Material,
    pub variants: Vec<Variant>,
    pub theta_i_deg: f64,
    pub phi_i_deg: f64,
    /// BRDF map side in pixels.
    pub size: u32,
    /// Pixels scored, spread evenly over the disk (where errors in dark regions show).
    pub pixels: usize,
    /// Pixels scored among the brightest of the first variant's map (where diffraction is).
    pub brightest: usize,
    /// Frames per variant after a warm-up frame; the median is reported.
    pub frames: usize,
    /// A mesh view timed per variant (not scored), when given.
    pub mesh: Option<Scene>,
    /// Also evaluate the variants that have a per-vertex stage per vertex on the mesh view,
    /// and score every mesh view against a per-pixel FLSS 1 nm render of it.
    pub per_vertex: bool,
    pub cache_dir: Option<PathBuf>,
}

/// Scored pixels and the reference XYZ at each.
type Samples = (Vec<(u32, u32)>, Vec<[f64; 3]>);

/// Pixels to score: the `bright` brightest of `map` and `spread` more spread evenly over the
/// rest of the disk, each at most once.
fn pick_pixels(map: &[[f32; 3]], size: u32, bright: usize, spread: usize) -> Vec<(u32, u32)> {
    let mut inside: Vec<(u32, u32, f32)> = (0..size * size)
        .filter_map(|k| {
            let (i, j) = (k % size, k / size);
            map_direction(i, j, size).map(|_| (i, j, map[k as usize][1]))
        })
        .collect();
    inside.sort_by(|a, b| b.2.total_cmp(&a.2));
    let bright = bright.min(inside.len());
    let mut picked: Vec<(u32, u32)> = inside[..bright].iter().map(|p| (p.0, p.1)).collect();
    let rest = &inside[bright..];
    let spread = spread.min(rest.len());
    let mut order: Vec<(u32, u32)> = rest.iter().map(|p| (p.0, p.1)).collect();
    order.sort_unstable_by_key(|&(i, j)| (j, i));
    for s in 0..spread {
        picked.push(order[s * order.len() / spread]);
    }
    picked
}

fn bar(len: usize, msg: &str) -> ProgressBar {
    let b = ProgressBar::new(len as u64).with_message(msg.to_string());
    b.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} {eta} left")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    b
}

/// Renders and scores every variant. The reference (1 nm, direct sum) is computed once at
/// the sampled pixels, so its cost is `pixels × N² × 401` complex multiply-adds.
pub fn profile(renderer: &mut Renderer, setup: &ProfileSetup) -> Result<Vec<VariantReport>> {
    if setup.variants.is_empty() {
        return Err(Error::invalid("variants", "none to profile"));
    }
    if setup.pixels + setup.brightest == 0 || setup.frames == 0 {
        return Err(Error::invalid(
            "profile",
            "at least one scored pixel and one frame are needed",
        ));
    }
    let wi = direction(setup.theta_i_deg, setup.phi_i_deg);
    // ωi as uploaded (float32), so the models see what the shader saw.
    let wi32 = wi.map(|c| c as f32 as f64);
    let mut reports = Vec::with_capacity(setup.variants.len());
    // Scored pixels and their reference XYZ, fixed by the first variant's map.
    let mut samples: Option<Samples> = None;
    let table_1nm = ColourTable::new(1)?;
    renderer.set_keep_models(true);
    renderer.set_cache_dir(setup.cache_dir.clone());
    let progress = bar(setup.variants.len(), "profile");
    // The mesh view's reference for per-vertex: per-pixel FLSS at 1 nm (on the map it
    // matches the f64 direct sum to 9e-5 rel L2, README), rendered once.
    let mesh_reference: Option<Vec<[f64; 3]>> = match (&setup.mesh, setup.per_vertex) {
        (Some(scene), true) => {
            progress.set_message("profile: mesh reference (flss 1 nm, per pixel)");
            let reference = Variant {
                name: "mesh reference".into(),
                kind: VariantKind::Flss,
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
            renderer.set_variant(VariantKind::Flss);
            renderer.set_storage_format(StorageFormat::Rg32f);
            renderer.set_per_vertex(false);
            let f = renderer.render_scene(scene, &prepared)?;
            Some(f.rgb.iter().map(|c| c.map(f64::from)).collect())
        }
        _ => None,
    };
    let mesh_error = |rgb: &[[f32; 3]]| -> Option<ErrorStats> {
        let reference = mesh_reference.as_ref()?;
        let xyz: Vec<[f64; 3]> = rgb
            .iter()
            .map(|c| linear_srgb_to_xyz(c.map(f64::from)))
            .collect();
        let refs: Vec<[f64; 3]> = reference.iter().map(|c| linear_srgb_to_xyz(*c)).collect();
        Some(error_stats(&xyz, &refs))
    };
    for variant in &setup.variants {
        progress.set_message(format!("profile: {}", variant.name));
        let material = variant.material(&setup.base);
        let prepared = material.prepare(setup.cache_dir.as_deref(), &crate::report::Stderr)?;
        renderer.set_variant(variant.kind);
        renderer.set_storage_format(variant.storage);
        renderer.set_table_options(variant.table);
        renderer.set_leave_out(variant.leave_out);
        let map = |r: &mut Renderer| {
            r.render_brdf_map(
                &prepared,
                setup.theta_i_deg,
                setup.phi_i_deg,
                setup.size,
                None,
            )
        };
        // The warm-up frame builds (or uploads) the variant's resources. A variant that
        // refuses this material (nmm without a dominant period) is reported and skipped.
        let mut frame = match map(renderer) {
            Ok(f) => f,
            Err(e @ Error::Invalid { .. }) => {
                progress.suspend(|| eprintln!("warning: {} skipped: {e}", variant.name));
                progress.inc(1);
                continue;
            }
            Err(e) => return Err(e),
        };
        let (mut gpu, mut wall) = (Vec::new(), Vec::new());
        for _ in 0..setup.frames {
            frame = map(renderer)?;
            gpu.extend(frame.gpu_ms);
            wall.push(frame.wall_ms);
        }
        let (pixels, refs) = match &samples {
            Some(s) => s.clone(),
            None => {
                let pixels = pick_pixels(&frame.rgb, setup.size, setup.brightest, setup.pixels);
                let wrs: Vec<[f64; 3]> = pixels
                    .iter()
                    .map(|&(i, j)| map_direction(i, j, setup.size).unwrap_or([0.0, 0.0, 1.0]))
                    .collect();
                let rb = bar(wrs.len(), "f64 reference at 1 nm");
                let refs = reference::xyz_many(
                    &prepared.heightfield,
                    material.coherence_um,
                    &prepared.shading,
                    &table_1nm,
                    wi,
                    &wrs,
                    &|| rb.inc(1),
                );
                rb.finish_and_clear();
                samples = Some((pixels, refs));
                samples.clone().unwrap_or_default()
            }
        };
        let gpu_xyz: Vec<[f64; 3]> = pixels
            .iter()
            .map(|&(i, j)| frame.at(i, j).map(f64::from))
            .collect();
        let wr_of =
            |&(i, j): &(u32, u32)| map_direction(i, j, setup.size).unwrap_or([0.0, 0.0, 1.0]);
        let conditioning = renderer.table_model().and_then(|t| t.conditioning());
        let overshoot = renderer.table_model().map(|t| {
            let (mut lowest, mut peak) = (0.0f64, 0.0f64);
            for k in 0..setup.size * setup.size {
                let Some(wr) = map_direction(k % setup.size, k / setup.size, setup.size) else {
                    continue;
                };
                if let Some(g) = t.g_unclamped(crate::brdf::uvw(wi32, wr)) {
                    peak = peak.max(g[1]);
                    lowest = g.iter().fold(lowest, |m, x| m.min(*x));
                }
            }
            if peak > 0.0 {
                lowest / peak
            } else {
                0.0
            }
        });
        // Dark: every reference sample lies under the error the variants promise there,
        // the tolerance on ρ/C (relative to a mirror's specular value) times the gain C.
        let reference_dark = pixels.iter().zip(&refs).all(|(p, r)| {
            let c = crate::brdf::gain(wi, wr_of(p), &prepared.shading);
            c <= 0.0 || r[1] < material.tolerance * c
        });
        // The wavelengths the variant kept (leaving out): its model integrates those only.
        let colour = match renderer.left_out().and_then(|l| l.wavelengths) {
            Some(w) if w.place == "per pixel" => {
                let mut c = prepared.colour.clone();
                for (l, wt) in c.lambdas_nm.iter().zip(c.weights.iter_mut()) {
                    if !w.kept_nm.iter().any(|k| (k - l).abs() < 1e-9) {
                        *wt = [0.0; 3];
                    }
                }
                c
            }
            _ => prepared.colour.clone(),
        };
        let density = crate::brdf::nmm::Density::new();
        let periodicity = renderer.pq_periodicity();
        let modelled: Vec<[f64; 3]> =
            match (renderer.table_model(), renderer.nmm_grating(), periodicity) {
                (_, _, Some(g)) => pixels
                    .iter()
                    .map(|p| {
                        crate::brdf::pq::xyz(
                            &prepared.stack,
                            prepared.terms(),
                            &g,
                            &prepared.shading,
                            &colour,
                            wi32,
                            wr_of(p),
                            crate::brdf::pq::Form::Intensity,
                        )
                    })
                    .collect(),
                (Some(t), _, _) => pixels
                    .iter()
                    .map(|p| t.xyz(&prepared.shading, wi32, wr_of(p)))
                    .collect(),
                (None, Some(g), None) => pixels
                    .iter()
                    .map(|p| {
                        crate::brdf::nmm::xyz(
                            &prepared.stack,
                            prepared.terms(),
                            &prepared.window,
                            &prepared.shading,
                            &colour,
                            &g,
                            &density,
                            wi32,
                            wr_of(p),
                            true,
                        )
                    })
                    .collect(),
                (None, None, None) => pixels
                    .iter()
                    .map(|p| {
                        model::xyz(
                            &prepared.stack,
                            prepared.terms(),
                            &prepared.window,
                            &prepared.shading,
                            &colour,
                            wi32,
                            wr_of(p),
                        )
                    })
                    .collect(),
            };
        // The mesh view: timed per pixel, and per vertex where the variant has that stage.
        let mesh_view =
            |r: &mut Renderer, per_vertex: bool| -> Result<Option<(f64, Vec<[f32; 3]>)>> {
                let Some(scene) = &setup.mesh else {
                    return Ok(None);
                };
                r.set_per_vertex(per_vertex);
                let mut last = r.render_scene(scene, &prepared)?;
                let mut t = Vec::new();
                for _ in 0..setup.frames {
                    last = r.render_scene(scene, &prepared)?;
                    t.extend(last.gpu_ms);
                }
                r.set_per_vertex(false);
                Ok(crate::render::median(t).map(|ms| (ms, last.rgb)))
            };
        let mesh = mesh_view(renderer, false)?;
        let mesh_gpu_ms = mesh.as_ref().map(|m| m.0);
        let per_vertex_mesh = if setup.per_vertex && variant.kind.per_vertex_file().is_some() {
            mesh_view(renderer, true)?
        } else {
            None
        };
        let v = &frame.variant;
        if let Some((ms, rgb)) = &per_vertex_mesh {
            reports.push(VariantReport {
                variant: Variant {
                    name: format!("{} per-vertex", variant.name),
                    ..variant.clone()
                },
                gpu_ms: None,
                wall_ms: 0.0,
                build_ms: v.build_ms,
                gpu_bytes: v.gpu_bytes,
                fetches: v.fetches,
                detail: format!("{} per-vertex", v.name),
                mesh_gpu_ms: Some(*ms),
                conditioning: None,
                overshoot: None,
                reference_dark,
                vs_reference: error_stats(&gpu_xyz, &refs),
                vs_model: error_stats(&gpu_xyz, &modelled),
                mesh_vs_reference: mesh_error(rgb),
                per_vertex: true,
            });
        }
        reports.push(VariantReport {
            variant: variant.clone(),
            gpu_ms: crate::render::median(gpu),
            wall_ms: crate::render::median(wall).unwrap_or(frame.wall_ms),
            build_ms: v.build_ms,
            gpu_bytes: v.gpu_bytes,
            fetches: v.fetches,
            detail: match &v.table_build {
                Some(built) => format!("{}, table {built}", v.name),
                None => v.name.clone(),
            },
            mesh_gpu_ms,
            conditioning,
            overshoot,
            reference_dark,
            vs_reference: error_stats(&gpu_xyz, &refs),
            vs_model: error_stats(&gpu_xyz, &modelled),
            mesh_vs_reference: mesh.as_ref().and_then(|m| mesh_error(&m.1)),
            per_vertex: false,
        });
        if per_vertex_mesh.is_some() {
            // Per-pixel row first, its per-vertex row after it.
            let n = reports.len();
            reports.swap(n - 1, n - 2);
        }
        progress.inc(1);
    }
    progress.finish_and_clear();
    renderer.set_keep_models(false);
    renderer.set_leave_out(false);
    Ok(reports)
}

fn ms(v: Option<f64>) -> String {
    v.map_or("n/a".into(), |g| format!("{g:.2}"))
}

/// Formats the reports as a Markdown table.
pub fn format_table(device: &str, setup: &ProfileSetup, reports: &[VariantReport]) -> String {
    let mesh = setup.mesh.as_ref().map_or(String::new(), |s| {
        format!("; mesh view {}×{}", s.output.width, s.output.height)
    });
    let mut s = format!(
        "device: {device}; BRDF map {}² at θi = {}°, φi = {}°{mesh}; {} scored pixels ({} brightest + {} spread); GPU ms = median of {} frames after a warm-up; reference: f64 direct sum at 1 nm\n\n",
        setup.size,
        setup.theta_i_deg,
        setup.phi_i_deg,
        setup.brightest + setup.pixels,
        setup.brightest,
        setup.pixels,
        setup.frames
    );
    let mesh_scored = reports.iter().any(|r| r.mesh_vs_reference.is_some());
    if mesh_scored {
        s.push_str("Per-vertex rows (thesis §1.5.1) measure the mesh view only: `mesh GPU ms` evaluated per vertex, and the last two columns, the mesh view against a per-pixel FLSS 1 nm render of it (rel L2 of XYZ, ΔE2000 p99). A BRDF map has no vertices: their map columns are `—`.\n\n");
    }
    s.push_str("| variant | fetches/px | build ms | GPU MB | GPU ms | mesh GPU ms | rel L2 vs ref | max ΔY vs ref | ΔE p50 | ΔE p99 | max ΔE | rel L2 vs f64 model |");
    s.push_str(if mesh_scored {
        " mesh rel L2 vs 1 nm | mesh ΔE p99 |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    } else {
        "\n|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    });
    for r in reports {
        let e = &r.vs_reference;
        let mesh_cols = if mesh_scored {
            r.mesh_vs_reference.map_or(" — | — |".to_string(), |m| {
                format!(" {:.2e} | {:.3} |", m.rel_l2, m.p99_de)
            })
        } else {
            String::new()
        };
        if r.per_vertex {
            s.push_str(&format!(
                "| {} | — | — | — | — | {} | — | — | — | — | — | — |{mesh_cols}\n",
                r.variant.name,
                ms(r.mesh_gpu_ms)
            ));
            continue;
        }
        let errors = if r.reference_dark {
            format!("reference dark | {:.2e} | — | — | —", e.max_abs_y)
        } else {
            format!(
                "{:.2e} | {:.2e} | {:.3} | {:.3} | {:.3}",
                e.rel_l2, e.max_abs_y, e.p50_de, e.p99_de, e.max_de
            )
        };
        s.push_str(&format!(
            "| {} | {} | {:.0} | {:.1} | {} | {} | {errors} | {:.2e} |\n",
            r.variant.name,
            r.fetches,
            r.build_ms,
            r.gpu_bytes as f64 / 1e6,
            ms(r.gpu_ms),
            ms(r.mesh_gpu_ms),
            r.vs_model.rel_l2
        ));
        s.pop();
        s.push_str(&mesh_cols);
        s.push('\n');
    }
    if reports.iter().any(|r| r.reference_dark) {
        s.push_str("\nreference dark: every reference sample is below the tolerance times its gain C (ρ/C under the tolerance of a mirror's specular value), the error every variant is allowed there; relative errors and ΔE of a dark map measure noise, so only max ΔY is shown.\n");
    }
    for r in reports {
        if let Some(k) = r.conditioning {
            s.push_str(&format!(
                "\n{}: condition number of its sum {k:.2e}; × float32's 6e-8 ≈ {:.1e} relative error expected\n",
                r.variant.name,
                k * 6e-8
            ));
        }
    }
    let over: Vec<String> = reports
        .iter()
        .filter_map(|r| Some(format!("{} {:.1e}", r.variant.name, r.overshoot?)))
        .collect();
    if !over.is_empty() {
        s.push_str(&format!(
            "\novershoot (most negative G of the interpolant over the map before the clamp to G ≥ 0, relative to the peak G_Y): {}\n",
            over.join(", ")
        ));
    }
    s
}

/// The CSV of the reports: the columns of the first profiler, then the new ones.
pub fn format_csv(reports: &[VariantReport]) -> String {
    let mut csv = String::from("variant,expansion,terms,window_radius,lambda_step_nm,storage,gpu_ms,wall_ms,rel_l2_ref,max_abs_y_ref,mean_de_ref,max_de_ref,rel_l2_model,kind,detail,fetches,build_ms,gpu_bytes,mesh_gpu_ms,p50_de_ref,p99_de_ref,p99_de_model,conditioning,per_vertex,mesh_rel_l2_ref,mesh_p99_de_ref,overshoot,reference_dark,leave_out\n");
    let opt = |v: Option<f64>| v.map_or(String::new(), |g| g.to_string());
    for r in reports {
        let v = &r.variant;
        csv.push_str(&format!(
            "{},{},{},{},{},{:?},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            v.name,
            v.expansion,
            v.terms,
            v.window_radius,
            v.lambda_step_nm,
            v.storage,
            opt(r.gpu_ms),
            r.wall_ms,
            r.vs_reference.rel_l2,
            r.vs_reference.max_abs_y,
            r.vs_reference.mean_de,
            r.vs_reference.max_de,
            r.vs_model.rel_l2,
            v.kind,
            r.detail.replace(',', ";"),
            r.fetches,
            r.build_ms,
            r.gpu_bytes,
            opt(r.mesh_gpu_ms),
            r.vs_reference.p50_de,
            r.vs_reference.p99_de,
            r.vs_model.p99_de,
            opt(r.conditioning),
            r.per_vertex,
            opt(r.mesh_vs_reference.map(|m| m.rel_l2)),
            opt(r.mesh_vs_reference.map(|m| m.p99_de)),
            opt(r.overshoot),
            r.reference_dark,
            v.leave_out
        ));
    }
    csv
}

/// `diffract profile` options.
#[derive(Debug, Clone, clap::Args)]
pub struct ProfileArgs {
    #[command(flatten)]
    pub material: MaterialArgs,
    /// Taylor terms T of the FLSS variants (Chebyshev gets ⌈2T/3⌉).
    #[arg(long = "variant-terms", default_value_t = 30)]
    pub variant_terms: usize,
    /// Profile only these (comma-separated names from the table; default: all).
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// Polar angle of the light (degrees).
    #[arg(long, default_value_t = 60.0)]
    pub theta_i: f64,
    /// Azimuth of the light (degrees).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub phi_i: f64,
    /// BRDF map side in pixels.
    #[arg(long, default_value_t = 128)]
    pub size: u32,
    /// Pixels scored against the reference, spread over the map (each costs N²·401
    /// complex multiply-adds).
    #[arg(long, default_value_t = 1024)]
    pub pixels: usize,
    /// Pixels scored among the brightest of the map.
    #[arg(long, default_value_t = 64)]
    pub brightest: usize,
    /// Frames per variant after the warm-up (the median is reported).
    #[arg(long, default_value_t = 5)]
    pub frames: usize,
    /// Side of the mesh view (the default scene) timed per variant; 0: none.
    #[arg(long, default_value_t = 128)]
    pub mesh_size: u32,
    /// Mesh view: quads along each side of a scale of the default scene's `scaly-snake`
    /// (its resolution; 6 by default).
    #[arg(long)]
    pub mesh_quads: Option<u32>,
    /// Also evaluate flss, nmm and pq per vertex on the mesh view (thesis §1.5.1), and score
    /// every mesh view against a per-pixel FLSS 1 nm render of it.
    #[arg(long)]
    pub per_vertex: bool,
    /// Also write the table as CSV.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Also write a PNG plot of error against GPU time (log–log, Pareto front marked).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    #[command(flatten)]
    pub table: TableArgs,
    #[command(flatten)]
    pub cache: CacheArgs,
}

/// Runs `diffract profile`.
pub fn run(args: &ProfileArgs) -> Result<()> {
    profile_args(args)?;
    for p in args.csv.iter().chain(&args.plot) {
        if p.file_name().is_none() {
            return Err(Error::invalid(
                "output",
                format!("{} is not a file", p.display()),
            ));
        }
    }
    let mut variants = flss_variants(args.variant_terms);
    variants.extend(table_variants(&args.table.options()));
    if !args.only.is_empty() {
        for name in &args.only {
            if !variants.iter().any(|v| &v.name == name) {
                let names: Vec<&str> = variants.iter().map(|v| v.name.as_str()).collect();
                return Err(Error::invalid(
                    "only",
                    format!(
                        "'{name}' is not a profiled variant; expected one of: {}",
                        names.join(", ")
                    ),
                ));
            }
        }
        variants.retain(|v| args.only.contains(&v.name));
    }
    let base = args.material.apply(Material::default());
    if args.per_vertex && args.mesh_size == 0 {
        return Err(Error::invalid(
            "per-vertex",
            "needs the mesh view (--mesh-size > 0): a BRDF map has no vertices",
        ));
    }
    if let Some(q) = args.mesh_quads {
        if !(1..=32).contains(&q) || args.mesh_size == 0 {
            return Err(Error::invalid(
                "mesh-quads",
                format!("{q}; expected 1..=32 with a mesh view (--mesh-size > 0)"),
            ));
        }
    }
    // The user's numbers and height field are checked before the device opens (each
    // variant loads the field again when it prepares; that is cheap next to its terms).
    base.validate()?;
    base.load_heightfield(&crate::report::Stderr)?;
    let mut renderer = Renderer::new(crate::cli::gpu::validation_requested())?;
    let mesh = (args.mesh_size > 0).then(|| {
        let mut s = Scene::default_scene();
        s.output.width = args.mesh_size;
        s.output.height = args.mesh_size;
        if args.mesh_quads.is_some() {
            s.mesh.scale_quads = args.mesh_quads;
        }
        s
    });
    let setup = ProfileSetup {
        base,
        variants,
        theta_i_deg: args.theta_i,
        phi_i_deg: args.phi_i,
        size: args.size,
        pixels: args.pixels,
        brightest: args.brightest,
        frames: args.frames,
        mesh,
        per_vertex: args.per_vertex,
        cache_dir: args.cache.dir(),
    };
    let reports = profile(&mut renderer, &setup)?;
    print!("{}", format_table(renderer.device_name(), &setup, &reports));
    if let Some(path) = &args.csv {
        crate::fsutil::write_atomic(path, format_csv(&reports).as_bytes())?;
    }
    if let Some(path) = &args.plot {
        // A dark reference's relative errors are noise: such rows are not plotted, and a
        // map that is dark for every row gives no plot at all.
        if reports.iter().all(|r| r.reference_dark) {
            return Err(Error::invalid(
                "plot",
                format!(
                    "the reference map is dark (every sample below the tolerance), so its relative errors are noise and {} is not written; lobes narrower than a pixel are missed by a small map: try a larger or odd --size (an odd map's middle row lies in the plane of incidence)",
                    path.display()
                ),
            ));
        }
        let mut points: Vec<crate::plot::Point> = reports
            .iter()
            .filter(|r| !r.reference_dark)
            .filter_map(|r| {
                r.gpu_ms.map(|t| crate::plot::Point {
                    label: r.variant.name.clone(),
                    time_ms: t,
                    error: r.vs_reference.rel_l2,
                })
            })
            .collect();
        // Per-vertex rows and their per-pixel twins on the mesh view (mesh GPU time, error
        // against the per-pixel FLSS 1 nm mesh render).
        points.extend(reports.iter().filter_map(|r| {
            let e = r.mesh_vs_reference?;
            let per_vertex_twin = r.per_vertex
                || reports
                    .iter()
                    .any(|o| o.variant.name == format!("{} per-vertex", r.variant.name));
            (per_vertex_twin && e.rel_l2 > 0.0).then(|| crate::plot::Point {
                label: format!("{} (mesh)", r.variant.name),
                time_ms: r.mesh_gpu_ms.unwrap_or(f64::NAN),
                error: e.rel_l2,
            })
        }));
        crate::plot::error_vs_time(
            path,
            &format!(
                "diffract profile: {} at θi = {}°, {}² map, {}",
                crate::plot::source_name(&setup.base.heightfield),
                setup.theta_i_deg,
                setup.size,
                renderer.device_name()
            ),
            "relative L2 error of XYZ vs the f64 reference at 1 nm",
            &points,
        )?;
    }
    let n = renderer.validation_messages();
    if n > 0 {
        return Err(Error::Validation(n));
    }
    Ok(())
}

/// `diffract profile`: map size, angles, scored pixels (no more than the map's disk holds),
/// repeats, the material's numbers and the CSV path.
pub fn profile_args(args: &ProfileArgs) -> Result<()> {
    use crate::render::{map_direction, MAX_MAP_SIZE};
    if !(1..=MAX_MAP_SIZE).contains(&args.size) {
        return Err(Error::invalid(
            "BRDF map size",
            format!("{}; expected 1..={MAX_MAP_SIZE} pixels", args.size),
        ));
    }
    crate::guard::in_range("theta-i", args.theta_i, 0.0..=90.0, "°")?;
    crate::guard::finite("phi-i", args.phi_i)?;
    let inside = (0..args.size)
        .flat_map(|j| (0..args.size).map(move |i| (i, j)))
        .filter(|&(i, j)| map_direction(i, j, args.size).is_some())
        .count();
    let scored = args.pixels.saturating_add(args.brightest);
    if scored == 0 || scored > inside {
        return Err(Error::invalid(
            "pixels",
            format!(
                "{} spread + {} brightest; a {}² map has {inside} pixels inside its disk to score (at least 1)",
                args.pixels, args.brightest, args.size
            ),
        ));
    }
    if !(1..=1000).contains(&args.frames) {
        return Err(Error::invalid(
            "frames",
            format!("{}; expected 1..=1000", args.frames),
        ));
    }
    if args.mesh_size > 8192 {
        return Err(Error::invalid(
            "mesh-size",
            format!("{}; expected 0 (none) ..=8192", args.mesh_size),
        ));
    }
    if let Some(q) = args.mesh_quads {
        if !(1..=32).contains(&q) || args.mesh_size == 0 {
            return Err(Error::invalid(
                "mesh-quads",
                format!("{q}; expected 1..=32 with a mesh view (--mesh-size > 0)"),
            ));
        }
    }
    args.table.check()?;
    if args.variant_terms > 64 {
        return Err(Error::invalid(
            "variant-terms",
            format!("{}; at most 64 terms are supported", args.variant_terms),
        ));
    }
    let material = args.material.apply(crate::material::Material::default());
    material.validate()?;
    let outputs: Vec<(&str, PathBuf)> = [("--csv", &args.csv), ("--plot", &args.plot)]
        .into_iter()
        .filter_map(|(flag, out)| out.clone().map(|o| (flag, o)))
        .collect();
    crate::guard::check_outputs(
        &crate::guard::heightfield_inputs(&material.heightfield),
        &outputs,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_samples_have_zero_error_and_differences_show() {
        let r = vec![[0.2, 0.3, 0.1], [0.01, 0.02, 0.03]];
        let e = error_stats(&r, &r);
        assert_eq!((e.rel_l2, e.max_abs_y, e.max_de), (0.0, 0.0, 0.0));
        let a = vec![[0.2, 0.33, 0.1], [0.01, 0.02, 0.03]];
        let e = error_stats(&a, &r);
        assert!((e.max_abs_y - 0.03).abs() < 1e-12);
        assert!(e.rel_l2 > 0.05 && e.rel_l2 < 0.1, "{}", e.rel_l2);
        assert!(e.max_de > 1.0);
    }
}
