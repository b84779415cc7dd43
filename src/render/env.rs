//! Environment light for the compute stages (MODEL §10): what the CPU prepares once
//! ([`EnvLighting`]: the radiance-weighted table the BRDF's `(u, v)` samples are drawn
//! from, which also draws `chebyshev-w`; the environment's CDFs; the lights), the stages'
//! device objects ([`EnvKernel`]) with the variant they evaluate bound beside them
//! ([`crate::render::env_brdf`]), and the dispatches that add `N` samples per pixel in
//! rounds ([`dispatch_rounds`]), a BRDF map's (glsl/env_map.glsl) among them.
//!
//! **The BRDF's sampler.** The largest over `M` nodes uniform in `w` of the table's
//! `G_X + G_Y + G_Z` is evaluated (as the spline interpolates it) at the corners of cells
//! `SUB` times finer than the table's, each corner raised to a sixteenth of its largest
//! neighbour (so a lobe's tail between two corners keeps its weights `G/p` bounded). The
//! density is bilinear between the corners inside each cell: a cell is drawn by its
//! integral (a marginal CDF over rows of cells and a conditional CDF over the cells of each
//! row), then the point inside it by the bilinear density's marginal in `v` and its
//! conditional in `u`, both linear, inverted in closed form. The shader evaluates that
//! density exactly, so the estimator is unbiased whatever the fit; the fit only sets the
//! variance (a cell holding the largest of its corners, uniform inside, took 1.44 times the
//! samples for the same error on the default scene under the sky).

use std::sync::Arc;
use std::time::Instant;

use ash::vk;
use gpu_allocator::MemoryLocation;
use rayon::prelude::*;

use super::env_brdf::{EnvBrdf, EnvStage};
use super::table_build::Built;
use crate::brdf::env_reference::{radiance_planes, radiance_slices_in};
use crate::brdf::table::{clenshaw, spline_weights, ChebyshevW, Response, TableSpec};
use crate::brdf::Shading;
use crate::colour::{linear_srgb_to_xyz, ColourTable};
use crate::gpu::compute::{self, ComputeLayout, ComputePipeline, StorageSet};
use crate::gpu::memory::Buffer;
use crate::gpu::Device;
use crate::heightfield::HeightField;
use crate::light::env::{map_to_direction, rotate_y, EnvMap, EnvSampler};
use crate::light::set::{light_every, Lights, PointLight};
use crate::{Error, Result};
use std::f64::consts::PI;

/// Cells of the BRDF's density a side of one table cell.
pub const SUB: usize = 2;
/// Most cells of the BRDF's density per node in `w`.
pub const MAX_DENSITY_CELLS: usize = 4 << 20;
/// Nodes in `w` whose largest `G` the BRDF's density follows.
pub const DENSITY_NODES: usize = 8;
/// Largest samples per pixel.
pub const MAX_SAMPLES: u32 = 65_536;
/// Most samples per pixel one dispatch adds. Fewer where the driver limits an
/// invocation's loop iterations ([`samples_per_dispatch`]).
pub const CHUNK: u32 = 256;

/// Samples per pixel one dispatch adds for a variant whose samples take at most
/// `iterations` loop iterations each: [`CHUNK`], or on a driver that ends an invocation's
/// loops after a fixed count of iterations (llvmpipe:
/// [`crate::gpu::DeviceInfo::loop_iteration_limit`], one counter over all loops of the
/// invocation, so the samples' loop and everything it calls share it) half of what fits
/// under it, at least one. Past the limit the loops end early without a word: a sample
/// loop that ran 2048 samples of `chebyshev-w` in one dispatch, or 256 of `flss`, added
/// nothing. The stages count the samples they add ([`mean_of`] divides by that count),
/// so a dispatch cut short is a noisier pixel, never a darker one.
pub fn samples_per_dispatch(info: &crate::gpu::DeviceInfo, iterations: u64) -> u32 {
    match info.loop_iteration_limit() {
        Some(limit) => (limit / 2 / iterations.max(1)).clamp(1, u64::from(CHUNK)) as u32,
        None => CHUNK,
    }
}
/// Default samples per pixel.
pub const DEFAULT_SAMPLES: u32 = 256;

/// The piecewise-bilinear density over `(u, v)` the BRDF's samples are drawn from.
#[derive(Debug, Clone)]
pub struct GDensity {
    pub bins: [usize; 2],
    pub lo: [f64; 2],
    pub step: [f64; 2],
    /// `w` of the first node and the step between nodes.
    pub w0: f64,
    pub dw: f64,
    pub nodes: usize,
    /// Per node: marginal CDF, conditional CDFs, the density at each cell corner (the
    /// shader's layout).
    pub data: Vec<f32>,
}

impl GDensity {
    /// The density of `table`: the largest `G` over [`DENSITY_NODES`] nodes in `w`, on
    /// cells [`SUB`] times finer than the table's nodes (fewer where that would pass
    /// [`MAX_DENSITY_CELLS`]). One density for every `w`: the `w` a sample reaches depends
    /// on where it lands (`w = −(cos θi + cos θr)`), and a density fitted at the pixel's
    /// specular `w` misses orders that are strong at another `w`, and their weights `G/p`
    /// reach the hundreds (measured: relative L2 error 0.77 at 256 samples on a 0.2 µm
    /// grating); the envelope over `w` keeps every weight below about 1.
    pub fn new(table: &ChebyshevW, splines: &std::sync::OnceLock<Vec<Vec<[f64; 3]>>>) -> Self {
        let r = table.region;
        let (nu, nv) = (table.nu, table.nv);
        let sub = if (SUB * (nu - 1)) * (SUB * (nv - 1)) <= MAX_DENSITY_CELLS {
            SUB
        } else {
            1
        };
        let (nbu, nbv) = (sub * (nu - 1), sub * (nv - 1));
        let step = [
            (r.hi[0] - r.lo[0]) / nbu as f64,
            (r.hi[1] - r.lo[1]) / nbv as f64,
        ];
        // Cells finer than the nodes are read through the splines, fitted here if not yet.
        let splines = (sub > 1).then(|| splines.get_or_init(|| table.spline_planes()).as_slice());
        // The largest G over the w nodes at every cell corner.
        let mut corners = vec![0.0f64; (nbu + 1) * (nbv + 1)];
        for m in 0..DENSITY_NODES {
            let w = r.lo[2] + (r.hi[2] - r.lo[2]) * m as f64 / (DENSITY_NODES - 1) as f64;
            let g = plane_sum(table, splines, table.w_hat(w), sub);
            corners
                .par_iter_mut()
                .zip(g.par_iter())
                .for_each(|(c, g)| *c = c.max(*g));
        }
        let corners = floored(&corners, nbu + 1, nbv + 1);
        let mut cells = vec![0.0f64; nbu * nbv];
        for b in 0..nbv {
            for a in 0..nbu {
                let at = |i: usize, j: usize| corners[j * (nbu + 1) + i];
                cells[b * nbu + a] =
                    (at(a, b) + at(a + 1, b) + at(a, b + 1) + at(a + 1, b + 1)) / 4.0;
            }
        }
        let corners = if cells.iter().sum::<f64>() <= 0.0 {
            cells.iter_mut().for_each(|c| *c = 1.0);
            vec![1.0; corners.len()]
        } else {
            corners
        };
        let data = cdf_block(&cells, &corners, nbu, nbv, step[0] * step[1]);
        let (nodes, dw) = (1, 1.0);
        GDensity {
            bins: [nbu, nbv],
            lo: [r.lo[0], r.lo[1]],
            step,
            w0: r.lo[2],
            dw,
            nodes,
            data,
        }
    }
}

