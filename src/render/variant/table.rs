//! What the pre-integrated variants share: building a [`GTable`] with a progress bar,
//! uploading its planes (a 3D image for `volume`, an image array of coefficient planes for
//! `chebyshev-w` and `dhillon`), the `TableInfo` uniform block (glsl/table.glsl) and a
//! linear, clamped sampler.

use std::sync::Arc;
use std::time::Instant;

use ash::vk;
use indicatif::{ProgressBar, ProgressStyle};

use super::{
    CpuModel, DrawSetup, PreparedVariant, SpecConstant, Specialisation, TableFormat, TableOptions,
    VariantKind, VariantStats,
};
use crate::brdf::table::{prefilter_disc, GTable, Levelled, Region, Slices, TableSpec, Truncation};
use crate::colour::ColourTable;
use crate::gpu::formats::f32_to_f16;
use crate::gpu::memory::{Buffer, Image, ImageDesc, Pod, Sampler};
use crate::gpu::pipeline::{Binding, Resource};
use crate::gpu::Device;
use crate::leave_out::{LeftOut, TermsLeft, WavelengthsLeft};
use crate::{Error, Result};

use super::packed::{self, Packed};

/// How a table's planes are stored on the GPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Layout {
    /// Planes are the slices of a 3D image: trilinear in (u, v, w).
    Volume,
    /// Planes are the layers of an image array: bilinear in (u, v) per plane.
    Planes,
    /// The planes' XYZ packed four values a texel: plane `j`'s X, Y, Z are values `3j`,
    /// `3j + 1`, `3j + 2` of each texel's flat sequence over the layers, so `K` planes take
    /// `⌈3K/4⌉` layers (no unused alpha channel to store and fetch).
    PackedPlanes,
}

/// What a table variant states about its table, all of it: no part has a default that a
/// new variant could inherit without saying so ([`super::Variant::table_traits`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct TableTraits {
    /// Nodes along `w` unless the options or the height field ask for more.
    pub w_nodes: usize,
    /// Whether the `w` nodes grow with the height range (a series in `w` whose coefficients
    /// decay like Bessel functions; [`super::TableOptions::w_nodes_for_field`]).
    pub follows_field: bool,
    /// How its planes lie on the GPU ([`footprint`]).
    pub layout: TableLayout,
}

/// How a table variant lays its planes out on the GPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct TableLayout {
    pub layout: Layout,
    /// Texels added on each side of a plane (a cubic B-spline's ghosts).
    pub ghosts: usize,
    /// The planes are fitted to the data after sampling, so there may be fewer than the
    /// `w` nodes.
    pub fitted: bool,
}

/// What a table takes on the GPU: the figures `render` reports and `diffract variants`
/// lists, both from [`footprint`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Footprint {
    /// Planes of XYZ (the `w` nodes, or coefficients).
    pub planes: usize,
    /// Image layers (or 3D slices) they take.
    pub layers: usize,
    /// Texels of a layer along `u` and `v`.
    pub dims: (usize, usize),
    /// Texel fetches per evaluation.
    pub fetches: usize,
    pub bytes: usize,
    pub format: TableFormat,
    /// Planes, layers, fetches and bytes are bounds: the planes are fitted to the data.
    pub at_most: bool,
}

/// The footprint of `planes` planes of `dims` texels (for `nodes` nodes) in `layout` and
/// `format`: per layer a bilinear plane takes one fetch, a spline plane (with ghosts,
/// `dims ≠ nodes`) four; a volume takes one trilinear fetch.
pub(crate) fn footprint(
    layout: Layout,
    planes: usize,
    nodes: (usize, usize),
    dims: (usize, usize),
    format: TableFormat,
) -> Footprint {
    let layers = layer_count(planes, layout);
    let per_layer = if dims == nodes { 1 } else { 4 };
    Footprint {
        planes,
        layers,
        dims,
        fetches: match layout {
            Layout::Volume => 1,
            Layout::Planes | Layout::PackedPlanes => per_layer * layers,
        },
        bytes: dims.0 * dims.1 * layers * format.texel_bytes(),
        format,
        at_most: false,
    }
}

/// The fetches of table variant `kind` for `inputs` (0 where its table cannot be built
/// for them: the draw refuses it too).
pub(crate) fn fetches(kind: VariantKind, inputs: &super::FetchInputs<'_>) -> usize {
    match kind.footprint(inputs) {
        Some(Ok(f)) => f.fetches,
        _ => 0,
    }
}

/// Image layers that `planes` planes of XYZ take when packed four values a texel.
pub(crate) fn packed_layers(planes: usize) -> usize {
    (3 * planes).div_ceil(4)
}

