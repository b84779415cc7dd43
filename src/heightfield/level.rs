//! Levelling a scan the way microscopists do before anything else (`--level STEPS`):
//!
//! - `plane`: the least-squares mean plane is subtracted (the sample's mounting tilt);
//! - `poly:N`: the least-squares polynomial background of total degree `N` (a curved
//!   scanner bow), fitted in a Legendre basis on `[-1, 1]²`: the basis is nearly orthogonal
//!   on a uniform grid, so the normal equations stay well conditioned up to high degrees,
//!   and they separate into products of 1-D sums;
//! - `rows`: scan-line alignment by the median of differences (Gwyddion's "align rows"):
//!   each row is shifted by the median of its differences to the row before, which removes
//!   drift between scan lines without seeing the structure along them;
//! - `none`.
//!
//! Row alignment removes every function of `y` alone, i.e. the `k_x = 0` column of the
//! spectrum. A grating whose ridges run along the scan lines lives exactly there, so before
//! `rows` the row means' spectrum is checked: a peak at three or more cycles per scan that
//! holds [`SCAN_LINE_GRATING_SHARE`] of the field's energy is a structure, not drift, and
//! `rows` is skipped with a warning. The report says what was removed: the tilt (degrees,
//! towards which azimuth the surface rises), the rms of the row offsets (nm) and the
//! curvature of the background (the mean of the quadratic background's two second
//! derivatives, and its bow over the scan).

use std::fmt;
use std::str::FromStr;

use super::HeightField;
use crate::{Error, Result};

/// Highest `poly:N` degree. Degree 10 has 66 coefficients; more removes structure, not
/// background, on any scan of a few ridge periods.
pub const MAX_POLY_DEGREE: usize = 10;

/// Share of the field's energy in one peak of the row means' spectrum (at ≥ 3 cycles per
/// scan) above which the rows are a grating along the scan lines, not drift. Random or
/// drifting offsets spread their energy over many bins; a grating puts it in one.
pub const SCAN_LINE_GRATING_SHARE: f64 = 0.2;

/// One levelling step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    Plane,
    Poly(usize),
    Rows,
}

/// A comma list of steps, applied in order; empty is `none`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Levelling(pub Vec<Step>);

impl Levelling {
    /// The default for scan files: `plane,rows`.
    pub fn scan_default() -> Self {
        Self(vec![Step::Plane, Step::Rows])
    }
}

impl FromStr for Levelling {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let mut steps = Vec::new();
        for word in s.split(',').map(str::trim) {
            let step = match word.to_ascii_lowercase().as_str() {
                "none" => continue,
                "" => {
                    return Err(Error::invalid(
                        "level",
                        format!(
                            "{s:?} has an empty step; expected a comma list of none, plane, \
                             rows, poly:N (none turns levelling off)"
                        ),
                    ))
                }
                "plane" => Step::Plane,
                "rows" => Step::Rows,
                w => match w.strip_prefix("poly:").map(str::parse::<usize>) {
                    Some(Ok(n)) if (1..=MAX_POLY_DEGREE).contains(&n) => Step::Poly(n),
                    _ => {
                        return Err(Error::invalid(
                            "level",
                            format!(
                                "{word:?}; expected a comma list of none, plane, rows, poly:N \
                                 (N = 1..={MAX_POLY_DEGREE})"
                            ),
                        ))
                    }
                },
            };
            steps.push(step);
        }
        Ok(Self(steps))
    }
}

impl fmt::Display for Levelling {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_empty() {
            return f.write_str("none");
        }
        let words: Vec<String> = self
            .0
            .iter()
            .map(|s| match s {
                Step::Plane => "plane".to_string(),
                Step::Rows => "rows".to_string(),
                Step::Poly(n) => format!("poly:{n}"),
            })
            .collect();
        f.write_str(&words.join(","))
    }
}

/// What levelling found and removed.
#[derive(Debug, Clone, PartialEq)]
pub struct LevelReport {
    /// The steps as asked for.
    pub steps: Levelling,
    /// Tilt of the input's mean plane (degrees) and the azimuth it rises towards (degrees
    /// from +x towards +y).
    pub tilt_deg: f64,
    pub tilt_azimuth_deg: f64,
    /// Whether a `plane` or `poly` step removed the tilt.
    pub tilt_removed: bool,
    /// Rms of the row offsets `rows` removed (nm); `None` when it did not run.
    pub row_offsets_rms_nm: Option<f64>,
    /// Mean curvature of the quadratic background (1/mm) and its bow over the scan (nm).
    pub curvature_per_mm: f64,
    pub bow_nm: f64,
    /// Whether a `poly:N ≥ 2` step removed the curvature.
    pub curvature_removed: bool,
    /// Rms of what was removed beyond the plane (nm) and rms of the result (nm).
    pub removed_nonplanar_rms_nm: f64,
    pub structure_rms_nm: f64,
    /// Warnings for the user (row alignment skipped, more removed than the structure has).
    pub warnings: Vec<String>,
}

