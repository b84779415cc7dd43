//! The grating-equation experiment of MODEL §8 (thesis ch. 4): light at `θi` in the plane
//! across the grating lines; for each wavelength find the viewing angle of peak reflectance,
//! estimate the period `d = λ/(sin θi + sin θr)` (first order, `θr` signed, negative on the
//! mirror side) and report its mean and variance over wavelength. Uses the f64 model.

use std::path::PathBuf;

use crate::brdf::{direction, model};
use crate::material::{default_cache_dir, MaterialArgs, PreparedMaterial};
use crate::{Error, Result};

/// One wavelength's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeakSample {
    pub lambda_nm: f64,
    /// Signed viewing angle of the first-order peak (degrees).
    pub theta_r_deg: f64,
    /// Period estimate (nm).
    pub period_nm: f64,
}

/// Mean and variance of the period estimates.
#[derive(Debug, Clone, PartialEq)]
pub struct GratingReport {
    pub theta_i_deg: f64,
    pub samples: Vec<PeakSample>,
    pub mean_nm: f64,
    pub variance_nm2: f64,
}

/// Signed in-plane direction: negative angles lie on the mirror side (`φ = 180°`).
fn signed_direction(theta_deg: f64, azimuth_deg: f64) -> [f64; 3] {
    direction(
        theta_deg.abs(),
        if theta_deg < 0.0 {
            azimuth_deg + 180.0
        } else {
            azimuth_deg
        },
    )
}

/// Runs the experiment for light at `theta_i_deg` in the plane of azimuth `azimuth_deg`
/// (0: across lines that run along y). The first order is the diffraction peak of `ρ(θr)`
/// nearest to specular in `u` (ignoring the specular lobe and peaks under 5% of the
/// strongest), refined by a parabola through the three samples around it (grid step
/// `step_deg`).
pub fn grating_equation(
    p: &PreparedMaterial,
    theta_i_deg: f64,
    azimuth_deg: f64,
    lambdas_nm: &[f64],
    step_deg: f64,
) -> Result<GratingReport> {
    if !(0.0..90.0).contains(&theta_i_deg) {
        return Err(Error::invalid(
            "theta_i",
            format!("{theta_i_deg}°; must be in [0, 90)"),
        ));
    }
    if !(step_deg > 0.0 && step_deg <= 1.0) {
        return Err(Error::invalid(
            "angle step",
            format!("{step_deg}°; must be in (0, 1]"),
        ));
    }
    let wi = signed_direction(theta_i_deg, azimuth_deg);
    let si = theta_i_deg.to_radians().sin();
    let sigma_s = p.material.coherence_um / 4.0;
    let n = (179.8 / step_deg).floor() as usize;
    let thetas: Vec<f64> = (0..=n).map(|k| -89.9 + k as f64 * step_deg).collect();
    let mut samples = Vec::new();
    for &l in lambdas_nm {
        let rho: Vec<f64> = thetas
            .iter()
            .map(|&t| {
                let wr = signed_direction(t, azimuth_deg);
                model::rho(&p.stack, p.terms(), &p.window, &p.shading, wi, wr, l)
            })
            .collect();
        // Diffraction peaks outside the specular lobe (|u| above a few window widths
        // λ/(2πσs), and at least 0.05, i.e. periods up to 20 λ). Order m sits at
        // |u| = mλ/d, so the first order is the peak nearest to specular in u; peaks below
        // 5% of the strongest are side lobes of the window and irregularity, not orders.
        let lobe = (10.0 * l * 1e-3 / (2.0 * std::f64::consts::PI * sigma_s)).max(0.05);
        let u_of = |k: usize| (si + thetas[k].to_radians().sin()).abs();
        let peaks: Vec<usize> = (1..thetas.len() - 1)
            .filter(|&k| u_of(k) > lobe && rho[k] > rho[k - 1] && rho[k] >= rho[k + 1])
            .collect();
        let strongest = peaks.iter().map(|&k| rho[k]).fold(0.0, f64::max);
        let best = peaks
            .iter()
            .filter(|&&k| rho[k] >= 0.05 * strongest)
            .map(|&k| (u_of(k), k))
            .min_by(|a, b| a.0.total_cmp(&b.0));
        let Some((_, k)) = best else {
            continue;
        };
        let (a, b, c) = (rho[k - 1], rho[k], rho[k + 1]);
        let denom = a - 2.0 * b + c;
        let shift = if denom.abs() > 0.0 {
            (0.5 * (a - c) / denom).clamp(-0.5, 0.5)
        } else {
            0.0
        };
        let theta = thetas[k] + shift * step_deg;
        let period_nm = l / (si + theta.to_radians().sin()).abs();
        samples.push(PeakSample {
            lambda_nm: l,
            theta_r_deg: theta,
            period_nm,
        });
    }
    if samples.is_empty() {
        return Err(Error::invalid(
            "grating",
            "no first-order peak found at any wavelength",
        ));
    }
    let m = samples.len() as f64;
    let mean_nm = samples.iter().map(|s| s.period_nm).sum::<f64>() / m;
    let variance_nm2 = samples
        .iter()
        .map(|s| (s.period_nm - mean_nm).powi(2))
        .sum::<f64>()
        / m;
    Ok(GratingReport {
        theta_i_deg,
        samples,
        mean_nm,
        variance_nm2,
    })
}

