//! `diffract stability`: the stability matrix. Every cell is one variant that declares a
//! spectral model ([`Stability::Spectral`]), height (peak-to-valley `h_max`), light angle
//! `θi`, wavelength, preferred expansion, term mode (`auto` or a fixed `T`) and evaluator
//! (the variant's f64 model, its float32 GPU shader); it holds the error against the f64
//! direct-sum reference, the expansion and `T` actually used, and whether the cell passed,
//! was warned about, or was refused. The variants that declare a float32 mirror of a table
//! ([`Stability::Table`]) are probed on narrow regions ([`run_table_cases`]).
//!
//! Errors are stated on `ρ/C = |P̂|²` (see [`crate::brdf::truncation`]): the reflectance
//! error divided by the gain factor, i.e. relative to a flat mirror's specular value, so
//! grazing Fresnel gains do not hide or inflate it. The f64 model is probed at the exact
//! specular direction (`u = v = 0`), backscatter (`ωr = ωi`), normal view, the first orders
//! of the field's strongest period, and an in-plane sweep; the GPU at every pixel of a tiny
//! spectral BRDF map, against the reference and against its own f64 model (the float32
//! error, checked against the planner's stated float32 bound).

use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;

use crate::brdf::table::{Region, TableSpec};
use crate::brdf::truncation::{Precision, Reach, TermPlan, Terms};
use crate::brdf::{direction, gain, reference};
use crate::budget::{Fits, Keeper};
use crate::heightfield::{generate, GratingKind, GratingSpec, HeightField};
use crate::material::Material;
use crate::render::variant::{Mirrored, SpectralModel, Stability, TableMirror};
use crate::render::{Renderer, TableOptions, VariantKind};
use crate::spectrum::Expansion;
use crate::{validity, Error, Result};

mod heartbeat;
pub mod lighting;
pub mod model_axis;

/// Which evaluator a cell measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Evaluator {
    /// The variant's CPU model in f64.
    Model,
    /// The GPU shader (float32), on a tiny spectral BRDF map.
    Gpu,
}

impl std::fmt::Display for Evaluator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Evaluator::Model => "f64 model",
            Evaluator::Gpu => "GPU float32",
        })
    }
}

/// Outcome of a cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// Within the tolerance, no warning.
    Pass,
    /// A warning was printed (expansion switched, or a fixed `T` above the tolerance);
    /// the error is what a user gets.
    Warned,
    /// The planner refused the configuration (nothing was evaluated).
    Refused,
    /// Silently wrong: above the tolerance without a warning, or the GPU off its f64 model
    /// by more than the stated float32 bound. Never expected.
    Fail,
    /// Not run: its estimated cost did not fit the time budget (the message gives it).
    Skipped,
}

impl std::fmt::Display for Status {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Status::Pass => "pass",
            Status::Warned => "warned",
            Status::Refused => "refused",
            Status::Fail => "FAIL",
            Status::Skipped => "skipped",
        })
    }
}

/// One cell of the matrix.
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    pub variant: VariantKind,
    pub h_max_um: f64,
    pub theta_i_deg: f64,
    pub lambda_nm: f64,
    /// The material's expansion (auto may switch it).
    pub expansion: Expansion,
    pub terms_mode: Terms,
    pub evaluator: Evaluator,
    /// Expansion and `T` used; `None` when refused.
    pub used: Option<(Expansion, usize)>,
    pub status: Status,
    /// Max `|ρ − ρ_ref|/C` over the probes; `None` when refused.
    pub error: Option<f64>,
    /// The planner's bound on `|ΔP̂|²` (truncation + rounding).
    pub bound: Option<f64>,
    /// GPU only: max `|ρ_gpu − ρ_model|/C`, and the stated float32 bound.
    pub f32_error: Option<f64>,
    pub f32_bound: Option<f64>,
    /// Probe of the largest error.
    pub worst_probe: String,
    /// The refusal or the warnings, one line.
    pub message: String,
}

/// The axes and settings of a run.
#[derive(Debug, Clone)]
pub struct MatrixSpec {
    /// The base field; every `h_max` rescales it to that peak-to-valley height.
    pub field: HeightField,
    /// Name of the field in reports.
    pub field_name: String,
    /// Strongest period of the field along x (µm), for the first-order probes.
    pub period_um: Option<f64>,
    pub h_max_um: Vec<f64>,
    pub theta_i_deg: Vec<f64>,
    pub lambdas_nm: Vec<f64>,
    pub expansions: Vec<Expansion>,
    pub terms_modes: Vec<Terms>,
    pub evaluators: Vec<Evaluator>,
    pub tolerance: f64,
    pub window_radius: usize,
    pub coherence_um: f64,
    /// GPU map side (pixels).
    pub map_size: u32,
    /// Renderer validation layer on.
    pub validation: bool,
    /// Time budget of the matrix (s): a cell whose estimated cost does not fit what is left
    /// is reported as skipped. `None` runs every cell.
    pub budget_s: Option<f64>,
}

/// The full matrix's axes (`--full`).
pub const H_MAX_UM: [f64; 6] = [0.05, 0.25, 0.5, 1.0, 2.0, 5.0];
pub const THETA_I_DEG: [f64; 5] = [0.0, 45.0, 80.0, 89.0, 89.99];
pub const LAMBDAS_NM: [f64; 3] = [380.0, 580.0, 780.0];

/// The default matrix's axes: the shallowest, a middle and the tallest field; normal,
/// oblique and grazing light; both ends of the visible range. The extremes of the full
/// matrix, where the stiff cases live, in a fifth of its cells.
pub const QUICK_H_MAX_UM: [f64; 3] = [0.05, 1.0, 5.0];
pub const QUICK_THETA_I_DEG: [f64; 3] = [0.0, 80.0, 89.99];
pub const QUICK_LAMBDAS_NM: [f64; 2] = [380.0, 780.0];

/// Default time budget of `diffract stability` (s) without `--full`.
pub const DEFAULT_BUDGET_S: f64 = 60.0;

/// The default field: a 128² sinusoid of period 1.6 µm (4 periods over 6.4 µm, dH = 50
/// nm), where the direct-sum reference is cheap.
pub fn default_field() -> Result<(HeightField, f64)> {
    let spec = GratingSpec {
        kind: GratingKind::Sinusoidal,
        size_um: 6.4,
        dh_um: 0.05,
        period_um: 1.6,
        height_um: 1.0,
        angle_deg: 0.0,
        seed: 1,
    };
    let (wave, _) = spec.waves()?;
    Ok((generate(&spec)?, wave.period_um))
}

impl MatrixSpec {
    /// The full matrix on `field`.
    pub fn full(field: HeightField, field_name: &str, period_um: Option<f64>) -> Self {
        MatrixSpec {
            field,
            field_name: field_name.into(),
            period_um,
            h_max_um: H_MAX_UM.to_vec(),
            theta_i_deg: THETA_I_DEG.to_vec(),
            lambdas_nm: LAMBDAS_NM.to_vec(),
            expansions: vec![Expansion::Taylor, Expansion::Chebyshev],
            terms_modes: vec![Terms::Auto, Terms::Fixed(30)],
            evaluators: vec![Evaluator::Model, Evaluator::Gpu],
            tolerance: crate::brdf::truncation::DEFAULT_TOLERANCE,
            window_radius: 2,
            coherence_um: crate::material::DEFAULT_COHERENCE_UM,
            map_size: 15,
            validation: crate::cli::gpu::validation_requested(),
            budget_s: None,
        }
    }
}

/// `field` rescaled to peak-to-valley `h_max` (a flat field stays flat).
fn scaled(field: &HeightField, h_max: f64) -> Result<HeightField> {
    let (lo, hi) = field.range();
    let s = if hi > lo { h_max / (hi - lo) } else { 0.0 };
    HeightField::new(
        field.nx(),
        field.ny(),
        field.dh_um(),
        field.heights_um().iter().map(|h| (h - lo) * s).collect(),
    )
}

