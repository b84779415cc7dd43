//! A profile in progress: the rows in the order the budget favours, each one's warm-up,
//! timed frames, scores and mesh views, and the entry [`profile`].

use std::time::{Duration, Instant};

use super::budget::{Budget, Deadline, FrameTimes, Frames, OverBudget, RowCost};
use super::env::env_rows;
use super::output::{ProfileRun, Skipped, VariantReport};
use super::plan::{EnvProfile, ProfileSetup, Variant};
use super::progress::{row_line, skipped_line, Progress};
use super::score::{mesh_error, mesh_reference, reference_samples, score_map, Samples, Scores};
use super::stats::ErrorStats;
use crate::brdf::direction;
use crate::budget::{Fits, Keeper};
use crate::colour::ColourTable;
use crate::material::{Material, PreparedMaterial};
use crate::render::variant::VariantKind;
use crate::render::Picture;
use crate::render::{Renderer, TableOptions};
use crate::{Error, Result};

/// A profile in progress.
struct Run<'a> {
    setup: &'a ProfileSetup,
    start: Instant,
    /// The budget and what the rows measured so far say about the cost of the next ones.
    keeper: Keeper<RowCost>,
    samples: Option<Samples>,
    table_1nm: ColourTable,
    /// The mesh view by the reference variant at 1 nm, for `--per-vertex`.
    mesh_reference: Option<Vec<[f64; 3]>>,
    progress: Progress,
    /// Per row of `setup.variants`: its report (and its per-vertex twin), or why not.
    done: Vec<Option<RowOutcome>>,
    /// The height field, loaded once for every row.
    heightfield: crate::heightfield::HeightField,
    /// Whether a row was measured (until then the pace is the prior's, and the first row
    /// is measured whatever its estimate).
    measured: bool,
    /// The tables this profile has sampled ([`sample_identity`]): a row whose table differs
    /// from one of them only in its texel format reads the samples from the cache.
    sampled: Vec<String>,
}

/// What a table row's samples depend on among its options: all but the texel format.
fn sample_identity(row: &Variant) -> String {
    format!(
        "{:?} {:?}",
        row.kind,
        TableOptions {
            format: crate::render::TableFormat::Rgba32f,
            ..row.table
        }
    )
}

/// Renders and scores every row. The reference (1 nm, direct sum) is computed once at the
/// sampled pixels, so its cost is `pixels × N² × 401` complex multiply-adds.
pub fn profile(renderer: &mut Renderer, setup: &ProfileSetup) -> Result<ProfileRun> {
    profile_with_env(renderer, setup, None)
}

/// Share of the budget the environment rows may take when variant rows follow them.
const ENV_SHARE: f64 = 0.5;

/// [`profile`], with the environment-lit rows of `env` first (within [`ENV_SHARE`] of the
/// budget when variant rows follow, else all of it). `setup.variants` may be empty when
/// `env` is given.
pub fn profile_with_env(
    renderer: &mut Renderer,
    setup: &ProfileSetup,
    env: Option<&EnvProfile>,
) -> Result<ProfileRun> {
    if setup.variants.is_empty() && env.is_none() {
        return Err(Error::invalid("variants", "none to profile"));
    }
    if setup.pixels + setup.brightest == 0 || setup.frames == Frames::Fixed(0) {
        return Err(Error::invalid(
            "profile",
            "at least one scored pixel and one frame are needed",
        ));
    }
    let start = Instant::now();
    let heightfield = setup.base.load_heightfield(&crate::report::Stderr)?;
    let env_run = match env {
        Some(e) => {
            let share = if setup.variants.is_empty() {
                1.0
            } else {
                ENV_SHARE
            };
            let end = match setup.frames {
                Frames::Budget(b) => Some(start + Duration::from_secs_f64(share * b.total_s)),
                Frames::Fixed(_) => None,
            };
            let size = setup.size;
            Some(env_rows(
                renderer,
                &heightfield,
                &setup.base,
                size,
                setup.frames,
                e,
                end,
            )?)
        }
        None => None,
    };
    let mut out = if setup.variants.is_empty() {
        ProfileRun::default()
    } else {
        variant_rows(renderer, setup, heightfield, start)?
    };
    out.env = env_run;
    out.wall_s = start.elapsed().as_secs_f64();
    Ok(out)
}