/// Wavelength step (nm) of a table that holds the sun's disc, when no step was asked for.
/// A step moves a line's lookup by `Δu = |u|·Δλ/λ`: 2 nm at |u| = 1 and 380 nm is 0.0053,
/// 1.7 standard deviations of the disc-blurred lobe (0.0031), where a pure line spectrum
/// ripples by 2·exp(−2π²/1.7²) ≈ 2e-3. On the default scene 1, 2 and 4 nm give the same
/// picture (ΔE2000 mean 0.04 against the 8-direction render, docs/tables.md).
const DISC_STEP_NM: u32 = 2;

/// How many times the lobe-resolving spacing a table's texel may be before it is smoothed
/// ([`smooth_slices`]).
const SMOOTH_ABOVE: f64 = 1.5;

/// Smooths every slice of a table coarser than asked by the cubic B-spline's own kernel,
/// `(1, 4, 1)/6` along `u` and `v` (the end nodes kept). The representations interpolate
/// their slices with a cubic spline ([`crate::brdf::table::spline_plane`]); interpolating the
/// smoothed slices gives the spline whose coefficients are the samples themselves, a convex
/// combination of them at every point: it never rises above the largest sample around it
/// and loses a narrow lobe's height gradually instead of ringing.
pub(crate) fn smooth_slices(slices: &mut Slices) {
    let (nu, nv) = (slices.nu, slices.nv);
    let pass = |plane: &mut [[f64; 3]], len: usize, stride: usize, count: usize, step: usize| {
        if len < 3 {
            return;
        }
        for line in 0..count {
            let at = |k: usize| line * step + k * stride;
            let old: Vec<[f64; 3]> = (0..len).map(|k| plane[at(k)]).collect();
            for k in 1..len - 1 {
                plane[at(k)] =
                    [0, 1, 2].map(|c| (old[k - 1][c] + 4.0 * old[k][c] + old[k + 1][c]) / 6.0);
            }
        }
    };
    for plane in &mut slices.data {
        pass(plane, nu, 1, nv, nu);
        pass(plane, nv, nu, nu, 1);
    }
}

/// The largest relative loss of a lobe's peak in a smoothed table of spacing `texel`: the
/// smoothing spline widens a Gaussian lobe of standard deviation `σ` by the cubic
/// B-spline's variance `texel²/3` along each axis, so its peak falls to
/// `σ² / (σ² + texel²/3)`; the narrowest lobe, at 380 nm, has `σ = λ/(2π σs)` with
/// `σs = coherence/4` (the window of MODEL §3).
pub(crate) fn smoothing_loss(texel: f64, coherence_um: f64) -> f64 {
    let sigma_s = coherence_um / 4.0;
    let sigma = crate::colour::LAMBDA_MIN_NM as f64 * 1e-3 / (2.0 * std::f64::consts::PI * sigma_s);
    let s2 = sigma * sigma;
    1.0 - s2 / (s2 + texel * texel / 3.0)
}

/// Mirror of `TableInfo` in glsl/table.glsl (std140: vec4 members only).
#[repr(C)]
#[derive(Clone, Copy)]
struct TableInfoUbo {
    lo: [f32; 4],
    inv_extent: [f32; 4],
    nodes: [f32; 4],
    /// The image's texels along u and v, and its levels ([`crate::brdf::table::Levelled`]).
    atlas: [f32; 4],
    /// Per level: nodes along u and v, and its first texel's column and row.
    levels: [[f32; 4]; crate::brdf::table::MAX_LEVELS],
}

// SAFETY: repr(C) of f32 arrays: no padding.
unsafe impl Pod for TableInfoUbo {}

