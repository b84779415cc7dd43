//! The grating-equation experiment of MODEL §8 (thesis ch. 4): light at `θi` in the plane
//! across the grating lines; for each wavelength find the viewing angle of peak reflectance,
//! estimate the period `d = λ/(sin θi + sin θr)` (first order, `θr` signed, negative on the
//! mirror side) and report its mean and variance over wavelength. Uses the f64 model.

use std::path::PathBuf;

use rayon::prelude::*;

use crate::brdf::{direction, model};
use crate::cli::cache::CacheArgs;
use crate::cli::material::MaterialArgs;
use crate::material::PreparedMaterial;
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
    /// The wavelengths scanned (nm).
    pub lambdas_nm: Vec<f64>,
    /// The signed viewing angles scanned (degrees).
    pub thetas_deg: Vec<f64>,
    /// `ρ[λ index][θ index]`, the f64 model.
    pub rho: Vec<Vec<f64>>,
    /// The ridge period of the height field's own spectrum ([`ridge_period_um`], nm), which
    /// chose the first order. On a crop holding a fractional number of periods the
    /// reflectance peaks sit on the crop's orders `jλ/L`, so the experiment reads `L/j`
    /// (within half a bin, `d²/2L`, of the ridge period) while this reads `d` itself.
    pub ridge_period_nm: Option<f64>,
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
/// (0: across lines that run along y). Following the thesis, the peak at each wavelength is
/// the viewing angle of **peak reflectance away from the specular lobe**: the largest local
/// maximum of `ρ(θr)` with `|u|` beyond the lobe, read at its first order (see
/// [`first_order`]: on tall gratings a higher order can be the brightest), refined by a
/// parabola through the three samples around it (grid step `step_deg`).
///
/// Which local maximum is the first order is decided from the height field itself where it
/// can be ([`ridge_period_um`]: the strongest peak of its own spectrum along the plane of
/// incidence): the peak nearest `|u| = λ/d_h`, within 5%. The period reported is still read
/// from the reflectance peak's angle, not from `d_h`. Without a clear spectral peak (or at
/// an azimuth off the axes) the brightest peak's first order is taken ([`first_order`]).
///
/// (An earlier rule took the maximum nearest to specular above 5% of the strongest. On a
/// crop whose edges do not tile, the crop is a grating of its own size, and its weak orders
/// near specular won: the experiment reported the crop size instead of the ridge period.
/// A crop holding a whole number of periods has the ridge's orders at whole multiples of
/// its own, which the sub-harmonic rule alone cannot tell apart.)
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
    let ridge_um = ridge_period_um(&p.heightfield, azimuth_deg);
    let si = theta_i_deg.to_radians().sin();
    let sigma_s = p.material.coherence_um / 4.0;
    let n = (179.8 / step_deg).floor() as usize;
    let thetas: Vec<f64> = (0..=n).map(|k| -89.9 + k as f64 * step_deg).collect();
    let mut samples = Vec::new();
    let mut rho_map = Vec::with_capacity(lambdas_nm.len());
    let stack = p.stack.get()?;
    for &l in lambdas_nm {
        let rho: Vec<f64> = thetas
            .par_iter()
            .map(|&t| {
                let wr = signed_direction(t, azimuth_deg);
                model::rho(stack, p.terms(), &p.window, &p.shading, wi, wr, l)
            })
            .collect();
        if let Some(k) = rho.iter().position(|r| !r.is_finite()) {
            return Err(Error::invalid(
                "grating",
                format!("ρ is not finite at λ = {l} nm, θr = {}°", thetas[k]),
            ));
        }
        // The specular lobe: |u| within a few window widths λ/(2πσs), and at least 0.05
        // (periods up to 20 λ). Outside it, the strongest local maximum is the peak.
        let lobe = (10.0 * l * 1e-3 / (2.0 * std::f64::consts::PI * sigma_s)).max(0.05);
        let u_of = |k: usize| (si + thetas[k].to_radians().sin()).abs();
        let peaks: Vec<usize> = (1..thetas.len() - 1)
            .filter(|&k| u_of(k) > lobe && rho[k] > rho[k - 1] && rho[k] >= rho[k + 1])
            .collect();
        let Some(&brightest) = peaks.iter().max_by(|&&a, &&b| rho[a].total_cmp(&rho[b])) else {
            rho_map.push(rho);
            continue;
        };
        let expected = ridge_um.map(|d| l * 1e-3 / d);
        let k = expected
            .and_then(|e| {
                peaks
                    .iter()
                    .copied()
                    .filter(|&k| (u_of(k) - e).abs() <= 0.05 * e)
                    .min_by(|&a, &b| (u_of(a) - e).abs().total_cmp(&(u_of(b) - e).abs()))
            })
            .unwrap_or_else(|| first_order(&peaks, &rho, brightest, &u_of));
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
        rho_map.push(rho);
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
        lambdas_nm: lambdas_nm.to_vec(),
        thetas_deg: thetas,
        rho: rho_map,
        ridge_period_nm: ridge_um.map(|d| d * 1e3),
    })
}