/// The variant rows of `setup`, the budget counted from `start`.
fn variant_rows(
    renderer: &mut Renderer,
    setup: &ProfileSetup,
    heightfield: crate::heightfield::HeightField,
    start: Instant,
) -> Result<ProfileRun> {
    let total_s = match setup.frames {
        Frames::Budget(b) => Some(b.total_s),
        Frames::Fixed(_) => None,
    };
    let mut run = Run {
        setup,
        start,
        heightfield,
        measured: false,
        sampled: Vec::new(),
        keeper: RowCost::keeper(start, total_s),
        samples: None,
        table_1nm: ColourTable::new(1)?,
        mesh_reference: None,
        progress: Progress::new(setup.variants.len()),
        done: vec![None; setup.variants.len()],
    };
    renderer.set_keep_models(true);
    renderer.set_cache_dir(setup.cache_dir.clone());
    let result = run.rows(renderer);
    renderer.set_keep_models(false);
    renderer.set_leave_out(false);
    renderer.set_report(std::sync::Arc::new(crate::report::Stderr));
    result?;
    if let Some(line) = run.keeper.broken("profile", start.elapsed().as_secs_f64()) {
        eprintln!("warning: {line}");
    }
    let mut out = ProfileRun::default();
    for row in run.done.into_iter().flatten() {
        match row {
            RowOutcome::Measured(reports) => out.reports.extend(reports),
            RowOutcome::Skipped(skipped) => out.skipped.push(skipped),
        }
    }
    out.scored = run.samples.as_ref().map_or(0, |s| s.0.len());
    Ok(out)
}