/// `Σ_c max(0, G_c)` of `table`'s plane at `ŵ = x` at the corners of cells `sub` times
/// finer than its nodes, row by row, through the spline planes `splines` of its
/// coefficients. At the nodes themselves (`sub` = 1) the spline takes the nodes' values,
/// so the series is summed there from the coefficients directly, and `splines` may be
/// `None`.
fn plane_sum(
    table: &ChebyshevW,
    splines: Option<&[Vec<[f64; 3]>]>,
    x: f64,
    sub: usize,
) -> Vec<f64> {
    let (nu, nv, k) = (table.nu, table.nv, table.coeffs.len());
    let splines = match splines {
        Some(s) if sub > 1 => s,
        _ => {
            return (0..nu * nv)
                .into_par_iter()
                .map_init(Vec::new, |c, p| {
                    c.clear();
                    c.extend((0..k).map(|j| table.coeffs[j][p]));
                    clenshaw(c, x).iter().map(|v| v.max(0.0)).sum::<f64>()
                })
                .collect();
        }
    };
    // The spline coefficients of the plane G(·, ·, w) (the series is linear).
    let su = nu + 2;
    let plane: Vec<[f64; 3]> = (0..su * (nv + 2))
        .into_par_iter()
        .map_init(Vec::new, |c, p| {
            c.clear();
            c.extend((0..k).map(|j| splines[j][p]));
            clenshaw(c, x)
        })
        .collect();
    let (nbu, nbv) = (sub * (nu - 1), sub * (nv - 1));
    (0..(nbu + 1) * (nbv + 1))
        .into_par_iter()
        .map(|p| {
            let (a, b) = (p % (nbu + 1), p / (nbu + 1));
            spline_sum(
                &plane,
                su,
                a as f64 / sub as f64,
                b as f64 / sub as f64,
                nu,
                nv,
            )
        })
        .collect()
}

/// `Σ_c max(0, G_c)` of the cubic B-spline with coefficients `plane` (`su` wide, one ghost
/// each side) at node coordinates `(x, y)`.
fn spline_sum(plane: &[[f64; 3]], su: usize, x: f64, y: f64, nu: usize, nv: usize) -> f64 {
    let i = (x.floor() as usize).min(nu - 2);
    let j = (y.floor() as usize).min(nv - 2);
    let (wx, wy) = (spline_weights(x - i as f64), spline_weights(y - j as f64));
    let mut g = [0.0; 3];
    for (b, wb) in wy.iter().enumerate() {
        for (a, wa) in wx.iter().enumerate() {
            let c = plane[(j + b) * su + i + a];
            for ch in 0..3 {
                g[ch] += wa * wb * c[ch];
            }
        }
    }
    g.iter().map(|v| v.max(0.0)).sum()
}

/// The corner values of the density, each raised to at least [`TAIL`] of the largest of its
/// eight neighbours: between a lobe's last sampled node and the next, where `G` falls
/// faster than that, the density stays above it (the weights `G/p` stay bounded in a
/// lobe's tail), and far from every lobe it stays 0.
fn floored(corners: &[f64], w: usize, h: usize) -> Vec<f64> {
    (0..w * h)
        .into_par_iter()
        .map(|p| {
            let (x, y) = (p % w, p / w);
            let mut near = 0.0f64;
            for j in y.saturating_sub(1)..(y + 2).min(h) {
                for i in x.saturating_sub(1)..(x + 2).min(w) {
                    near = near.max(corners[j * w + i]);
                }
            }
            corners[p].max(TAIL * near)
        })
        .collect()
}

/// The least a density corner keeps of its largest neighbour ([`floored`]).
const TAIL: f64 = 1.0 / 16.0;

/// Marginal CDF over rows and conditional CDFs over each row's columns of the cells'
/// `weights` (their mean density), then the density (probability over area) at every cell
/// corner, as f32 in the shader's layout: inside a cell the density is bilinear between
/// its corners, and its integral over the cell is the cell's weight.
fn cdf_block(weights: &[f64], corners: &[f64], w: usize, h: usize, cell_area: f64) -> Vec<f32> {
    let total: f64 = weights.iter().sum();
    let mut marginal = vec![0f32; h + 1];
    let mut conditional = vec![0f32; h * (w + 1)];
    let mut acc = 0.0;
    for r in 0..h {
        let row = &weights[r * w..(r + 1) * w];
        let rs: f64 = row.iter().sum();
        let mut c = 0.0;
        for (i, x) in row.iter().enumerate() {
            c += x;
            conditional[r * (w + 1) + i + 1] = if rs > 0.0 {
                (c / rs) as f32
            } else {
                (i + 1) as f32 / w as f32
            };
        }
        conditional[r * (w + 1) + w] = 1.0;
        acc += rs;
        marginal[r + 1] = (acc / total) as f32;
    }
    marginal[h] = 1.0;
    let density = corners.iter().map(|x| (x / total / cell_area) as f32);
    marginal
        .into_iter()
        .chain(conditional)
        .chain(density)
        .collect()
}

/// What an environment-lit BRDF map is drawn from, prepared on the CPU once.
pub struct EnvLighting {
    /// The table's Chebyshev coefficients in `w` at the `(u, v)` nodes (its `splines`
    /// left empty: [`Self::splines`]).
    pub table: ChebyshevW,
    /// The splines of the coefficient planes, fitted once, by the first that reads them:
    /// the density where its cells are finer than the nodes, `chebyshev-w`'s upload
    /// ([`Self::brdf_in`]), the CPU's [`Self::g`]. A scene drawn by `volume` alone (no
    /// point light) reads none.
    splines: std::sync::OnceLock<Vec<Vec<[f64; 3]>>>,
    /// What the table was sampled over.
    pub spec: TableSpec,
    pub density: GDensity,
    /// D65's white XYZ (`Y = 1`): the colour of the sun.
    pub white: [f64; 3],
    /// The factor that turns the relative reflectance `ρ` into the absolute BRDF,
    /// `A_λ·R0` (`A_λ` alone without Fresnel) weighted by D65's luminance `w_Y`:
    /// `Σ A_λ R0 w_Y,λ / Σ w_Y,λ` (about 440 for 65 µm with Fresnel), the scale of
    /// [`Response::radiance`] that every radiance picture shares.
    pub mirror_scale: f64,
    /// Chebyshev terms sampled but left out ([`TERM_TOLERANCE`]).
    pub dropped: usize,
    pub build_ms: f64,
    /// A fresh float32 build's measured difference from float64, relative to the peak
    /// ([`crate::brdf::table::Sampled::probe`]); `None` for a float64 build or a cached one.
    pub probe: Option<f64>,
}

