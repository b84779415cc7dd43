//! Height fields of nanostructures (MODEL §1): a periodic grid of heights in µm with pixel
//! size `dH`. Owns validation, loading (PNG 8/16-bit, raw f32 with a TOML sidecar, Gwyddion
//! `.gsf`/`.gwy` scans with their units; one loader, [`Source`]), levelling, seams, the
//! seeded generators of the MODEL §9 test gratings and the growing of a measured crop into a
//! coherence-sized field. It knows nothing about spectra or GPUs.

use crate::{Error, Result};

mod generate;
mod grow;
pub mod gsf;
pub mod gwy;
mod io;
pub mod level;
pub mod load;
pub mod scan;
pub mod seam;

pub use generate::{
    generate, GratingKind, GratingSpec, LatticeWave, DEFAULT_DH_UM, DEFAULT_SIZE_UM,
    MAX_GENERATED_DH_UM,
};
pub use grow::{grow, GROW_ITERATIONS};
pub use io::{
    sidecar_path, BUILTIN_PREFIX, GROWN_SAMPLES, MEASURED_ELAPHE_DH_UM, MEASURED_ELAPHE_H_MAX_UM,
};
pub use level::{LevelReport, Levelling};
pub use load::Source;
pub use seam::Tile;

/// Largest accepted side length (samples). 4096² f64 heights are 128 MiB, and each DFT
/// term of that size another 256 MiB: beyond this the precompute is not interactive.
pub const MAX_SIDE: usize = 4096;
/// Fewest samples of a height field: one sample has no neighbour, so no slope and no
/// spatial frequency but zero.
pub const MIN_SAMPLES: usize = 2;

/// Smallest accepted pixel size (µm, 0.1 nm). At `dH = 1e-20 µm` the lookup offset
/// `u·N·dH/λ` vanishes next to the centre index `N/2` in f64, so every direction read the
/// specular texel and off-specular `ρ` was nonzero; at 0.1 nm the patch is already far below
/// a wavelength and the offset is still exact to ~1e-12 texels.
pub const MIN_DH_UM: f64 = 1e-4;
/// Largest accepted pixel size (µm, 1 mm): lookups then sit millions of texels off centre,
/// beyond what float32 positions resolve.
pub const MAX_DH_UM: f64 = 1e3;
/// Largest accepted |height| (µm). Taylor terms reach `h^64`, which must stay finite in f64
/// (`1e3^64 = 1e192`); anything this tall is far beyond what any expansion can sum (the
/// term planner refuses well before), and a stray `1e30` sample or `h_max = 1e6` turned every
/// output into inf/NaN.
pub const MAX_HEIGHT_UM: f64 = 1e3;

/// A periodic height field. Sample (column `c`, row `r`) sits at `x = c·dH`, `y = r·dH`;
/// `x` runs along the surface tangent. Heights are stored row-major in µm.
#[derive(Debug, Clone, PartialEq)]
pub struct HeightField {
    nx: usize,
    ny: usize,
    dh_um: f64,
    heights_um: Vec<f64>,
}

