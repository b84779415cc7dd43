//! `diffract validity`: the scalar model's power per diffraction order against the rigorous
//! solver, for a height field or a scene's material (library: [`crate::validity`]).

use std::fmt::Write as _;
use std::path::PathBuf;

use crate::cli::material::MaterialArgs;
use crate::validity::{self, Check, Profile, ScalarModel, Solve};
use crate::Result;

/// `diffract validity` options.
#[derive(Debug, Clone, clap::Args)]
pub struct ValidityArgs {
    /// Scene file whose material is checked (the flags below override it); the embedded
    /// default scene's when omitted.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    #[command(flatten)]
    pub material: MaterialArgs,
    /// Refractive index of the material (overrides the scene's).
    #[arg(long)]
    pub ior: Option<f64>,
    /// Wavelength in nm (repeatable) [default: 450, 550, 650].
    #[arg(long = "lambda-nm")]
    pub lambda_nm: Vec<f64>,
    /// Polar angle of the light in degrees, in the plane across the ridges on +x's side
    /// (repeatable) [default: 0, 30, 60].
    #[arg(long = "theta-i")]
    pub theta_i: Vec<f64>,
    /// Every order of every (θi, λ) as CSV.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// PNG validity map over θi (0–80°) and λ (400–700 nm): the worst order-ratio error
    /// (solves converged to 5 %: enough to tell 10 % from 25 %).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Convergence tolerance of the rigorous solver: harmonics and slices grow until no
    /// reflected order moves by more than this (relative).
    #[arg(long, default_value_t = crate::brdf::rcwa::DEFAULT_TOLERANCE)]
    pub rcwa_tolerance: f64,
    /// Instead of the material's grating, print where scalar theory holds for sinusoidal
    /// gratings of the material's index: the worst order-ratio error over periods of
    /// 1.6–5 wavelengths and depths of 0.05–1 wavelength, as Markdown tables, at the first
    /// `--lambda-nm` (500 nm when omitted) and each `--theta-i` (0° and 60° when omitted).
    /// 56 solves per angle: about a minute.
    #[arg(long)]
    pub limits: bool,
}

/// `diffract validity --limits`: the sinusoidal-grating table for the material's index.
fn print_limits(args: &ValidityArgs, material: &crate::material::Material) -> Result<()> {
    if args.csv.is_some() || args.plot.is_some() {
        return Err(crate::Error::invalid(
            "limits",
            "--limits prints its tables to stdout; it takes no --csv or --plot",
        ));
    }
    let lambda = args.lambda_nm.first().copied().unwrap_or(500.0);
    let thetas = if args.theta_i.is_empty() {
        vec![0.0, 60.0]
    } else {
        args.theta_i.clone()
    };
    let (periods, depths) = (validity::LIMITS_PERIODS, validity::LIMITS_DEPTHS);
    let cells = thetas.len() * periods.len() * depths.len();
    let bar = crate::progress::bar(cells as u64, "validity limits");
    let table = validity::limits_table(
        &ScalarModel::of(material),
        lambda,
        &thetas,
        &periods,
        &depths,
        args.rcwa_tolerance,
        || bar.inc(1),
    )?;
    bar.finish_and_clear();
    print!("{table}");
    Ok(())
}

