//! The `diffract heightfield` command: generate a test grating, or grow a measured sample
//! into a coherence-sized field, and save it with its sidecar. Argument parsing only; the
//! work is [`generate`], [`grow`] and [`HeightField::save`].

use std::path::PathBuf;

use crate::heightfield::{generate, grow, GratingKind, GratingSpec, HeightField, DEFAULT_SIZE_UM};
use crate::{Error, Result};

/// Generate a test grating height field (MODEL §9), or grow a measured sample (`--from-sample`)
/// into a coherence-sized field with the sample's height histogram and power spectrum.
#[derive(Debug, Clone, clap::Args)]
#[command(group(clap::ArgGroup::new("source").required(true).args(["kind", "from_sample"])))]
pub struct HeightfieldArgs {
    /// Which grating to synthesise.
    #[arg(long, value_enum)]
    pub kind: Option<GratingKind>,
    /// Grow this height field (PNG or .f32 with its sidecar, a .gsf/.gwy scan, or builtin:…) instead: spectral
    /// synthesis from its tapered power spectrum, random phases, its height histogram.
    #[arg(long, value_name = "F.png")]
    pub from_sample: Option<String>,
    /// Output file: .png (16-bit grayscale) or .f32 (raw µm); a .toml sidecar is written beside it.
    #[arg(short, long)]
    pub out: PathBuf,
    /// Patch side in µm [default: 65].
    #[arg(long, allow_negative_numbers = true, conflicts_with = "samples")]
    pub size_um: Option<f64>,
    /// --from-sample: side in samples instead of --size-um.
    #[arg(long, requires = "from_sample")]
    pub samples: Option<usize>,
    /// Pixel size in µm, at most 0.095 [default: 65/704]. With --from-sample: the sample's
    /// pixel size (overrides its sidecar); the grown field keeps it.
    #[arg(long, allow_negative_numbers = true)]
    pub dh_um: Option<f64>,
    /// --from-sample: height of the sample's grey level 1 in µm (a scan's peak-to-valley
    /// height; overrides its sidecar).
    #[arg(
        long = "hmax-um",
        value_name = "HMAX_UM",
        allow_negative_numbers = true,
        requires = "from_sample"
    )]
    pub h_max_um: Option<f64>,
    /// --from-sample: the scan channel, by index or title [default: the first height channel].
    #[arg(long, requires = "from_sample")]
    pub channel: Option<String>,
    /// --from-sample: levelling, none, plane, poly:N, rows, comma-separated [default:
    /// plane,rows for scans, none otherwise].
    #[arg(long, requires = "from_sample")]
    pub level: Option<String>,
    /// Ridge period in µm, snapped so a whole number fits the patch [default: per kind].
    #[arg(long, allow_negative_numbers = true, conflicts_with = "from_sample")]
    pub period_um: Option<f64>,
    /// Peak-to-valley height in µm [default: per kind].
    #[arg(long, allow_negative_numbers = true, conflicts_with = "from_sample")]
    pub height_um: Option<f64>,
    /// Orientation in degrees (xenopeltis: tilt of the second domain) [default: per kind].
    #[arg(long, allow_negative_numbers = true, conflicts_with = "from_sample")]
    pub angle_deg: Option<f64>,
    /// Seed of the irregularities (elaphe, xenopeltis) or of the grown field's phases [default: 1].
    #[arg(long)]
    pub seed: Option<u64>,
}

impl HeightfieldArgs {
    /// The grating spec these arguments describe: the kind's defaults with the given options
    /// applied (`None` for `--from-sample`).
    pub fn spec(&self) -> Option<GratingSpec> {
        let kind = self.kind?;
        let d = GratingSpec::default_for(kind);
        Some(GratingSpec {
            kind,
            size_um: self.size_um.unwrap_or(d.size_um),
            dh_um: self.dh_um.unwrap_or(d.dh_um),
            period_um: self.period_um.unwrap_or(d.period_um),
            height_um: self.height_um.unwrap_or(d.height_um),
            angle_deg: self.angle_deg.unwrap_or(d.angle_deg),
            seed: self.seed.unwrap_or(d.seed),
        })
    }