impl Run<'_> {
    /// The mesh reference, then every row (budgeted: the default variant's first, then the
    /// rest cheapest first).
    fn rows(&mut self, renderer: &mut Renderer) -> Result<()> {
        if self.progress.bar.is_none() {
            let how = match self.setup.frames {
                Frames::Fixed(n) => format!("{n} frames a row"),
                Frames::Budget(b) => format!("a budget of {:.0} s", b.total_s),
            };
            eprintln!(
                "profile: {} rows, {how}; a line as each row finishes",
                self.setup.variants.len()
            );
        }
        if let (Some(scene), true) = (&self.setup.mesh, self.setup.per_vertex) {
            self.progress.started("mesh reference (per pixel, 1 nm)");
            self.mesh_reference = Some(mesh_reference(renderer, self.setup, scene)?);
        }
        for i in self.order() {
            let row = &self.setup.variants[i];
            self.progress.started(&row.name);
            let outcome = self.row(renderer, i)?;
            let line = match &outcome {
                RowOutcome::Measured(reports) => row_line(&reports[0]),
                RowOutcome::Skipped(s) => skipped_line(s),
            };
            self.done[i] = Some(outcome);
            let left = self.keeper.left_s();
            self.progress.finished(&line, left);
        }
        Ok(())
    }

    fn budget(&self) -> Option<Budget> {
        match self.setup.frames {
            Frames::Budget(b) => Some(b),
            Frames::Fixed(_) => None,
        }
    }

    /// The order rows are measured in: as given, or, with a budget, the default variant's
    /// row first (the one a user most needs measured), then the rest by estimated cost
    /// (cheapest first, so a tight budget measures as many rows as it can).
    fn order(&self) -> Vec<usize> {
        let mut order: Vec<usize> = (0..self.setup.variants.len()).collect();
        if self.budget().is_some() {
            // Tables by their planes at an assumed pace: fewer planes are tried first.
            let cost: Vec<f64> = self
                .setup
                .variants
                .iter()
                .map(|v| {
                    let (ms, planes) = self.estimate(v);
                    ms + planes as f64 * RowCost::PRIOR_TABLE_MS_PER_PLANE
                })
                .collect();
            let default = |i: usize| {
                let v = &self.setup.variants[i];
                v.kind == VariantKind::DEFAULT && v.name == VariantKind::DEFAULT.name()
            };
            order.sort_by(|&a, &b| {
                default(b)
                    .cmp(&default(a))
                    .then(cost[a].total_cmp(&cost[b]))
            });
        }
        order
    }

    /// Estimated cost of a row's warm-up and one timed frame (ms), with its table's build
    /// once a build's pace is known; and the `(w, λ)` planes its table samples.
    fn estimate(&self, row: &Variant) -> (f64, usize) {
        let material = row.material(&self.setup.base);
        let (lo, hi) = self.heightfield.range();
        let wi = direction(self.setup.theta_i_deg, self.setup.phi_i_deg);
        let inputs = crate::render::variant::FetchInputs {
            terms: row.terms,
            material: &material,
            table: &row.table,
            region: crate::render::variant::map_region(wi),
            h_range_um: hi - lo,
            leave_out: row.leave_out,
            heightfield: None,
        };
        let fetches = row.kind.fetches(&inputs);
        let step = row
            .table
            .step_nm
            .unwrap_or(TableOptions::DEFAULT_STEP_NM)
            .max(1);
        // A table already sampled (with the cache on) is read, not built.
        let read = self.setup.cache_dir.is_some() && self.sampled.contains(&sample_identity(row));
        let planes = match row.kind.footprint(&inputs) {
            Some(Ok(f)) if !read => f.planes * (400 / step as usize + 1),
            _ => 0,
        };
        let k = &self.keeper;
        let build = match planes {
            0 => 0.0,
            p => k.estimate_s(&RowCost::TablePlanes, p as f64).unwrap_or(0.0),
        };
        let frame = RowCost::frame_units(fetches, self.setup.size);
        let s = k.estimate_s(&RowCost::Prepare, 0.0).unwrap_or(0.0)
            + 2.0 * k.estimate_s(&RowCost::Frame, frame).unwrap_or(0.0)
            + build;
        (1e3 * s, planes)
    }

    fn estimate_ms(&self, row: &Variant) -> f64 {
        self.estimate(row).0
    }
}

/// A row's timed frames.
struct Timed {
    times: FrameTimes,
    wall: Vec<f64>,
    last: Picture,
}

/// How a row ended: its report (and its per-vertex twin), or why it was skipped.
#[derive(Clone)]
enum RowOutcome {
    Measured(Vec<VariantReport>),
    Skipped(Skipped),
}

