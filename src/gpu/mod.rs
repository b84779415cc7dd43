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
/// them into aligned words, so the byte alignment of `include_bytes!` does not matter).
pub mod shaders {
    /// Thesis Algorithm 2.
    pub const DIFFRACTION_VERT: &[u8] =
        include_bytes!(concat!(env!("OUT_DIR"), "/diffraction.vert.spv"));
    /// Full-screen triangle for BRDF maps.
    pub const BRDFMAP_VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/brdfmap.vert.spv"));
    /// Variant `flss`: thesis Algorithms 3 and 4.
    pub const FLSS_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/flss.frag.spv"));
    /// Variant `nmm`: FLSS at the wavelengths of the grating's orders.
    pub const NMM_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/nmm.frag.spv"));
    /// Variant `pq`: one period's spectrum × the periodic factor.
    pub const PQ_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/pq.frag.spv"));
    /// Per-vertex evaluation (thesis §1.5.1): the vertex stages of `flss`, `nmm`, `pq` and
    /// the fragment stage that blends the interpolated colour.
    pub const FLSS_VERTEX_VERT: &[u8] =
        include_bytes!(concat!(env!("OUT_DIR"), "/flss_vertex.vert.spv"));
    pub const NMM_VERTEX_VERT: &[u8] =
        include_bytes!(concat!(env!("OUT_DIR"), "/nmm_vertex.vert.spv"));
    pub const PQ_VERTEX_VERT: &[u8] =
        include_bytes!(concat!(env!("OUT_DIR"), "/pq_vertex.vert.spv"));
    pub const PER_VERTEX_FRAG: &[u8] =
        include_bytes!(concat!(env!("OUT_DIR"), "/per_vertex.frag.spv"));
    /// Variant `volume`: G(u, v, w) in a 3D texture.
    pub const VOLUME_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/volume.frag.spv"));
    /// Variant `chebyshev-w`: Chebyshev coefficient planes in w, Clenshaw.
    pub const CHEBYSHEV_W_FRAG: &[u8] =
        include_bytes!(concat!(env!("OUT_DIR"), "/chebyshev_w.frag.spv"));
    /// Variant `dhillon`: planes of the powers of w, Horner.
    pub const DHILLON_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/dhillon.frag.spv"));
}