/// Runs `diffract validity`.
pub fn run(args: &ValidityArgs) -> Result<()> {
    let base = match &args.scene {
        Some(p) => crate::scene::Scene::load(p)?.material,
        None => crate::scene::Scene::default_scene().material,
    };
    let mut material = args.material.apply(base);
    if let Some(n) = args.ior {
        material.ior = n;
    }
    material.validate()?;
    validity::check_index(material.ior)?;
    let lambdas = if args.lambda_nm.is_empty() {
        validity::SUMMARY_LAMBDAS_NM.to_vec()
    } else {
        args.lambda_nm.clone()
    };
    let thetas = if args.theta_i.is_empty() {
        vec![0.0, 30.0, 60.0]
    } else {
        args.theta_i.clone()
    };
    for &l in &lambdas {
        crate::guard::in_range("lambda-nm", l, 200.0..=2000.0, " nm")?;
    }
    for &t in &thetas {
        crate::guard::in_range("theta-i", t, 0.0..=85.0, "°")?;
    }
    crate::guard::in_range("rcwa-tolerance", args.rcwa_tolerance, 1e-4..=0.5, "")?;
    if args.limits {
        return print_limits(args, &material);
    }
    let outputs: Vec<(&str, PathBuf)> = [("--csv", &args.csv), ("--plot", &args.plot)]
        .into_iter()
        .filter_map(|(n, p)| p.clone().map(|p| (n, p)))
        .collect();
    let mut inputs = crate::guard::heightfield_inputs(&material.heightfield);
    if let Some(s) = &args.scene {
        inputs.push(("scene", s.clone()));
    }
    crate::guard::check_outputs(&inputs, &outputs)?;

    // The loader's lines (levelling, a scan's channel, the seam) are held until validity
    // has checked the field (crate::report::hold_notes): a refusal prints only its error.
    let hf = material.load_heightfield(&crate::report::Stderr)?;
    let profile = validity::extract_profile(&hf)?;
    crate::report::work_begins();
    let model = ScalarModel::of(&material);
    println!(
        "{}: period {:.4} µm across the ridges (grating vector {:.1}° from +x), mean profile {:.4} µm deep, n = {}; the 1-D mean profile explains {:.1} % of the height variance",
        material.heightfield,
        profile.period_um,
        profile.direction_deg,
        profile.depth_um(),
        material.ior,
        100.0 * profile.explained
    );
    let mut csv = String::from("theta_i_deg,lambda_nm,m,theta_r_deg,eta_te,eta_tm,eta_unpolarised,eta_scalar,rel_error,ratio_error,verdict\n");
    for &t in &thetas {
        for &l in &lambdas {
            let c = validity::check(&profile, &model, l, t, Solve::Converge(args.rcwa_tolerance))?;
            if let Some(e) = c.unconverged(args.rcwa_tolerance) {
                eprintln!(
                    "warning: λ = {l} nm, θi = {t}°: the rigorous solve stopped at {} orders × {} slices without converging to {}: its last refinement moved an order by {}, the estimated error of its orders",
                    2 * c.harmonics + 1,
                    c.slices,
                    validity::percent(args.rcwa_tolerance),
                    validity::percent(e)
                );
            }
            print!("{}", describe(&profile, &c));
            for r in &c.rows {
                let _ = writeln!(
                    csv,
                    "{t},{l},{},{:.4},{:.6e},{:.6e},{:.6e},{:.6e},{:.4},{},{}",
                    r.m,
                    r.theta_r_deg,
                    r.eta_te,
                    r.eta_tm,
                    r.eta_unpolarised,
                    r.eta_scalar,
                    r.rel_error,
                    r.ratio_error.map_or(String::new(), |e| format!("{e:.4}")),
                    r.verdict.label()
                );
            }
        }
    }
    if let Some(p) = &args.csv {
        crate::fsutil::write_atomic(p, csv.as_bytes())?;
        eprintln!("csv → {}", p.display());
    }
    if let Some(p) = &args.plot {
        let (ts, ls) = validity::map_grid();
        let bar = crate::progress::bar((ts.len() * ls.len()) as u64, "validity map");
        let map = validity::map(&profile, &model, &ts, &ls, validity::MAP_TOLERANCE, &bar)?;
        bar.finish_and_clear();
        if let Some(e) = map.unconverged {
            eprintln!(
                "warning: validity map: the rigorous solve at its hardest cell stopped at {} orders × {} slices without converging to {}: its last refinement moved an order by {}, the estimated error of every cell",
                2 * map.harmonics + 1,
                map.slices,
                validity::percent(validity::MAP_TOLERANCE),
                validity::percent(e)
            );
        }
        let title = format!(
            "Scalar model vs RCWA: {}, Λ = {:.3} µm, d = {:.3} µm, n = {}",
            crate::plot::source_name(&material.heightfield),
            profile.period_um,
            profile.depth_um(),
            material.ior
        );
        validity::plot::write_map(p, &map, &title)?;
        eprintln!(
            "plot → {} ({} harmonics, {} slices per cell)",
            p.display(),
            2 * map.harmonics + 1,
            map.slices
        );
    }
    Ok(())
}

/// The block of one check: its numbers, a table of the orders and the verdict.
pub fn describe(profile: &Profile, c: &Check) -> String {
    let mut s = String::new();
    let lambda_um = c.lambda_nm * 1e-3;
    let _ = writeln!(
        s,
        "\nλ = {} nm, θi = {}°: Λ/λ = {:.2}, d/λ = {:.2}; RCWA {} orders × {} slices, last refinement moved an order by {:.1e} (harmonics) and {:.1e} (slices); |R+T−1| = {:.1e}",
        c.lambda_nm,
        c.theta_i_deg,
        profile.period_um / lambda_um,
        profile.depth_um() / lambda_um,
        2 * c.harmonics + 1,
        c.slices,
        c.harmonic_change,
        c.slice_change,
        c.energy_error
    );
    let _ = writeln!(
        s,
        "{:>4} {:>11} {:>11} {:>11} {:>15} {:>11} {:>9} {:>11}  verdict",
        "m",
        "theta_r_deg",
        "eta_te",
        "eta_tm",
        "eta_unpolarised",
        "eta_scalar",
        "rel_error",
        "ratio_error"
    );
    for r in &c.rows {
        let _ = writeln!(
            s,
            "{:>4} {:>11.3} {:>11.3e} {:>11.3e} {:>15.3e} {:>11.3e} {:>9} {:>11}  {}",
            r.m,
            r.theta_r_deg,
            r.eta_te,
            r.eta_tm,
            r.eta_unpolarised,
            r.eta_scalar,
            format!("{:+.1} %", 100.0 * r.rel_error),
            r.ratio_error.map_or("-".into(), validity::percent),
            r.verdict.label()
        );
    }
    let _ = writeln!(
        s,
        "overall: {} (worst order-ratio error {} on {})",
        c.verdict.label(),
        validity::percent(c.error),
        c.error_of
    );
    s
}
