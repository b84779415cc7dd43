//! Batch BRDF queries (`diffract brdf`): read directions and wavelengths from a CSV file,
//! evaluate the reference or the model, write one result row per query. Scripts and
//! external checks rely on this interface; keep its columns stable.
//!
//! Input columns: `theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm` (tangent frame of
//! MODEL §1; an empty `lambda_nm` integrates the spectrum). Output repeats them and adds
//! `rho,X,Y,Z`: for a spectral row `rho = ρ_λ` and `XYZ` is the per-nm tristimulus density
//! of that line under D65; for an integrated row `rho = Y`.

use std::path::Path;

use rayon::prelude::*;

use crate::colour::{monochromatic_xyz, LAMBDA_MAX_NM, LAMBDA_MIN_NM};
use crate::{Error, Result};

use super::direction;

/// Which evaluator answers the queries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Direct f64 windowed sum (MODEL §6.1): exact, slow.
    Reference,
    /// f64 model of the GPU algorithm (MODEL §6.2) with the material's T, R and Δλ.
    Model,
}

/// One parsed query row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Query {
    pub theta_i_deg: f64,
    pub phi_i_deg: f64,
    pub theta_r_deg: f64,
    pub phi_r_deg: f64,
    /// `None`: integrate over the spectrum.
    pub lambda_nm: Option<f64>,
}

/// One answered query.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Answer {
    pub rho: f64,
    pub xyz: [f64; 3],
}

const COLUMNS: [&str; 5] = [
    "theta_i_deg",
    "phi_i_deg",
    "theta_r_deg",
    "phi_r_deg",
    "lambda_nm",
];

/// Bad rows reported in one error before the list is cut short.
const MAX_REPORTED_ROWS: usize = 20;

/// Parses a query CSV. Errors name the file and the 1-based line of every bad row (the
/// first [`MAX_REPORTED_ROWS`] of them, then how many more), all in one line. A leading
/// UTF-8 byte-order mark is ignored.
pub fn parse_queries(path: &Path, text: &str) -> Result<Vec<Query>> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let Some((hl, header)) = lines.next() else {
        return Err(Error::parse(path, "empty file; expected a header line"));
    };
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    if names != COLUMNS {
        return Err(Error::parse(
            path,
            format!(
                "line {}: header must be '{}', found '{}'",
                hl + 1,
                COLUMNS.join(","),
                header.trim().escape_debug()
            ),
        ));
    }
    let mut out = Vec::new();
    let mut bad: Vec<String> = Vec::new();
    let mut bad_count = 0usize;
    for (i, line) in lines {
        match parse_row(i, line) {
            Ok(q) => out.push(q),
            Err(msg) => {
                bad_count += 1;
                if bad.len() < MAX_REPORTED_ROWS {
                    bad.push(msg);
                }
            }
        }
    }
    if bad_count > 0 {
        let more = bad_count - bad.len();
        let mut msg = format!(
            "{bad_count} bad row{}: {}",
            if bad_count == 1 { "" } else { "s" },
            bad.join("; ")
        );
        if more > 0 {
            msg.push_str(&format!("; and {more} more"));
        }
        return Err(Error::parse(path, msg));
    }
    Ok(out)
}

/// One data row (0-based line index `i`); the error names the 1-based line.
fn parse_row(i: usize, line: &str) -> std::result::Result<Query, String> {
    let at = |msg: String| format!("line {}: {msg}", i + 1);
    let cells: Vec<&str> = line.split(',').map(str::trim).collect();
    if cells.len() != 5 {
        return Err(at(format!("expected 5 columns, found {}", cells.len())));
    }
    let num = |j: usize| -> std::result::Result<f64, String> {
        let v: f64 = cells[j]
            .parse()
            .map_err(|_| at(format!("{} = '{}' is not a number", COLUMNS[j], cells[j])))?;
        if !v.is_finite() {
            return Err(at(format!("{} = {v} is not finite", COLUMNS[j])));
        }
        Ok(v)
    };
    let q = Query {
        theta_i_deg: num(0)?,
        phi_i_deg: num(1)?,
        theta_r_deg: num(2)?,
        phi_r_deg: num(3)?,
        lambda_nm: if cells[4].is_empty() {
            None
        } else {
            Some(num(4)?)
        },
    };
    for (name, t) in [
        ("theta_i_deg", q.theta_i_deg),
        ("theta_r_deg", q.theta_r_deg),
    ] {
        if !(0.0..=180.0).contains(&t) {
            return Err(at(format!("{name} = {t} is outside [0, 180]")));
        }
    }
    if let Some(l) = q.lambda_nm {
        if !(LAMBDA_MIN_NM as f64..=LAMBDA_MAX_NM as f64).contains(&l) {
            return Err(at(format!(
                "lambda_nm = {l} is outside [{LAMBDA_MIN_NM}, {LAMBDA_MAX_NM}]"
            )));
        }
    }
    Ok(q)
}

/// Answers queries with an evaluator `spectral(wi, wr, λ)` / `integrated(wi, wr)`.
pub fn answer_all(
    queries: &[Query],
    spectral: impl Fn([f64; 3], [f64; 3], f64) -> f64 + Sync,
    integrated: impl Fn([f64; 3], [f64; 3]) -> [f64; 3] + Sync,
) -> Vec<Answer> {
    // 10⁶ model queries take about a minute.
    let bar = crate::progress::bar(queries.len() as u64, "queries");
    let answers = queries
        .par_iter()
        .map(|q| {
            bar.inc(1);
            let wi = direction(q.theta_i_deg, q.phi_i_deg);
            let wr = direction(q.theta_r_deg, q.phi_r_deg);
            match q.lambda_nm {
                Some(l) => {
                    let rho = spectral(wi, wr, l);
                    Answer {
                        rho,
                        xyz: monochromatic_xyz(l).map(|c| c * rho),
                    }
                }
                None => {
                    let xyz = integrated(wi, wr);
                    Answer { rho: xyz[1], xyz }
                }
            }
        })
        .collect();
    bar.finish_and_clear();
    answers
}

/// Formats result rows (full f64 round-trip precision).
pub fn format_answers(queries: &[Query], answers: &[Answer]) -> String {
    let mut s = format!("{},rho,X,Y,Z\n", COLUMNS.join(","));
    for (q, a) in queries.iter().zip(answers) {
        let l = q.lambda_nm.map(|l| l.to_string()).unwrap_or_default();
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{}\n",
            q.theta_i_deg,
            q.phi_i_deg,
            q.theta_r_deg,
            q.phi_r_deg,
            l,
            a.rho,
            a.xyz[0],
            a.xyz[1],
            a.xyz[2]
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_rows_and_reports_bad_lines() {
        let p = Path::new("q.csv");
        let ok = "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm\n30,0,30,180,500\n# c\n10,0,20,0,\n";
        let q = parse_queries(p, ok).unwrap();
        assert_eq!(q.len(), 2);
        assert_eq!(q[0].lambda_nm, Some(500.0));
        assert_eq!(q[1].lambda_nm, None);
        let bad = "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm\n30,0,30,180,500\n30,x,30,180,500\n";
        let e = parse_queries(p, bad).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("phi_i_deg"), "{e}");
        let e = parse_queries(p, "a,b\n").unwrap_err().to_string();
        assert!(e.contains("line 1") && e.contains("header"), "{e}");
        let e = parse_queries(
            p,
            "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm\n1,2,3\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("line 2") && e.contains("5 columns"), "{e}");
        let e = parse_queries(
            p,
            "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm\n1,2,3,4,1000\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("lambda_nm"), "{e}");
        assert!(parse_queries(p, "").is_err());
    }
}
