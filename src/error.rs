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
    /// An output could not be written (a full disk, a closed pipe): named as a write.
    #[error("writing {path}: {source}")]
    Write {
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
    /// A Vulkan call failed; `what` names the call. The results that need their own
    /// handling have their own variants ([`Error::DeviceLost`], [`Error::SurfaceLost`],
    /// [`Error::OutOfMemory`]); [`Error::vk`] sorts them.
    #[error("Vulkan error in {what}: {result}")]
    Vulkan {
        what: &'static str,
        result: ash::vk::Result,
    },
    /// `VK_ERROR_DEVICE_LOST`: the driver reset the GPU (a hang, a removed device). Nothing
    /// on the device can be used any more.
    #[error("the GPU device was lost in {what} (driver reset, GPU hang or removal); nothing more can be drawn in this run")]
    DeviceLost { what: &'static str },
    /// `VK_ERROR_SURFACE_LOST_KHR`: the window's surface is gone (e.g. the display closed).
    #[error(
        "the window's Vulkan surface was lost in {what} (the window or the display went away)"
    )]
    SurfaceLost { what: &'static str },
    /// `VK_ERROR_OUT_OF_DEVICE_MEMORY` or `VK_ERROR_OUT_OF_HOST_MEMORY`.
    #[error("out of {} memory in {what}; try a smaller image, table or storage format", if *.device { "GPU" } else { "host" })]
    OutOfMemory { what: &'static str, device: bool },
    /// GPU memory allocation failed.
    #[error("GPU allocation failed: {0}")]
    Alloc(#[from] gpu_allocator::AllocationError),
    /// The validation layer reported messages (tests treat this as failure).
    #[error("Vulkan validation reported {0} message(s)")]
    Validation(usize),
    /// Code read a value before the step that computes it ran: a bug in diffract, not
    /// in the input (the message names what was read and what should have come first).
    #[error("internal error: {0}")]
    Internal(&'static str),
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

    /// Shorthand for [`Error::Write`].
    pub fn write(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Write {
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

    /// Wraps a `vk::Result` with the name of the call that returned it. The one place
    /// where `vk::Result`s become errors: a lost device, a lost surface and exhausted
    /// memory get their own variants, everything else is [`Error::Vulkan`].
    pub fn vk(what: &'static str) -> impl FnOnce(ash::vk::Result) -> Self {
        use ash::vk::Result as R;
        move |result| match result {
            R::ERROR_DEVICE_LOST => Error::DeviceLost { what },
            R::ERROR_SURFACE_LOST_KHR => Error::SurfaceLost { what },
            R::ERROR_OUT_OF_DEVICE_MEMORY => Error::OutOfMemory { what, device: true },
            R::ERROR_OUT_OF_HOST_MEMORY => Error::OutOfMemory {
                what,
                device: false,
            },
            result => Error::Vulkan { what, result },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ash::vk;

    #[test]
    fn vulkan_results_map_to_their_kinds_with_one_line_messages() {
        let e = Error::vk("vkQueueSubmit")(vk::Result::ERROR_DEVICE_LOST);
        assert!(matches!(
            e,
            Error::DeviceLost {
                what: "vkQueueSubmit"
            }
        ));
        let e = Error::vk("vkQueuePresentKHR")(vk::Result::ERROR_SURFACE_LOST_KHR);
        assert!(matches!(e, Error::SurfaceLost { .. }));
        let e = Error::vk("vkAllocateMemory")(vk::Result::ERROR_OUT_OF_DEVICE_MEMORY);
        assert!(matches!(e, Error::OutOfMemory { device: true, .. }));
        assert!(e
            .to_string()
            .starts_with("out of GPU memory in vkAllocateMemory"));
        let e = Error::vk("vkCreateFence")(vk::Result::ERROR_OUT_OF_HOST_MEMORY);
        assert!(e.to_string().starts_with("out of host memory"));
        let e = Error::vk("vkCreateFence")(vk::Result::ERROR_INITIALIZATION_FAILED);
        assert!(matches!(e, Error::Vulkan { .. }));
        for e in [
            Error::vk("a")(vk::Result::ERROR_DEVICE_LOST),
            Error::vk("a")(vk::Result::ERROR_SURFACE_LOST_KHR),
            Error::vk("a")(vk::Result::ERROR_OUT_OF_DEVICE_MEMORY),
        ] {
            assert!(!e.to_string().contains('\n'), "{e}");
        }
    }
}
