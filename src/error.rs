//! The crate's one error type. Every fallible public function returns [`Result`];
//! the binary prints `error: {e}` on one line and exits non-zero. Nothing here panics.

use std::path::PathBuf;

/// Everything that can go wrong in diffract, from a user's bad input to a Vulkan failure.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// An image could not be decoded, or is not what the caller needs.
    #[error("{path}: {msg}")]
    Image { path: PathBuf, msg: String },
    /// A file parsed but its content is wrong (bad mesh, bad scene, bad CSV row, ...).
    /// `msg` already carries line numbers where they exist.
    #[error("{path}: {msg}")]
    Parse { path: PathBuf, msg: String },
    /// A parameter is out of its valid range (named, with the value and the rule).
    #[error("invalid {what}: {msg}")]
    Invalid { what: &'static str, msg: String },
    /// A cached term file is corrupt or stale (callers recompute instead of failing).
    #[error("term cache {path}: {msg}")]
    Cache { path: PathBuf, msg: String },
    /// The Vulkan loader or a usable device is missing.
    #[error("Vulkan unavailable: {0}")]
    NoVulkan(String),
    /// No window can be shown: no display, no surface support, or no device that presents.
    #[error("cannot show a window: {0}")]
    NoPresentation(String),
    /// A Vulkan call failed; `what` names the call.
    #[error("Vulkan error in {what}: {result}")]
    Vulkan {
        what: &'static str,
        result: ash::vk::Result,
    },
    /// GPU memory allocation failed.
    #[error("GPU allocation failed: {0}")]
    Alloc(#[from] gpu_allocator::AllocationError),
    /// The validation layer reported messages (tests treat this as failure).
    #[error("Vulkan validation reported {0} message(s)")]
    Validation(usize),
}

/// Crate-wide result alias.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Shorthand for [`Error::Invalid`].
    pub fn invalid(what: &'static str, msg: impl Into<String>) -> Self {
        Error::Invalid {
            what,
            msg: msg.into(),
        }
    }

    /// Shorthand for [`Error::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// Shorthand for [`Error::Parse`].
    pub fn parse(path: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        Error::Parse {
            path: path.into(),
            msg: msg.into(),
        }
    }

    /// Wraps a `vk::Result` with the name of the call that returned it.
    pub fn vk(what: &'static str) -> impl FnOnce(ash::vk::Result) -> Self {
        move |result| Error::Vulkan { what, result }
    }
}
