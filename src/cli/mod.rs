//! The command line's shared flag groups: each is a `clap::Args` struct that the commands
//! flatten into their own arguments, with its checks and its translation into library
//! settings beside it, so a flag is declared, documented and checked once.
//!
//! - [`gpu::GpuArgs`]: the shader variant, the term storage, per-vertex evaluation and the
//!   table options ([`gpu::TableArgs`]);
//! - [`cache::CacheArgs`]: `--cache-dir` and `--no-cache`;
//! - [`material::MaterialArgs`]: the height field and the material's numbers;
//! - [`scene::SceneArgs`]: the scene file and the overrides of its output (size, exposure).
//!
//! It also holds the commands whose library module sits below these groups: `render`
//! ([`render`]), `brdf` ([`brdf`]) and `heightfield` ([`heightfield`]). The other commands
//! (`view`, `profile`, `stability`, `eval-grating`) live in their own modules, above this
//! one.
//!
//! This is the edge between the commands and the library: the groups import the library's
//! types, the commands import the groups, and nothing below the commands imports this
//! module. Import a group from its own file (`crate::cli::gpu::GpuArgs`); this file hands no
//! names on.

pub mod brdf;
pub mod cache;
pub mod env;
pub mod gpu;
pub mod heightfield;
pub mod material;
pub mod render;
pub mod scene;
pub mod validity;