/// In-plane direction at signed polar angle: negative on the light's side (`φ = 0`),
/// positive on the mirror side (`φ = 180°`).
fn in_plane(theta_deg: f64) -> [f64; 3] {
    if theta_deg < 0.0 {
        direction(-theta_deg, 0.0)
    } else {
        direction(theta_deg, 180.0)
    }
}

/// The f64 model's probes for light at `theta_i` (φ = 0): name and `ωr`.
fn probes(theta_i: f64, lambda_nm: f64, period_um: Option<f64>) -> Vec<(String, [f64; 3])> {
    let wi = direction(theta_i, 0.0);
    let mut p = vec![
        ("specular (u=v=0)".to_string(), direction(theta_i, 180.0)),
        ("backscatter".to_string(), wi),
        ("normal view".to_string(), [0.0, 0.0, 1.0]),
    ];
    if let Some(d) = period_um {
        // In plane, u = sin θr − sin θi on the mirror side: orders at u = ±mλ/d.
        let si = theta_i.to_radians().sin();
        for m in [-2.0, -1.0, 1.0, 2.0] {
            let s = si + m * lambda_nm * 1e-3 / d;
            if s.abs() < 1.0 {
                p.push((format!("order {m:+}"), in_plane(s.asin().to_degrees())));
            }
        }
    }
    for k in -8..=8 {
        let t = k as f64 * 10.0 + 0.5;
        p.push((format!("θr = {t}°"), in_plane(t)));
    }
    p
}

/// Max `|ρ − ρ_ref|/C` over `dirs`, and the name of the worst one.
fn max_error(
    dirs: &[(String, [f64; 3])],
    wi: [f64; 3],
    shading: &crate::brdf::Shading,
    eval: impl Fn([f64; 3]) -> Result<f64> + Sync,
    refer: impl Fn([f64; 3]) -> Result<f64> + Sync,
) -> Result<(f64, String)> {
    let errs: Vec<(f64, String)> = dirs
        .par_iter()
        .map(|(name, wr)| {
            let c = gain(wi, *wr, shading);
            if c == 0.0 {
                return Ok((0.0, name.clone()));
            }
            let (a, b) = (eval(*wr)?, refer(*wr)?);
            let e = if a.is_finite() && b.is_finite() {
                (a - b).abs() / c
            } else {
                f64::INFINITY
            };
            Ok((e, name.clone()))
        })
        .collect::<Result<_>>()?;
    let worst = errs
        .into_iter()
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .unwrap_or((0.0, String::new()));
    Ok(worst)
}

/// The material of a cell (the base field replaced by the scaled one at prepare time).
fn material(spec: &MatrixSpec, expansion: Expansion, terms: Terms) -> Material {
    Material {
        heightfield: "stability field".into(),
        expansion,
        terms,
        tolerance: spec.tolerance,
        window_radius: spec.window_radius,
        coherence_um: spec.coherence_um,
        ..Material::default()
    }
}

/// A spectral map of `prepared` by the renderer's variant under light at `(theta_i, 0)`.
/// Returns per-pixel `(ωr, ρ)`.
fn gpu_spectral_map(
    renderer: &mut Renderer,
    prepared: &crate::material::PreparedMaterial,
    theta_i: f64,
    size: u32,
    lambda_nm: f64,
) -> Result<Vec<([f64; 3], f64)>> {
    let frame = renderer.render_brdf_map(prepared, theta_i, 0.0, size, Some(lambda_nm))?;
    let mut out = Vec::new();
    for j in 0..size {
        for i in 0..size {
            if let Some(wr) = crate::render::map_direction(i, j, size) {
                out.push((wr, frame.at(i, j)[0] as f64));
            }
        }
    }
    Ok(out)
}

/// The variants in the spectral matrix, with their f64 models at one wavelength, in
/// registry order.
pub(crate) fn spectral_variants() -> Vec<(VariantKind, SpectralModel)> {
    VariantKind::ALL
        .into_iter()
        .filter_map(|k| match k.implementation().stability() {
            Stability::Spectral(rho) => Some((k, rho)),
            _ => None,
        })
        .collect()
}

/// One point of the matrix's axes.
#[derive(Clone, Copy)]
struct Point {
    variant: VariantKind,
    rho: SpectralModel,
    /// Index into `spec.h_max_um`.
    h: usize,
    theta_i: f64,
    lambda: f64,
    expansion: Expansion,
    terms: Terms,
    evaluator: Evaluator,
}

/// Every point, in run order: variant, then `h_max`, `θi`, `λ`, expansion, terms and
/// evaluator.
fn points(spec: &MatrixSpec) -> Vec<Point> {
    let mut out = Vec::new();
    for (variant, rho) in spectral_variants() {
        for h in 0..spec.h_max_um.len() {
            for &theta_i in &spec.theta_i_deg {
                for &lambda in &spec.lambdas_nm {
                    for &expansion in &spec.expansions {
                        for &terms in &spec.terms_modes {
                            for &evaluator in &spec.evaluators {
                                out.push(Point {
                                    variant,
                                    rho,
                                    h,
                                    theta_i,
                                    lambda,
                                    expansion,
                                    terms,
                                    evaluator,
                                });
                            }
                        }
                    }
                }
            }
        }
    }
    out
}

/// Runs the matrix over every variant that declares a spectral model. `renderer` is
/// needed when `spec.evaluators` holds [`Evaluator::Gpu`]; `progress` is called after each
/// cell. With a budget the cells run round-robin over the variants (so a budget that runs
/// out leaves every variant's tail, not the last variants), and a cell whose estimated cost
/// (the mean of the cells run so far with its variant and evaluator, else of all cells)
/// does not fit the time left is [`Status::Skipped`]. The cells come back in
/// [`points`]' order either way.
pub fn run_matrix(
    spec: &MatrixSpec,
    mut renderer: Option<&mut Renderer>,
    mut progress: impl FnMut(&Cell),
) -> Result<Vec<Cell>> {
    let shading = Material::default().shading();
    let fields = spec
        .h_max_um
        .iter()
        .map(|&h| scaled(&spec.field, h))
        .collect::<Result<Vec<_>>>()?;
    let all = points(spec);
    let order = match spec.budget_s {
        Some(_) => round_robin(&all),
        None => (0..all.len()).collect(),
    };
    // A cell's cost: the mean of its variant and evaluator's cells; for a pair not run
    // yet, the mean first cell of the pairs with its evaluator (what a first cell costs,
    // its set-up included), else of every pair.
    let mut keeper = Keeper::new(Instant::now(), spec.budget_s);
    let mut cells: Vec<Option<Cell>> = vec![None; all.len()];
    for i in order {
        let p = &all[i];
        let key = (p.variant, p.evaluator);
        let estimate = keeper
            .estimate_like(&key, 1.0, |k| k.1 == key.1)
            .or_else(|| keeper.estimate_like(&key, 1.0, |_| true));
        let cell = match keeper.fits(estimate) {
            Fits::No { estimated_s, .. } => skipped_cell(spec, p, estimated_s),
            Fits::Yes => {
                let t = Instant::now();
                let c = run_cell(spec, p, &fields[p.h], renderer.as_deref_mut(), &shading)?;
                keeper.learn(&key, 1.0, t.elapsed().as_secs_f64());
                c
            }
        };
        progress(&cell);
        cells[i] = Some(cell);
    }
    Ok(cells.into_iter().flatten().collect())
}