    /// Side in samples of the field grown from a sample of pixel size `dh_um`:
    /// `--samples`, or `round(--size-um / dH)` (65 µm by default).
    pub fn grown_samples(&self, dh_um: f64) -> Result<usize> {
        if let Some(n) = self.samples {
            return Ok(n);
        }
        let size = self.size_um.unwrap_or(DEFAULT_SIZE_UM);
        if !(size.is_finite() && size > 0.0) {
            return Err(Error::invalid(
                "size",
                format!("{size} µm; must be positive and finite"),
            ));
        }
        let n = (size / dh_um).round();
        if n > crate::heightfield::MAX_SIDE as f64 {
            return Err(Error::invalid(
                "size",
                format!(
                    "{size} µm at dH = {:.2} nm is {n} samples, over the limit of {}",
                    dh_um * 1e3,
                    crate::heightfield::MAX_SIDE
                ),
            ));
        }
        Ok(n as usize)
    }
}

/// Generates (or grows), saves and prints one summary line.
pub fn run_heightfield(args: &HeightfieldArgs) -> Result<()> {
    crate::guard::heightfield_args(&args.out, args.from_sample.as_deref())?;
    match (&args.kind, &args.from_sample) {
        (Some(_), None) => run_generate(args),
        (None, Some(sample)) => run_grow(args, sample),
        _ => Err(Error::invalid(
            "heightfield",
            "give exactly one of --kind and --from-sample",
        )),
    }
}

fn run_generate(args: &HeightfieldArgs) -> Result<()> {
    if args.samples.is_some() || args.h_max_um.is_some() {
        return Err(Error::invalid(
            "heightfield",
            "--samples and --hmax-um only apply to --from-sample",
        ));
    }
    let Some(spec) = args.spec() else {
        return Err(Error::invalid("heightfield", "--kind is missing"));
    };
    let (first, second) = spec.waves()?;
    let hf = generate(&spec)?;
    hf.save(&args.out)?;
    let period = match second {
        Some(b) => format!(
            "period {:.4} µm at {:.2}° / {:.4} µm at {:.2}°",
            first.period_um, first.angle_deg, b.period_um, b.angle_deg
        ),
        None => format!(
            "period {:.4} µm at {:.2}°",
            first.period_um, first.angle_deg
        ),
    };
    summary(args, &spec.kind.to_string(), &hf, &period);
    Ok(())
}

fn run_grow(args: &HeightfieldArgs, sample: &str) -> Result<()> {
    let source = crate::heightfield::Source {
        dh_um: args.dh_um,
        h_max_um: args.h_max_um,
        channel: args.channel.clone(),
        level: args.level.clone(),
        ..crate::heightfield::Source::new(sample)
    };
    let crop = source.load(&crate::report::Stderr)?;
    let n = args.grown_samples(crop.dh_um())?;
    let hf = grow(&crop, n, args.seed.unwrap_or(1))?;
    hf.save(&args.out)?;
    let what = format!("grown from {} ({}×{})", sample, crop.nx(), crop.ny());
    summary(
        args,
        &what,
        &hf,
        &format!("seed {}", args.seed.unwrap_or(1)),
    );
    Ok(())
}

fn summary(args: &HeightfieldArgs, what: &str, hf: &HeightField, extra: &str) {
    let (lo, hi) = hf.range();
    let (ex, ey) = hf.extent_um();
    println!(
        "{}: {what} {}×{} samples ({ex:.3}×{ey:.3} µm), dH {:.2} nm, h {lo:.4}–{hi:.4} µm, {extra}",
        args.out.display(),
        hf.nx(),
        hf.ny(),
        hf.dh_um() * 1e3,
    );
}