/// The most the Chebyshev terms left out of an environment table may add to `G`, relative
/// to its peak ([`ChebyshevW::truncate`]): a material's default tolerance, far below the
/// integration's noise (a sample reads every term kept: the default skin keeps 6 of 8, and
/// its pictures move by ΔE2000 mean 0.012, p99 0.09 against 7, with the same samples).
pub const TERM_TOLERANCE: f64 = 1e-3;

/// A table whose last Chebyshev term in `w` is above this (relative to the peak) gets a
/// warning that more `w` nodes would resolve it: a material's default tolerance
/// (`[material] tolerance`, relative to a mirror's specular value).
pub const W_TOLERANCE: f64 = 1e-3;

impl EnvLighting {
    /// The radiance-weighted table of `hf` over `spec` and its sampling density.
    pub fn build(
        hf: &HeightField,
        coherence_um: f64,
        shading: &Shading,
        spec: &TableSpec,
    ) -> Result<Self> {
        Self::build_cached(
            hf,
            coherence_um,
            shading,
            spec,
            None,
            &crate::report::Stderr,
        )
        .map(|(l, _)| l)
    }

    /// [`Self::build`] with the table's samples through the on-disk table cache in `dir`
    /// ([`crate::brdf::table_cache`], keyed like every sampled table, tagged with the
    /// radiance weights and the Fresnel factor they carry); also whether they were read
    /// from it. `build_ms` is the whole preparation either way.
    pub fn build_cached(
        hf: &HeightField,
        coherence_um: f64,
        shading: &Shading,
        spec: &TableSpec,
        dir: Option<&std::path::Path>,
        report: &dyn crate::report::Report,
    ) -> Result<(Self, bool)> {
        let start = Instant::now();
        let tag = format!(
            "radiance weights, Fresnel {} (ior {:016x})",
            shading.fresnel,
            shading.ior.to_bits()
        );
        let probe = std::cell::Cell::new(None);
        let (slices, cached) = crate::brdf::table_cache::sample_g_cached_by(
            hf,
            coherence_um,
            spec,
            &ChebyshevW::nodes(spec),
            None,
            dir,
            Some(&format!("{tag}, f32 sums")),
            report,
            &|| {
                let bar = indicatif::ProgressBar::new(radiance_planes(spec)?)
                    .with_message("environment table");
                let bar = report.progress(bar);
                let sampled = radiance_slices_in(
                    hf,
                    coherence_um,
                    shading,
                    spec,
                    crate::brdf::truncation::Precision::F32,
                    &|| bar.inc(1),
                );
                bar.finish_and_clear();
                let sampled = sampled?;
                probe.set(sampled.probe);
                Ok(sampled.slices)
            },
        )?;
        let (table, truncation) =
            ChebyshevW::coefficients_within(spec.region, &slices, Some(TERM_TOLERANCE));
        let dropped = truncation.of - truncation.kept;
        drop(slices);
        let last = table.decay().last().copied().unwrap_or(0.0);
        if dropped == 0 && last > W_TOLERANCE {
            report.warn(&format!(
                "environment table: its last Chebyshev term in w is {last:.1e} of the peak (above {W_TOLERANCE:.0e}): more --table-w-nodes than {} resolve w better",
                spec.w_nodes
            ));
        }
        let splines = std::sync::OnceLock::new();
        let density = GDensity::new(&table, &splines);
        let colours = ColourTable::new(spec.step_nm)?;
        let white = crate::brdf::env_reference::white(&colours);
        let mirror_scale = Response::radiance(coherence_um, shading).scale();
        let lighting = EnvLighting {
            table,
            splines,
            spec: *spec,
            density,
            white,
            mirror_scale,
            dropped,
            build_ms: start.elapsed().as_secs_f64() * 1e3,
            probe: probe.get(),
        };
        Ok((lighting, cached))
    }
}

impl EnvLighting {
    /// The spline planes of the table's coefficients, fitted on the first call.
    pub fn splines(&self) -> &[Vec<[f64; 3]>] {
        self.splines.get_or_init(|| self.table.spline_planes())
    }

    /// `G` of the table at `(u, v, w)` as the CPU evaluates it ([`GTable::g`]: clamped to
    /// `G ≥ 0`), through [`Self::splines`].
    pub fn g(&self, uvw: [f64; 3]) -> Option<[f64; 3]> {
        self.table
            .g_with(self.splines(), uvw)
            .map(|g| g.map(|x| x.max(0.0)))
    }

    /// `chebyshev-w` drawn from the lighting's own table for the environment-lit stages,
    /// stored in float32, the table alone (read at each point).
    pub(crate) fn brdf(&self, dev: &Arc<Device>, shading: &Shading) -> Result<EnvBrdf> {
        self.brdf_in(
            dev,
            shading,
            crate::render::variant::TableFormat::Rgba32f,
            1,
        )
    }

    /// [`EnvLighting::brdf`] stored in `format` (`--table-format`: the values are those of
    /// a relative table, [`EnvBrdf::scale`], so float16 holds them), read over a pixel's
    /// footprint where `levels` > 1 (`--table-levels`; 1: the table alone,
    /// [`EnvBrdf::chebyshev_w`]).
    pub fn brdf_in(
        &self,
        dev: &Arc<Device>,
        shading: &Shading,
        format: crate::render::variant::TableFormat,
        levels: usize,
    ) -> Result<EnvBrdf> {
        EnvBrdf::chebyshev_w(
            dev,
            (&self.table, self.splines()),
            &self.spec,
            shading,
            self.mirror_scale,
            (format, levels),
        )
    }
}