impl Run<'_> {
    /// Measures row `i`: its warm-up (which prepares it), its timed frames, its scores and
    /// its mesh views; or says why it was skipped.
    fn row(&mut self, renderer: &mut Renderer, i: usize) -> Result<RowOutcome> {
        let setup = self.setup;
        let row = &setup.variants[i];
        let skipped = |estimated_s, reason| Skipped {
            variant: row.clone(),
            estimated_s,
            reason,
        };
        let row_start = Instant::now();
        let estimate = self.estimate_ms(row) / 1e3;
        let (deadline, frames_end) = match self.keeper.left_s() {
            None => (None, None),
            Some(allowance) => {
                // Greedy: in that order, each row while its estimate fits what is left (the
                // first row whatever its estimate: the prior's pace is only a guess).
                if let (Fits::No { left_s, .. }, true) =
                    (self.keeper.fits(Some(estimate)), self.measured)
                {
                    let why = format!(
                        "estimated {estimate:.1} s, over the {left_s:.1} s left of the budget"
                    );
                    return Ok(RowOutcome::Skipped(skipped(Some(estimate), why)));
                }
                let rows_left = self.done.iter().filter(|d| d.is_none()).count().max(1);
                let fair = allowance / rows_left as f64;
                let at = |s: f64| row_start + std::time::Duration::from_secs_f64(s);
                (Some(at(allowance)), Some(at(fair.min(allowance))))
            }
        };
        let material = row.material(&setup.base);
        // The terms are computed (or read from the cache) only if the row's variant reads
        // them: a table variant builds from the height field.
        // A row's preset (its T, its R) is the profile's choice, not a flag the user passed:
        // what the planner says of it is a note on the row, in the row's words.
        let said = crate::report::Collect::default();
        let plan = material.plan_loaded(
            &self.heightfield,
            &crate::brdf::truncation::Reach::ALL,
            crate::brdf::truncation::Precision::F32,
            &said,
        );
        for line in said.notes() {
            crate::report::Report::note(&crate::report::Stderr, &line);
        }
        for line in said.warnings() {
            crate::report::Report::note(
                &crate::report::Stderr,
                &format!("profile: {}: {}", row.name, as_preset(&line)),
            );
        }
        let plan = plan?;
        let prepared = material.prepare_planned_deferred(
            self.heightfield.clone(),
            plan,
            setup.cache_dir.as_deref(),
        )?;
        renderer.set_variant(row.kind);
        renderer.set_storage_format(row.storage);
        renderer.set_table_options(row.table);
        renderer.set_leave_out(row.leave_out);
        let warm = match self.warm_up(renderer, &prepared, deadline) {
            Ok(f) => f,
            Err(Warm::Refused(e)) => {
                return Ok(RowOutcome::Skipped(skipped(None, format!("refused: {e}"))))
            }
            Err(Warm::OverBudget(over)) => {
                let est = over.projected_s;
                let steps = over.steps.max(1) as f64;
                self.keeper.learn(&RowCost::TablePlanes, steps, est);
                let took = row_start.elapsed().as_secs_f64();
                self.keeper.timed(&row.name, Some(estimate), took);
                let why = format!(
                    "its table build would take about {est:.0} s, over the time left of the budget (a table built once, by a larger --budget-s or --full, is read from the cache after)"
                );
                return Ok(RowOutcome::Skipped(skipped(Some(est), why)));
            }
            Err(Warm::Failed(e)) => return Err(e),
        };
        let warm_ms = row_start.elapsed().as_secs_f64() * 1e3;
        if warm.variant.table_build.is_some() {
            self.sampled.push(sample_identity(row));
        }
        let timed = self.timed_frames(renderer, &prepared, frames_end)?;
        let built_ms = match &warm.variant.table_build {
            Some(b) if !b.contains("cache") => warm.variant.build_ms,
            _ => 0.0,
        };
        let planes = self.estimate(row).1;
        if built_ms > 0.0 && planes > 0 {
            let k = &mut self.keeper;
            k.learn(&RowCost::TablePlanes, planes as f64, built_ms / 1e3);
        }
        let frame_ms = crate::render::median(timed.wall.clone()).unwrap_or(warm.wall_ms);
        let frame = RowCost::frame_units(warm.variant.fetches, setup.size);
        self.keeper.learn(&RowCost::Frame, frame, frame_ms / 1e3);
        let prepare_ms = (warm_ms - frame_ms - built_ms).max(0.0);
        self.keeper.learn(&RowCost::Prepare, 0.0, prepare_ms / 1e3);
        self.measured = true;
        let scores = self.score(renderer, &prepared, &material, &timed.last)?;
        let outcome = self
            .reports(renderer, row, &prepared, timed, scores)
            .map(|mut reports| {
                for r in &mut reports {
                    r.warm_up_ms = warm_ms;
                }
                RowOutcome::Measured(reports)
            });
        let took = row_start.elapsed().as_secs_f64();
        self.keeper.timed(&row.name, Some(estimate), took);
        outcome
    }

    /// The warm-up frame, which builds (or uploads) the row's resources; with a deadline,
    /// a table build that would end past it is stopped.
    fn warm_up(
        &self,
        renderer: &mut Renderer,
        prepared: &PreparedMaterial,
        deadline: Option<Instant>,
    ) -> std::result::Result<Picture, Warm> {
        renderer.set_report(std::sync::Arc::new(Deadline::new(deadline)));
        let drawn = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            draw_map(renderer, prepared, self.setup)
        }));
        renderer.set_report(std::sync::Arc::new(crate::report::Stderr));
        match drawn {
            Ok(Ok(f)) => Ok(f),
            // A row that refuses this material (nmm without a dominant period).
            Ok(Err(e @ Error::Invalid { .. })) => Err(Warm::Refused(e)),
            Ok(Err(e)) => Err(Warm::Failed(e)),
            Err(payload) => match payload.downcast::<OverBudget>() {
                Ok(over) => Err(Warm::OverBudget(*over)),
                Err(payload) => std::panic::resume_unwind(payload),
            },
        }
    }

    /// The timed frames: a fixed count, or, with a budget, until the median is known to
    /// the budget's precision or the next frame would end past `end`.
    fn timed_frames(
        &self,
        renderer: &mut Renderer,
        prepared: &PreparedMaterial,
        end: Option<Instant>,
    ) -> Result<Timed> {
        let mut times = FrameTimes::default();
        let mut wall: Vec<f64> = Vec::new();
        let mut last = None;
        while self.setup.frames.more(&times, wall.last().copied(), end) {
            let f = draw_map(renderer, prepared, self.setup)?;
            times.0.push(f.gpu_ms.unwrap_or(f.wall_ms));
            wall.push(f.wall_ms);
            last = Some(f);
        }
        let last = last.ok_or_else(|| Error::invalid("profile", "no timed frame"))?;
        Ok(Timed { times, wall, last })
    }
}

