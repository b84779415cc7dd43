//! The `diffract heightfield` command: generate a test grating and save it with its
//! sidecar. Argument parsing only; the work is [`generate`] and [`HeightField::save`].

use std::path::PathBuf;

use super::generate::{generate, GratingKind, GratingSpec};
use crate::Result;

/// Generate a test grating height field (MODEL §9).
#[derive(Debug, Clone, clap::Args)]
pub struct HeightfieldArgs {
    /// Which grating to synthesise.
    #[arg(long, value_enum)]
    pub kind: GratingKind,
    /// Output file: .png (16-bit grayscale) or .f32 (raw µm); a .toml sidecar is written beside it.
    #[arg(short, long)]
    pub out: PathBuf,
    /// Patch side in µm [default: 65].
    #[arg(long, allow_negative_numbers = true)]
    pub size_um: Option<f64>,
    /// Pixel size in µm, at most 0.095 [default: 65/704].
    #[arg(long, allow_negative_numbers = true)]
    pub dh_um: Option<f64>,
    /// Ridge period in µm, snapped so a whole number fits the patch [default: per kind].
    #[arg(long, allow_negative_numbers = true)]
    pub period_um: Option<f64>,
    /// Peak-to-valley height in µm [default: per kind].
    #[arg(long, allow_negative_numbers = true)]
    pub height_um: Option<f64>,
    /// Orientation in degrees (xenopeltis: tilt of the second domain) [default: per kind].
    #[arg(long, allow_negative_numbers = true)]
    pub angle_deg: Option<f64>,
    /// Seed of the irregularities (elaphe, xenopeltis) [default: 1].
    #[arg(long)]
    pub seed: Option<u64>,
}

impl HeightfieldArgs {
    /// The spec these arguments describe: the kind's defaults with the given options applied.
    pub fn spec(&self) -> GratingSpec {
        let d = GratingSpec::default_for(self.kind);
        GratingSpec {
            kind: self.kind,
            size_um: self.size_um.unwrap_or(d.size_um),
            dh_um: self.dh_um.unwrap_or(d.dh_um),
            period_um: self.period_um.unwrap_or(d.period_um),
            height_um: self.height_um.unwrap_or(d.height_um),
            angle_deg: self.angle_deg.unwrap_or(d.angle_deg),
            seed: self.seed.unwrap_or(d.seed),
        }
    }
}

/// Generates, saves and prints one summary line.
pub fn run_heightfield(args: &HeightfieldArgs) -> Result<()> {
    crate::guard::heightfield_args(&args.out)?;
    let spec = args.spec();
    let (first, second) = spec.waves()?;
    let hf = generate(&spec)?;
    hf.save(&args.out)?;
    let (lo, hi) = hf.range();
    let (ex, ey) = hf.extent_um();
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
    println!(
        "{}: {} {}×{} samples ({ex:.3}×{ey:.3} µm), dH {:.2} nm, h {lo:.4}–{hi:.4} µm, {period}",
        args.out.display(),
        spec.kind,
        hf.nx(),
        hf.ny(),
        hf.dh_um() * 1e3,
    );
    Ok(())
}