impl EnvLighting {
    /// The one line that says what the table holds and how it was obtained, in the form
    /// every table's report takes ([`crate::render::table_build::TableLine`]); `cached`:
    /// its samples were read from the table cache (then the fit and the density are what
    /// `build_ms` took). The size is of the CPU's float32 spline planes; the device's copy
    /// is the variant's (`render --env` names it).
    pub fn report_line(&self, cached: bool) -> String {
        let t = &self.table;
        let r = t.region;
        let seconds = self.build_ms / 1e3;
        let origin = if cached {
            format!("{}, prepared in {seconds:.1} s", Built::Cached)
        } else {
            Built::Cpu {
                seconds,
                probe: self.probe,
            }
            .to_string()
        };
        let kept = t.coeffs.len();
        let terms = match self.dropped {
            0 => format!("K={kept}"),
            n => format!("K={kept} of {}", kept + n),
        };
        let dropped = (self.dropped > 0)
            .then(|| format!("the terms left out stay below {TERM_TOLERANCE:.0e} of the peak; "));
        crate::render::table_build::TableLine {
            label: "environment table",
            holds: format!(
                "chebyshev-w {terms} {}×{} texel {:.4} dλ={} over u ∈ [{}, {}], v ∈ [{}, {}], w ∈ [{}, {}]",
                t.nu, t.nv, self.spec.texel_uv, self.spec.step_nm,
                r.lo[0], r.hi[0], r.lo[1], r.hi[1], r.lo[2], r.hi[2],
            ),
            origin,
            bytes: (t.nu + 2) * (t.nv + 2) * kept * 12,
            bytes_of: Some("float32 planes"),
            extra: Some(format!(
                "{}BRDF density {}×{} cells",
                dropped.unwrap_or_default(),
                self.density.bins[0],
                self.density.bins[1]
            )),
        }
        .to_string()
    }
}

/// One environment-lit BRDF map.
pub struct EnvMapRequest<'a> {
    pub env: &'a EnvMap,
    pub shading: Shading,
    /// Samples per pixel (each a BRDF sample; every m-th also a light sample, [`light_every`]).
    pub samples: u32,
    /// Map side in pixels.
    pub size: u32,
    /// Towards the sun (tangent space, unit) and its irradiance; `None`: no sun.
    pub sun: Option<([f64; 3], f64)>,
    /// Scrambles the sequence (0 for the default picture).
    pub seed: u32,
    /// The variant the stages evaluate (`None`: `chebyshev-w` from the lighting's own table;
    /// [`crate::render::Renderer::env_brdf`] binds another).
    pub brdf: Option<&'a std::sync::Arc<crate::render::env_brdf::EnvBrdf>>,
    /// Samples per dispatch; `None`: what the device and the variant allow
    /// ([`samples_per_dispatch`]).
    pub per_dispatch: Option<u32>,
}

/// XYZ radiance per pixel, row-major from the top, and the dispatch's wall time.
pub struct EnvPicture {
    pub size: u32,
    pub xyz: Vec<[f32; 3]>,
    pub gpu_ms: f64,
    /// Batches of samples left out for a NaN or an infinity (0 on every case measured).
    pub dropped: u64,
    /// The samples each pixel added (row-major; 0 outside the disc): fewer than asked
    /// where the driver ended a dispatch's loops early or a batch was dropped.
    pub taken: Vec<u32>,
}

/// Normals of the irradiance table, around and down (env_common.glsl's IRR_W, IRR_H).
pub const IRRADIANCE_SIZE: (u32, u32) = (128, 64);
/// Largest map the irradiance table sums directly; a larger one is summed over blocks.
const IRRADIANCE_MAP: u32 = 256;

/// The irradiance `E(n) = ∫ L(ω)·max(0, n·ω) dω` (linear sRGB) of `env` at the normals of
/// [`IRRADIANCE_SIZE`], placed like a map's pixel centres in the world frame, row-major from
/// the zenith. The map is summed as about 256×128 patches of constant radiance, each at its
/// middle direction with its exact `Σ L·Ω`: a smaller map's pixels are split into
/// sub-patches; a larger map's square blocks of pixels are merged, each at its
/// luminance-weighted mean direction (exact for a block that holds one small source, such
/// as a sun). `E` is the cosine's convolution of the map, so the shader interpolates it
/// bilinearly (within about 0.03 % at 2.8° between normals, where it is smooth).
pub fn irradiance_table(env: &EnvMap) -> Vec<[f64; 3]> {
    let patches = irradiance_patches(env);
    let (w, h) = IRRADIANCE_SIZE;
    (0..w * h)
        .into_par_iter()
        .map(|k| {
            let n = crate::light::env::map_to_direction(
                (f64::from(k % w) + 0.5) / f64::from(w),
                (f64::from(k / w) + 0.5) / f64::from(h),
            );
            let mut e = [0.0; 3];
            for (s, d) in &patches {
                let c = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
                if c > 0.0 {
                    for ch in 0..3 {
                        e[ch] += s[ch] * c;
                    }
                }
            }
            e
        })
        .collect()
}

/// The patches [`irradiance_table`] sums: `(Σ L·Ω, unit direction)`, black ones left out.
fn irradiance_patches(env: &EnvMap) -> Vec<([f64; 3], [f64; 3])> {
    let (w, h) = (env.width, env.height);
    if w < IRRADIANCE_MAP {
        // Each pixel split into sub × sub patches, uniform in θ and φ.
        let sub = IRRADIANCE_MAP.div_ceil(w);
        let (sw, sh) = (f64::from(w * sub), f64::from(h * sub));
        return (0..w * sub * h * sub)
            .into_par_iter()
            .filter_map(|k| {
                let (a, b) = (k % (w * sub), k / (w * sub));
                let l = env.radiance[((b / sub) * w + a / sub) as usize];
                let (t0, t1) = (f64::from(b) / sh * PI, f64::from(b + 1) / sh * PI);
                let omega = 2.0 * PI / sw * (t0.cos() - t1.cos());
                let ct = 0.5 * (t0.cos() + t1.cos());
                let m = map_to_direction((f64::from(a) + 0.5) / sw, ct.acos() / PI);
                let d = rotate_y(m, env.rotate_rad);
                let s = l.map(|c| f64::from(c) * omega);
                s.iter().any(|&x| x > 0.0).then_some((s, d))
            })
            .collect();
    }
    let f = w.div_ceil(IRRADIANCE_MAP);
    let (bw, bh) = (w.div_ceil(f), h.div_ceil(f));
    (0..bw * bh)
        .into_par_iter()
        .filter_map(|b| {
            let (bi, bj) = (b % bw, b / bw);
            let (mut sum, mut dir, mut centre) = ([0.0; 3], [0.0; 3], [0.0; 3]);
            for j in bj * f..((bj + 1) * f).min(h) {
                let omega = env.pixel_solid_angle(j);
                for i in bi * f..((bi + 1) * f).min(w) {
                    let l = env.radiance[(j * w + i) as usize];
                    let d = env.pixel_direction(i, j);
                    let y = crate::light::env::luminance(l) * omega;
                    for c in 0..3 {
                        sum[c] += f64::from(l[c]) * omega;
                        dir[c] += y * d[c];
                        centre[c] += d[c];
                    }
                }
            }
            let norm = |v: [f64; 3]| {
                let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                (n > 0.0).then(|| v.map(|x| x / n))
            };
            let d = norm(dir).or_else(|| norm(centre))?;
            sum.iter().any(|&x| x > 0.0).then_some((sum, d))
        })
        .collect()
}

