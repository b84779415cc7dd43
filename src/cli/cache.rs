//! `--cache-dir` and `--no-cache`: where the on-disk caches (DFT terms, sampled tables,
//! pipeline cache) of a command live; and `diffract cache`, which lists and clears the
//! directory.

use std::path::PathBuf;

use crate::cache;
use crate::{Error, Result};

/// The cache flags shared by `render`, `view`, `profile`, `brdf` and `eval-grating`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct CacheArgs {
    /// Directory of the on-disk cache: DFT terms, sampled tables, model checks, pipelines
    /// (default: $DIFFRACT_CACHE, else $XDG_CACHE_HOME/diffract, else ~/.cache/diffract).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Do not read or write the on-disk cache.
    #[arg(long)]
    pub no_cache: bool,
}

impl CacheArgs {
    /// The command's cache directory: none with `--no-cache`, else `--cache-dir`, else the
    /// default ([`crate::cachedir::resolve`]).
    pub fn dir(&self) -> Option<PathBuf> {
        crate::cachedir::resolve(self.no_cache, self.cache_dir.as_deref())
    }
}

/// `diffract cache` options.
#[derive(Debug, Clone, clap::Args)]
pub struct CacheCommandArgs {
    /// What to do.
    #[arg(value_enum, default_value_t = CacheAction::List)]
    pub action: CacheAction,
    /// Directory of the DFT-term cache (default: $DIFFRACT_CACHE or ~/.cache/diffract).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
}

/// `diffract cache list|clear`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CacheAction {
    /// One line per file (size, last use, what it holds) and the total against the cap.
    List,
    /// Remove every term file and stale temporary file.
    Clear,
}

/// Runs `diffract cache`.
pub fn run(args: &CacheCommandArgs) -> Result<()> {
    let dir = args
        .cache_dir
        .clone()
        .or_else(crate::cachedir::default_cache_dir)
        .ok_or_else(|| {
            Error::invalid(
                "cache directory",
                "none: set DIFFRACT_CACHE or HOME, or give --cache-dir",
            )
        })?;
    let max = cache::cache_max_bytes()?;
    let temps = cache::clean_stale_temps(&dir);
    let list = cache::entries(&dir)?;
    let total: u64 = list.iter().map(|e| e.bytes).sum();
    match args.action {
        CacheAction::List => {
            for e in &list {
                let age = e
                    .last_used
                    .elapsed()
                    .map_or("?".to_string(), |d| format!("{}", d.as_secs()));
                let gtable = e
                    .path
                    .file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with(cache::TABLE_FILES));
                let validity = e
                    .path
                    .file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with(cache::VALIDITY_FILES));
                let packed = e
                    .path
                    .file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with(cache::PACKED_FILES));
                let what = match crate::spectrum::cache::read_header(&e.path) {
                    _ if gtable => "sampled G table of a table variant".to_string(),
                    _ if packed => {
                        "a table variant's GPU texels (pre-filtered, fitted, packed)".to_string()
                    }
                    _ if validity => "scalar model against RCWA (validity cells)".to_string(),
                    Ok(h) => format!(
                        "{}×{} {} T={} band {}×{} {:?}",
                        h.nx,
                        h.ny,
                        h.expansion,
                        h.count.saturating_sub(1),
                        h.band.width,
                        h.band.height,
                        h.precision
                    ),
                    Err(msg) => format!("unreadable: {msg}"),
                };
                println!(
                    "{}  {:>8.1} MiB  used {age} s ago  {what}",
                    e.path.display(),
                    e.bytes as f64 / (1u64 << 20) as f64
                );
            }
            println!(
                "{}: {} file(s), {:.1} MiB of {:.1} MiB (DIFFRACT_CACHE_MAX){}",
                dir.display(),
                list.len(),
                total as f64 / (1u64 << 20) as f64,
                max as f64 / (1u64 << 20) as f64,
                if temps > 0 {
                    format!("; removed {temps} stale temporary file(s)")
                } else {
                    String::new()
                }
            );
        }
        CacheAction::Clear => {
            let mut removed = 0u64;
            let mut count = 0usize;
            for e in &list {
                std::fs::remove_file(&e.path).map_err(|err| Error::io(&e.path, err))?;
                removed += e.bytes;
                count += 1;
            }
            println!(
                "{}: removed {count} file(s), {:.1} MiB{}",
                dir.display(),
                removed as f64 / (1u64 << 20) as f64,
                if temps > 0 {
                    format!(" and {temps} stale temporary file(s)")
                } else {
                    String::new()
                }
            );
        }
    }
    Ok(())
}
