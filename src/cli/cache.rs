//! `--cache-dir` and `--no-cache`: where the on-disk caches (DFT terms, sampled tables,
//! pipeline cache) of a command live.

use std::path::PathBuf;

/// The cache flags shared by `render`, `view`, `profile`, `brdf` and `eval-grating`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct CacheArgs {
    /// Directory of the DFT term cache (default: $DIFFRACT_CACHE or ~/.cache/diffract).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Do not read or write the term cache.
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