/// Mirror of `EnvParams` in glsl/env_common.glsl.
#[repr(C)]
#[derive(Clone, Copy)]
struct ParamsSsbo {
    blend: [f32; 4],
    cdf_lo: [f32; 4],
    cdf_step: [f32; 4],
    env_rot: [f32; 4],
    cdf_dims: [i32; 4],
    env_dims: [i32; 4],
    light_dims: [i32; 4],
    sequence: [i32; 4],
}

// SAFETY: repr(C) of 4-byte scalars in 16-byte groups: no padding.
unsafe impl crate::gpu::memory::Pod for ParamsSsbo {}

fn f32_bytes(v: impl IntoIterator<Item = f32>) -> Vec<u8> {
    v.into_iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// One integration over `pixels` invocations of a stage that includes env_common.glsl.
pub(crate) struct Dispatch<'a> {
    pub env: &'a EnvMap,
    pub lights: &'a Lights,
    pub shading: Shading,
    /// Samples per pixel: every pixel's for a map, the most a pixel takes for a G-buffer.
    pub samples: u32,
    /// The fewest samples a picture is read at (its first pass; `samples` for one pass):
    /// the light samples are exactly their share at every multiple of it ([`light_every`]).
    pub first: u32,
    pub seed: u32,
    /// Texture blending's `w_diffuse`, `None` without a texture.
    pub w_diffuse: Option<f64>,
    pub pixels: u64,
    /// A BRDF map's side in pixels (0 for a G-buffer).
    pub map_side: u32,
    /// vec4s each pixel writes.
    pub outputs: u64,
    /// The stage's own buffer at binding 7 (the G-buffer), if any; with it, binding 8 lists
    /// the pixels each pass integrates.
    pub extra: Option<&'a [u8]>,
    /// Pixels that interleave one sequence (a G-buffer's supersample²; 1 for a map).
    pub stride: u32,
    /// Samples per noise batch (a G-buffer's; a map ignores it).
    pub batch: u32,
    pub stage: EnvStage,
    /// The variant the stage evaluates; `None`: `chebyshev-w` drawn from the lighting's own
    /// table.
    pub brdf: Option<&'a Arc<EnvBrdf>>,
    /// Samples per dispatch; `None`: [`samples_per_dispatch`].
    pub per_dispatch: Option<u32>,
    pub name: &'a str,
}

impl<'a> Dispatch<'a> {
    /// A BRDF map of `side` pixels (glsl/env_map.comp: the patch's every pixel, no
    /// texture, [`MAP_OUTPUTS`] a pixel), every pixel taking `samples` in one pass, seed 0.
    pub fn map(
        env: &'a EnvMap,
        lights: &'a Lights,
        shading: Shading,
        samples: u32,
        side: u32,
        name: &'a str,
    ) -> Self {
        Dispatch {
            env,
            lights,
            shading,
            samples,
            first: samples,
            seed: 0,
            w_diffuse: None,
            pixels: u64::from(side) * u64::from(side),
            map_side: side,
            outputs: MAP_OUTPUTS,
            extra: None,
            stride: 1,
            batch: 1,
            stage: EnvStage::Map,
            brdf: None,
            per_dispatch: None,
            name,
        }
    }
}

/// Pixels that [`dispatch_rounds`] gives samples `[from, to)` (indices into the G-buffer;
/// empty for every pixel of a map): every one of them has taken `from` samples before.
pub(crate) struct Group {
    pub pixels: Vec<u32>,
    pub from: u32,
    pub to: u32,
}

/// What decides the next round of groups from the sums so far (none: the integration
/// ends).
pub(crate) type NextRound<'a> = dyn FnMut(&[[f32; 4]]) -> Vec<Group> + 'a;

/// The device objects of an integration that stay while the environment, the table and
/// the stage stay: the table's coefficients, the environment's radiance and CDFs, the
/// BRDF's density, the layout and the pipeline. What changes with the view, the lights or
/// the rotation is bound per [`EnvTarget`]; [`EnvKernel::record`] adds samples
/// `[base, base + count)` to a target's running sums, so a progressive picture (the
/// viewer) dispatches a few samples a frame into the same sums, and an adaptive one
/// ([`dispatch_rounds`]) narrows the pixels between rounds ([`EnvKernel::set_pass`]).
pub(crate) struct EnvKernel {
    dev: Arc<Device>,
    pipeline: ComputePipeline,
    layout: ComputeLayout,
    radiance: Buffer,
    env_cdf: Buffer,
    density: Buffer,
    /// The environment's `∫ Y dω` and `∫ Y² dω` (the light sampler's share, [`light_share`]).
    env_power: f64,
    env_square: f64,
    /// The irradiance table of the rotation it was made for (texture blending reads it).
    irradiance: Option<(f64, Vec<[f64; 3]>)>,
    /// Whether the stage reads its own buffer at binding 6 (the G-buffer) and the pass's
    /// pixels at binding 7.
    extra: bool,
    name: String,
    /// The stage of the variant that evaluates the point lights, where the BRDF names
    /// another ([`EnvBrdf::points`]).
    points: Option<PointStage>,
    /// Set 0 of the stage: the variant it evaluates. Last: the pipeline was made with its
    /// layout.
    brdf: Arc<EnvBrdf>,
}

/// The same stage made of another variant's fragment file, dispatched once after the first
/// dispatch of a picture with no samples (`count = 0`): it writes the point lights alone,
/// over the first dispatch's. It binds the kernel's storage set after its own set 0 (the
/// two layouts define set 1 alike).
struct PointStage {
    pipeline: ComputePipeline,
    layout: ComputeLayout,
    /// Last: the pipeline was made with its layout.
    brdf: Arc<EnvBrdf>,
}

/// What one picture integrates into: the parameters, the lights, the stage's own buffer,
/// the pixels of the pass and the running sums (`outputs` vec4s a pixel), with their
/// descriptor set.
pub(crate) struct EnvTarget {
    /// Made by [`EnvKernel::set_pass`].
    set: Option<StorageSet>,
    params: ParamsSsbo,
    params_buf: Buffer,
    lights: Buffer,
    extra: Option<Buffer>,
    pass: Option<Buffer>,
    mapped: bool,
    pub out: Buffer,
    /// Invocations of a dispatch: the pixels of the pass.
    pub pixels: u64,
    /// Samples per pixel of one dispatch.
    pub per_dispatch: u32,
}

