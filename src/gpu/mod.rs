//! Everything `ash`: the headless device layer ([`context`], which knows no surface), memory
//! objects ([`memory`]), texel storage formats ([`formats`]), layouts/descriptors/pipelines
//! ([`pipeline`]) and the on-disk pipeline cache ([`pipeline_cache`]), the one render-pass
//! builder ([`render_pass`]), render targets ([`target`]), frames in flight with deferred
//! release ([`frames`]), presentation ([`swapchain`], optional), GPU timestamps ([`timer`])
//! and the SPIR-V compiled by `build.rs`.
//!
//! Imports run one way, from the presentation end down to the device: `swapchain` → `target`
//! → `render_pass`, `memory` → `context` → `pipeline_cache`; `frames` → `timer` → `context`
//! (docs/architecture.md lists them all).
//!
//! This module knows Vulkan, not physics: what the bindings and specialisation constants
//! mean is decided by `render.rs` and `glsl/`. Every object is named (debug utils), owned by
//! an RAII type that destroys it in reverse creation order, and every allocation is freed
//! explicitly.
#![warn(unsafe_op_in_unsafe_fn)]

pub mod compute;
pub mod context;
pub mod formats;
pub mod frames;
pub mod memory;
pub mod pipeline;
pub mod pipeline_cache;
pub mod render_pass;
pub mod swapchain;
pub mod target;
pub mod timer;

pub use context::{Canary, Device, DeviceInfo, Instance};
pub use formats::StorageFormat;

/// SPIR-V modules compiled from `glsl/` by `build.rs` (bytes; `ash::util::read_spv` copies
/// them into aligned words, so the byte alignment of `include_bytes!` does not matter): one
/// constant per stage, named after its file (`flss.frag` → `FLSS_FRAG`), and [`shaders::FILES`]
/// by file name, both generated from the directory's contents.
pub mod shaders {
    include!(concat!(env!("OUT_DIR"), "/shaders.rs"));

    /// The built-in SPIR-V of the stage `file` of glsl/ (e.g. `"flss.frag"`).
    pub fn spirv(file: &str) -> Option<&'static [u8]> {
        FILES.iter().find(|(f, _)| *f == file).map(|(_, b)| *b)
    }
}