/// Share of the non-DC power (of the row-averaged spectrum) that the strongest peak and its
/// two neighbours must hold for [`ridge_period_um`] to trust it.
const RIDGE_PEAK_SHARE: f64 = 0.2;

/// The ridge period (µm) along the plane of incidence at `azimuth_deg` (0 or 180: along x,
/// the rows; 90 or 270: along y, the columns), from the height field's own spectrum: the
/// power spectrum of each mean-removed line along that axis, averaged over the lines, its
/// strongest non-DC bin `k`, refined between `k` and its larger neighbour by the
/// rectangular window's sinc ratio `δ = |X_{k±1}|/(|X_k| + |X_{k±1}|)` (exact for one
/// sinusoid, whole number of periods or not), and `d = L/(k ± δ)`. `None` off the axes, on
/// a flat field, or when the peak holds less than [`RIDGE_PEAK_SHARE`] of the power.
///
/// A crop's own orders (its seam) put power at every bin `j`, but a whole number of ridge
/// periods puts the ridge's at bin `L/d` itself and a fractional number puts it between
/// two: in both cases the strongest bin of a ridged surface is the ridge's, which is what
/// the reflectance peaks alone (whose orders coincide on a whole-period crop) cannot say.
pub fn ridge_period_um(hf: &crate::heightfield::HeightField, azimuth_deg: f64) -> Option<f64> {
    let a = azimuth_deg.rem_euclid(180.0);
    let along_x = if a.abs() < 1e-9 || (a - 180.0).abs() < 1e-9 {
        true
    } else if (a - 90.0).abs() < 1e-9 {
        false
    } else {
        return None;
    };
    let (nx, ny) = (hf.nx(), hf.ny());
    let h = hf.heights_um();
    let (n, lines) = if along_x { (nx, ny) } else { (ny, nx) };
    if n < 4 {
        return None;
    }
    let mut planner = rustfft::FftPlanner::new();
    let fft = planner.plan_fft_forward(n);
    let mut power = vec![0.0f64; n / 2 + 1];
    let mut line = vec![rustfft::num_complex::Complex64::new(0.0, 0.0); n];
    for l in 0..lines {
        for (i, z) in line.iter_mut().enumerate() {
            let v = if along_x {
                h[l * nx + i]
            } else {
                h[i * nx + l]
            };
            *z = rustfft::num_complex::Complex64::new(v, 0.0);
        }
        let mean = line.iter().map(|z| z.re).sum::<f64>() / n as f64;
        line.iter_mut().for_each(|z| z.re -= mean);
        fft.process(&mut line);
        for (p, z) in power.iter_mut().zip(&line) {
            *p += z.norm_sqr();
        }
    }
    let total: f64 = power[1..].iter().sum();
    if total <= 0.0 {
        return None;
    }
    let k = (1..power.len()).max_by(|&a, &b| power[a].total_cmp(&power[b]))?;
    let at = |i: usize| power.get(i).copied().unwrap_or(0.0);
    let near = at(k) + at(k - 1) * (k > 1) as u8 as f64 + at(k + 1);
    if near < RIDGE_PEAK_SHARE * total {
        return None;
    }
    let amp = |i: usize| at(i).sqrt();
    let (left, right) = (if k > 1 { amp(k - 1) } else { 0.0 }, amp(k + 1));
    let f = if right >= left {
        k as f64 + right / (amp(k) + right)
    } else {
        k as f64 - left / (amp(k) + left)
    };
    let length = n as f64 * hf.dh_um();
    (f > 0.0).then(|| length / f)
}