/// Builds the GPU pipeline of every shader configuration the matrix's GPU cells use (a
/// variant with its expansion and term count, which are specialisation constants), once
/// each, by drawing a one-pixel map. On a CPU driver with a cold shader cache one build
/// takes up to seconds (Chebyshev with 30 terms: 4 s on lavapipe, 2 cores), and only the
/// first cell of its configuration pays it, which no cell's cost could predict: built here,
/// it is a step of the run's setup and every cell costs what its evaluation costs. Returns
/// how many configurations there are.
fn build_pipelines(spec: &MatrixSpec, renderer: &mut Renderer) -> Result<usize> {
    let mut built: Vec<(VariantKind, Expansion, usize)> = Vec::new();
    for p in points(spec)
        .iter()
        .filter(|p| p.evaluator == Evaluator::Gpu)
    {
        let hf = scaled(&spec.field, spec.h_max_um[p.h])?;
        let m = material(spec, p.expansion, p.terms);
        let reach = Reach::at(1.0 + p.theta_i.to_radians().cos(), p.lambda);
        // A refused plan is a refused cell: it draws nothing.
        let Ok(plan) = m.plan(&hf, &reach, Precision::F32) else {
            continue;
        };
        let key = (p.variant, plan.expansion, plan.terms);
        if built.contains(&key) {
            continue;
        }
        built.push(key);
        let prepared = m.prepare_planned(hf, plan, None, &crate::report::Stderr)?;
        renderer.set_variant(p.variant);
        renderer.render_brdf_map(&prepared, p.theta_i, 0.0, 1, Some(p.lambda))?;
    }
    Ok(built.len())
}

/// Indices of `points` taking one cell of each variant in turn.
fn round_robin(points: &[Point]) -> Vec<usize> {
    let mut lanes: Vec<(VariantKind, Vec<usize>)> = Vec::new();
    for (i, p) in points.iter().enumerate() {
        match lanes.iter_mut().find(|(v, _)| *v == p.variant) {
            Some((_, lane)) => lane.push(i),
            None => lanes.push((p.variant, vec![i])),
        }
    }
    let longest = lanes.iter().map(|(_, l)| l.len()).max().unwrap_or(0);
    (0..longest)
        .flat_map(|k| lanes.iter().filter_map(move |(_, l)| l.get(k).copied()))
        .collect()
}

/// A cell the budget left out, with its estimated cost.
fn skipped_cell(spec: &MatrixSpec, p: &Point, est_s: f64) -> Cell {
    Cell {
        status: Status::Skipped,
        message: format!("over the time budget: estimated {est_s:.1} s"),
        ..blank_cell(spec, p)
    }
}

/// A cell of `p` with nothing evaluated yet (refused until judged).
fn blank_cell(spec: &MatrixSpec, p: &Point) -> Cell {
    Cell {
        variant: p.variant,
        h_max_um: spec.h_max_um[p.h],
        theta_i_deg: p.theta_i,
        lambda_nm: p.lambda,
        expansion: p.expansion,
        terms_mode: p.terms,
        evaluator: p.evaluator,
        used: None,
        status: Status::Refused,
        error: None,
        bound: None,
        f32_error: None,
        f32_bound: None,
        worst_probe: String::new(),
        message: String::new(),
    }
}

/// One cell: the plan (or its refusal), the evaluation, and the verdict.
fn run_cell(
    spec: &MatrixSpec,
    p: &Point,
    hf: &HeightField,
    renderer: Option<&mut Renderer>,
    shading: &crate::brdf::Shading,
) -> Result<Cell> {
    let m = material(spec, p.expansion, p.terms);
    let precision = match p.evaluator {
        Evaluator::Model => Precision::F64,
        Evaluator::Gpu => Precision::F32,
    };
    let mut cell = blank_cell(spec, p);
    let reach = Reach::at(1.0 + p.theta_i.to_radians().cos(), p.lambda);
    let plan = match m.plan(hf, &reach, precision) {
        Ok(plan) => plan,
        Err(e) => {
            cell.message = e.to_string();
            return Ok(cell);
        }
    };
    let prepared = m.prepare_planned(hf.clone(), plan.clone(), None, &crate::report::Stderr)?;
    let result = match p.evaluator {
        Evaluator::Model => model_cell(spec, p, &prepared, hf, shading)?,
        Evaluator::Gpu => {
            let Some(r) = renderer else {
                return Err(Error::invalid(
                    "stability",
                    "the GPU evaluator needs a renderer",
                ));
            };
            gpu_cell(spec, p, &prepared, hf, r, shading)?
        }
    };
    judge(spec, &mut cell, &plan, result);
    Ok(cell)
}

/// Records an evaluated cell's numbers and decides its status.
fn judge(spec: &MatrixSpec, cell: &mut Cell, plan: &TermPlan, r: CellResult) {
    cell.used = Some((plan.expansion, plan.terms));
    cell.bound = Some(plan.error_bound());
    cell.error = Some(r.0);
    cell.worst_probe = r.1;
    cell.f32_error = r.2;
    // |P̂_model| ≤ 1 + truncation, so rounding δ moves |P̂|² by at most
    // 2(1 + truncation)δ + δ² (unbounded where the series has not converged: those cells
    // carry a warning).
    let ro = plan.rounding;
    cell.f32_bound = r.2.map(|_| 2.0 * (1.0 + plan.truncation) * ro + ro * ro);
    cell.message = plan.warnings.join("; ");
    let f32_ok = match (cell.f32_error, cell.f32_bound) {
        (Some(e), Some(b)) => e <= b,
        _ => true,
    };
    cell.status = if !f32_ok {
        Status::Fail
    } else if !plan.warnings.is_empty() {
        Status::Warned
    } else if r.0 <= spec.tolerance {
        Status::Pass
    } else {
        Status::Fail
    };
}

type CellResult = (f64, String, Option<f64>);

/// The variant's f64 model at the probes against the direct sum.
fn model_cell(
    spec: &MatrixSpec,
    p: &Point,
    prepared: &crate::material::PreparedMaterial,
    hf: &HeightField,
    shading: &crate::brdf::Shading,
) -> Result<CellResult> {
    let wi = direction(p.theta_i, 0.0);
    let dirs = probes(p.theta_i, p.lambda, spec.period_um);
    let (e, worst) = max_error(
        &dirs,
        wi,
        shading,
        |wr| (p.rho)(prepared, shading, wi, wr, p.lambda),
        |wr| {
            Ok(reference::rho(
                hf,
                spec.coherence_um,
                shading,
                wi,
                wr,
                p.lambda,
            ))
        },
    )?;
    Ok((e, worst, None))
}

/// The variant's GPU spectral map against the direct sum and against its f64 model.
fn gpu_cell(
    spec: &MatrixSpec,
    p: &Point,
    prepared: &crate::material::PreparedMaterial,
    hf: &HeightField,
    renderer: &mut Renderer,
    shading: &crate::brdf::Shading,
) -> Result<CellResult> {
    renderer.set_variant(p.variant);
    let pixels = gpu_spectral_map(renderer, prepared, p.theta_i, spec.map_size, p.lambda)?;
    // What the shader saw: ωi and λ rounded to float32.
    let wi32 = direction(p.theta_i, 0.0).map(|c| c as f32 as f64);
    let l32 = (p.lambda * 1e-3) as f32 as f64 * 1e3;
    let dirs: Vec<(String, [f64; 3])> = pixels
        .iter()
        .map(|(wr, _)| (format!("pixel ({:.3}, {:.3})", wr[0], wr[1]), *wr))
        .collect();
    let lookup = |wr: [f64; 3]| -> Result<f64> {
        Ok(pixels
            .iter()
            .find(|(d, _)| *d == wr)
            .map_or(f64::NAN, |(_, v)| *v))
    };
    let (e_ref, worst) = max_error(&dirs, wi32, shading, lookup, |wr| {
        Ok(reference::rho(
            hf,
            spec.coherence_um,
            shading,
            wi32,
            wr,
            l32,
        ))
    })?;
    let (e_model, _) = max_error(&dirs, wi32, shading, lookup, |wr| {
        (p.rho)(prepared, shading, wi32, wr, l32)
    })?;
    Ok((e_ref, worst, Some(e_model)))
}

