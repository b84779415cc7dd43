//! The matrix's "model" axis: the scalar model itself against Maxwell's equations. For each
//! height and angle of the matrix, the field's dominant 1-D grating is solved rigorously
//! (RCWA, [`crate::validity`]) and the scalar model's worst order-ratio error is reported
//! beside the evaluators' errors against the scalar reference. The evaluators can only be as
//! right as the model they approximate: this axis says how right that is.

use std::fmt::Write as _;
use std::time::Instant;

use super::{scaled, MatrixSpec};
use crate::validity::{self, ScalarModel, Solve, Verdict};
use crate::Result;

/// The rigorous solver's largest angle of incidence (degrees).
pub const MAX_THETA_I_DEG: f64 = 85.0;

/// One (h_max, θi, λ) of the model axis.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelCell {
    pub h_max_um: f64,
    pub theta_i_deg: f64,
    pub lambda_nm: f64,
    /// The scalar model's worst order-ratio error against RCWA; `None` where not solved.
    pub error: Option<f64>,
    /// Why it was not solved, or what the error was measured on.
    pub note: String,
}

impl ModelCell {
    fn verdict(&self) -> &'static str {
        self.error.map_or("", |e| Verdict::of(e).label())
    }
}

/// Solves every (h_max, θi, λ) of `spec` (converged to [`validity::MAP_TOLERANCE`], which
/// sorts 10 % from 25 %). A field without a dominant grating, an angle beyond the solver's
/// and a cell past `deadline` (estimated from the mean cost so far) get a note instead.
/// `progress` is called after each cell.
pub fn run(
    spec: &MatrixSpec,
    model: &ScalarModel,
    deadline: Option<Instant>,
    mut progress: impl FnMut(&ModelCell),
) -> Result<Vec<ModelCell>> {
    let mut cells = Vec::new();
    let (mut spent, mut solved) = (0.0, 0usize);
    for &h in &spec.h_max_um {
        let profile = validity::extract_profile(&scaled(&spec.field, h)?);
        for &theta in &spec.theta_i_deg {
            for &lambda in &spec.lambdas_nm {
                let mut cell = ModelCell {
                    h_max_um: h,
                    theta_i_deg: theta,
                    lambda_nm: lambda,
                    error: None,
                    note: String::new(),
                };
                let est = if solved > 0 {
                    spent / solved as f64
                } else {
                    0.0
                };
                let left = deadline.map(|d| d.saturating_duration_since(Instant::now()));
                match &profile {
                    Err(e) => cell.note = format!("no 1-D grating: {e}"),
                    Ok(_) if theta > MAX_THETA_I_DEG => {
                        cell.note = format!("beyond the rigorous solver's {MAX_THETA_I_DEG}°")
                    }
                    Ok(_) if left.is_some_and(|l| l.is_zero() || l.as_secs_f64() < est) => {
                        cell.note = format!("over the time budget: estimated {est:.1} s")
                    }
                    Ok(p) => {
                        let t = Instant::now();
                        let c = validity::check(
                            p,
                            model,
                            lambda,
                            theta,
                            Solve::Converge(validity::MAP_TOLERANCE),
                        )?;
                        spent += t.elapsed().as_secs_f64();
                        solved += 1;
                        cell.error = Some(c.error);
                        cell.note = c.error_of.clone();
                        // A solve short of the tolerance says so, with its estimated error.
                        let short = c.unconverged(validity::MAP_TOLERANCE).map(|e| {
                            format!(
                                "unconverged at {} orders × {} slices: its orders ±{}",
                                2 * c.harmonics + 1,
                                c.slices,
                                validity::percent(e)
                            )
                        });
                        if let Some(s) = &short {
                            cell.note = if cell.note.is_empty() {
                                s.clone()
                            } else {
                                format!("{}; {s}", cell.note)
                            };
                        }
                        eprintln!(
                            "stability: model h_max {h} µm, θi {theta}°, λ {lambda} nm: {} ({}){}, {:.1} s",
                            validity::percent(c.error),
                            cell.verdict(),
                            short.map_or(String::new(), |s| format!(", {s}")),
                            t.elapsed().as_secs_f64()
                        );
                    }
                }
                progress(&cell);
                cells.push(cell);
            }
        }
    }
    Ok(cells)
}

