//! What a profile found and how it is written: the rows' reports, the Markdown table with
//! its notes, the CSV and the Pareto plot of error against GPU time.

use super::budget::Frames;
use super::plan::{ProfileSetup, Variant};
use super::stats::{ErrorIntervals, ErrorStats};
use crate::{Error, Result};

/// One row of the profile.
#[derive(Debug, Clone, PartialEq)]
pub struct VariantReport {
    pub variant: Variant,
    /// Median GPU time of the map frames after the warm-up (ms); `None` without timestamps.
    pub gpu_ms: Option<f64>,
    /// The 10th and 90th percentiles of the same frames' times (GPU, else wall).
    pub spread_ms: Option<(f64, f64)>,
    /// Timed map frames after the warm-up.
    pub frames: usize,
    /// Wall time of the warm-up frame (ms): preparing the row (terms, table) and its draw.
    pub warm_up_ms: f64,
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
    /// 95 % bootstrap intervals of `vs_reference` over the scored pixels.
    pub intervals: ErrorIntervals,
    /// GPU against the f64 model of the same variant (float32 and driver error only).
    pub vs_model: ErrorStats,
    /// With `--per-vertex`: the mesh view against the per-pixel reference variant's mesh
    /// render.
    pub mesh_vs_reference: Option<ErrorStats>,
    /// A per-vertex row (thesis §1.5.1): only its mesh columns are measured (a BRDF map has
    /// no vertices; its map columns repeat the per-pixel variant's).
    pub per_vertex: bool,
}

/// A row that was not measured, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Skipped {
    pub variant: Variant,
    /// Its estimated cost (s) where it did not fit the budget; `None` where it refused the
    /// material.
    pub estimated_s: Option<f64>,
    pub reason: String,
}

/// What a profile measured: the rows in the order asked for, and those it skipped.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ProfileRun {
    pub reports: Vec<VariantReport>,
    pub skipped: Vec<Skipped>,
    /// Wall time of the whole profile (s).
    pub wall_s: f64,
    /// Pixels scored: those asked for, or fewer where the budget's share of the reference
    /// ran out (the first ones picked, bright and spread in proportion).
    pub scored: usize,
    /// The environment-lit rows (`--env`), when asked for.
    pub env: Option<EnvRun>,
    /// The whole-picture rows (`--picture`), when asked for.
    pub picture: Option<super::picture::PictureRun>,
}

/// One measured environment row.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvRow {
    /// The variant that drew it, by its command-line name.
    pub variant: String,
    pub samples: u32,
    /// Median time of the dispatches (submit to fence, as `render` reports it) (ms).
    pub gpu_ms: f64,
    /// Their 10th and 90th percentiles.
    pub spread_ms: Option<(f64, f64)>,
    pub frames: usize,
    /// Median wall time of a whole map (uploads, pipeline, dispatches, readback) (ms).
    pub wall_ms: f64,
    /// The map against the f64 quadrature at the scored pixels.
    pub vs_reference: ErrorStats,
    /// 95 % bootstrap intervals of `vs_reference` over the scored pixels.
    pub intervals: ErrorIntervals,
}

/// An environment row that did not fit the budget.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvSkipped {
    pub variant: String,
    pub samples: u32,
    pub estimated_s: f64,
    pub reason: String,
}

/// What the environment rows measured, with what they share: the table, the first
/// dispatch and the reference.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvRun {
    /// The environment's name (`builtin:sky`, a file name).
    pub source: String,
    /// The table on one line, as `render --brdf-map --env` prints it.
    pub table: String,
    /// Building the radiance table and its density on the CPU (ms).
    pub build_ms: f64,
    /// The first map at 1 sample per pixel: its wall time (uploads and the pipeline's
    /// compile included) and its dispatch time (ms).
    pub first_wall_ms: f64,
    pub first_gpu_ms: f64,
    /// The reference: its wall time (ms), the finest cell side `h` in `(u, v)` a pixel
    /// reached, and the largest difference of a channel between a pixel's last two cell
    /// sides, relative to the brightest scored pixel's Y (as the rows' errors are scaled).
    pub reference_ms: f64,
    pub reference_h: f64,
    pub reference_error: f64,
    /// Pixels scored, and asked for.
    pub scored: usize,
    pub asked: usize,
    pub rows: Vec<EnvRow>,
    pub skipped: Vec<EnvSkipped>,
}