/// `diffract stability` options.
#[derive(Debug, Clone, clap::Args)]
pub struct StabilityArgs {
    /// Height field (any source; rescaled to each h_max) [default: a 128² sinusoid of
    /// period 1.6 µm, dH = 50 nm].
    #[arg(long)]
    pub heightfield: Option<String>,
    /// Pixel size override for --heightfield (µm).
    #[arg(long)]
    pub dh_um: Option<f64>,
    /// Scan channel of --heightfield, by index or title [default: the first height channel].
    #[arg(long, requires = "heightfield")]
    pub channel: Option<String>,
    /// Levelling of --heightfield: none, plane, poly:N, rows, comma-separated [default:
    /// plane,rows for scans, none otherwise].
    #[arg(long, requires = "heightfield")]
    pub level: Option<String>,
    /// Peak-to-valley heights (µm) [default: 0.05 1 5; with --full: 0.05 0.25 0.5 1 2 5].
    #[arg(long = "hmax-um", num_args = 1..)]
    pub h_max_um: Vec<f64>,
    /// Light polar angles (degrees) [default: 0 80 89.99; with --full: 0 45 80 89 89.99].
    #[arg(long, num_args = 1..)]
    pub theta_i: Vec<f64>,
    /// Wavelengths (nm) [default: 380 780; with --full: 380 580 780].
    #[arg(long, num_args = 1..)]
    pub lambda_nm: Vec<f64>,
    /// The full matrix (every height, angle and wavelength above), with no time budget
    /// unless --budget-s is given.
    #[arg(long)]
    pub full: bool,
    /// Time budget (s): cells whose estimated cost does not fit what is left are reported
    /// as skipped, with that estimate [default: 60; none with --full].
    #[arg(long)]
    pub budget_s: Option<f64>,
    /// Leave out the model axis (the scalar model against the rigorous solver).
    #[arg(long)]
    pub no_model: bool,
    /// Fixed term counts to show beside auto.
    #[arg(long, num_args = 0.., default_values_t = [30usize])]
    pub fixed_terms: Vec<usize>,
    /// Tolerance on ρ/C = |P̂|².
    #[arg(long, default_value_t = crate::brdf::truncation::DEFAULT_TOLERANCE)]
    pub tolerance: f64,
    /// Skip the GPU evaluator.
    #[arg(long)]
    pub no_gpu: bool,
    /// GPU map side in pixels.
    #[arg(long, default_value_t = 15)]
    pub map_size: u32,
    /// Output directory: stability.md, stability.csv, stability.png.
    #[arg(short, long, default_value = "stability")]
    pub out: PathBuf,
}

/// Smallest `--tolerance` the matrix judges: a float32 evaluation of ρ/C (a GPU map, a
/// table variant) carries rounding of a few 1e-7 relative to a mirror's specular value, so
/// a cell could never pass a finer tolerance.
pub const MIN_TOLERANCE: f64 = 1e-6;

/// A result for people: `1.23e-4`, or `none`.
fn sci(x: Option<f64>) -> String {
    x.map_or_else(|| "none".to_string(), |v| format!("{v:.2e}"))
}

/// Share of the time budget the spectral matrix may take when the model axis runs after it.
const MATRIX_SHARE: f64 = 0.75;

/// Runs `diffract stability`. The budget's clock starts with the run: the height field,
/// the device and the steps that do not divide into cells (the lighting and table cases)
/// come first, and the matrix and the model axis share what is left of the budget; a run
/// that still ends more than 20 % over it says why in one warning line.
pub fn run(args: &StabilityArgs) -> Result<()> {
    stability_args(args)?;
    let start = Instant::now();
    let beat = heartbeat::Heartbeat::start(start);
    beat.step("loading the height field");
    let mut spec = matrix_spec(args)?;
    let mut steps = Steps {
        keeper: Keeper::new(start, spec.budget_s),
        last: 0.0,
    };
    steps.done("loading the height field", &beat);
    beat.step("opening the device");
    let mut renderer = if args.no_gpu {
        spec.evaluators = vec![Evaluator::Model];
        None
    } else {
        Some(Renderer::new(spec.validation)?)
    };
    steps.done("opening the device", &beat);
    let device = renderer
        .as_ref()
        .map_or("none".to_string(), |r| r.device_name().to_string());
    let budget = spec.budget_s;
    beat.step("the lighting cases");
    let lighting_cells = match renderer.as_mut() {
        Some(r) => {
            let cells = lighting::run(r)?;
            if r.validation_messages() > 0 {
                return Err(Error::Validation(r.validation_messages()));
            }
            cells
        }
        None => Vec::new(),
    };
    steps.done("the lighting cases", &beat);
    beat.step("the table cases");
    let table_cells = run_table_cases(&spec)?;
    steps.done("the table cases", &beat);
    if let Some(r) = renderer.as_mut() {
        beat.step("building the GPU pipelines");
        let n = build_pipelines(&spec, r)?;
        steps.done("building the GPU pipelines", &beat);
        beat.line(&format!("stability: {n} GPU pipeline(s) built"));
    }
    let before_cells = beat.elapsed_s();
    beat.line(&format!(
        "stability: setup in {before_cells:.1} s{}",
        match budget {
            Some(b) => format!(
                "; {:.1} s of the {b} s budget left for the cells",
                (b - before_cells).max(0.0)
            ),
            None => String::new(),
        }
    ));
    let left = budget.map(|b| (b - before_cells).max(0.0));
    let matrix = MatrixSpec {
        budget_s: left.map(|l| if args.no_model { l } else { l * MATRIX_SHARE }),
        ..spec.clone()
    };
    let total = points(&spec).len();
    let mut done = 0;
    let matrix_start = Instant::now();
    beat.step("the spectral matrix");
    let cells = run_matrix(&matrix, renderer.as_mut(), |c| {
        done += 1;
        beat.step(format!("the spectral matrix, {done}/{total} cells"));
        report_cell(c, done, total, matrix_start, matrix.budget_s, &beat);
    })?;
    steps.done_within("the spectral matrix", matrix.budget_s, &beat);
    if let Some(r) = &renderer {
        if r.validation_messages() > 0 {
            return Err(Error::Validation(r.validation_messages()));
        }
    }
    let model_cells = if args.no_model {
        Vec::new()
    } else {
        beat.step("the model axis");
        let deadline = budget.map(|b| start + std::time::Duration::from_secs_f64(b));
        let model = validity::ScalarModel::of(&material(&spec, Expansion::Taylor, Terms::Auto));
        let cells = model_axis::run(&spec, &model, deadline, |_| ())?;
        steps.done("the model axis", &beat);
        cells
    };
    if let Some(line) = steps.keeper.broken("stability", beat.elapsed_s()) {
        eprintln!("warning: {line}");
    }
    drop(beat);
    let secs = start.elapsed().as_secs_f64();
    let skipped = cells.iter().filter(|c| c.status == Status::Skipped).count();
    let header = format!(
        "Field: {}; tolerance {:.0e} on ρ/C; window R = {}, coherence {} µm; GPU: {device}, \
         {}² spectral maps; {total} cells in {secs:.0} s{}.",
        spec.field_name,
        spec.tolerance,
        spec.window_radius,
        spec.coherence_um,
        spec.map_size,
        match (skipped, budget) {
            (0, _) | (_, None) => String::new(),
            (n, Some(b)) => format!(
                ", {n} skipped by the {b:.0} s budget (--full or a larger --budget-s runs them)"
            ),
        }
    );
    let reports = Reports {
        cells: &cells,
        table_cells: &table_cells,
        lighting_cells: &lighting_cells,
        model_cells: &model_cells,
        header: &header,
    };
    write_reports(&args.out, &spec, &reports)?;
    print_results(&spec, &reports, &args.out)
}