/// Largest diffraction order the brightest peak is read as.
const MAX_ORDER: usize = 10;

/// Share of the brightest peak a lower peak needs to be taken as its first order. On the
/// Xenopeltis-like grating (0.82 µm) the first order is 27–100% of the brightest; on the
/// measured 100² Elaphe crop the crop's own first order (its seam) is 6–8% of the ridge
/// peak, which sits exactly at the crop's 6th order.
const SUBHARMONIC_SHARE: f64 = 0.2;

/// The first order belonging to the brightest peak: on a tall grating (Xenopeltis-like,
/// `k|w|h` of several radians) an order `m > 1` can outshine the first, and reading it as the
/// first would give `d/m`. The first order is the lowest strong peak (≥ 20% of the
/// brightest) whose `|u|` divides the brightest's by a whole `m ≤ 10` within 0.5% (peak
/// positions on the 0.01° grid are good to ~0.1%); the brightest itself when none does. A
/// crop's own orders (`|u| = jλ/L`) miss these ratios by the crop's mismatch with the period
/// (1.2% for 8.1 periods), and the lobe cut removes those of crops much larger than it.
fn first_order(
    peaks: &[usize],
    rho: &[f64],
    brightest: usize,
    u_of: &impl Fn(usize) -> f64,
) -> usize {
    let ub = u_of(brightest);
    let mut candidates: Vec<usize> = peaks
        .iter()
        .copied()
        .filter(|&k| rho[k] >= SUBHARMONIC_SHARE * rho[brightest] && u_of(k) < ub)
        .collect();
    candidates.sort_by(|&a, &b| u_of(a).total_cmp(&u_of(b)));
    candidates
        .into_iter()
        .find(|&k| {
            let ratio = ub / u_of(k);
            let m = ratio.round();
            m >= 2.0 && m <= MAX_ORDER as f64 && (ratio - m).abs() <= 0.005 * ratio
        })
        .unwrap_or(brightest)
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
    #[command(flatten)]
    pub cache: CacheArgs,
    /// Print each wavelength's peak.
    #[arg(long)]
    pub verbose: bool,
    /// Write a PNG: log ρ over λ (x, left to right) and signed θr (y, −90° at the bottom),
    /// the peaks found (white) and the grating equation at the mean period (green).
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// Rows of the plot (θr is pooled by maximum into this many bands).
const PLOT_ROWS: usize = 360;

/// Writes the thesis-style evaluation figure of `r` (see [`EvalArgs::plot`]).
pub fn write_plot(r: &GratingReport, path: &std::path::Path) -> Result<()> {
    write_plot_of(r, &format!("θi = {}°", r.theta_i_deg), path)
}

/// [`write_plot`] with `subject` (the field and the light) in the title.
pub fn write_plot_of(r: &GratingReport, subject: &str, path: &std::path::Path) -> Result<()> {
    let n_theta = r.thetas_deg.len();
    let (t0, t1) = (r.thetas_deg[0], r.thetas_deg[n_theta - 1]);
    let rows = PLOT_ROWS.min(n_theta);
    let mut values = vec![vec![0.0f64; r.lambdas_nm.len()]; rows];
    for (c, rho) in r.rho.iter().enumerate() {
        for (k, v) in rho.iter().enumerate() {
            let row = (k * rows / n_theta).min(rows - 1);
            values[row][c] = values[row][c].max(*v);
        }
    }
    let dl = if r.lambdas_nm.len() > 1 {
        r.lambdas_nm[1] - r.lambdas_nm[0]
    } else {
        1.0
    };
    let (l0, l1) = (
        r.lambdas_nm[0] - 0.5 * dl,
        r.lambdas_nm[r.lambdas_nm.len() - 1] + 0.5 * dl,
    );
    let si = r.theta_i_deg.to_radians().sin();
    let peaks = crate::plot::Curve {
        points: r
            .samples
            .iter()
            .map(|s| (s.lambda_nm, s.theta_r_deg))
            .collect(),
        colour: (255, 255, 255),
        label: "peak found at each λ".into(),
        markers: true,
    };
    // The side of specular the peaks lie on: si + sin θr = ±λ/d.
    let side = r
        .samples
        .iter()
        .map(|s| (si + s.theta_r_deg.to_radians().sin()).signum())
        .sum::<f64>()
        .signum();
    let grating = crate::plot::Curve {
        points: r
            .lambdas_nm
            .iter()
            .map(|&l| {
                let s = side * l / r.mean_nm - si;
                (
                    l,
                    if s.abs() <= 1.0 {
                        s.asin().to_degrees()
                    } else {
                        f64::NAN
                    },
                )
            })
            .collect(),
        colour: (0, 220, 0),
        label: format!("grating equation, d = {:.1} nm", r.mean_nm),
        markers: false,
    };
    let x_step = crate::plot::nice_step(l1 - l0, 8);
    crate::plot::write_heat_map(
        path,
        &crate::plot::HeatMap {
            title: format!(
                "Grating equation: {subject}, mean period {:.1} nm",
                r.mean_nm
            ),
            values: &values,
            x: (l0, l1),
            y: (t0, t1),
            x_axis: crate::plot::Axis {
                label: "wavelength λ (nm)".into(),
                ticks: crate::plot::ticks_every(l0, l1, x_step, ""),
                ..Default::default()
            },
            y_axis: crate::plot::Axis {
                label: "signed θr (°), negative on the specular side".into(),
                ticks: crate::plot::ticks_every(t0, t1, 30.0, "°"),
                ..Default::default()
            },
            log: true,
            scale_label: "log₁₀ ρ (sr⁻¹)".into(),
            scale_limits: (None, None),
            scale_marks: Vec::new(),
            missing_label: None,
            curves: vec![grating, peaks],
            size: (1000, 640),
        },
    )
}

/// Runs `diffract eval-grating`.
pub fn run(args: &EvalArgs) -> Result<()> {
    eval_args(args)?;
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
    let cache = args.cache.dir();
    // The f64 model evaluates in-plane directions only: |w| ≤ cos θi + 1.
    let p = material.prepare_for(
        cache.as_deref(),
        &crate::brdf::truncation::Reach::brdf_map(args.theta_i),
        crate::brdf::truncation::Precision::F64,
        &crate::report::Stderr,
    )?;
    let spin = crate::progress::spinner("grating equation");
    let r = grating_equation(&p, args.theta_i, args.azimuth, &lambdas, args.step_deg)?;
    drop(spin);
    if let Some(path) = &args.plot {
        let subject = format!(
            "{}, θi = {}°, azimuth {}°",
            crate::plot::source_name(&material.heightfield),
            args.theta_i,
            args.azimuth
        );
        write_plot_of(&r, &subject, path)?;
        eprintln!("plot → {}", path.display());
    }
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
    if let Some(d) = r.ridge_period_nm {
        println!("height-field spectrum along the plane of incidence: ridge period {d:.3} nm");
    }
    Ok(())
}

/// Finest viewing-angle step of `eval-grating` (degrees): 179 800 samples per wavelength,
/// about a minute and a quarter with the default material.
pub const MIN_STEP_DEG: f64 = 1e-3;
/// Most wavelengths `eval-grating` evaluates (0.1 nm steps over 380–780 nm).
pub const MAX_WAVELENGTHS: f64 = 4001.0;

/// `diffract eval-grating`: angles, steps and wavelengths, and the material's numbers.
pub fn eval_args(args: &EvalArgs) -> Result<()> {
    let t = args.theta_i;
    if !(t.is_finite() && (0.0..90.0).contains(&t)) {
        return Err(Error::invalid(
            "theta-i",
            format!("{t}°; must be in [0, 90)"),
        ));
    }
    crate::guard::finite("azimuth", args.azimuth)?;
    crate::guard::in_range("step-deg", args.step_deg, MIN_STEP_DEG..=1.0, "°")?;
    if let [from, to, step] = args.lambdas_nm[..] {
        if step.is_finite() && step > 0.0 && ((to - from) / step).floor() + 1.0 > MAX_WAVELENGTHS {
            return Err(Error::invalid(
                "wavelengths",
                format!("{from}..{to} step {step} nm is more than {MAX_WAVELENGTHS} wavelengths"),
            ));
        }
    }
    let material = args.material.apply(crate::material::Material::default());
    material.validate()?;
    if let Some(plot) = &args.plot {
        crate::guard::check_outputs(
            &crate::guard::heightfield_inputs(&material.heightfield),
            &[("--plot", plot.clone())],
        )?;
    }
    Ok(())
}