impl EnvRow {
    /// The row's name in the table, the CSV and the plot.
    pub fn name(&self) -> String {
        row_name(&self.variant, self.samples)
    }
}

pub(super) fn row_name(variant: &str, samples: u32) -> String {
    format!("env {variant} {samples} spp")
}

/// A time in ms to two decimals, `n/a` without one.
pub(super) fn ms(v: Option<f64>) -> String {
    v.map_or("n/a".into(), |g| format!("{g:.2}"))
}

/// The table's first line: the device, the map, the pixels and how frames were counted.
fn header(device: &str, setup: &ProfileSetup, run: &ProfileRun) -> String {
    let mesh = setup.mesh.as_ref().map_or(String::new(), |s| {
        format!("; mesh view {}×{}", s.output.width, s.output.height)
    });
    let frames = match setup.frames {
        Frames::Fixed(n) => format!("GPU ms = median of {n} frames after a warm-up"),
        Frames::Budget(b) => format!(
            "budget {:.0} s ({:.0} s spent): each row draws frames after a warm-up until its median's standard error is under {:.0} % or its share of the budget is spent; GPU ms = their median, p10–p90 their spread",
            b.total_s,
            run.wall_s,
            100.0 * b.precision
        ),
    };
    let asked = setup.brightest + setup.pixels;
    let scored = if run.scored < asked {
        format!(
            "{} of {asked} scored pixels (the reference's share of the budget ran out; {} brightest + {} spread asked)",
            run.scored, setup.brightest, setup.pixels
        )
    } else {
        format!(
            "{asked} scored pixels ({} brightest + {} spread)",
            setup.brightest, setup.pixels
        )
    };
    format!(
        "device: {device}; BRDF map {}² at θi = {}°, φi = {}°{mesh}; {scored}, errors against the reference with 95 % bootstrap intervals over them; {frames}; reference: f64 direct sum at 1 nm\n\n",
        setup.size,
        setup.theta_i_deg,
        setup.phi_i_deg,
    )
}

/// One row of the Markdown table (`mesh_cols`: the per-vertex columns, or empty).
fn table_row(r: &VariantReport, mesh_cols: &str) -> String {
    if r.per_vertex {
        return format!(
            "| {} | — | — | — | — | — | — | {} | — | — | — | — | — | — |{mesh_cols}\n",
            r.variant.name,
            ms(r.mesh_gpu_ms)
        );
    }
    let e = &r.vs_reference;
    let i = &r.intervals;
    let errors = if r.reference_dark {
        format!("reference dark | {:.2e} | — | — | —", e.max_abs_y)
    } else {
        format!(
            "{:.2e} ({:.2e}–{:.2e}) | {:.2e} | {:.3} | {:.3} ({:.3}–{:.3}) | {:.3}",
            e.rel_l2,
            i.rel_l2.lo,
            i.rel_l2.hi,
            e.max_abs_y,
            e.p50_de,
            e.p99_de,
            i.p99_de.lo,
            i.p99_de.hi,
            e.max_de
        )
    };
    let spread = r
        .spread_ms
        .map_or("—".to_string(), |(a, b)| format!("{a:.2}–{b:.2}"));
    format!(
        "| {} | {} | {:.0} | {:.1} | {} | {} | {spread} | {} | {errors} | {:.2e} |{mesh_cols}\n",
        r.variant.name,
        r.fetches,
        r.build_ms,
        r.gpu_bytes as f64 / 1e6,
        r.frames,
        ms(r.gpu_ms),
        ms(r.mesh_gpu_ms),
        r.vs_model.rel_l2
    )
}

/// Formats a profile as a Markdown table, then its notes: skipped rows, dark references,
/// conditioning and overshoot.
pub fn format_table(device: &str, setup: &ProfileSetup, run: &ProfileRun) -> String {
    let env = run
        .env
        .as_ref()
        .map_or(String::new(), |e| env_table(device, setup, e));
    if run.reports.is_empty() && run.skipped.is_empty() && run.env.is_some() {
        return env.trim_start().to_string();
    }
    variant_table(device, setup, run) + &env
}