/// What a run found, for its files and its stdout.
struct Reports<'a> {
    cells: &'a [Cell],
    table_cells: &'a [TableCell],
    lighting_cells: &'a [lighting::LightingCell],
    model_cells: &'a [model_axis::ModelCell],
    header: &'a str,
}

/// The results on stdout: table-case failures, the header, the summaries; an error when any
/// cell is silently wrong.
fn print_results(spec: &MatrixSpec, r: &Reports, out: &Path) -> Result<()> {
    for c in r.table_cells.iter().filter(|c| c.status == Status::Fail) {
        println!(
            "FAIL: {} on {}, h_max {} µm: error {}",
            c.variant,
            c.case,
            c.h_max_um,
            sci(c.error)
        );
    }
    println!("{}", r.header);
    println!("{}", summary(spec, r.cells).join("\n"));
    for line in lighting::summary(r.lighting_cells) {
        println!("{line}");
    }
    if !r.model_cells.is_empty() {
        println!("{}", model_axis::summary(r.model_cells));
    }
    println!("→ {}/stability.{{md,csv,png}}", out.display());
    let fails = r.cells.iter().filter(|c| c.status == Status::Fail).count()
        + r.table_cells
            .iter()
            .filter(|c| c.status == Status::Fail)
            .count()
        + r.lighting_cells
            .iter()
            .filter(|c| c.status == Status::Fail)
            .count();
    if fails > 0 {
        return Err(Error::invalid(
            "stability",
            format!("{fails} cell(s) silently wrong (FAIL); see the report"),
        ));
    }
    Ok(())
}

/// The matrix the arguments ask for: the field (the default sinusoid unless
/// `--heightfield`) and the axes.
fn matrix_spec(args: &StabilityArgs) -> Result<MatrixSpec> {
    let (field, name, period) = match &args.heightfield {
        Some(src) => (
            crate::heightfield::Source {
                dh_um: args.dh_um,
                channel: args.channel.clone(),
                level: args.level.clone(),
                ..crate::heightfield::Source::new(src.as_str())
            }
            .load(&crate::report::Stderr)?,
            src.clone(),
            None,
        ),
        None => {
            let (f, p) = default_field()?;
            (
                f,
                "128² sinusoid, period 1.6 µm, dH 50 nm".to_string(),
                Some(p),
            )
        }
    };
    let mut spec = MatrixSpec::full(field, &name, period);
    let axis = |given: &[f64], quick: &[f64], full: &[f64]| match (given.is_empty(), args.full) {
        (false, _) => given.to_vec(),
        (true, true) => full.to_vec(),
        (true, false) => quick.to_vec(),
    };
    spec.h_max_um = axis(&args.h_max_um, &QUICK_H_MAX_UM, &H_MAX_UM);
    spec.theta_i_deg = axis(&args.theta_i, &QUICK_THETA_I_DEG, &THETA_I_DEG);
    spec.lambdas_nm = axis(&args.lambda_nm, &QUICK_LAMBDAS_NM, &LAMBDAS_NM);
    spec.budget_s = args.budget_s.or((!args.full).then_some(DEFAULT_BUDGET_S));
    spec.tolerance = args.tolerance;
    spec.map_size = args.map_size;
    spec.terms_modes = std::iter::once(Terms::Auto)
        .chain(args.fixed_terms.iter().map(|&t| Terms::Fixed(t)))
        .collect();
    Ok(spec)
}

/// How long each step of a run took, for the explanation of an overrun.
/// The run's steps, timed against the budget (which leaves out whole cells only).
struct Steps {
    keeper: Keeper<()>,
    last: f64,
}

impl Steps {
    /// Records `name` as ending now.
    fn done(&mut self, name: &'static str, beat: &heartbeat::Heartbeat) {
        self.done_within(name, None, beat);
    }

    /// Records `name`, given `budget_s` of its own, as ending now.
    fn done_within(&mut self, name: &str, budget_s: Option<f64>, beat: &heartbeat::Heartbeat) {
        let now = beat.elapsed_s();
        self.keeper.timed(name, budget_s, now - self.last);
        self.last = now;
    }
}

/// A failing cell at once on stdout (a result, for people), and progress on stderr: a
/// line every 20 cells with the time taken and an estimate of the time left (the pace so
/// far, at most the budget left).
fn report_cell(
    c: &Cell,
    done: usize,
    total: usize,
    start: Instant,
    budget_s: Option<f64>,
    beat: &heartbeat::Heartbeat,
) {
    if c.status == Status::Fail {
        println!(
            "FAIL: {}, h_max {} µm, θi {}°, λ {} nm, {} {} {}: error {}, float32 error {} (bound {})",
            c.variant,
            c.h_max_um,
            c.theta_i_deg,
            c.lambda_nm,
            c.expansion,
            c.terms_mode,
            c.evaluator,
            sci(c.error),
            sci(c.f32_error),
            sci(c.f32_bound)
        );
    }
    if done.is_multiple_of(20) || done == total {
        let secs = start.elapsed().as_secs_f64();
        let mut left = secs / done as f64 * (total - done) as f64;
        if let Some(b) = budget_s {
            left = left.min((b - secs).max(0.0));
        }
        beat.line(&format!(
            "stability: {done}/{total} cells, {secs:.0} s, about {left:.0} s left"
        ));
    }
}

/// Writes [`STABILITY_FILES`] into `dir` (created unless it exists).
fn write_reports(dir: &Path, spec: &MatrixSpec, r: &Reports) -> Result<()> {
    crate::fsutil::create_output_dir(dir)?;
    crate::fsutil::write_atomic(&dir.join("stability.csv"), to_csv(r.cells).as_bytes())?;
    let mut md = to_markdown(spec, r.cells, r.header) + &table_cases_markdown(spec, r.table_cells);
    if !r.lighting_cells.is_empty() {
        md += &lighting::to_markdown(r.lighting_cells);
    }
    if !r.model_cells.is_empty() {
        md += &model_axis::to_markdown(spec, r.model_cells);
        crate::fsutil::write_atomic(
            &dir.join("stability-model.csv"),
            model_axis::to_csv(r.model_cells).as_bytes(),
        )?;
    }
    crate::fsutil::write_atomic(&dir.join("stability.md"), md.as_bytes())?;
    write_png(spec, r.cells, &dir.join("stability.png"))
}

fn opt(x: Option<f64>) -> String {
    x.map_or(String::new(), |v| format!("{v:.3e}"))
}

/// One CSV row per cell.
pub fn to_csv(cells: &[Cell]) -> String {
    let mut s = String::from(
        "h_max_um,theta_i_deg,lambda_nm,expansion,terms_mode,evaluator,expansion_used,terms_used,status,error,bound,f32_error,f32_bound,worst_probe,message,variant\n",
    );
    for c in cells {
        let (eu, tu) = c.used.map_or((String::new(), String::new()), |(e, t)| {
            (e.to_string(), t.to_string())
        });
        s += &format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},\"{}\",\"{}\",{}\n",
            c.h_max_um,
            c.theta_i_deg,
            c.lambda_nm,
            c.expansion,
            c.terms_mode,
            c.evaluator,
            eu,
            tu,
            c.status,
            opt(c.error),
            opt(c.bound),
            opt(c.f32_error),
            opt(c.f32_bound),
            c.worst_probe.replace('"', "'"),
            c.message.replace('"', "'"),
            c.variant
        );
    }
    s
}