/// The Markdown section: rows `h_max`, columns `θi`, each entry the errors per wavelength.
pub fn to_markdown(spec: &MatrixSpec, cells: &[ModelCell]) -> String {
    let mut s = String::from(
        "\n## The model against Maxwell's equations\n\nThe scalar model's worst unpolarised \
         order-ratio error against the rigorous solver (RCWA, solves converged to 5 %) for the \
         field's mean 1-D profile, per wavelength: within 10 % the colours and their \
         strengths hold, beyond 25 % only the colours' angles do (`diffract validity`, \
         docs/accuracy.md).\n\n| h_max (µm) |",
    );
    s += &super::theta_columns(spec);
    for &h in &spec.h_max_um {
        let _ = write!(s, "| {h} |");
        for &th in &spec.theta_i_deg {
            let parts: Vec<String> = cells
                .iter()
                .filter(|c| c.h_max_um == h && c.theta_i_deg == th)
                .map(|c| match c.error {
                    Some(e) => format!("{}: {}", c.lambda_nm, validity::percent(e)),
                    None => format!("{}: –", c.lambda_nm),
                })
                .collect();
            let notes: Vec<&str> = cells
                .iter()
                .filter(|c| c.h_max_um == h && c.theta_i_deg == th && c.error.is_none())
                .map(|c| c.note.as_str())
                .collect();
            let entry = match notes.first() {
                Some(n) if notes.len() == parts.len() => n.to_string(),
                _ => parts.join(", "),
            };
            let _ = write!(s, " {} |", entry.replace('|', "/"));
        }
        s += "\n";
    }
    s
}

/// One CSV row per cell.
pub fn to_csv(cells: &[ModelCell]) -> String {
    let mut s = String::from("h_max_um,theta_i_deg,lambda_nm,error,verdict,note\n");
    for c in cells {
        let _ = writeln!(
            s,
            "{},{},{},{},{},\"{}\"",
            c.h_max_um,
            c.theta_i_deg,
            c.lambda_nm,
            c.error.map_or(String::new(), |e| format!("{e:.4}")),
            c.verdict(),
            c.note.replace('"', "'")
        );
    }
    s
}

/// The summary line: the worst solved error and where.
pub fn summary(cells: &[ModelCell]) -> String {
    let solved: Vec<&ModelCell> = cells.iter().filter(|c| c.error.is_some()).collect();
    let worst = solved
        .iter()
        .max_by(|a, b| a.error.unwrap_or(0.0).total_cmp(&b.error.unwrap_or(0.0)));
    match worst {
        None => {
            // Why none was solved: the note of each cell (skipped by the budget, beyond the
            // solver, refused), counted.
            let mut why: Vec<(String, usize)> = Vec::new();
            for c in cells {
                let note = if c.note.is_empty() { "not solved" } else { c.note.as_str() };
                match why.iter_mut().find(|w| w.0 == note) {
                    Some(w) => w.1 += 1,
                    None => why.push((note.to_string(), 1)),
                }
            }
            let why: Vec<String> = why.iter().map(|(n, k)| format!("{k} {n}")).collect();
            format!(
                "model (scalar theory against RCWA): no cell solved of {}: {}",
                cells.len(),
                why.join("; ")
            )
        }
        Some(w) => format!(
            "model (scalar theory against RCWA): {} of {} cells solved; worst {} ({}) at h_max {} µm, θi {}°, λ {} nm",
            solved.len(),
            cells.len(),
            validity::percent(w.error.unwrap_or(0.0)),
            w.verdict(),
            w.h_max_um,
            w.theta_i_deg,
            w.lambda_nm
        ),
    }
}