impl EnvKernel {
    /// The objects of `lighting` and `env` for `stage` evaluating `brdf` (a scene's stage
    /// reads a G-buffer at binding 6 and the pass's pixels at binding 7).
    pub fn new(
        dev: &Arc<Device>,
        lighting: &EnvLighting,
        env: &EnvMap,
        brdf: &Arc<EnvBrdf>,
        stage: EnvStage,
        name: &str,
    ) -> Result<Self> {
        let extra = stage == EnvStage::Scene;
        let sampler = EnvSampler::new(env);
        let env_pdf = sampler
            .prob
            .iter()
            .enumerate()
            .map(|(p, pr)| (pr / env.pixel_solid_angle(p as u32 / env.width)) as f32);
        let mut env_cdf = f32_bytes(sampler.marginal.iter().map(|&x| x as f32));
        env_cdf.extend(f32_bytes(sampler.conditional.iter().map(|&x| x as f32)));
        env_cdf.extend(f32_bytes(env_pdf));
        let env_xyz = f32_bytes(
            env.radiance
                .iter()
                .flat_map(|p| linear_srgb_to_xyz(p.map(f64::from)).map(|x| x as f32)),
        );
        let b = |what: &str, bytes: &[u8]| {
            compute::storage_with_data(dev, &format!("{name} {what}"), bytes)
        };
        let bindings = 6 + 2 * u32::from(extra);
        let layout = ComputeLayout::after(dev, name, &[brdf.set_layout()], bindings, 8)?;
        let pipeline = ComputePipeline::new(dev, name, &layout, brdf.spirv(stage)?, brdf.spec())?;
        let points = match brdf.points() {
            Some(p) => {
                let label = format!("{name} point lights");
                let layout = ComputeLayout::after(dev, &label, &[p.set_layout()], bindings, 8)?;
                let pipeline =
                    ComputePipeline::new(dev, &label, &layout, p.spirv(stage)?, p.spec())?;
                Some(PointStage {
                    pipeline,
                    layout,
                    brdf: Arc::clone(p),
                })
            }
            None => None,
        };
        let (env_power, env_square) = env.moments();
        Ok(EnvKernel {
            dev: Arc::clone(dev),
            radiance: b("radiance", &env_xyz)?,
            env_cdf: b("environment CDFs", &env_cdf)?,
            density: b(
                "BRDF density",
                &f32_bytes(lighting.density.data.iter().copied()),
            )?,
            pipeline,
            layout,
            env_power,
            env_square,
            irradiance: None,
            extra,
            name: name.to_string(),
            points,
            brdf: Arc::clone(brdf),
        })
    }

    /// A small buffer of a target: host-visible when `mapped` (no upload that waits for
    /// the queue, for a frame path).
    fn small(&self, what: &str, bytes: &[u8], mapped: bool) -> Result<Buffer> {
        let label = format!("{} {what}", self.name);
        if mapped {
            Buffer::with_data(
                &self.dev,
                &label,
                vk::BufferUsageFlags::STORAGE_BUFFER,
                bytes,
            )
        } else {
            compute::storage_with_data(&self.dev, &label, bytes)
        }
    }

    /// Binds a picture of `d` (whose `env` is the kernel's map, at any rotation): the
    /// parameters, the lights and `d.extra` uploaded, every pixel in the pass, the sums
    /// allocated (written by the first dispatch, at `base = 0`). `mapped`: the small
    /// buffers stay host-visible.
    pub fn bind(
        &mut self,
        lighting: &EnvLighting,
        d: &Dispatch<'_>,
        mapped: bool,
    ) -> Result<EnvTarget> {
        if !(1..=MAX_SAMPLES).contains(&d.samples) {
            return Err(Error::invalid(
                "env samples",
                format!("{}; expected 1 to {MAX_SAMPLES}", d.samples),
            ));
        }
        let (q_env, q_discs) = d.lights.probabilities(self.env_power);
        let share = d.lights.light_share_with(self.env_power, self.env_square);
        let every = light_every(share, &[d.samples, d.first.max(1)]);
        let params = params(lighting, d, q_env, every, self.brdf.scale);
        let rotation = d.env.rotate_rad;
        if d.w_diffuse.is_some() && self.irradiance.as_ref().is_none_or(|(r, _)| *r != rotation) {
            self.irradiance = Some((rotation, irradiance_table(d.env)));
        }
        let irradiance: &[[f64; 3]] = match (&self.irradiance, d.w_diffuse) {
            (Some((_, e)), Some(_)) => e,
            _ => &[],
        };
        let lights = self.small(
            "lights",
            &f32_bytes(d.lights.buffer(&q_discs, irradiance)),
            mapped,
        )?;
        let extra = match (self.extra, d.extra) {
            (true, Some(e)) => Some(self.small("G-buffer", e, mapped)?),
            (true, None) => Some(self.small("G-buffer", &[0; 64], mapped)?),
            (false, _) => None,
        };
        let out_bytes = (d.pixels * d.outputs * 16).max(16);
        let out = compute::storage(&self.dev, &format!("{} output", self.name), out_bytes)?;
        let params_buf = self.small("params", crate::gpu::memory::bytes_of(&[params]), mapped)?;
        let mut t = EnvTarget {
            set: None,
            params,
            params_buf,
            lights,
            extra,
            pass: None,
            mapped,
            out,
            pixels: d.pixels,
            per_dispatch: d.per_dispatch.unwrap_or_else(|| {
                samples_per_dispatch(
                    &self.dev.info,
                    self.brdf.iterations_per_sample(d.lights.discs.len()),
                )
            }),
        };
        let all: Vec<u32> = if self.extra {
            (0..d.pixels as u32).collect()
        } else {
            Vec::new()
        };
        self.set_pass(&mut t, &all)?;
        Ok(t)
    }

    /// The next dispatches of `t` integrate `pixels` (G-buffer indices; a map's stage
    /// integrates every pixel whatever the list). Call it between submissions.
    pub fn set_pass(&self, t: &mut EnvTarget, pixels: &[u32]) -> Result<()> {
        let invocations = if self.extra {
            pixels.len() as u64
        } else {
            t.pixels
        };
        t.params.env_dims[3] = invocations as i32;
        t.params_buf = self.small(
            "params",
            crate::gpu::memory::bytes_of(&[t.params]),
            t.mapped,
        )?;
        if self.extra {
            let list: Vec<u8> = pixels.iter().flat_map(|i| i.to_le_bytes()).collect();
            let bytes: &[u8] = if list.is_empty() { &[0; 4] } else { &list };
            t.pass = Some(self.small("pixels of the pass", bytes, t.mapped)?);
        }
        let mut buffers = vec![
            &t.params_buf,
            &self.radiance,
            &self.env_cdf,
            &self.density,
            &t.out,
            &t.lights,
        ];
        buffers.extend(t.extra.as_ref());
        buffers.extend(t.pass.as_ref());
        t.set = None;
        t.set = Some(StorageSet::new(
            &self.dev,
            &self.name,
            &self.layout,
            &buffers,
        )?);
        t.pixels = invocations;
        Ok(())
    }