/// One configuration of the matrix: a table of the markdown, a group of the PNG's columns.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Config {
    variant: VariantKind,
    expansion: Expansion,
    terms: Terms,
    evaluator: Evaluator,
}

impl Config {
    fn holds(&self, c: &Cell) -> bool {
        c.variant == self.variant
            && c.expansion == self.expansion
            && c.terms_mode == self.terms
            && c.evaluator == self.evaluator
    }
}

/// The configurations in run order.
fn configs(spec: &MatrixSpec) -> Vec<Config> {
    let mut v = Vec::new();
    for (variant, _) in spectral_variants() {
        for &expansion in &spec.expansions {
            for &terms in &spec.terms_modes {
                for &evaluator in &spec.evaluators {
                    v.push(Config {
                        variant,
                        expansion,
                        terms,
                        evaluator,
                    });
                }
            }
        }
    }
    v
}

/// Per configuration: which `h_max` is the last where every cell passes, and the
/// refusals/warnings; the lines the README quotes.
pub fn summary(spec: &MatrixSpec, cells: &[Cell]) -> Vec<String> {
    let mut out = Vec::new();
    for cfg in configs(spec) {
        let mine: Vec<&Cell> = cells.iter().filter(|c| cfg.holds(c)).collect();
        let count = |s: Status| mine.iter().filter(|c| c.status == s).count();
        let worst = |s: Status| {
            mine.iter()
                .filter(|c| c.status == s)
                .filter_map(|c| c.error)
                .fold(0.0, f64::max)
        };
        let trusted_up_to = spec
            .h_max_um
            .iter()
            .take_while(|&&h| {
                mine.iter()
                    .filter(|c| c.h_max_um == h)
                    .all(|c| c.status == Status::Pass)
            })
            .last();
        let Config {
            variant,
            expansion: e,
            terms: t,
            evaluator: ev,
        } = cfg;
        out.push(format!(
            "{variant} {e} T={t} {ev}: pass {}, warned {} (worst error {:.1e}), refused {}, FAIL {}{}; \
             {}; worst passing error {:.1e}",
            count(Status::Pass),
            count(Status::Warned),
            worst(Status::Warned),
            count(Status::Refused),
            count(Status::Fail),
            match count(Status::Skipped) {
                0 => String::new(),
                n => format!(", skipped by the budget {n}"),
            },
            trusted_up_to.map_or("no height passes in every cell".to_string(), |h| format!(
                "every cell passes up to h_max = {h} µm"
            )),
            worst(Status::Pass)
        ));
    }
    out
}

/// Markdown: one table per configuration, rows `h_max`, columns `θi`, each entry the
/// worst cell over wavelength: error (`T`, expansion letter) or the status.
pub fn to_markdown(spec: &MatrixSpec, cells: &[Cell], header: &str) -> String {
    let mut s = format!(
        "# Stability matrix\n\n{header}\n\nEach entry: the worst over λ ∈ {:?} nm of \
         max |ρ − ρ_ref|/C (error relative to a mirror's specular value), then T and the \
         expansion used (T = Taylor, C = Chebyshev), `!` = warned, `refused` = refused, \
         `skipped` = left out by the time budget, `FAIL` = silently wrong.\n\n",
        spec.lambdas_nm
    );
    for line in summary(spec, cells) {
        s += &format!("- {line}\n");
    }
    for kind in VariantKind::ALL {
        if let Stability::Excluded(why) = kind.implementation().stability() {
            s += &format!("- not in the spectral matrix: {kind}, which {why}\n");
        }
    }
    for cfg in configs(spec) {
        s += &format!(
            "\n### {}: {}, preferred {}, T = {}\n\n| h_max (µm) |",
            cfg.variant, cfg.evaluator, cfg.expansion, cfg.terms
        );
        s += &theta_columns(spec);
        for &h in &spec.h_max_um {
            s += &format!("| {h} |");
            for &th in &spec.theta_i_deg {
                let group: Vec<&Cell> = cells
                    .iter()
                    .filter(|c| c.h_max_um == h && c.theta_i_deg == th && cfg.holds(c))
                    .collect();
                s += &format!(" {} |", entry(&group));
            }
            s += "\n";
        }
    }
    s
}

/// The rest of a table's header after its `| h_max (µm) |` cell: a column per `θi`, and
/// the rule under it.
fn theta_columns(spec: &MatrixSpec) -> String {
    let mut s = String::new();
    for th in &spec.theta_i_deg {
        s += &format!(" θi = {th}° |");
    }
    s + "\n|---|" + &"---|".repeat(spec.theta_i_deg.len()) + "\n"
}

fn entry(group: &[&Cell]) -> String {
    if group.is_empty() {
        return String::new();
    }
    if group.iter().any(|c| c.status == Status::Fail) {
        let e = group
            .iter()
            .filter(|c| c.status == Status::Fail)
            .filter_map(|c| c.error)
            .fold(0.0, f64::max);
        return format!("FAIL {e:.1e}");
    }
    if group.iter().all(|c| c.status == Status::Refused) {
        return "refused".into();
    }
    if group.iter().all(|c| c.status == Status::Skipped) {
        return "skipped".into();
    }
    let worst = group
        .iter()
        .filter(|c| c.error.is_some())
        .max_by(|a, b| a.error.unwrap_or(0.0).total_cmp(&b.error.unwrap_or(0.0)));
    let Some(w) = worst else {
        return String::new();
    };
    let (exp, t) = w.used.unwrap_or((w.expansion, 0));
    let letter = match exp {
        Expansion::Taylor => "T",
        Expansion::Chebyshev => "C",
    };
    let count = |s: Status| group.iter().filter(|c| c.status == s).count();
    let warned = group.iter().any(|c| c.status == Status::Warned);
    let mut out = format!(
        "{:.1e} ({t}{letter}){}",
        w.error.unwrap_or(0.0),
        if warned { "!" } else { "" }
    );
    for (n, what) in [
        (count(Status::Refused), "refused"),
        (count(Status::Skipped), "skipped"),
    ] {
        if n > 0 {
            out += &format!(" +{n} {what}");
        }
    }
    out
}

/// The heat map: one row per (h_max, θi) — h_max rising upwards, θi rising within each —
/// one column per (configuration, λ) in the markdown's order, labelled in groups
/// (variant and evaluator, terms, expansion, λ); colour = log10 error, grey = refused or
/// skipped by the budget.
pub fn write_png(spec: &MatrixSpec, cells: &[Cell], path: &Path) -> Result<()> {
    let cfg = configs(spec);
    let cols = cfg.len() * spec.lambdas_nm.len();
    let rows = spec.h_max_um.len() * spec.theta_i_deg.len();
    let values = heat_values(spec, &cfg, cells);
    let n_l = spec.lambdas_nm.len() as f64;
    let x_ticks = (0..cols)
        .map(|c| {
            let l = spec.lambdas_nm[c % spec.lambdas_nm.len()];
            (c as f64 + 0.5, format!("{l}"))
        })
        .collect();
    let n_th = spec.theta_i_deg.len();
    let y_ticks = (0..rows)
        .map(|r| {
            let t = spec.theta_i_deg[r % n_th];
            (r as f64 + 0.5, format!("{t}°"))
        })
        .collect();
    let heights = (0..spec.h_max_um.len())
        .map(|i| {
            let h = spec.h_max_um[i];
            let (a, b) = ((i * n_th) as f64, ((i + 1) * n_th) as f64);
            (a, b, format!("{h} µm"))
        })
        .collect();
    let between = |group: f64, count: usize| (1..count).map(|i| i as f64 * group).collect();
    let title = format!(
        "Stability: error against the f64 reference, {} (tolerance {:.0e})",
        crate::plot::source_name(&spec.field_name),
        spec.tolerance
    );
    crate::plot::write_heat_map(
        path,
        &crate::plot::HeatMap {
            title,
            values: &values,
            x: (0.0, cols as f64),
            y: (0.0, rows as f64),
            x_axis: crate::plot::Axis {
                label: "λ (nm), by evaluator, terms and expansion".into(),
                ticks: x_ticks,
                groups: column_groups(spec, &cfg),
                rules: between(n_l, cfg.len()),
            },
            y_axis: crate::plot::Axis {
                label: "h_max (peak to valley), θi within each".into(),
                ticks: y_ticks,
                groups: vec![heights],
                rules: between(n_th as f64, spec.h_max_um.len()),
            },
            log: true,
            scale_label: "log₁₀ max |ρ − ρ_ref| / C".into(),
            // Errors of the size of the mirror's peak and beyond are all simply wrong.
            scale_limits: (None, Some(0.0)),
            scale_marks: vec![(spec.tolerance.log10(), "tolerance".into())],
            missing_label: Some("refused or skipped".into()),
            curves: Vec::new(),
            size: (
                (cols as u32 * 30 + 330).clamp(700, 1400),
                (rows as u32 * 18 + 230).clamp(450, 1100),
            ),
        },
    )
}

