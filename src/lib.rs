//! diffract: spectral diffraction from natural nanostructures (Stam 1999; Dhillon et al.
//! 2014), from a measured height field to a rendered image, with f64 CPU evaluators that
//! the GPU is checked against.
//!
//! Data flows top-down through the modules:
//! [`heightfield`] → [`spectrum`] (DFT terms) → [`colour`] (CIE tables) → [`brdf`] (CPU
//! reference and model) → `gpu` (Vulkan resources and pipelines) → `render` (frames and
//! BRDF maps) → images and numbers. `gpu` knows no physics and `brdf` knows no Vulkan.
#![warn(unsafe_op_in_unsafe_fn)]

pub mod brdf;
pub mod budget;
pub mod cache;
pub mod cachedir;
pub mod cli;
pub mod colour;
pub mod error;
pub mod eval;
pub mod fsutil;
pub mod gpu;
pub mod guard;
pub mod heightfield;
pub mod image_io;
pub mod leave_out;
pub mod light;
pub mod material;
pub mod mesh;
pub mod plot;
pub mod profile;
pub mod progress;
pub mod render;
pub mod report;
pub mod scene;
pub mod skin;
pub mod spectrum;
pub mod stability;
pub mod validity;
pub mod view;

pub use error::{Error, Result};
