//! Where the on-disk caches live: the DFT terms, the sampled tables and the pipeline cache
//! share one directory. A low module (no crate imports), so every command and every cache
//! resolves the directory the same way.

use std::path::{Path, PathBuf};

/// Default cache directory: `$DIFFRACT_CACHE`, else `$XDG_CACHE_HOME/diffract`, else
/// `$HOME/.cache/diffract`; `None` when none is set (or `DIFFRACT_CACHE` is empty).
pub fn default_cache_dir() -> Option<PathBuf> {
    if let Some(d) = std::env::var_os("DIFFRACT_CACHE") {
        return (!d.is_empty()).then(|| PathBuf::from(d));
    }
    if let Some(d) = std::env::var_os("XDG_CACHE_HOME") {
        return Some(PathBuf::from(d).join("diffract"));
    }
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache").join("diffract"))
}

/// The cache directory of a command: none with `--no-cache`, else `--cache-dir` if given,
/// else [`default_cache_dir`].
pub fn resolve(no_cache: bool, explicit: Option<&Path>) -> Option<PathBuf> {
    if no_cache {
        return None;
    }
    explicit.map(Path::to_path_buf).or_else(default_cache_dir)
}