/// The heat map's cells: row (h_max, θi), column (configuration, λ); NaN where refused.
fn heat_values(spec: &MatrixSpec, cfg: &[Config], cells: &[Cell]) -> Vec<Vec<f64>> {
    let cols = cfg.len() * spec.lambdas_nm.len();
    let rows = spec.h_max_um.len() * spec.theta_i_deg.len();
    let mut values = vec![vec![f64::NAN; cols]; rows];
    for c in cells {
        let (Some(hi), Some(ti), Some(li), Some(ci)) = (
            spec.h_max_um.iter().position(|&h| h == c.h_max_um),
            spec.theta_i_deg.iter().position(|&t| t == c.theta_i_deg),
            spec.lambdas_nm.iter().position(|&l| l == c.lambda_nm),
            cfg.iter().position(|k| k.holds(c)),
        ) else {
            continue;
        };
        let row = hi * spec.theta_i_deg.len() + ti;
        let col = ci * spec.lambdas_nm.len() + li;
        values[row][col] = c.error.map_or(f64::NAN, |e| e.max(1e-16));
    }
    values
}

/// Column groups, innermost first: variant and evaluator, terms, expansion; each spans the
/// configurations that share it ([`configs`] nests variant > expansion > terms >
/// evaluator).
fn column_groups(spec: &MatrixSpec, cfg: &[Config]) -> Vec<Vec<(f64, f64, String)>> {
    let n_l = spec.lambdas_nm.len() as f64;
    let (n_ev, n_t) = (spec.evaluators.len(), spec.terms_modes.len());
    // Groups of `inner` consecutive configurations, named by their first.
    let groups = |inner: usize, name: &dyn Fn(&Config) -> String| {
        (0..cfg.len() / inner)
            .map(|i| {
                let width = inner as f64 * n_l;
                (
                    i as f64 * width,
                    (i + 1) as f64 * width,
                    name(&cfg[i * inner]),
                )
            })
            .collect()
    };
    let many = spectral_variants().len() > 1;
    vec![
        groups(1, &|c| {
            let ev = match c.evaluator {
                Evaluator::Model => "f64 model",
                Evaluator::Gpu => "GPU f32",
            };
            if many {
                format!("{} {ev}", c.variant)
            } else {
                ev.to_string()
            }
        }),
        groups(n_ev, &|c| match c.terms {
            Terms::Auto => "auto terms".to_string(),
            Terms::Fixed(t) => format!("T = {t}"),
        }),
        groups(n_ev * n_t, &|c| {
            match c.expansion {
                Expansion::Taylor => "Taylor",
                Expansion::Chebyshev => "Chebyshev",
            }
            .to_string()
        }),
    ]
}

/// The narrow regions of the table cases: what a distant camera on a plane reaches (`w`
/// within ±0.0025), and one narrow in `u` or `v` with a wide `w` (a thin strip of view).
/// Centred on the first order of the default field at 520 nm under light at 30° viewed at
/// 10° on the mirror side: `(u, v, w) = (−0.326, 0, −1.851)`.
pub const TABLE_CASES: [(&str, [f64; 3]); 3] = [
    ("narrow w", [0.02, 0.02, 0.0025]),
    ("narrow u", [0.0025, 0.02, 0.3]),
    ("narrow v", [0.02, 0.0025, 0.3]),
];

/// One table variant on one narrow region at one height.
#[derive(Debug, Clone, PartialEq)]
pub struct TableCell {
    pub variant: VariantKind,
    pub case: &'static str,
    pub h_max_um: f64,
    pub status: Status,
    /// Max `|G_f32 − G|` over the probes (absolute; a mirror's specular `G_Y` is 1), with
    /// `G_f32` the representation evaluated in float32 as its shader does (the variant's
    /// own mirror of it) and `G` sampled exactly there.
    pub error: Option<f64>,
    /// A refusal's expected error.
    pub expected: Option<f64>,
    /// The largest exact `G` (any channel) over the probes: the signal the error is of.
    pub peak: f64,
    pub message: String,
}

/// The variants in the table cases, with their float32 mirrors, in registry order.
pub(crate) fn table_variants() -> Vec<(VariantKind, TableMirror)> {
    VariantKind::ALL
        .into_iter()
        .filter_map(|k| match k.implementation().stability() {
            Stability::Table(mirror) => Some((k, mirror)),
            _ => None,
        })
        .collect()
}

/// `G` sampled exactly on one narrow region at the probes' `w`.
struct ExactCase {
    spec: TableSpec,
    /// `w` strictly between the nodes of every representation.
    probes: Vec<f64>,
    exact: crate::brdf::table::Slices,
    peak: f64,
}

impl ExactCase {
    /// The region of half-widths `half` around the first order of [`TABLE_CASES`].
    fn sample(hf: &HeightField, coherence_um: f64, half: [f64; 3]) -> Result<Self> {
        let centre = crate::brdf::uvw(direction(30.0, 0.0), direction(10.0, 180.0));
        let region = Region {
            lo: [0, 1, 2].map(|a| centre[a] - half[a]),
            hi: [0, 1, 2].map(|a| centre[a] + half[a]),
        };
        let probes: Vec<f64> = [0.137, 0.391, 0.503, 0.777, 0.951]
            .iter()
            .map(|f| region.lo[2] + f * (region.hi[2] - region.lo[2]))
            .collect();
        let spec = TableSpec {
            region,
            texel_uv: 0.005,
            w_nodes: probes.len(),
            step_nm: 10,
            response: crate::brdf::table::Response::Relative,
        };
        let exact = crate::brdf::table::sample_g(hf, coherence_um, &spec, &probes, &|| ())?;
        let peak = exact
            .data
            .iter()
            .flatten()
            .flatten()
            .fold(0.0f64, |m, x| m.max(*x));
        Ok(Self {
            spec,
            probes,
            exact,
            peak,
        })
    }

    /// Max `|G_f32 − G|` of `eval` over the probes and the `(u, v)` nodes.
    fn worst(&self, eval: &dyn Fn(usize, f64) -> [f64; 3]) -> f64 {
        let mut worst = 0.0f64;
        for (k, &w) in self.probes.iter().enumerate() {
            for (t, want) in self.exact.data[k].iter().enumerate() {
                let got = eval(t, w);
                for c in 0..3 {
                    let e = (got[c] - want[c]).abs();
                    worst = worst.max(if e.is_finite() { e } else { f64::INFINITY });
                }
            }
        }
        worst
    }
}

