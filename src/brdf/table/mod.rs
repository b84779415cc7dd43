//! Pre-integrated tables (MODEL §7). With the height field, the coherence window, D65 and
//! the CIE functions fixed, the colour is `XYZ(ωi, ωr) = C(ωi, ωr) · G(u, v, w)`, where
//!
//! `G(u, v, w) = Σ_λ |P̂_λ(ku, kv; w)|² · weights(λ)`
//!
//! depends on three scalars only. This module computes `G` in f64 on a grid over the region
//! of `(u, v, w)` a scene can reach — exactly, from the windowed spectrum of `exp(i·s·h)` at
//! `s = k·w` (one FFT of the phase field gives the whole `(u, v)` plane of one `s`), with
//! the Gaussian window untruncated (6σ) — so no series and no cancellation reach the GPU.
//! It also holds the f64 CPU models of the three stored representations, which interpolate
//! exactly as the GPU variants do: [`Volume`] (trilinear in `(u, v, w)`), [`ChebyshevW`]
//! (bilinear coefficients of a Chebyshev series in `w`, Clenshaw) and [`Dhillon`]
//! (bilinear coefficients of powers of `w`, Horner). No Vulkan here.
//!
//! One file each: the region and the spec ([`region`]), the exact sampler ([`sample`]), the
//! disc pre-filter ([`disc`]), the splines ([`spline`]), the `w` nodes and how many a table
//! needs ([`nodes`]), the representations ([`representation`]), and for a pixel's footprint
//! the levels pre-filtered ([`levels`]) and the summed-area planes ([`summed`]).

mod disc;
mod levels;
mod nodes;
mod region;
mod representation;
mod sample;
mod spline;
mod summed;

pub use disc::{prefilter_disc, DiscKernel};
pub use levels::{Levelled, MAX_LEVELS};
pub use nodes::{
    chebyshev_nodes, chebyshev_w_nodes, uniform_nodes, CHEBYSHEV_W_TOLERANCE, MIN_CHEBYSHEV_W_NODES,
};
pub use region::{Region, Response, Slices, TableSpec, MAX_NODES_UV, MAX_NODES_W, MAX_SAMPLES};
pub use representation::{clenshaw, ChebyshevW, Dhillon, GTable, Truncation, Volume, F32_ROUNDOFF};
pub use sample::{
    sample_g, sample_g_kept, sample_g_kept_in, sample_g_lines, sample_g_lines_in, Sampled,
    FAST_BUILD_TOLERANCE,
};
pub use spline::{spline_plane, spline_weights};
pub use summed::Summed;