impl HeightField {
    /// Builds a validated height field: non-empty, at most [`MAX_SIDE`] a side, finite
    /// heights, finite `dH > 0`.
    pub fn new(nx: usize, ny: usize, dh_um: f64, heights_um: Vec<f64>) -> Result<Self> {
        if nx == 0 || ny == 0 {
            return Err(Error::invalid(
                "height field",
                format!("size {nx}×{ny} is empty"),
            ));
        }
        if nx * ny < MIN_SAMPLES {
            return Err(Error::invalid(
                "height field",
                format!(
                    "size {nx}×{ny} is a single sample, a flat mirror with no surface to diffract; at least {MIN_SAMPLES} samples (2×1, a profile along one axis, or larger)"
                ),
            ));
        }
        if nx > MAX_SIDE || ny > MAX_SIDE {
            return Err(Error::invalid(
                "height field",
                format!("size {nx}×{ny} exceeds the limit of {MAX_SIDE} samples a side"),
            ));
        }
        if heights_um.len() != nx * ny {
            return Err(Error::invalid(
                "height field",
                format!("{} samples for a {nx}×{ny} grid", heights_um.len()),
            ));
        }
        if !(dh_um.is_finite() && dh_um > 0.0) {
            return Err(Error::invalid(
                "dH",
                format!("{dh_um} µm; the pixel size must be a finite positive length"),
            ));
        }
        if !(MIN_DH_UM..=MAX_DH_UM).contains(&dh_um) {
            return Err(Error::invalid(
                "dH",
                format!(
                    "{dh_um} µm; the pixel size must lie in [{MIN_DH_UM}, {MAX_DH_UM}] µm \
                     (0.1 nm to 1 mm): below it the lookup offset u·N·dH/λ is lost to rounding \
                     and off-specular directions read the specular lobe"
                ),
            ));
        }
        if let Some(i) = heights_um.iter().position(|h| !h.is_finite()) {
            return Err(Error::invalid(
                "height field",
                format!("sample (column {}, row {}) is not finite", i % nx, i / nx),
            ));
        }
        if let Some(i) = heights_um.iter().position(|h| h.abs() > MAX_HEIGHT_UM) {
            return Err(Error::invalid(
                "height field",
                format!(
                    "sample (column {}, row {}) is {} µm; heights must lie within ±{MAX_HEIGHT_UM} µm \
                     (check h_max and the units: heights are in µm)",
                    i % nx,
                    i / nx,
                    heights_um[i]
                ),
            ));
        }
        Ok(Self {
            nx,
            ny,
            dh_um,
            heights_um,
        })
    }

    /// Samples along `x` (columns).
    pub fn nx(&self) -> usize {
        self.nx
    }
    /// Samples along `y` (rows).
    pub fn ny(&self) -> usize {
        self.ny
    }
    /// Pixel size in µm.
    pub fn dh_um(&self) -> f64 {
        self.dh_um
    }
    /// Row-major heights in µm.
    pub fn heights_um(&self) -> &[f64] {
        &self.heights_um
    }
    /// Height at column `c`, row `r`, both wrapped periodically.
    pub fn at(&self, c: i64, r: i64) -> f64 {
        let c = c.rem_euclid(self.nx as i64) as usize;
        let r = r.rem_euclid(self.ny as i64) as usize;
        self.heights_um[r * self.nx + c]
    }
    /// Mean height (µm).
    pub fn mean(&self) -> f64 {
        self.heights_um.iter().sum::<f64>() / self.heights_um.len() as f64
    }
    /// (min, max) height in µm.
    pub fn range(&self) -> (f64, f64) {
        self.heights_um
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &h| {
                (lo.min(h), hi.max(h))
            })
    }
    /// The same field with every height multiplied by `factor` (finite, ≥ 0): the
    /// structure `factor` times as tall.
    pub fn scaled(&self, factor: f64) -> Result<Self> {
        if !(factor.is_finite() && factor >= 0.0) {
            return Err(Error::invalid(
                "height scale",
                format!("{factor}; must be finite and ≥ 0"),
            ));
        }
        let heights = self.heights_um.iter().map(|h| h * factor).collect();
        Self::new(self.nx, self.ny, self.dh_um, heights)
    }
    /// Largest deviation from the mean, `max|h − mean|` (the Taylor bound of MODEL §4).
    pub fn max_deviation(&self) -> f64 {
        let m = self.mean();
        self.heights_um
            .iter()
            .fold(0.0, |acc: f64, &h| acc.max((h - m).abs()))
    }
    /// Patch extent along x and y in µm.
    pub fn extent_um(&self) -> (f64, f64) {
        (self.nx as f64 * self.dh_um, self.ny as f64 * self.dh_um)
    }
    /// The MODEL §3 Nyquist warning: lookups leave the spectrum when `dH > λ_min/4`.
    pub fn nyquist_warning(&self, lambda_min_um: f64) -> Option<String> {
        let limit = lambda_min_um / 4.0;
        (self.dh_um > limit).then(|| {
            format!(
                "dH = {:.1} nm exceeds λ_min/4 = {:.1} nm: directions far from specular alias (MODEL §3)",
                self.dh_um * 1e3,
                limit * 1e3
            )
        })
    }
}