/// `diffract eval-grating` options.
#[derive(Debug, Clone, clap::Args)]
pub struct EvalArgs {
    #[command(flatten)]
    pub material: MaterialArgs,
    /// Incident polar angle (degrees).
    #[arg(long, default_value_t = 75.0)]
    pub theta_i: f64,
    /// Azimuth of the plane of incidence (degrees; 0 = across lines running along y).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub azimuth: f64,
    /// First, last wavelength and step (nm).
    #[arg(long, num_args = 3, value_names = ["FROM", "TO", "STEP"], default_values_t = [400.0, 700.0, 10.0])]
    pub lambdas_nm: Vec<f64>,
    /// Viewing-angle grid step (degrees).
    #[arg(long, default_value_t = 0.01)]
    pub step_deg: f64,
    /// Directory of the DFT-term cache.
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Print each wavelength's peak.
    #[arg(long)]
    pub verbose: bool,
}

/// Runs `diffract eval-grating`.
pub fn run(args: &EvalArgs) -> Result<()> {
    let [from, to, step] = [args.lambdas_nm[0], args.lambdas_nm[1], args.lambdas_nm[2]];
    if !(from >= 380.0 && to <= 780.0 && from <= to && step > 0.0) {
        return Err(Error::invalid(
            "wavelengths",
            format!("{from}..{to} step {step} nm; need 380 ≤ from ≤ to ≤ 780, step > 0"),
        ));
    }
    let count = ((to - from) / step).floor() as usize + 1;
    let lambdas: Vec<f64> = (0..count).map(|i| from + i as f64 * step).collect();
    let material = args.material.apply(crate::material::Material::default());
    let cache = args.cache_dir.clone().or_else(default_cache_dir);
    let p = material.prepare(cache.as_deref())?;
    let r = grating_equation(&p, args.theta_i, args.azimuth, &lambdas, args.step_deg)?;
    if args.verbose {
        for s in &r.samples {
            println!(
                "λ = {:5.1} nm  θr = {:8.3}°  d = {:9.3} nm",
                s.lambda_nm, s.theta_r_deg, s.period_nm
            );
        }
    }
    println!(
        "{}: θi = {}°, {} wavelengths: period mean {:.3} nm, variance {:.3} nm²",
        material.heightfield,
        r.theta_i_deg,
        r.samples.len(),
        r.mean_nm,
        r.variance_nm2
    );
    Ok(())
}