/// The variant rows' Markdown table and its notes.
fn variant_table(device: &str, setup: &ProfileSetup, run: &ProfileRun) -> String {
    let reports = &run.reports;
    let mut s = header(device, setup, run);
    let mesh_scored = reports.iter().any(|r| r.mesh_vs_reference.is_some());
    if mesh_scored {
        s.push_str("Per-vertex rows (thesis §1.5.1) measure the mesh view only: `mesh GPU ms` evaluated per vertex, and the last two columns, the mesh view against a per-pixel render of it by the reference variant at 1 nm (rel L2 of XYZ, ΔE2000 p99). A BRDF map has no vertices: their map columns are `—`.\n\n");
    }
    s.push_str("| variant | fetches/px | build ms | GPU MB | frames | GPU ms | p10–p90 ms | mesh GPU ms | rel L2 vs ref (95 %) | max ΔY vs ref | ΔE p50 | ΔE p99 (95 %) | max ΔE | rel L2 vs f64 model |");
    s.push_str(if mesh_scored {
        " mesh rel L2 vs 1 nm | mesh ΔE p99 |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    } else {
        "\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    });
    for r in reports {
        let mesh_cols = if mesh_scored {
            r.mesh_vs_reference.map_or(" — | — |".to_string(), |m| {
                format!(" {:.2e} | {:.3} |", m.rel_l2, m.p99_de)
            })
        } else {
            String::new()
        };
        s.push_str(&table_row(r, &mesh_cols));
    }
    s.push_str(&notes(run));
    s
}

/// The environment rows' Markdown table: what they share (the table, the first map, the
/// reference) on one line, a row per sample count, then the skipped ones.
fn env_table(device: &str, setup: &ProfileSetup, e: &EnvRun) -> String {
    let mut s = format!(
        "\ndevice: {device}; environment-lit BRDF map {}² under {}, the environment alone (no sun); {}; first map (1 spp: uploads, pipeline compile, dispatch) {:.1} ms wall, {:.2} ms dispatch; reference: f64 quadrature of the same table and environment at {} of {} pixels spread over the disk, cells halved from half a texel until two values agree to 2e-3 (down to {:.5} in (u, v)), the largest difference between a pixel's last two {:.1e} of the brightest pixel's Y, {:.1} s; errors against it with 95 % bootstrap intervals over the pixels; GPU ms = the dispatches' median (submit to fence), p10–p90 their spread, wall ms a whole map's\n\n",
        setup.size,
        e.source,
        e.table,
        e.first_wall_ms,
        e.first_gpu_ms,
        e.scored,
        e.asked,
        e.reference_h,
        e.reference_error,
        e.reference_ms / 1e3,
    );
    s.push_str("| row | samples/px | frames | GPU ms | p10–p90 ms | wall ms | rel L2 vs ref (95 %) | max ΔY vs ref | ΔE p50 | ΔE p99 (95 %) | max ΔE |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in &e.rows {
        let (v, i) = (&r.vs_reference, &r.intervals);
        let spread = r
            .spread_ms
            .map_or("—".to_string(), |(a, b)| format!("{a:.2}–{b:.2}"));
        s.push_str(&format!(
            "| {} | {} | {} | {:.2} | {spread} | {:.2} | {:.2e} ({:.2e}–{:.2e}) | {:.2e} | {:.3} | {:.3} ({:.3}–{:.3}) | {:.3} |\n",
            r.name(),
            r.samples,
            r.frames,
            r.gpu_ms,
            r.wall_ms,
            v.rel_l2,
            i.rel_l2.lo,
            i.rel_l2.hi,
            v.max_abs_y,
            v.p50_de,
            v.p99_de,
            i.p99_de.lo,
            i.p99_de.hi,
            v.max_de
        ));
    }
    for k in &e.skipped {
        s.push_str(&format!(
            "\nskipped: {}: {}\n",
            row_name(&k.variant, k.samples),
            k.reason
        ));
    }
    s
}

/// The notes under the table.
fn notes(run: &ProfileRun) -> String {
    let reports = &run.reports;
    let mut s = String::new();
    for k in &run.skipped {
        s.push_str(&format!("\nskipped: {}: {}\n", k.variant.name, k.reason));
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

/// The CSV of a profile: a line per measured row with every figure of the table and the
/// intervals; a skipped row has its name, its settings, `skipped`, the reason and its
/// estimated cost only.
pub fn format_csv(run: &ProfileRun) -> String {
    let mut csv = String::from("variant,expansion,terms,window_radius,lambda_step_nm,storage,gpu_ms,wall_ms,rel_l2_ref,max_abs_y_ref,mean_de_ref,max_de_ref,rel_l2_model,kind,detail,fetches,build_ms,gpu_bytes,mesh_gpu_ms,p50_de_ref,p99_de_ref,p99_de_model,conditioning,per_vertex,mesh_rel_l2_ref,mesh_p99_de_ref,overshoot,reference_dark,leave_out,frames,gpu_ms_p10,gpu_ms_p90,rel_l2_ref_lo,rel_l2_ref_hi,p99_de_ref_lo,p99_de_ref_hi,skipped,estimated_s,env_spp,picture_aa,flip_mean,p95_de_ref\n");
    let opt = |v: Option<f64>| v.map_or(String::new(), |g| g.to_string());
    let settings = |v: &Variant| {
        format!(
            "{},{},{},{},{},{:?}",
            v.name, v.expansion, v.terms, v.window_radius, v.lambda_step_nm, v.storage
        )
    };
    for r in &run.reports {
        let v = &r.variant;
        let (e, m, i) = (&r.vs_reference, &r.vs_model, &r.intervals);
        let columns = [
            opt(r.gpu_ms),
            r.wall_ms.to_string(),
            e.rel_l2.to_string(),
            e.max_abs_y.to_string(),
            e.mean_de.to_string(),
            e.max_de.to_string(),
            m.rel_l2.to_string(),
            v.kind.to_string(),
            r.detail.replace(',', ";"),
            r.fetches.to_string(),
            r.build_ms.to_string(),
            r.gpu_bytes.to_string(),
            opt(r.mesh_gpu_ms),
            e.p50_de.to_string(),
            e.p99_de.to_string(),
            m.p99_de.to_string(),
            opt(r.conditioning),
            r.per_vertex.to_string(),
            opt(r.mesh_vs_reference.map(|m| m.rel_l2)),
            opt(r.mesh_vs_reference.map(|m| m.p99_de)),
            opt(r.overshoot),
            r.reference_dark.to_string(),
            v.leave_out.to_string(),
            r.frames.to_string(),
            opt(r.spread_ms.map(|s| s.0)),
            opt(r.spread_ms.map(|s| s.1)),
            i.rel_l2.lo.to_string(),
            i.rel_l2.hi.to_string(),
            i.p99_de.lo.to_string(),
            i.p99_de.hi.to_string(),
            "false".to_string(),
            String::new(),
            String::new(),
            String::new(),
            String::new(),
            String::new(),
        ];
        csv.push_str(&format!("{},{}\n", settings(v), columns.join(",")));
    }
    for k in &run.skipped {
        let mut columns = vec![String::new(); 36];
        columns[7] = k.variant.kind.to_string();
        columns[8] = k.reason.replace(',', ";");
        columns[22] = k.variant.leave_out.to_string();
        columns[30] = "true".to_string();
        columns[31] = opt(k.estimated_s);
        csv.push_str(&format!("{},{}\n", settings(&k.variant), columns.join(",")));
    }
    if let Some(e) = &run.env {
        csv.push_str(&env_csv(e));
    }
    if let Some(p) = &run.picture {
        csv.push_str(&p.csv());
    }
    csv
}

/// The environment rows' CSV lines, in the columns of [`format_csv`]: the figures they
/// have, `env` as their kind, the table's build as theirs, and their samples per pixel.
fn env_csv(e: &EnvRun) -> String {
    let mut csv = String::new();
    let detail = format!("{}; {}", e.source, e.table).replace(',', ";");
    for r in &e.rows {
        let (v, i) = (&r.vs_reference, &r.intervals);
        let mut c = vec![String::new(); 42];
        c[0] = r.name();
        c[6] = r.gpu_ms.to_string();
        c[7] = r.wall_ms.to_string();
        c[8] = v.rel_l2.to_string();
        c[9] = v.max_abs_y.to_string();
        c[10] = v.mean_de.to_string();
        c[11] = v.max_de.to_string();
        c[13] = "env".into();
        c[14] = detail.clone();
        c[16] = e.build_ms.to_string();
        c[19] = v.p50_de.to_string();
        c[20] = v.p99_de.to_string();
        c[23] = "false".into();
        c[27] = "false".into();
        c[29] = r.frames.to_string();
        if let Some((lo, hi)) = r.spread_ms {
            c[30] = lo.to_string();
            c[31] = hi.to_string();
        }
        c[32] = i.rel_l2.lo.to_string();
        c[33] = i.rel_l2.hi.to_string();
        c[34] = i.p99_de.lo.to_string();
        c[35] = i.p99_de.hi.to_string();
        c[36] = "false".into();
        c[38] = r.samples.to_string();
        csv.push_str(&(c.join(",") + "\n"));
    }
    for k in &e.skipped {
        let mut c = vec![String::new(); 42];
        c[0] = row_name(&k.variant, k.samples);
        c[13] = "env".into();
        c[14] = k.reason.replace(',', ";");
        c[36] = "true".into();
        c[37] = k.estimated_s.to_string();
        c[38] = k.samples.to_string();
        csv.push_str(&(c.join(",") + "\n"));
    }
    csv
}

/// The Pareto plot of error against GPU time: the map rows, the per-vertex rows with
/// their per-pixel twins on the mesh view, and the environment rows as a curve of their
/// own (their errors are against the environment's quadrature).
pub(super) fn write_plot(
    path: &std::path::Path,
    setup: &ProfileSetup,
    run: &ProfileRun,
    device: &str,
) -> Result<()> {
    let (reports, env) = (&run.reports[..], run.env.as_ref());
    // A dark reference's relative errors are noise: such rows are not plotted, and a map
    // that is dark for every row gives no plot at all.
    let env_points =
        env.map_or(0, |e| e.rows.len()) + run.picture.as_ref().map_or(0, |p| p.rows.len());
    if env_points == 0 && reports.iter().all(|r| r.reference_dark) {
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
                error_range: Some((r.intervals.rel_l2.lo, r.intervals.rel_l2.hi)),
                time_range: r.spread_ms,
            })
        })
        .collect();
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
            ..Default::default()
        })
    }));
    // The environment rows' errors are against their own reference: a curve of their
    // own beside the variants' Pareto front.
    let mut curves: Vec<crate::plot::SideCurve> = env
        .map(|e| crate::plot::SideCurve {
            label: format!(
                "under {} (vs f64 quadrature), by samples per pixel",
                e.source
            ),
            points: e
                .rows
                .iter()
                .map(|r| crate::plot::Point {
                    label: r.name(),
                    time_ms: r.gpu_ms,
                    error: r.vs_reference.rel_l2,
                    error_range: Some((r.intervals.rel_l2.lo, r.intervals.rel_l2.hi)),
                    time_range: r.spread_ms,
                })
                .collect(),
        })
        .into_iter()
        .collect();
    // The whole-picture rows: their error is the picture's against itself supersampled, a
    // curve for each row (its modes joined from the fewest samples a pixel to the most).
    if let Some(p) = &run.picture {
        let mut groups: Vec<(String, Vec<crate::plot::Point>)> = Vec::new();
        for r in p.rows.iter().filter(|r| r.gpu_ms.is_some()) {
            let key = r.name.rsplit_once(' ').map_or(r.name.as_str(), |(k, _)| k);
            let point = crate::plot::Point {
                label: r.name.clone(),
                time_ms: r.gpu_ms.unwrap_or(f64::NAN),
                error: r.error.rel_l2,
                ..Default::default()
            };
            match groups.iter_mut().find(|(k, _)| k == key) {
                Some((_, points)) => points.push(point),
                None => groups.push((key.to_string(), vec![point])),
            }
        }
        for (key, points) in groups {
            curves.push(crate::plot::SideCurve {
                label: format!(
                    "{key}: whole picture {}×{} vs itself at {}×{} samples a pixel",
                    p.width, p.height, p.reference_ss, p.reference_ss
                ),
                points,
            });
        }
    }
    let (lit, y_label) = match (env, points.is_empty()) {
        (Some(e), true) => (
            format!("under {}", e.source),
            "relative L2 error of XYZ vs the f64 quadrature of the environment",
        ),
        (Some(_), false) => (
            format!("at θi = {}°", setup.theta_i_deg),
            "relative L2 error of XYZ vs the f64 reference (env rows: its quadrature)",
        ),
        (None, _) => (
            format!("at θi = {}°", setup.theta_i_deg),
            "relative L2 error of XYZ vs the f64 reference at 1 nm",
        ),
    };
    crate::plot::error_vs_time_with(
        path,
        &format!(
            "diffract profile: {} {lit}, {}² map, {device}",
            crate::plot::source_name(&setup.base.heightfield),
            setup.size,
        ),
        y_label,
        &points,
        &curves,
    )
}
