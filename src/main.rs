//! The `diffract` command line: parses arguments, calls the library, prints one error line
//! and exits non-zero on failure.

use std::process::ExitCode;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

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
    Render(diffract::cli::render::RenderArgs),
    /// Evaluate the BRDF for a CSV of directions and wavelengths (reference or model).
    Brdf(diffract::cli::brdf::BrdfArgs),
    /// Generate a test grating height field (PNG or .f32 with a .toml sidecar).
    Heightfield(diffract::cli::heightfield::HeightfieldArgs),
    /// Grating-equation experiment (MODEL §8): period estimated from first-order peaks.
    EvalGrating(diffract::eval::EvalArgs),
    /// Shader variants on the GPU: error against the f64 reference together with GPU time.
    Profile(diffract::profile::ProfileArgs),
    /// List the shader variants: per-pixel fetches, memory, the default.
    Variants {
        /// Print the Markdown table of the variants (as in the README) instead.
        #[arg(long, conflicts_with = "fetches")]
        markdown: bool,
        /// Print docs/variants.md's names and fetch table instead.
        #[arg(long)]
        fetches: bool,
    },
    /// The DFT-term cache: list its files or clear it.
    Cache(diffract::cli::cache::CacheCommandArgs),
    /// Stability matrix: error of each evaluator against the f64 reference over heights,
    /// light angles, wavelengths and expansions, with the terms used and pass/warned/refused.
    Stability(diffract::stability::StabilityArgs),
    /// Where the scalar model is wrong: each diffraction order's power against a rigorous
    /// (RCWA) solution for the material's 1-D grating, with a verdict and a validity map.
    Validity(diffract::cli::validity::ValidityArgs),
    /// Show a scene in a window: orbit camera, light, exposure, variants, hot reload.
    View(diffract::view::ViewArgs),
}

/// The parser: every option that takes a value accepts a negative number (`--phi-i -30`,
/// `--table-texel -1` reaches the range check instead of reading `-1` as a flag). An option
/// of one floating-point value takes any value that starts with `-` (`-1e-3`, `-inf`), which
/// clap's own test for negative numbers does not cover; its number parser then judges it.
///
/// Whole-number options take any value that starts with `-` too (`--size -inf`), and their
/// parser says what is wrong and what is accepted (`not a whole number`, `negative`) instead
/// of the standard library's "invalid digit found in string"; a float32 option refuses a
/// number beyond float32's range instead of reading it as infinity.
fn command() -> clap::Command {
    use std::any::TypeId;
    Cli::command().mut_subcommands(|sub| {
        sub.mut_args(|a| {
            if !a.get_action().takes_values() {
                return a;
            }
            let id = a.get_value_parser().type_id();
            let single = a.get_num_args().is_none_or(|n| n.max_values() == 1);
            let a = if id == TypeId::of::<f32>() {
                a.value_parser(float32())
            } else if let Some(parser) = whole_number_parser(|t| id == t) {
                a.value_parser(parser)
            } else {
                a
            };
            let numeric = id == TypeId::of::<f64>()
                || id == TypeId::of::<f32>()
                || whole_number_parser(|t| id == t).is_some();
            if numeric && single {
                a.allow_hyphen_values(true)
            } else {
                a.allow_negative_numbers(true)
            }
        })
    })
}

/// The parser of a whole-number option, where `is` says its type is one.
fn whole_number_parser(
    is: impl Fn(std::any::TypeId) -> bool,
) -> Option<clap::builder::ValueParser> {
    use std::any::TypeId;
    if is(TypeId::of::<u8>()) {
        Some(whole::<u8>(0, u8::MAX.into()))
    } else if is(TypeId::of::<u16>()) {
        Some(whole::<u16>(0, u16::MAX.into()))
    } else if is(TypeId::of::<u32>()) {
        Some(whole::<u32>(0, u32::MAX.into()))
    } else if is(TypeId::of::<u64>()) {
        Some(whole::<u64>(0, u64::MAX.into()))
    } else if is(TypeId::of::<usize>()) {
        Some(whole::<usize>(0, usize::MAX as i128))
    } else if is(TypeId::of::<i32>()) {
        Some(whole::<i32>(i32::MIN.into(), i32::MAX.into()))
    } else if is(TypeId::of::<i64>()) {
        Some(whole::<i64>(i64::MIN.into(), i64::MAX.into()))
    } else {
        None
    }
}

/// A whole number of `T` in `[min, max]`; the message names what is wrong with the value
/// and what is accepted.
fn whole<T>(min: i128, max: i128) -> clap::builder::ValueParser
where
    T: TryFrom<i128> + Clone + Send + Sync + 'static,
{
    clap::builder::ValueParser::new(move |s: &str| -> Result<T, String> {
        let accepted = if max >= 1 << 32 {
            format!("a whole number ≥ {min}")
        } else {
            format!("a whole number from {min} to {max}")
        };
        let t = s.trim();
        match t.parse::<i128>() {
            Ok(v) if v < min => Err(format!("{v} is below {min}; expected {accepted}")),
            Ok(v) => T::try_from(v).map_err(|_| format!("{v} is too large; expected {accepted}")),
            Err(_) => match t.parse::<f64>() {
                Ok(x) if x.is_nan() => Err(format!("not a number; expected {accepted}")),
                Ok(_) => Err(format!("not a whole number; expected {accepted}")),
                Err(_) => Err(format!("not a number; expected {accepted}")),
            },
        }
    })
}