/// How a warm-up ended without a frame.
enum Warm {
    Refused(Error),
    OverBudget(OverBudget),
    Failed(Error),
}

/// The row's BRDF map.
fn draw_map(
    renderer: &mut Renderer,
    prepared: &PreparedMaterial,
    setup: &ProfileSetup,
) -> Result<Picture> {
    renderer.render_brdf_map(
        prepared,
        setup.theta_i_deg,
        setup.phi_i_deg,
        setup.size,
        None,
    )
}

impl Run<'_> {
    /// The scored pixels and their reference XYZ, fixed by the first measured row's map.
    fn samples(&mut self, prepared: &PreparedMaterial, frame: &Picture) -> Samples {
        if let Some(s) = &self.samples {
            return s.clone();
        }
        let samples = reference_samples(
            self.setup,
            prepared,
            frame,
            &self.table_1nm,
            self.start,
            self.progress.bar.is_none(),
        );
        self.samples = Some(samples.clone());
        samples
    }

    /// The map's errors against the reference and against the row's own CPU model, and
    /// what its table says about itself.
    fn score(
        &mut self,
        renderer: &Renderer,
        prepared: &PreparedMaterial,
        material: &Material,
        frame: &Picture,
    ) -> Result<Scores> {
        let samples = self.samples(prepared, frame);
        score_map(renderer, self.setup, prepared, material, frame, &samples)
    }
}