impl LevelReport {
    /// The report line.
    pub fn line(&self) -> String {
        let done = |b: bool| if b { "removed" } else { "left" };
        let rows = match self.row_offsets_rms_nm {
            Some(r) => format!("row offsets rms {r:.1} nm removed"),
            None => "rows not aligned".to_string(),
        };
        format!(
            "levelling {}: tilt {:.3}° rising towards azimuth {:.0}° {}, {rows}, curvature \
             {:.3} /mm (bow {:.1} nm over the scan) {}; structure rms {:.1} nm",
            self.steps,
            self.tilt_deg,
            self.tilt_azimuth_deg,
            done(self.tilt_removed),
            self.curvature_per_mm,
            self.bow_nm,
            done(self.curvature_removed),
            self.structure_rms_nm
        )
    }
}

/// Legendre polynomials `P_0..=P_n` at `t`.
fn legendre(n: usize, t: f64) -> Vec<f64> {
    let mut p = vec![1.0; n + 1];
    if n >= 1 {
        p[1] = t;
    }
    for k in 2..=n {
        p[k] = ((2 * k - 1) as f64 * t * p[k - 1] - (k - 1) as f64 * p[k - 2]) / k as f64;
    }
    p
}

/// Pixel centres mapped onto `(-1, 1)`.
fn unit_coord(i: usize, n: usize) -> f64 {
    (2 * i + 1) as f64 / n as f64 - 1.0
}

/// A least-squares polynomial background of total degree `deg`: the coefficients of
/// `P_i(tx)·P_j(ty)` for `i + j ≤ deg`, in the order of `terms`.
struct PolyFit {
    terms: Vec<(usize, usize)>,
    coef: Vec<f64>,
    deg: usize,
}

impl PolyFit {
    fn fit(h: &[f64], nx: usize, ny: usize, deg: usize) -> Result<Self> {
        if deg >= nx.min(ny) {
            return Err(Error::invalid(
                "level",
                format!("poly:{deg} needs more than {deg} samples a side; the scan is {nx}×{ny}"),
            ));
        }
        let px: Vec<Vec<f64>> = (0..nx).map(|c| legendre(deg, unit_coord(c, nx))).collect();
        let py: Vec<Vec<f64>> = (0..ny).map(|r| legendre(deg, unit_coord(r, ny))).collect();
        let gram = |p: &[Vec<f64>]| {
            let mut g = vec![vec![0.0; deg + 1]; deg + 1];
            for v in p {
                for a in 0..=deg {
                    for b in 0..=deg {
                        g[a][b] += v[a] * v[b];
                    }
                }
            }
            g
        };
        let (gx, gy) = (gram(&px), gram(&py));
        // Row projections s[r][i] = Σ_c h(r, c)·P_i(tx(c)).
        let proj: Vec<Vec<f64>> = h
            .chunks_exact(nx)
            .map(|row| {
                let mut s = vec![0.0; deg + 1];
                for (v, p) in row.iter().zip(&px) {
                    for i in 0..=deg {
                        s[i] += v * p[i];
                    }
                }
                s
            })
            .collect();
        let terms: Vec<(usize, usize)> = (0..=deg)
            .flat_map(|i| (0..=deg - i).map(move |j| (i, j)))
            .collect();
        let m = terms.len();
        let mut a = vec![vec![0.0; m + 1]; m];
        for (k, &(i, j)) in terms.iter().enumerate() {
            for (l, &(p, q)) in terms.iter().enumerate() {
                a[k][l] = gx[i][p] * gy[j][q];
            }
            a[k][m] = proj.iter().zip(&py).map(|(s, p)| s[i] * p[j]).sum();
        }
        let coef = solve(a).ok_or_else(|| {
            Error::invalid(
                "level",
                format!("poly:{deg}: the background fit is singular"),
            )
        })?;
        Ok(Self { terms, coef, deg })
    }