/// A float32 option: any number float32 holds (NaN and ±inf pass to the option's own range
/// check, which names the option); one beyond float32's range is refused here instead of
/// becoming infinity.
fn float32() -> clap::builder::ValueParser {
    clap::builder::ValueParser::new(|s: &str| -> Result<f32, String> {
        let x: f64 = s.trim().parse().map_err(|_| {
            "not a number; expected a decimal number such as 0.5 or 2e3".to_string()
        })?;
        if x.is_finite() && x.abs() > f64::from(f32::MAX) {
            return Err(format!("{x:e} is beyond float32's range (±{:e})", f32::MAX));
        }
        Ok(x as f32)
    })
}

/// An argument error as one line without the `error: ` prefix: clap's message, with its
/// indented notes (a list of missing arguments, the possible values, a tip) joined on, and
/// without the usage that follows.
fn one_line(e: &clap::Error) -> String {
    let text = strip_ansi(&e.render().to_string());
    let mut msg = String::new();
    // Within a list introduced by a line ending in ':' (the missing arguments).
    let mut in_list = false;
    for line in text.lines() {
        let line = line.trim();
        if line.starts_with("Usage:") || line.starts_with("For more information") {
            break;
        }
        if line.is_empty() {
            continue;
        }
        if msg.is_empty() {
            msg = line
                .strip_prefix("error:")
                .unwrap_or(line)
                .trim()
                .to_string();
            in_list = msg.ends_with(':');
        } else if msg.ends_with(':') {
            msg = format!("{msg} {line}");
        } else if in_list && !line.starts_with("tip:") && !line.starts_with('[') {
            msg = format!("{msg}, {line}");
        } else {
            msg = format!("{msg}; {line}");
            in_list = false;
        }
    }
    if msg.is_empty() {
        "invalid arguments; see diffract --help".to_string()
    } else {
        msg
    }
}

/// `s` without ANSI escape sequences (`ESC [ ... letter`).
fn strip_ansi(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            if chars.next() == Some('[') {
                for d in chars.by_ref() {
                    if d.is_ascii_alphabetic() {
                        break;
                    }
                }
            }
        } else {
            out.push(c);
        }
    }
    out
}

/// Parses the command line: `--help` and `--version` print and exit 0; any other problem
/// is one `error:` line and exit status 1, like every other error of diffract.
fn parse() -> Result<Cli, ExitCode> {
    use clap::error::ErrorKind;
    let parsed = command()
        .try_get_matches()
        .and_then(|m| Cli::from_arg_matches(&m));
    match parsed {
        Ok(cli) => Ok(cli),
        Err(e) if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) => {
            let _ = e.print();
            Err(ExitCode::SUCCESS)
        }
        Err(e) if e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            let names: Vec<String> = command()
                .get_subcommands()
                .map(|s| s.get_name().to_string())
                .collect();
            eprintln!(
                "error: no command given; expected one of: {} (see diffract --help)",
                names.join(", ")
            );
            Err(ExitCode::FAILURE)
        }
        Err(e) => {
            eprintln!("error: {}", one_line(&e));
            Err(ExitCode::FAILURE)
        }
    }
}

fn main() -> ExitCode {
    diffract::report::start_clock();
    let cli = match parse() {
        Ok(cli) => cli,
        Err(code) => return code,
    };
    diffract::fsutil::remove_temps_on_interrupt();
    // A refused command prints one error line: the notes of its checks wait for the work.
    diffract::report::hold_notes();
    // Large cache files are written while the command goes on, and waited for at its end.
    diffract::cache::write_behind_from_now();
    // The environment is an input like the flags: a bad cache cap is refused before any
    // work, by every command that may write the cache.
    if !matches!(
        cli.command,
        Command::Variants { .. } | Command::Heightfield(_)
    ) {
        if let Err(e) = diffract::cache::cache_max_bytes() {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    }
    let result = match &cli.command {
        Command::Render(a) => diffract::cli::render::run(a),
        Command::Brdf(a) => diffract::cli::brdf::run(a),
        Command::Heightfield(a) => diffract::cli::heightfield::run_heightfield(a),
        Command::EvalGrating(a) => diffract::eval::run(a),
        Command::Profile(a) => diffract::profile::run(a),
        Command::View(a) => diffract::view::run(a),
        Command::Variants { markdown, fetches } => {
            if *markdown {
                print!("{}", diffract::render::variant::markdown_table());
            } else if *fetches {
                print!("{}", diffract::render::variant::markdown_fetches());
            } else {
                print!("{}", diffract::render::variant::list());
            }
            Ok(())
        }
        Command::Cache(a) => diffract::cli::cache::run(a),
        Command::Stability(a) => diffract::stability::run(a),
        Command::Validity(a) => diffract::cli::validity::run(a),
    };
    diffract::cache::finish_writes(&diffract::report::Stderr);
    match result {
        Ok(()) => {
            diffract::report::work_begins();
            ExitCode::SUCCESS
        }
        Err(e) => {
            diffract::report::discard_notes();
            eprintln!("error: {}", diffract::report::readable(&e.to_string()));
            ExitCode::FAILURE
        }
    }
}