    /// Records the dispatches that add samples `[base, base + count)` to `t`'s sums
    /// (`base = 0` starts them and writes the point lights apart, by the point lights' own
    /// stage where there is one), each followed by a barrier, so what comes after in `cb`
    /// reads the sums.
    pub fn record(
        &self,
        cb: vk::CommandBuffer,
        t: &EnvTarget,
        base: u32,
        count: u32,
    ) -> Result<()> {
        let set = t
            .set
            .as_ref()
            .ok_or(Error::Internal("an environment target without its pass"))?;
        compute::compute_barrier(&self.dev, cb);
        // One dispatch of samples [at, at + n) over the target's pixels, then a barrier.
        let dispatch = |(layout, pipeline, brdf): (&ComputeLayout, &ComputePipeline, &EnvBrdf),
                        at: u32,
                        n: u32| {
            let push: Vec<u8> = [at, n].iter().flat_map(|v| v.to_le_bytes()).collect();
            layout.dispatch_after(cb, pipeline, &[brdf.set()], set, &push, t.pixels.max(1))?;
            compute::compute_barrier(&self.dev, cb);
            Ok::<(), Error>(())
        };
        let mut at = base;
        loop {
            let n = t.per_dispatch.max(1).min(base + count - at);
            dispatch((&self.layout, &self.pipeline, &self.brdf), at, n)?;
            // Without point lights the first dispatch's part is the lights' stage's too (the
            // irradiance term does not depend on the BRDF).
            let points = t.params.light_dims[0] > 0;
            if let (0, Some(p), true) = (at, &self.points, points) {
                dispatch((&p.layout, &p.pipeline, &p.brdf), 0, 0)?;
            }
            at += n;
            if at >= base + count {
                return Ok(());
            }
        }
    }
}

/// The parameter block of `d` (env_common.glsl's `EnvParams`), a light sample every
/// `light_every`-th sample, the BRDF's values times `scale` in radiance.
fn params(
    lighting: &EnvLighting,
    d: &Dispatch<'_>,
    q_env: f64,
    light_every: u32,
    scale: f64,
) -> ParamsSsbo {
    let env = d.env;
    let g = &lighting.density;
    ParamsSsbo {
        blend: [
            d.w_diffuse.unwrap_or(0.0) as f32,
            q_env as f32,
            light_every as f32,
            scale as f32,
        ],
        cdf_lo: [g.lo[0] as f32, g.lo[1] as f32, g.w0 as f32, g.dw as f32],
        cdf_step: [g.step[0] as f32, g.step[1] as f32, 0.0, 0.0],
        env_rot: [
            env.rotate_rad.cos() as f32,
            env.rotate_rad.sin() as f32,
            0.0,
            0.0,
        ],
        cdf_dims: [
            g.bins[0] as i32,
            g.bins[1] as i32,
            g.nodes as i32,
            d.batch.max(1) as i32,
        ],
        env_dims: [
            env.width as i32,
            env.height as i32,
            d.samples as i32,
            d.pixels as i32,
        ],
        light_dims: [
            d.lights.points.len() as i32,
            d.lights.discs.len() as i32,
            i32::from(d.w_diffuse.is_some()),
            d.map_side as i32,
        ],
        sequence: [
            d.stride.max(1) as i32,
            i32::from(q_env > 0.0),
            d.seed as i32,
            // A scene's G-buffer is followed by its pixels' neighbours
            // (`GBuffer::device_bytes`).
            match d.stage {
                EnvStage::Scene => d.pixels as i32,
                EnvStage::Map => 0,
            },
        ],
    }
}

/// What [`dispatch_rounds`] integrated.
pub(crate) struct Integrated {
    /// `outputs` vec4s a pixel: the stage's raw sums.
    pub sums: Vec<[f32; 4]>,
    /// The GPU time of all passes.
    pub gpu_ms: f64,
    /// Batches of samples left out for a NaN or an infinity, over every pixel (the `w` of
    /// each pixel's second vec4).
    pub dropped: u64,
}

/// Runs `d` with `lighting` in rounds: `first`, then whatever `next` asks for after reading
/// the sums so far (no group ends). Each group of a round is submitted apart (its pixels
/// are bound for it); the sums are read back after the round's last.
pub(crate) fn dispatch_rounds(
    dev: &Arc<Device>,
    lighting: &EnvLighting,
    d: &Dispatch<'_>,
    first: Vec<Group>,
    next: &mut NextRound<'_>,
) -> Result<Integrated> {
    let brdf = match d.brdf {
        Some(b) => Arc::clone(b),
        None => Arc::new(lighting.brdf(dev, &d.shading)?),
    };
    let mut kernel = EnvKernel::new(dev, lighting, d.env, &brdf, d.stage, d.name)?;
    let mut target = kernel.bind(lighting, d, false)?;
    let out_bytes = (d.pixels * d.outputs * 16).max(16);
    let readback = Buffer::new(
        dev,
        &format!("{} readback", d.name),
        out_bytes,
        vk::BufferUsageFlags::TRANSFER_DST,
        MemoryLocation::GpuToCpu,
    )?;
    let start = Instant::now();
    let mut round = first;
    let mut sums = Vec::new();
    loop {
        round.retain(|g| {
            g.to.min(d.samples) > g.from && (d.extra.is_none() || !g.pixels.is_empty())
        });
        let Some(last) = round.len().checked_sub(1) else {
            break;
        };
        for (i, g) in round.iter().enumerate() {
            if d.extra.is_some() {
                kernel.set_pass(&mut target, &g.pixels)?;
            }
            dev.submit_once(d.name, |cb| {
                kernel.record(cb, &target, g.from, g.to.min(d.samples) - g.from)?;
                if i == last {
                    compute::copy_to_host(dev, cb, &target.out, &readback, out_bytes);
                }
                Ok(())
            })?;
        }
        sums = read_sums(&readback, d.pixels * d.outputs)?;
        round = next(&sums);
    }
    let dropped = sums
        .chunks_exact(d.outputs as usize)
        .map(|p| p[1][3] as u64)
        .sum();
    Ok(Integrated {
        sums,
        gpu_ms: start.elapsed().as_secs_f64() * 1e3,
        dropped,
    })
}

/// vec4s a pixel of the map's stage writes: (the added samples' XYZ sum, their number),
/// (the point lights' XYZ, the batches dropped) (glsl/env_map.glsl).
pub const MAP_OUTPUTS: u64 = 2;

/// A pixel's value from its sums: the point lights plus the samples' mean.
pub fn mean_of(sum: [f32; 4], point: [f32; 4]) -> [f32; 3] {
    let n = sum[3].max(1.0);
    [0, 1, 2].map(|c| point[c] + sum[c] / n)
}

/// The vec4s of `buf`.
fn read_sums(buf: &Buffer, count: u64) -> Result<Vec<[f32; 4]>> {
    let raw = buf.mapped()?;
    Ok(raw
        .chunks_exact(16)
        .take(count as usize)
        .map(|c| {
            let f =
                |i: usize| f32::from_le_bytes([c[4 * i], c[4 * i + 1], c[4 * i + 2], c[4 * i + 3]]);
            [f(0), f(1), f(2), f(3)]
        })
        .collect())
}

