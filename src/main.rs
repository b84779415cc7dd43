//! The `diffract` command line: parses arguments, calls the library, prints one error line
//! and exits non-zero on failure.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Diffraction colours of natural nanostructures (Stam 1999; Dhillon et al. 2014).
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene (default: the embedded snake) or a BRDF map on the GPU.
    Render(diffract::render::RenderArgs),
    /// Evaluate the BRDF for a CSV of directions and wavelengths (reference or model).
    Brdf(diffract::brdf::query::BrdfArgs),
    /// Generate a test grating height field (PNG or .f32 with a .toml sidecar).
    Heightfield(diffract::heightfield::HeightfieldArgs),
    /// Grating-equation experiment (MODEL §8): period estimated from first-order peaks.
    EvalGrating(diffract::eval::EvalArgs),
    /// Shader variants on the GPU: error against the f64 reference together with GPU time.
    Profile(diffract::profile::ProfileArgs),
    /// List the shader variants: per-pixel fetches, memory, the default.
    Variants {
        /// Print the Markdown table of the variants (as in the README) instead.
        #[arg(long)]
        markdown: bool,
    },
    /// The DFT-term cache: list its files or clear it.
    Cache(diffract::spectrum::cache::CacheArgs),
    /// Stability matrix: error of each evaluator against the f64 reference over heights,
    /// light angles, wavelengths and expansions, with the terms used and pass/warned/refused.
    Stability(diffract::stability::StabilityArgs),
    /// Show a scene in a window: orbit camera, light, exposure, variants, hot reload.
    View(diffract::view::ViewArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    diffract::fsutil::remove_temps_on_interrupt();
    let result = match &cli.command {
        Command::Render(a) => diffract::render::run(a),
        Command::Brdf(a) => diffract::brdf::query::run(a),
        Command::Heightfield(a) => diffract::heightfield::run_heightfield(a),
        Command::EvalGrating(a) => diffract::eval::run(a),
        Command::Profile(a) => diffract::profile::run(a),
        Command::View(a) => diffract::view::run(a),
        Command::Variants { markdown } => {
            if *markdown {
                print!("{}", diffract::render::variant::markdown_table());
            } else {
                print!("{}", diffract::render::variant::list());
            }
            Ok(())
        }
        Command::Cache(a) => diffract::spectrum::cache::run(a),
        Command::Stability(a) => diffract::stability::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