impl Run<'_> {
    /// The mesh view of the row's prepared variant: its median GPU time and last picture.
    fn mesh_view(
        &self,
        renderer: &mut Renderer,
        prepared: &PreparedMaterial,
        per_vertex: bool,
        frames: usize,
    ) -> Result<Option<(f64, Vec<[f32; 3]>)>> {
        let Some(scene) = &self.setup.mesh else {
            return Ok(None);
        };
        renderer.set_per_vertex(per_vertex);
        let mut last = renderer.render_scene(scene, prepared)?;
        let mut t = Vec::new();
        for _ in 0..frames.max(1) {
            last = renderer.render_scene(scene, prepared)?;
            t.extend(last.gpu_ms);
        }
        renderer.set_per_vertex(false);
        Ok(crate::render::median(t).map(|ms| (ms, last.rgb)))
    }

    /// A mesh view against the reference variant's mesh render (with `--per-vertex`).
    fn mesh_error(&self, rgb: &[[f32; 3]]) -> Option<ErrorStats> {
        Some(mesh_error(self.mesh_reference.as_ref()?, rgb))
    }

    /// The row's report, after its per-vertex twin's where it has one.
    fn reports(
        &self,
        renderer: &mut Renderer,
        row: &Variant,
        prepared: &PreparedMaterial,
        timed: Timed,
        scores: Scores,
    ) -> Result<Vec<VariantReport>> {
        let frames = timed.wall.len();
        let mesh = self.mesh_view(renderer, prepared, false, frames)?;
        let v = &timed.last.variant;
        let report = VariantReport {
            variant: row.clone(),
            gpu_ms: timed.last.gpu_ms.and_then(|_| timed.times.median()),
            spread_ms: timed.times.quantile(0.1).zip(timed.times.quantile(0.9)),
            frames,
            warm_up_ms: 0.0,
            wall_ms: crate::render::median(timed.wall).unwrap_or(timed.last.wall_ms),
            build_ms: v.build_ms,
            gpu_bytes: v.gpu_bytes,
            fetches: v.fetches,
            detail: match &v.table_build {
                Some(built) => format!("{}, table {built}", v.name),
                None => v.name.clone(),
            },
            mesh_gpu_ms: mesh.as_ref().map(|m| m.0),
            conditioning: scores.conditioning,
            overshoot: scores.overshoot,
            reference_dark: scores.reference_dark,
            vs_reference: scores.vs_reference,
            intervals: scores.intervals,
            vs_model: scores.vs_model,
            mesh_vs_reference: mesh.as_ref().and_then(|m| self.mesh_error(&m.1)),
            per_vertex: false,
        };
        let mut out = vec![report];
        if self.setup.per_vertex && row.kind.per_vertex_file().is_some() {
            if let Some((ms, rgb)) = self.mesh_view(renderer, prepared, true, frames)? {
                let r = &out[0];
                out.push(VariantReport {
                    variant: Variant {
                        name: format!("{} per-vertex", row.name),
                        ..row.clone()
                    },
                    gpu_ms: None,
                    spread_ms: None,
                    wall_ms: 0.0,
                    detail: format!("{} per-vertex", v.name),
                    mesh_gpu_ms: Some(ms),
                    conditioning: None,
                    overshoot: None,
                    mesh_vs_reference: self.mesh_error(&rgb),
                    per_vertex: true,
                    ..r.clone()
                });
            }
        }
        Ok(out)
    }
}

/// A planner warning about a flag's value, said of a profile row's preset: `--terms 30`
/// reads `T = 30`, `--window-radius 1` reads `R = 1`, and the advice to pass another flag
/// goes (the row's measured error says what it costs).
fn as_preset(line: &str) -> String {
    let cut = ["; --terms auto chooses", "; more terms cannot fix it"]
        .iter()
        .filter_map(|c| line.find(c))
        .min()
        .unwrap_or(line.len());
    line[..cut]
        .replacen("--terms ", "T = ", 1)
        .replacen("--window-radius ", "R = ", 1)
}

#[cfg(test)]
mod tests {
    use super::as_preset;

    #[test]
    fn a_row_preset_is_said_without_flags() {
        let t = "--terms 30 with taylor: expected error of ρ/C up to 9.1e-3 (tolerance 1e-3; \
                 k|w|·h = 8.9); --terms auto chooses a sufficient T";
        let s = as_preset(t);
        assert!(s.starts_with("T = 30 with taylor: expected error"), "{s}");
        assert!(!s.contains("--"), "{s}");
        let r = "--window-radius 1: the window (std 0.64 texels) cut at R = 1 alone leaves an \
                 error of ρ/C up to 8.5e-2 (tolerance 1e-3); more terms cannot fix it, R = 2 meets it";
        let s = as_preset(r);
        assert!(
            s.starts_with("R = 1: the window") && !s.contains("--"),
            "{s}"
        );
    }
}
