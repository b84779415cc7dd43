//! Error-versus-time profiling of shader variants (MODEL §6–7): every row (a variant with
//! its numerical choices) renders the same BRDF map (and, optionally, a mesh view) on the
//! GPU, is timed with GPU timestamps (median of the frames after a warm-up frame that also
//! builds its tables), and is scored at sampled pixels against the f64 reference (direct
//! sum, 1 nm) and against the variant's own f64 model
//! ([`CpuModel`](crate::render::variant::CpuModel)), which separates approximation error
//! from float32 and driver error.
//!
//! Metrics per row (MODEL §6): relative L2 of linear XYZ over the sampled pixels, max
//! |ΔY|, and CIEDE2000 (p50, p99, mean, max) of the colours after scaling so the brightest
//! reference sample has `Y = 1`; the relative L2 and ΔE p99 against the reference carry a
//! 95 % bootstrap interval over the scored pixels.
//!
//! Frames per row are either fixed ([`Frames::Fixed`], `--full`) or budgeted
//! ([`Frames::Budget`]): the default variant's row first, then the rest cheapest first;
//! each draws frames until its median is known to the budget's precision or its share of
//! the time left is spent, and a row whose estimated cost exceeds the time left is reported
//! as skipped with that estimate.
//!
//! The files, in the order a reader meets them: `plan` (the rows and the set-up), `run`
//! (the entry [`profile`] and each row's measurement), `budget` (frames, budget, pace),
//! `score` (the scored pixels, the references and a row's scores), `stats` (the error
//! figures and their bootstrap intervals), `output` (the reports, table, CSV and plot),
//! `progress` (the lines on stderr), `picture` (the whole-picture rows: a scene against
//! the same scene supersampled) and `command` (`diffract profile`'s flags and run).

mod budget;
mod command;
mod env;
mod output;
mod picture;
mod plan;
mod progress;
mod run;
mod score;
mod stats;

pub use budget::{Budget, FrameTimes, Frames};
pub use command::{profile_args, run, Counts, ProfileArgs};
pub use output::{
    format_csv, format_table, EnvRow, EnvRun, EnvSkipped, ProfileRun, Skipped, VariantReport,
};
pub use picture::{PictureError, PictureRow, PictureRun, PictureSetup};
pub use plan::{
    flss_variants, standard_variants, table_variants, EnvProfile, ProfileSetup, Variant,
    DEFAULT_ENV_PIXELS, DEFAULT_ENV_SPP,
};
pub use run::{profile, profile_with_env};
pub use stats::{bootstrap, error_stats, ErrorIntervals, ErrorStats, Interval};