/// Samples `G` at the `w` nodes `nodes(spec)` (through the table cache), assembles the
/// representation of `kind` from the samples (which may refuse it; a series says which of
/// its terms it kept), and uploads it; a progress bar shows the build on a terminal.
pub(crate) fn prepare<T: GTable + 'static>(
    kind: VariantKind,
    dev: &Arc<Device>,
    setup: &DrawSetup<'_>,
    layout: Layout,
    nodes: fn(&TableSpec) -> Vec<f64>,
    assemble: impl FnOnce(Region, Slices) -> Result<(T, Option<Truncation>)>,
) -> Result<Box<dyn PreparedVariant>> {
    let start = Instant::now();
    let material = &setup.prepared.material;
    let (lo, hi) = setup.prepared.heightfield.range();
    // A table that holds the sun's disc integrates the spectrum at DISC_STEP_NM unless asked
    // otherwise: the disc blurs the ripple of the coarser step. Its (u, v) spacing stays the
    // one that resolves the unblurred lobe, because G is sampled before the disc blurs it
    // (a spacing fitted to the blurred lobe undersampled the blue lines and added their
    // aliases to the blur: ΔE2000 3.8 at an order's edge on the default scene, 0.9 with it).
    let options = match &setup.disc {
        Some(_) => TableOptions {
            step_nm: Some(setup.table.step_nm.unwrap_or(DISC_STEP_NM)),
            ..*setup.table
        },
        None => *setup.table,
    };
    let (spec, coarsened) = options.spec(kind, material, hi - lo, setup.region)?;
    let smoothed = spec.texel_uv > TableSpec::default_texel(material.coherence_um) * SMOOTH_ABOVE;
    if let Some(asked) = coarsened {
        let cost = if smoothed {
            format!(
                "smoothed, never above its samples; the narrowest lobes' peaks (380 nm) come out {:.0} % low on a node, more between nodes",
                100.0 * smoothing_loss(spec.texel_uv, material.coherence_um)
            )
        } else {
            format!(
                "still within {SMOOTH_ABOVE} times the lobe-resolving spacing, so interpolated as is: the narrowest lobes (380 nm) within about 5 % of their peaks"
            )
        };
        setup.report.warn(&format!(
            "{kind} table over u ∈ [{:.2}, {:.2}], v ∈ [{:.2}, {:.2}] coarsened from texel {asked:.4} to {:.4} to fit {} MB and the build's limits: {cost}",
            spec.region.lo[0],
            spec.region.hi[0],
            spec.region.lo[1],
            spec.region.hi[1],
            spec.texel_uv,
            setup.table.budget_bytes >> 20,
        ));
    }
    // Leaving out: the build integrates only the wavelengths whose weight matters.
    let (selection, wavelengths) = WavelengthsLeft::of(
        &setup.colour(&ColourTable::new(spec.step_nm)?),
        setup.leave_out_tolerance(),
        "in the table build",
    );
    let keep = setup.leave_out.then_some(selection.keep.as_slice());
    // The GPU-ready texels of this very table, when a draw that keeps no f64 model made
    // them before.
    let p = setup.prepared;
    let packed_key = packed_key(kind, dev, setup, &spec, nodes, keep, layout, smoothed)?;
    if let (Some(key), Some(dir)) = (packed_key, setup.cache_dir) {
        let (nu, nv) = spec.uv_nodes()?;
        // The levels for a pixel's footprint take up to half as many texels again; the
        // summed-area planes, in float32, twice as many bytes as the table in float16.
        let levels = if setup.table.levels > 1 { 4 } else { 1 };
        let most = (levels * (nu + 3) * (nv + 3) * spec.w_nodes.max(1) * 16) as u64;
        if let Some(cached) = packed::load(dir, key, (nu, nv), most, setup.report) {
            let mut gpu = TableGpu::from_packed(kind, dev, &spec, &cached, layout, start)?;
            let built = crate::render::table_build::Built::Cached.to_string();
            finish_stats(&mut gpu, built, setup, wavelengths, layout);
            return Ok(Box::new(gpu));
        }
    }
    let lambdas = selection.keep.len() as u64;
    let bar = ProgressBar::new(spec.w_nodes as u64 * lambdas).with_message(format!("{kind} table"));
    let bar = setup.report.progress(bar);
    bar.set_style(
        crate::progress::style("{msg} [{bar:30}] {pos}/{len} (w, λ) planes, {left} left")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let (mut samples, built) = crate::render::table_build::sample_g_built(
        dev,
        setup.table.build,
        &p.heightfield,
        p.material.coherence_um,
        &spec,
        &nodes(&spec),
        keep,
        setup.cache_dir,
        setup.report,
        &|| {
            setup.report.checkpoint();
            bar.inc(1)
        },
    )?;
    bar.finish_and_clear();
    // The sun's disc, convolved into every slice: the shader then evaluates the disc's
    // centre once instead of each of its directions (glsl/shade.glsl, DISC_PREFILTERED).
    if let Some(kernel) = &setup.disc {
        prefilter_disc(&mut samples, &spec.region, kernel);
    }
    // A spacing well coarser than the one that resolves the coherence lobe (coarsened to
    // fit, or asked for) cannot follow the lobes: the interpolating spline would ring beside
    // them (a pixel beside the specular at 4.8 times the map's peak at texel 0.0070, 2.6
    // times that spacing; clamped to 0 at 0.02). Smoothed, the table loses their height
    // gradually instead. Up to SMOOTH_ABOVE times the spacing the spline still follows the
    // lobes (within 5 % of the peak at 0.004, tests/gpu_variants.rs) and smoothing would
    // only cost height.
    if smoothed {
        smooth_slices(&mut samples);
    }
    let (table, terms) = assemble(spec.region, samples)?;
    let (mut gpu, texels) = TableGpu::upload(
        kind,
        dev,
        &spec,
        (&table, terms),
        layout,
        setup.table.format,
        start,
    )?;
    if let (Some(key), Some(dir)) = (packed_key, setup.cache_dir) {
        packed::store(dir, key, texels, setup.report);
    }
    finish_stats(&mut gpu, built.to_string(), setup, wavelengths, layout);
    if setup.keep_model {
        gpu.model = Some(TableModel(Box::new(table)));
    }
    Ok(Box::new(gpu))
}

/// `table`, built elsewhere (the environment's sampling table), uploaded as the table
/// variant `kind` stores it, in `format`.
pub(crate) fn upload_built(
    kind: VariantKind,
    dev: &Arc<Device>,
    spec: &TableSpec,
    table: &dyn GTable,
    format: super::TableFormat,
) -> Result<Box<dyn PreparedVariant>> {
    let layout = kind
        .implementation()
        .table_traits()
        .map(|t| t.layout)
        .ok_or_else(|| Error::invalid("variant", format!("'{kind}' is not a table variant")))?;
    let (gpu, _) = TableGpu::upload(
        kind,
        dev,
        spec,
        (table, None),
        layout.layout,
        format,
        Instant::now(),
    )?;
    Ok(Box::new(gpu))
}

/// The rest of a prepared table's report: how it was obtained, the disc, what was left out.
fn finish_stats(
    gpu: &mut TableGpu,
    built: String,
    setup: &DrawSetup<'_>,
    wavelengths: WavelengthsLeft,
    layout: Layout,
) {
    gpu.stats.table_build = Some(built);
    gpu.stats.disc_prefiltered = setup.disc.is_some();
    if gpu.stats.disc_prefiltered {
        gpu.stats.name.push_str(" sun's disc pre-filtered");
    }
    // The table's size does not depend on the wavelengths: the saving is build time. The
    // terms left out save their layers (the planes and the sums alike).
    let terms = gpu.series.zip(setup.leave_out_tolerance());
    let all_bytes = match terms {
        Some((t, _)) => {
            gpu.stats.gpu_bytes * layer_count(t.of, layout) / layer_count(t.kept, layout).max(1)
        }
        None => gpu.stats.gpu_bytes,
    };
    gpu.left_out = Some(LeftOut {
        wavelengths: Some(wavelengths),
        texels: None,
        terms: terms.map(|(truncation, tolerance)| TermsLeft {
            truncation,
            tolerance,
        }),
        gpu_bytes: gpu.stats.gpu_bytes,
        gpu_bytes_keep_all: all_bytes,
    });
}

/// The packed-texel cache's key of a table: everything its texels depend on (the sampled
/// table's key and its wavelengths, where and in what arithmetic it is built, the disc
/// pre-filter, the smoothing, the variant's layout and the texel format the device
/// filters). `None` where the draw keeps the f64 model, which only the full path makes.
#[allow(clippy::too_many_arguments)]
fn packed_key(
    kind: VariantKind,
    dev: &Arc<Device>,
    setup: &DrawSetup<'_>,
    spec: &TableSpec,
    nodes: fn(&TableSpec) -> Vec<f64>,
    keep: Option<&[usize]>,
    layout: Layout,
    smoothed: bool,
) -> Result<Option<u64>> {
    if setup.keep_model || setup.cache_dir.is_none() {
        return Ok(None);
    }
    let p = setup.prepared;
    let mut h = crate::cache::Fnv1a::new();
    h.bytes(b"packed table");
    h.u64(crate::brdf::table_cache::key(
        &p.heightfield,
        p.material.coherence_um,
        spec,
        &nodes(spec),
    ));
    if let Some(k) = keep {
        h.bytes(b"kept wavelengths");
        k.iter().for_each(|&i| h.u64(i as u64));
    }
    h.bytes(format!("{:?} on {:?}", setup.table.build, setup.table.build.on(dev)).as_bytes());
    if let Some(d) = &setup.disc {
        h.bytes(b"disc");
        d.axes.iter().flatten().for_each(|a| h.u64(a.to_bits()));
    }
    h.bytes(format!("{kind} {layout:?} smoothed {smoothed}").as_bytes());
    if setup.table.levels > 1 {
        h.bytes(format!("levels {}", setup.table.levels).as_bytes());
    }
    if kind == VariantKind::ChebyshevW && reads_boxes(dev, setup) {
        h.bytes(b"summed-area planes");
    }
    if let (VariantKind::ChebyshevW, Some(t)) = (kind, setup.leave_out_tolerance()) {
        h.bytes(b"series terms within");
        h.u64(t.to_bits());
    }
    let (format, _) = filterable_format(dev, setup.table.format)?;
    h.bytes(format!("{format:?}").as_bytes());
    Ok(Some(h.finish()))
}

/// A table variant in f64: `C(ωi, ωr)·G` with the f64 table the shader's planes were
/// rounded from, interpolated as the shader interpolates them.
struct TableModel(Box<dyn GTable>);

impl CpuModel for TableModel {
    fn xyz(
        &self,
        p: &crate::material::PreparedMaterial,
        _colour: &ColourTable,
        wi: [f64; 3],
        wr: [f64; 3],
    ) -> Result<[f64; 3]> {
        Ok(self.0.xyz(&p.shading, wi, wr))
    }

    fn table(&self) -> Option<&dyn GTable> {
        Some(&*self.0)
    }
}

struct TableGpu {
    stats: VariantStats,
    model: Option<TableModel>,
    left_out: Option<LeftOut>,
    terms: u32,
    /// What a series kept of its terms.
    series: Option<Truncation>,
    /// Levels of its table pre-filtered for a pixel's footprint (1: none).
    levels: usize,
    info: Buffer,
    sampler: Sampler,
    image: Image,
    /// The summed-area planes (a 1×1 placeholder where there are none).
    summed: Image,
    /// Whether the shader reads `summed` at the pixel's footprint.
    boxes: bool,
}

impl TableGpu {
    /// Packs `table`'s planes for `layout` in `format` (where the device filters it) and
    /// uploads them ([`Self::from_packed`]); also the packed texels, for the cache. `terms`:
    /// what a series kept of its terms.
    fn upload(
        kind: VariantKind,
        dev: &Arc<Device>,
        spec: &TableSpec,
        (table, terms): (&dyn GTable, Option<Truncation>),
        layout: Layout,
        format: TableFormat,
        start: Instant,
    ) -> Result<(Self, Packed)> {
        let (nu, nv) = table.nodes_uv();
        let (pu, pv) = table.plane_dims();
        let planes = table.planes();
        let (format, _) = filterable_format(dev, format)?;
        let fp = footprint(layout, planes.len(), (nu, nv), (pu, pv), format);
        let packed = Packed {
            nu,
            nv,
            pu,
            pv,
            planes: planes.len(),
            layers: fp.layers,
            fetches: fp.fetches,
            levels: table.footprint_levels(),
            format,
            region: *table.region(),
            bytes: texel_bytes_of(planes, layout, fp.layers, format),
            summed: table.summed().map_or_else(Vec::new, |s| {
                texel_bytes_of(&s, layout, fp.layers, TableFormat::Rgba32f)
            }),
            terms,
        };
        debug_assert_eq!(packed.bytes.len(), fp.bytes);
        let gpu = Self::from_packed(kind, dev, spec, &packed, layout, start)?;
        Ok((gpu, packed))
    }

    /// Uploads packed texels: the image, its sampler and the table's uniform block.
    fn from_packed(
        kind: VariantKind,
        dev: &Arc<Device>,
        spec: &TableSpec,
        p: &Packed,
        layout: Layout,
        start: Instant,
    ) -> Result<Self> {
        let (format, vk_format) = filterable_format(dev, p.format)?;
        if format != p.format {
            return Err(Error::invalid(
                "table format",
                format!("{} cannot filter {:?} linearly", dev.info.name, p.format),
            ));
        }
        let info = &dev.info;
        let (limit, view_type) = match layout {
            Layout::Volume => (info.max_image_dimension_3d, vk::ImageViewType::TYPE_3D),
            Layout::Planes | Layout::PackedPlanes => (
                info.max_image_dimension_2d,
                vk::ImageViewType::TYPE_2D_ARRAY,
            ),
        };
        let depth_limit = match layout {
            Layout::Volume => info.max_image_dimension_3d,
            Layout::Planes | Layout::PackedPlanes => info.max_image_array_layers,
        };
        let (pu, pv, layers) = (p.pu, p.pv, p.layers);
        if pu as u32 > limit || pv as u32 > limit || layers as u32 > depth_limit {
            return Err(Error::invalid(
                "table size",
                format!(
                    "{pu}×{pv}×{layers} texels exceed the device limits ({limit} a side, {depth_limit} deep): use a coarser texel"
                ),
            ));
        }
        let image = Image::sampled_with_data(
            dev,
            &format!("{kind} table"),
            ImageDesc {
                format: vk_format,
                width: pu as u32,
                height: pv as u32,
                layers: layers as u32,
                usage: vk::ImageUsageFlags::SAMPLED,
                aspect: vk::ImageAspectFlags::COLOR,
                view_type,
            },
            format.texel_bytes(),
            &p.bytes,
        )?;
        let r = p.region;
        let e = r.extent();
        // The levels pre-filtered for a pixel's footprint, where the planes hold them.
        let level_count = p.levels.max(1);
        let levels = Levelled::layout_of(p.nu, p.nv, level_count);
        let ubo = TableInfoUbo {
            lo: [r.lo[0] as f32, r.lo[1] as f32, r.lo[2] as f32, 0.0],
            inv_extent: [
                (1.0 / e[0]) as f32,
                (1.0 / e[1]) as f32,
                (1.0 / e[2]) as f32,
                0.0,
            ],
            nodes: [p.nu as f32, p.nv as f32, p.planes as f32, 0.0],
            atlas: [p.pu as f32, p.pv as f32, level_count as f32, 0.0],
            levels: std::array::from_fn(|i| {
                levels.get(i).map_or([0.0; 4], |l| l.map(|x| x as f32))
            }),
        };
        // A table without summed planes binds one placeholder texel a layer.
        let placeholder;
        let (sw, sh, summed_bytes, what) = if p.summed.is_empty() {
            placeholder = vec![0u8; 16 * layers];
            (1, 1, placeholder.as_slice(), "summed table (none)")
        } else {
            (p.nu + 1, p.nv + 1, p.summed.as_slice(), "summed table")
        };
        let summed = Image::sampled_with_data(
            dev,
            &format!("{kind} {what}"),
            ImageDesc {
                format: vk::Format::R32G32B32A32_SFLOAT,
                width: sw as u32,
                height: sh as u32,
                layers: layers as u32,
                usage: vk::ImageUsageFlags::SAMPLED,
                aspect: vk::ImageAspectFlags::COLOR,
                view_type,
            },
            16,
            summed_bytes,
        )?;
        let info = Buffer::with_data(
            dev,
            &format!("{kind} table info"),
            vk::BufferUsageFlags::UNIFORM_BUFFER,
            std::slice::from_ref(&ubo),
        )?;
        Ok(Self {
            model: None,
            left_out: None,
            stats: VariantStats {
                name: format!(
                    "{kind} K={}{} {}×{} texel {:.4} dλ={} {format:?}{}",
                    p.planes,
                    match p.terms {
                        Some(t) if t.kept < t.of => format!(" of {}", t.of),
                        _ => String::new(),
                    },
                    p.nu,
                    p.nv,
                    spec.texel_uv,
                    spec.step_nm,
                    match (p.summed.is_empty(), level_count) {
                        (false, _) => " summed-area planes for the pixel footprint".to_string(),
                        (true, 1) => String::new(),
                        (true, n) => format!(" {n} levels for the pixel footprint"),
                    }
                ),
                build_ms: start.elapsed().as_secs_f64() * 1e3,
                gpu_bytes: p.bytes.len() + p.summed.len(),
                fetches: p.fetches,
                table_build: None,
                disc_prefiltered: false,
            },
            terms: p.planes as u32,
            series: p.terms,
            levels: level_count,
            info,
            sampler: Sampler::new(
                dev,
                &format!("{kind} table (linear)"),
                vk::Filter::LINEAR,
                vk::SamplerAddressMode::CLAMP_TO_EDGE,
            )?,
            image,
            boxes: !p.summed.is_empty(),
            summed,
        })
    }
}

/// Whether `chebyshev-w` reads its table as the mean over a pixel's footprint from
/// summed-area planes ([`crate::brdf::table::Summed`]): where the footprint is asked for
/// (`levels > 1`) and the device filters float32 linearly (the sums need its precision);
/// elsewhere it reads the levels pre-filtered for the footprint.
pub(super) fn reads_boxes(dev: &Device, setup: &DrawSetup<'_>) -> bool {
    setup.table.levels > 1 && sums_filter(dev)
}

/// Whether `dev` filters the summed-area planes (float32) linearly, as
/// [`crate::brdf::table::Summed`] needs.
pub(crate) fn sums_filter(dev: &Device) -> bool {
    filters_linearly(dev, vk::Format::R32G32B32A32_SFLOAT)
}

/// Whether the device samples `format` with linear filtering.
fn filters_linearly(dev: &Device, format: vk::Format) -> bool {
    let linear =
        vk::FormatFeatureFlags::SAMPLED_IMAGE | vk::FormatFeatureFlags::SAMPLED_IMAGE_FILTER_LINEAR;
    dev.supports_format(format, linear)
}

/// `format` where the device filters it linearly (float32 falls back to float16), and its
/// Vulkan format; an error where it filters neither.
fn filterable_format(dev: &Device, format: TableFormat) -> Result<(TableFormat, vk::Format)> {
    let format = match format {
        TableFormat::Rgba32f if filters_linearly(dev, vk::Format::R32G32B32A32_SFLOAT) => {
            TableFormat::Rgba32f
        }
        _ => TableFormat::Rgba16f,
    };
    let vk_format = match format {
        TableFormat::Rgba32f => vk::Format::R32G32B32A32_SFLOAT,
        TableFormat::Rgba16f => vk::Format::R16G16B16A16_SFLOAT,
    };
    if !filters_linearly(dev, vk_format) {
        return Err(Error::invalid(
            "table format",
            format!("{} cannot filter {vk_format:?} linearly", dev.info.name),
        ));
    }
    Ok((format, vk_format))
}

/// The bytes of `layers` image layers of `planes` in `layout` and `format`, layer by
/// layer, texel by texel.
fn texel_bytes_of(
    planes: &[Vec<[f64; 3]>],
    layout: Layout,
    layers: usize,
    format: TableFormat,
) -> Vec<u8> {
    use rayon::prelude::*;
    let texels = planes.first().map_or(0, Vec::len);
    let size = format.texel_bytes();
    let mut bytes = vec![0u8; texels * layers * size];
    // Runs of texels in parallel: the packing is the last step before the upload.
    const RUN: usize = 4096;
    bytes
        .par_chunks_mut(RUN * size)
        .enumerate()
        .for_each(|(k, out)| {
            for (i, texel) in out.chunks_exact_mut(size).enumerate() {
                let at = k * RUN + i;
                let rgba = layer_texel(planes, layout, at / texels, at % texels);
                match format {
                    TableFormat::Rgba32f => {
                        for (o, c) in texel.chunks_exact_mut(4).zip(rgba) {
                            o.copy_from_slice(&c.to_le_bytes());
                        }
                    }
                    TableFormat::Rgba16f => {
                        for (o, c) in texel.chunks_exact_mut(2).zip(rgba) {
                            o.copy_from_slice(&f32_to_f16(c).to_le_bytes());
                        }
                    }
                }
            }
        });
    bytes
}

/// Image layers that `planes` planes of XYZ take in `layout`.
fn layer_count(planes: usize, layout: Layout) -> usize {
    match layout {
        Layout::Volume | Layout::Planes => planes,
        Layout::PackedPlanes => packed_layers(planes),
    }
}

/// Texel `t` of image layer `layer` (RGBA, float32) for `planes` of XYZ in `layout`.
fn layer_texel(planes: &[Vec<[f64; 3]>], layout: Layout, layer: usize, t: usize) -> [f32; 4] {
    match layout {
        Layout::Volume | Layout::Planes => {
            let x = planes[layer][t];
            [x[0] as f32, x[1] as f32, x[2] as f32, 0.0]
        }
        Layout::PackedPlanes => std::array::from_fn(|c| {
            let q = 4 * layer + c;
            planes.get(q / 3).map_or(0.0, |p| p[t][q % 3] as f32)
        }),
    }
}

impl PreparedVariant for TableGpu {
    fn bindings(&self) -> Vec<Binding> {
        vec![
            Binding {
                binding: 1,
                kind: vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
                stages: vk::ShaderStageFlags::FRAGMENT,
            },
            Binding {
                binding: 4,
                kind: vk::DescriptorType::UNIFORM_BUFFER,
                stages: vk::ShaderStageFlags::FRAGMENT,
            },
            Binding {
                binding: 5,
                kind: vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
                stages: vk::ShaderStageFlags::FRAGMENT,
            },
        ]
    }

    fn resources(&self) -> Vec<(u32, Resource<'_>)> {
        vec![
            (1, Resource::Sampled(&self.image, &self.sampler)),
            (4, Resource::Uniform(&self.info)),
            (5, Resource::Sampled(&self.summed, &self.sampler)),
        ]
    }

    fn specialise(&self, spec: &mut Specialisation) {
        spec[SpecConstant::TableTerms] = self.terms;
        // FOOTPRINT_POINT, _LEVELS or _BOX (glsl/chebyshev_w.frag).
        spec[SpecConstant::Footprint] = match (self.boxes, self.levels > 1) {
            (true, _) => 2,
            (false, true) => 1,
            (false, false) => 0,
        };
        spec[SpecConstant::DiscPrefiltered] = self.stats.disc_prefiltered as u32;
    }

    fn stats(&self) -> VariantStats {
        self.stats.clone()
    }

    fn model(&self) -> Option<&dyn CpuModel> {
        self.model.as_ref().map(|m| m as &dyn CpuModel)
    }

    fn left_out(&self) -> Option<LeftOut> {
        self.left_out.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_planes_hold_every_value_once_in_order() {
        // Five planes of two texels: 15 values a texel in four layers, the last one padded.
        let planes: Vec<Vec<[f64; 3]>> = (0..5)
            .map(|j| {
                (0..2)
                    .map(|t| std::array::from_fn(|c| (100 * t + 3 * j + c) as f64))
                    .collect()
            })
            .collect();
        assert_eq!(packed_layers(5), 4);
        let layers = layer_count(planes.len(), Layout::PackedPlanes);
        assert_eq!(layers, 4);
        for t in 0..2 {
            let flat: Vec<f32> = (0..layers)
                .flat_map(|l| layer_texel(&planes, Layout::PackedPlanes, l, t))
                .collect();
            let want: Vec<f32> = (0..15).map(|q| (100 * t + q) as f32).collect();
            assert_eq!(&flat[..15], &want[..]);
            assert_eq!(flat[15], 0.0);
        }
        assert_eq!(layer_count(planes.len(), Layout::Planes), 5);
        assert_eq!(
            layer_texel(&planes, Layout::Planes, 2, 1),
            [106.0, 107.0, 108.0, 0.0]
        );
        assert_eq!(packed_layers(12), 9);
    }

    /// A lobe of the 65 µm window at 380 nm (σ = 0.0037) on a table of texel 0.0071, its
    /// centre between nodes: the interpolating spline rings (below zero beside the lobe)
    /// and can rise above its samples; the smoothed table is a convex combination of its
    /// samples everywhere (never above their peak, never below zero) and loses the lobe's
    /// height by no more than [`smoothing_loss`] says, plus what sampling between the
    /// nodes costs.
    #[test]
    fn a_coarse_table_is_smoothed_and_never_rises_above_its_samples() {
        use crate::brdf::table::{ChebyshevW, GTable};
        let (n, texel, sigma) = (15usize, 0.1 / 14.0, 0.0037f64);
        let region = Region {
            lo: [-0.05, -0.05, -1.6],
            hi: [0.05, 0.05, -1.4],
        };
        let (cu, cv) = (0.3 * texel, 0.5 * texel);
        let node = |i: usize| -0.05 + i as f64 * texel;
        let slice: Vec<[f64; 3]> = (0..n)
            .flat_map(|j| {
                (0..n).map(move |i| {
                    let (du, dv) = (node(i) - cu, node(j) - cv);
                    [(-(du * du + dv * dv) / (2.0 * sigma * sigma)).exp(); 3]
                })
            })
            .collect();
        let max_sample = slice.iter().map(|p| p[1]).fold(0.0, f64::max);
        let slices = Slices {
            nu: n,
            nv: n,
            w: vec![-1.55, -1.45],
            data: vec![slice.clone(), slice],
        };
        let extremes = |t: &dyn GTable| {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for j in 0..=200 {
                for i in 0..=200 {
                    let uvw = [-0.05 + i as f64 * 5e-4, -0.05 + j as f64 * 5e-4, -1.5];
                    let g = t.g_unclamped(uvw).unwrap()[1];
                    lo = lo.min(g);
                    hi = hi.max(g);
                }
            }
            (lo, hi)
        };
        let (ring_lo, _) = extremes(&ChebyshevW::from_nodes(region, &slices));
        assert!(
            ring_lo < -0.01,
            "the interpolating spline rings: min {ring_lo}"
        );
        let mut smoothed = slices.clone();
        smooth_slices(&mut smoothed);
        let (lo, hi) = extremes(&ChebyshevW::from_nodes(region, &smoothed));
        assert!(lo >= -1e-12, "min {lo}");
        assert!(
            hi <= max_sample * (1.0 + 1e-12),
            "max {hi} above the samples' {max_sample}"
        );
        let loss = smoothing_loss(texel, 65.0);
        assert!((0.4..0.7).contains(&loss), "{loss}");
        assert!(hi >= (1.0 - loss) * max_sample, "max {hi}, loss {loss}");
    }
}