/// Every table variant on [`TABLE_CASES`] for every `h_max` of `spec`: each representation
/// built as `render` builds it (its default `w` nodes, raised for the height where the
/// variant's nodes follow the field), probed at its `(u, v)` nodes (the `(u, v)`
/// interpolation is the profile's business) and at `w` between its nodes, in float32 on
/// the CPU by the variant's own mirror, against `G` sampled exactly at those `w`. A cell
/// passes within the tolerance, is refused where the variant refuses, and fails otherwise.
pub fn run_table_cases(spec: &MatrixSpec) -> Result<Vec<TableCell>> {
    let variants = table_variants();
    let mut cells = Vec::new();
    for &h in &spec.h_max_um {
        let hf = scaled(&spec.field, h)?;
        for (case, half) in TABLE_CASES {
            let exact = ExactCase::sample(&hf, spec.coherence_um, half)?;
            for &(kind, mirror) in &variants {
                cells.push(table_cell(spec, &hf, &exact, kind, mirror, case, h)?);
            }
        }
    }
    Ok(cells)
}

/// One variant on one exact case.
fn table_cell(
    spec: &MatrixSpec,
    hf: &HeightField,
    exact: &ExactCase,
    kind: VariantKind,
    mirror: TableMirror,
    case: &'static str,
    h_max_um: f64,
) -> Result<TableCell> {
    let (lo, hi) = hf.range();
    let region = exact.spec.region;
    let w_nodes =
        TableOptions::default().w_nodes_for_field(kind, hi - lo, [region.lo[2], region.hi[2]]);
    let tspec = TableSpec {
        w_nodes,
        ..exact.spec
    };
    let mut cell = TableCell {
        variant: kind,
        case,
        h_max_um,
        status: Status::Refused,
        error: None,
        expected: None,
        peak: exact.peak,
        message: String::new(),
    };
    match mirror(hf, spec.coherence_um, &tspec, spec.tolerance)? {
        Mirrored::Refused { expected, message } => {
            cell.expected = Some(expected);
            cell.message = message;
        }
        Mirrored::Eval(eval) => {
            let worst = exact.worst(&*eval);
            cell.error = Some(worst);
            cell.status = if worst <= spec.tolerance {
                Status::Pass
            } else {
                Status::Fail
            };
        }
    }
    Ok(cell)
}

/// Markdown of the table cases: one row per case and height, one column per variant.
pub fn table_cases_markdown(spec: &MatrixSpec, cells: &[TableCell]) -> String {
    let variants: Vec<VariantKind> = table_variants().into_iter().map(|v| v.0).collect();
    let mut s = format!(
        "\n## Table variants on narrow regions\n\nEach entry: max |G_f32 − G| (a mirror's specular G_Y is 1; tolerance {:.0e}) of the representation evaluated in float32 as its shader does, at its (u, v) nodes and at w between its nodes, against G sampled exactly there (10 nm); `refused` with the expected error where the variant refuses. Regions centred on (u, v, w) = (−0.326, 0, −1.851), half-widths: narrow w (a distant camera on a plane) ±(0.02, 0.02, 0.0025); narrow u ±(0.0025, 0.02, 0.3); narrow v ±(0.02, 0.0025, 0.3).\n\n| case | h_max (µm) | max G |",
        spec.tolerance
    );
    for k in &variants {
        s += &format!(" {k} |");
    }
    s += &format!("\n|---|---|---|{}\n", "---|".repeat(variants.len()));
    for (case, _) in TABLE_CASES {
        for &h in &spec.h_max_um {
            let mine = |c: &&TableCell| c.case == case && c.h_max_um == h;
            let peak = cells.iter().find(mine).map_or(0.0, |c| c.peak);
            s += &format!("| {case} | {h} | {peak:.1e} |");
            for &kind in &variants {
                let e = cells
                    .iter()
                    .filter(mine)
                    .find(|c| c.variant == kind)
                    .map_or(String::new(), |c| match c.status {
                        Status::Refused => {
                            format!("refused (expected {:.1e})", c.expected.unwrap_or(f64::NAN))
                        }
                        Status::Fail => format!("FAIL {:.1e}", c.error.unwrap_or(f64::NAN)),
                        _ => format!("{:.1e}", c.error.unwrap_or(f64::NAN)),
                    });
                s += &format!(" {e} |");
            }
            s += "\n";
        }
    }
    s
}

/// Files `diffract stability -o DIR` writes into `DIR`.
pub const STABILITY_FILES: [&str; 4] = [
    "stability.csv",
    "stability.md",
    "stability.png",
    "stability-model.csv",
];

/// `diffract stability`: every number of the matrix (heights, angles, wavelengths, term
/// counts, the tolerance, the map size) and the output directory, whose files must not be
/// the height field or its sidecar.
pub fn stability_args(args: &StabilityArgs) -> Result<()> {
    use crate::brdf::truncation::MAX_TERMS;
    use crate::render::MAX_MAP_SIZE;
    check_axes(args)?;
    for &n in &args.fixed_terms {
        if n > MAX_TERMS {
            return Err(Error::invalid(
                "fixed-terms",
                format!("{n}; at most {MAX_TERMS} terms are supported"),
            ));
        }
    }
    if let Some(dh) = args.dh_um {
        crate::guard::positive("dh-um", dh, " µm")?;
        if args.heightfield.is_none() {
            return Err(Error::invalid(
                "arguments",
                "--dh-um only applies with --heightfield",
            ));
        }
    }
    if !(1..=MAX_MAP_SIZE).contains(&args.map_size) {
        return Err(Error::invalid(
            "map-size",
            format!("{}; expected 1..={MAX_MAP_SIZE} pixels", args.map_size),
        ));
    }
    check_output_dir(args)
}

/// The tolerance, heights, angles and wavelengths.
fn check_axes(args: &StabilityArgs) -> Result<()> {
    let t = args.tolerance;
    if !(t.is_finite() && (MIN_TOLERANCE..1.0).contains(&t)) {
        return Err(Error::invalid(
            "tolerance",
            format!(
                "{t:e}; must be in [{MIN_TOLERANCE:e}, 1): the matrix's float32 evaluators (GPU maps, table variants) resolve no finer error on ρ/C"
            ),
        ));
    }
    if let Some(b) = args.budget_s {
        crate::guard::budget_s(b)?;
    }
    for &h in &args.h_max_um {
        if !(h.is_finite() && h >= 0.0) {
            return Err(Error::invalid(
                "hmax-um",
                format!("{h} µm; must be finite and ≥ 0"),
            ));
        }
    }
    for &th in &args.theta_i {
        if !(th.is_finite() && (0.0..90.0).contains(&th)) {
            return Err(Error::invalid(
                "theta-i",
                format!("{th}°; expected [0, 90)"),
            ));
        }
    }
    let (lo, hi) = (
        crate::colour::LAMBDA_MIN_NM as f64,
        crate::colour::LAMBDA_MAX_NM as f64,
    );
    for &l in &args.lambda_nm {
        crate::guard::in_range("wavelength", l, lo..=hi, " nm")?;
    }
    Ok(())
}

/// The output directory ([`crate::fsutil::check_output_dir`]: an existing directory this
/// process may write, or a new one in such a directory) and its [`STABILITY_FILES`], which
/// must pass the output policy and not be the height field or its sidecar.
fn check_output_dir(args: &StabilityArgs) -> Result<()> {
    let dir = &args.out;
    crate::fsutil::check_output_dir(dir)?;
    let outputs: Vec<(&str, PathBuf)> = STABILITY_FILES
        .iter()
        .map(|f| ("-o", dir.join(f)))
        .collect();
    let inputs = args
        .heightfield
        .as_deref()
        .map(crate::guard::heightfield_inputs)
        .unwrap_or_default();
    if dir.is_dir() {
        crate::guard::check_outputs(&inputs, &outputs)
    } else {
        // A new directory holds no file yet: nothing in it can be an input.
        crate::guard::refuse_overwrite(&inputs, &outputs)
    }
}