    /// The background at every sample; `max_deg` leaves out terms of higher total degree.
    fn eval(&self, nx: usize, ny: usize, max_deg: usize) -> Vec<f64> {
        let px: Vec<Vec<f64>> = (0..nx)
            .map(|c| legendre(self.deg, unit_coord(c, nx)))
            .collect();
        let mut out = Vec::with_capacity(nx * ny);
        for r in 0..ny {
            let py = legendre(self.deg, unit_coord(r, ny));
            for p in &px {
                let v: f64 = self
                    .terms
                    .iter()
                    .zip(&self.coef)
                    .filter(|((i, j), _)| i + j <= max_deg)
                    .map(|(&(i, j), c)| c * p[i] * py[j])
                    .sum();
                out.push(v);
            }
        }
        out
    }

    fn coef_of(&self, i: usize, j: usize) -> f64 {
        self.terms
            .iter()
            .position(|&t| t == (i, j))
            .map_or(0.0, |k| self.coef[k])
    }
}

/// Gaussian elimination with partial pivoting on an augmented `m × (m+1)` system.
fn solve(mut a: Vec<Vec<f64>>) -> Option<Vec<f64>> {
    let m = a.len();
    for col in 0..m {
        let pivot = (col..m).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))?;
        if a[pivot][col].abs() < 1e-300 {
            return None;
        }
        a.swap(col, pivot);
        let (top, rest) = a.split_at_mut(col + 1);
        let pivot_row = &top[col];
        for row in rest.iter_mut() {
            let f = row[col] / pivot_row[col];
            for (v, p) in row[col..].iter_mut().zip(&pivot_row[col..]) {
                *v -= f * p;
            }
        }
    }
    let mut x = vec![0.0; m];
    for row in (0..m).rev() {
        let s: f64 = (row + 1..m).map(|k| a[row][k] * x[k]).sum();
        x[row] = (a[row][m] - s) / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_unstable_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Row offsets by the median of differences to the previous row, mean-free.
fn row_offsets(h: &[f64], nx: usize, ny: usize) -> Vec<f64> {
    let mut off = vec![0.0; ny];
    let mut diff = vec![0.0; nx];
    for r in 1..ny {
        for (c, d) in diff.iter_mut().enumerate() {
            *d = h[r * nx + c] - h[(r - 1) * nx + c];
        }
        off[r] = off[r - 1] + median(&mut diff);
    }
    let mean = off.iter().sum::<f64>() / ny as f64;
    off.iter().map(|o| o - mean).collect()
}

/// The strongest peak of the row means' spectrum at `k ≥ 3` cycles per scan: its share of
/// the field's energy (the bin and its two neighbours) and its `k`.
pub fn scan_line_peak(h: &[f64], nx: usize, ny: usize) -> (f64, usize) {
    use rustfft::num_complex::Complex64;
    let mean = h.iter().sum::<f64>() / h.len() as f64;
    let energy: f64 = h.iter().map(|v| (v - mean).powi(2)).sum();
    if ny < 8 || energy <= 0.0 {
        return (0.0, 0);
    }
    let mut m: Vec<Complex64> = h
        .chunks_exact(nx)
        .map(|row| Complex64::new(row.iter().sum::<f64>() / nx as f64 - mean, 0.0))
        .collect();
    rustfft::FftPlanner::new()
        .plan_fft_forward(ny)
        .process(&mut m);
    // Parseval: the k_x = 0 column holds nx·Σ_r m_r² = (nx/ny)·Σ_k |M_k|²; ±k both count.
    let power = |k: usize| 2.0 * nx as f64 / ny as f64 * m[k].norm_sqr();
    let top = ny.div_ceil(2) - 1;
    let Some(k) = (3..top).max_by(|&a, &b| power(a).total_cmp(&power(b))) else {
        return (0.0, 0);
    };
    ((power(k - 1) + power(k) + power(k + 1)) / energy, k)
}

/// Levels `hf` by `steps` (module docs). The result keeps the grid and `dH`.
pub fn level(hf: &HeightField, steps: &Levelling) -> Result<(HeightField, LevelReport)> {
    let (nx, ny, dh) = (hf.nx(), hf.ny(), hf.dh_um());
    if nx.min(ny) < 3 {
        return Err(Error::invalid(
            "level",
            format!("{steps}: a {nx}×{ny} field is too small to level (at least 3×3); use none"),
        ));
    }
    let input = hf.heights_um();
    let mut h = input.to_vec();
    let mut warnings = Vec::new();
    let mut row_rms = None;
    let (mut tilt_removed, mut curvature_removed) = (false, false);
    for &step in &steps.0 {
        match step {
            Step::Plane | Step::Poly(_) => {
                let deg = if let Step::Poly(n) = step { n } else { 1 };
                let bg = PolyFit::fit(&h, nx, ny, deg)?.eval(nx, ny, deg);
                h.iter_mut().zip(&bg).for_each(|(v, b)| *v -= b);
                tilt_removed = true;
                curvature_removed |= deg >= 2;
            }
            Step::Rows => {
                let (share, k) = scan_line_peak(&h, nx, ny);
                if share >= SCAN_LINE_GRATING_SHARE {
                    warnings.push(format!(
                        "rows not aligned: {:.0} % of the height variance is a grating along \
                         the scan lines ({k} periods over the scan's {ny} rows, {:.3} µm), which \
                         row alignment would erase; remove drift by other means or rotate the \
                         scan so the fast axis crosses the ridges",
                        share * 100.0,
                        ny as f64 * dh / k as f64
                    ));
                    continue;
                }
                let off = row_offsets(&h, nx, ny);
                for (row, o) in h.chunks_exact_mut(nx).zip(&off) {
                    row.iter_mut().for_each(|v| *v -= o);
                }
                row_rms = Some((off.iter().map(|o| o * o).sum::<f64>() / ny as f64).sqrt() * 1e3);
            }
        }
    }
    let report = measure(
        hf,
        &h,
        steps,
        (tilt_removed, curvature_removed),
        row_rms,
        warnings,
    )?;
    let levelled = HeightField::new(nx, ny, dh, h)?;
    Ok((levelled, report))
}

fn rms(v: impl Iterator<Item = f64> + Clone) -> f64 {
    let n = v.clone().count().max(1) as f64;
    let mean = v.clone().sum::<f64>() / n;
    (v.map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt()
}

/// The report's numbers: the input's tilt and curvature, what was removed beyond the plane,
/// and the warning when that is more than the structure left.
fn measure(
    hf: &HeightField,
    out: &[f64],
    steps: &Levelling,
    (tilt_removed, curvature_removed): (bool, bool),
    row_offsets_rms_nm: Option<f64>,
    mut warnings: Vec<String>,
) -> Result<LevelReport> {
    let (nx, ny, dh) = (hf.nx(), hf.ny(), hf.dh_um());
    let input = hf.heights_um();
    let (lx, ly) = (nx as f64 * dh, ny as f64 * dh);
    let fit = PolyFit::fit(input, nx, ny, 2)?;
    // P_1(t) = t with t = 2x/L − 1 (heights and x both in µm): slope = 2·c/L.
    let (sx, sy) = (2.0 * fit.coef_of(1, 0) / lx, 2.0 * fit.coef_of(0, 1) / ly);
    let tilt_deg = sx.hypot(sy).atan().to_degrees();
    let tilt_azimuth_deg = sy.atan2(sx).to_degrees().rem_euclid(360.0);
    // P_2(t) = (3t² − 1)/2: d²/dx² = 3·c·(2/L)²; µm/µm² → 1/mm is ×1e3.
    let kx = 3.0 * fit.coef_of(2, 0) * (2.0 / lx).powi(2);
    let ky = 3.0 * fit.coef_of(0, 2) * (2.0 / ly).powi(2);
    let (plane, quad) = (fit.eval(nx, ny, 1), fit.eval(nx, ny, 2));
    let bow = quad.iter().zip(&plane).map(|(q, p)| q - p);
    let (lo, hi) = bow.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    // What was removed, less its own best plane.
    let removed: Vec<f64> = input.iter().zip(out).map(|(i, o)| i - o).collect();
    let removed_plane = PolyFit::fit(&removed, nx, ny, 1)?.eval(nx, ny, 1);
    let removed_nonplanar_rms_nm =
        rms(removed.iter().zip(&removed_plane).map(|(r, p)| r - p)) * 1e3;
    let structure_rms_nm = rms(out.iter().copied()) * 1e3;
    if removed_nonplanar_rms_nm > structure_rms_nm {
        warnings.push(format!(
            "levelling ({steps}) removed {removed_nonplanar_rms_nm:.1} nm rms beyond the mean \
             plane, more than the {structure_rms_nm:.1} nm rms the structure keeps: check that \
             the background was not the structure (a lower poly degree, or --level plane)"
        ));
    }
    Ok(LevelReport {
        steps: steps.clone(),
        tilt_deg,
        tilt_azimuth_deg,
        tilt_removed,
        row_offsets_rms_nm,
        curvature_per_mm: 0.5 * (kx + ky) * 1e3,
        bow_nm: if hi > lo { (hi - lo) * 1e3 } else { 0.0 },
        curvature_removed,
        removed_nonplanar_rms_nm,
        structure_rms_nm,
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(nx: usize, ny: usize, dh: f64, f: impl Fn(f64, f64) -> f64) -> HeightField {
        let h = (0..ny)
            .flat_map(|r| (0..nx).map(move |c| (c, r)))
            .map(|(c, r)| f(c as f64 * dh, r as f64 * dh))
            .collect();
        HeightField::new(nx, ny, dh, h).unwrap()
    }

    #[test]
    fn parses_steps() {
        let l: Levelling = "plane, rows,poly:3".parse().unwrap();
        assert_eq!(l.0, vec![Step::Plane, Step::Rows, Step::Poly(3)]);
        assert_eq!(l.to_string(), "plane,rows,poly:3");
        assert!("none".parse::<Levelling>().unwrap().0.is_empty());
        for bad in [
            "plain",
            "poly:0",
            "poly:11",
            "poly:x",
            "rows;plane",
            "",
            ",,",
            "plane,",
            " , rows",
        ] {
            assert!(bad.parse::<Levelling>().is_err(), "{bad}");
        }
    }

    #[test]
    fn plane_removes_a_known_tilt_and_reports_it() {
        // 2° rising towards +x, 1° towards +y, on a cosine along x, even about the scan's
        // centre: a sine would correlate with the ramp and bias the least-squares tilt.
        let (tx, ty) = (2f64.to_radians().tan(), 1f64.to_radians().tan());
        let wave = |x: f64| 0.1 * (std::f64::consts::TAU * (x + 0.025) / 0.8).cos();
        let hf = field(64, 48, 0.05, |x, y| wave(x) + tx * x + ty * y);
        let (out, rep) = level(&hf, &"plane".parse().unwrap()).unwrap();
        let want = tx.hypot(ty).atan().to_degrees();
        assert!(
            (rep.tilt_deg - want).abs() < 0.02,
            "{} vs {want}",
            rep.tilt_deg
        );
        let az = ty.atan2(tx).to_degrees();
        assert!(
            (rep.tilt_azimuth_deg - az).abs() < 1.0,
            "{}",
            rep.tilt_azimuth_deg
        );
        // 4 whole periods: the sinusoid is orthogonal to the plane, so it comes back.
        let clean = field(64, 48, 0.05, |x, _| wave(x));
        let err = out
            .heights_um()
            .iter()
            .zip(clean.heights_um())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(err < 0.01, "{err}");
    }

    #[test]
    fn poly_removes_a_quadratic_bow_and_measures_its_curvature() {
        // h = a·(x − x0)²: curvature 2a (1/µm).
        let a = 0.002;
        let hf = field(40, 40, 0.1, |x, y| {
            a * (x - 2.0).powi(2) + a * (y - 2.0).powi(2)
        });
        let (out, rep) = level(&hf, &"poly:2".parse().unwrap()).unwrap();
        assert!(out.heights_um().iter().all(|h| h.abs() < 1e-9));
        assert!(
            (rep.curvature_per_mm - 2.0 * a * 1e3).abs() < 1e-6,
            "{}",
            rep.curvature_per_mm
        );
        assert!(rep.curvature_removed);
    }

    #[test]
    fn rows_remove_offsets_but_not_a_grating_along_the_scan_lines() {
        let offsets = [0.0, 0.03, -0.02, 0.05, 0.01, -0.04, 0.02, 0.0];
        let across = field(64, 64, 0.05, |x, y| {
            0.1 * (std::f64::consts::TAU * x / 0.8).sin() + offsets[(y / 0.05).round() as usize % 8]
        });
        let (out, rep) = level(&across, &"rows".parse().unwrap()).unwrap();
        assert!(rep.warnings.is_empty(), "{:?}", rep.warnings);
        assert!(rep.row_offsets_rms_nm.unwrap() > 20.0);
        let r0 = &out.heights_um()[..64];
        for row in out.heights_um().chunks_exact(64) {
            let d = row
                .iter()
                .zip(r0)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(d < 1e-9, "{d}");
        }
        let along = field(64, 64, 0.05, |_, y| {
            0.1 * (std::f64::consts::TAU * y / 0.8).sin()
        });
        let (kept, rep) = level(&along, &"rows".parse().unwrap()).unwrap();
        assert_eq!(rep.row_offsets_rms_nm, None);
        assert!(
            rep.warnings[0].contains("along the scan lines"),
            "{:?}",
            rep.warnings
        );
        assert_eq!(kept.heights_um(), along.heights_um());
    }
}