/// The lights of an environment-lit BRDF map: the sun at `sun` (tangent space of the map's
/// patch, towards it, and its irradiance) as one point light, or none.
pub fn map_lights(lighting: &EnvLighting, sun: Option<([f64; 3], f64)>) -> Lights {
    // The sun in the world: the map's patch is N = +Y, T = +X, B = −Z (MODEL §10).
    let frame = crate::brdf::env_reference::Frame::BRDF_MAP;
    Lights {
        points: sun
            .filter(|s| s.1 > 0.0)
            .map(|(wi, e)| PointLight {
                towards: frame.to_world(wi),
                irradiance_xyz: lighting.white.map(|w| w * e),
            })
            .into_iter()
            .collect(),
        discs: Vec::new(),
    }
}

/// Draws `req` with `lighting` on `dev`.
pub fn render_env_brdf_map(
    dev: &Arc<Device>,
    lighting: &EnvLighting,
    req: &EnvMapRequest<'_>,
) -> Result<EnvPicture> {
    let lights = map_lights(lighting, req.sun);
    let first = vec![Group {
        pixels: Vec::new(),
        from: 0,
        to: req.samples,
    }];
    let run = dispatch_rounds(
        dev,
        lighting,
        &Dispatch {
            seed: req.seed,
            brdf: req.brdf,
            per_dispatch: req.per_dispatch,
            ..Dispatch::map(
                req.env,
                &lights,
                req.shading,
                req.samples,
                req.size,
                "env map",
            )
        },
        first,
        &mut |_| Vec::new(),
    )?;
    Ok(EnvPicture {
        size: req.size,
        xyz: run
            .sums
            .chunks_exact(2)
            .map(|p| mean_of(p[0], p[1]))
            .collect(),
        gpu_ms: run.gpu_ms,
        dropped: run.dropped,
        taken: (0..req.size * req.size)
            .map(|p| {
                let inside = map_direction(p % req.size, p / req.size, req.size).is_some();
                if inside {
                    run.sums[2 * p as usize][3] as u32
                } else {
                    0
                }
            })
            .collect(),
    })
}

/// The map's tangent-space `ωr` at pixel `(i, j)` of a `size`-pixel map (the pixel centre),
/// `None` outside the disc: as the shader places them.
pub fn map_direction(i: u32, j: u32, size: u32) -> Option<[f64; 3]> {
    let x = 2.0 * (f64::from(i) + 0.5) / f64::from(size) - 1.0;
    let y = 1.0 - 2.0 * (f64::from(j) + 0.5) / f64::from(size);
    let r2 = x * x + y * y;
    (r2 < 1.0).then(|| [x, y, (1.0 - r2).sqrt()])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::env::EnvSource;

    #[test]
    fn a_plane_at_the_nodes_is_the_spline_at_the_nodes() {
        // Three terms in w over 7×5 nodes, with negative values the sum clamps.
        let (nu, nv) = (7usize, 5usize);
        let coeffs: Vec<Vec<[f64; 3]>> = (0..3)
            .map(|j| {
                (0..nu * nv)
                    .map(|p| {
                        let (i, k) = ((p % nu) as f64, (p / nu) as f64);
                        let g = (0.7 * i + 1.3 * k + j as f64).sin() / (1.0 + j as f64);
                        [g, 0.5 * g - 0.1, 1.0 - g]
                    })
                    .collect()
            })
            .collect();
        let table = ChebyshevW {
            region: crate::brdf::table::Region {
                lo: [-0.1, -0.05, -2.0],
                hi: [0.1, 0.05, 0.0],
            },
            nu,
            nv,
            splines: coeffs
                .iter()
                .map(|c| crate::brdf::table::spline_plane(c, nu, nv))
                .collect(),
            coeffs,
        };
        for x in [-1.0, -0.3, 0.6, 1.0] {
            let direct = plane_sum(&table, None, x, 1);
            let plane: Vec<[f64; 3]> = (0..(nu + 2) * (nv + 2))
                .map(|p| {
                    let c: Vec<[f64; 3]> = table.splines.iter().map(|s| s[p]).collect();
                    clenshaw(&c, x)
                })
                .collect();
            for (p, d) in direct.iter().enumerate() {
                let (i, k) = ((p % nu) as f64, (p / nu) as f64);
                let spline = spline_sum(&plane, nu + 2, i, k, nu, nv);
                assert!((d - spline).abs() < 1e-12, "{x} {p}: {d} {spline}");
            }
        }
        // Finer cells go through the spline: at their nodes it agrees again.
        let fine = plane_sum(&table, Some(&table.splines), 0.2, 2);
        let direct = plane_sum(&table, None, 0.2, 1);
        for (p, d) in direct.iter().enumerate() {
            let (i, k) = (p % nu, p / nu);
            let at = 2 * k * (2 * (nu - 1) + 1) + 2 * i;
            assert!((fine[at] - d).abs() < 1e-12, "{p}");
        }
    }

    #[test]
    fn the_irradiance_table_is_the_cosine_integral_of_the_map() {
        let (w, h) = IRRADIANCE_SIZE;
        let normal = |k: u32| {
            map_to_direction(
                (f64::from(k % w) + 0.5) / f64::from(w),
                (f64::from(k / w) + 0.5) / f64::from(h),
            )
        };
        // Uniform radiance 1: E = π for every normal.
        let white = EnvMap::load(&EnvSource::White, 1.0, 0.0).unwrap();
        let e = irradiance_table(&white);
        let worst = e
            .iter()
            .flatten()
            .fold(0f64, |m, x| m.max((x / std::f64::consts::PI - 1.0).abs()));
        assert!(worst < 2e-3, "{worst} ({}×{})", white.width, white.height);
        // One bright pixel of a 1024×512 map (summed over 4×4 blocks), turned by 40°:
        // E = L·Ω·max(0, n·d) at its direction d, whichever block holds it.
        let (mw, mh) = (1024u32, 512u32);
        let (col, row) = (301u32, 130u32);
        let mut px = vec![[0.0f32; 3]; (mw * mh) as usize];
        px[(row * mw + col) as usize] = [1000.0, 500.0, 250.0];
        let mut map = EnvMap::from_pixels(mw, mh, px, "one pixel").unwrap();
        map.rotate_rad = 40f64.to_radians();
        let d = map.pixel_direction(col, row);
        let omega = map.pixel_solid_angle(row);
        let e = irradiance_table(&map);
        for (k, got) in e.iter().enumerate() {
            let n = normal(k as u32);
            let c = (n[0] * d[0] + n[1] * d[1] + n[2] * d[2]).max(0.0);
            for (ch, l) in [1000.0, 500.0, 250.0].iter().enumerate() {
                assert!(
                    (got[ch] - l * omega * c).abs() < 1e-9 * l * omega,
                    "{k}: {got:?}"
                );
            }
        }
    }
}
