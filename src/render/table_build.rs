//! Sampling `G(u, v, w)` on the device (MODEL §7, "Building G on the device"): the same
//! computation as the CPU build ([`crate::brdf::table::sample_g_kept`]), as a batch of
//! `(w, λ)` jobs in Vulkan compute (glsl/table_build.glsl). Per job: the phase field
//! `exp(i·s·h)`, `s = 2πw/λ`; the `+i` DFT of every row, then of only the columns the
//! lookups reach, as mixed-radix Stockham stages (any length: each stage's radix is a
//! prime factor of the length, or 4); the Gaussian window at the lookups of the table's
//! `(u, v)` nodes as two separable passes; `|P̂|²` times the wavelength's XYZ weight summed
//! into the slice of the job's `w`. One submission per `w` node covers all its
//! wavelengths, in batches as large as the field buffers allow.
//!
//! In float64 (`shaderFloat64`) the result equals the CPU's to rounding; in float32 its
//! error is measured by the tests (docs/tables.md).

use std::f64::consts::PI;
use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use crate::brdf::table::{Slices, TableSpec};
use crate::gpu::compute::{self, ComputeLayout, ComputePipeline, StorageSet};
use crate::gpu::memory::Buffer;
use crate::gpu::Device;
use crate::heightfield::HeightField;
use crate::{Error, Result};

const SPIRV_F64: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/table_build_f64.comp.spv"));
const SPIRV_F32: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/table_build_f32.comp.spv"));

/// Bytes a field buffer (the batch's complex fields) may take.
const FIELD_BUDGET: u64 = 256 << 20;
/// Storage-buffer bindings of glsl/table_build.glsl.
const BINDINGS: u32 = 13;

/// Floating-point precision of a device build.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Precision {
    F64,
    F32,
}

impl Precision {
    /// Float64 where the device has `shaderFloat64`, else float32.
    pub fn best(dev: &Device) -> Precision {
        if dev.info.shader_float64 {
            Precision::F64
        } else {
            Precision::F32
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Precision::F64 => "f64",
            Precision::F32 => "f32",
        }
    }

    fn real_bytes(self) -> u64 {
        match self {
            Precision::F64 => 8,
            Precision::F32 => 4,
        }
    }

    fn reals(self, values: &[f64]) -> Vec<u8> {
        match self {
            Precision::F64 => values.iter().flat_map(|x| x.to_le_bytes()).collect(),
            Precision::F32 => values
                .iter()
                .flat_map(|x| (*x as f32).to_le_bytes())
                .collect(),
        }
    }

    fn read(self, bytes: &[u8]) -> Vec<f64> {
        match self {
            Precision::F64 => bytes
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
                .collect(),
            Precision::F32 => bytes
                .chunks_exact(4)
                .map(|c| f64::from(f32::from_le_bytes(c.try_into().unwrap_or([0; 4]))))
                .collect(),
        }
    }
}

/// The radices of the Stockham stages for length `n`: 4 while 4 divides it, then 2, then
/// the odd prime factors in increasing order (a large prime is one stage of that radix).
pub fn radices(n: usize) -> Vec<usize> {
    let mut out = Vec::new();
    if n == 0 {
        return out;
    }
    let mut m = n;
    while m.is_multiple_of(4) {
        out.push(4);
        m /= 4;
    }
    if m.is_multiple_of(2) {
        out.push(2);
        m /= 2;
    }
    let mut p = 3;
    while p * p <= m {
        while m.is_multiple_of(p) {
            out.push(p);
            m /= p;
        }
        p += 2;
    }
    if m > 1 {
        out.push(m);
    }
    out
}

/// `exp(+2πi t/n)`, `t < n`, interleaved (re, im).
fn twiddles(n: usize) -> Vec<f64> {
    (0..n)
        .flat_map(|t| {
            let a = 2.0 * PI * t as f64 / n as f64;
            [a.cos(), a.sin()]
        })
        .collect()
}

/// Push constants of glsl/table_build.glsl, in declaration order.
#[derive(Clone, Copy, Default)]
struct Push {
    total: u32,
    n: i32,
    ns: i32,
    radix: i32,
    lines: i32,
    axis: i32,
    src: i32,
    jobs: i32,
    job_base: i32,
    lam_base: i32,
    slot: i32,
}

impl Push {
    const BYTES: u32 = 44;

    fn bytes(&self) -> Vec<u8> {
        let mut out = self.total.to_le_bytes().to_vec();
        for v in [
            self.n,
            self.ns,
            self.radix,
            self.lines,
            self.axis,
            self.src,
            self.jobs,
            self.job_base,
            self.lam_base,
            self.slot,
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out
    }
}

/// The passes, by their `PASS` constant.
#[derive(Clone, Copy)]
enum Pass {
    Phase = 0,
    Fft = 1,
    Gather = 2,
    Taps = 3,
    WindowX = 4,
    WindowY = 5,
}

/// An `i32` from a size that must fit one (shader indices are 32-bit).
fn small(x: i64, what: &str) -> Result<i32> {
    i32::try_from(x).map_err(|_| {
        Error::invalid(
            "device table build",
            format!("{what} = {x} exceeds 32-bit indexing"),
        )
    })
}

/// [`sample_g_kept`](crate::brdf::table::sample_g_kept) on `dev` in `precision`: the same
/// sampling of `G` (same nodes, lookups, window and weights), built with Vulkan compute.
/// `progress` is called once per finished `(w, λ)` pair.
///
/// The steps: check the request ([`check_request`]), plan the lookups of every wavelength
/// ([`Lookups::plan`]), size the batches of wavelengths one dispatch round holds
/// ([`Batches::of`]), upload the inputs ([`BuildBuffers::new`]), build the pipelines of the
/// passes ([`Passes::new`]), then per `w` node record and run every batch
/// ([`record_slice`]) and read the slice back ([`read_slice`]).
#[allow(clippy::too_many_arguments)]
pub fn sample_g_device(
    dev: &Arc<Device>,
    hf: &HeightField,
    coherence_um: f64,
    spec: &TableSpec,
    w_nodes: &[f64],
    keep: Option<&[usize]>,
    precision: Precision,
    progress: &(dyn Fn() + Sync),
) -> Result<Slices> {
    let (nu, nv) = spec.validate()?;
    check_request(dev, coherence_um, precision)?;
    let samples = spec.spectral_samples(keep)?;
    let lookups = Lookups::plan(hf, coherence_um, spec, (nu, nv), &samples, w_nodes)?;
    let batches = Batches::of(dev, &lookups, precision)?;
    let buffers = BuildBuffers::new(dev, hf, &lookups, &batches, precision)?;
    let layout = ComputeLayout::new(dev, "table build", BINDINGS, Push::BYTES)?;
    let set = StorageSet::new(dev, "table build", &layout, &buffers.bindings())?;
    let passes = Passes::new(dev, &layout, &lookups, precision)?;
    let mut data = Vec::with_capacity(w_nodes.len());
    for (k, &w) in w_nodes.iter().enumerate() {
        let build = SliceBuild {
            dev,
            layout: &layout,
            set: &set,
            passes: &passes,
            lookups: &lookups,
            batches: &batches,
            buffers: &buffers,
        };
        dev.submit_once(&format!("table build w = {w:.4}"), |cb| {
            record_slice(&build, cb, k)
        })?;
        data.push(read_slice(&buffers.readback, &lookups, precision)?);
        for _ in 0..lookups.lambdas {
            progress();
        }
    }
    Ok(Slices {
        nu,
        nv,
        w: w_nodes.to_vec(),
        data,
    })
}

/// A positive coherence length, and float64 shaders for a float64 build.
fn check_request(dev: &Arc<Device>, coherence_um: f64, precision: Precision) -> Result<()> {
    if !(coherence_um.is_finite() && coherence_um > 0.0) {
        return Err(Error::invalid(
            "coherence length",
            format!("{coherence_um} µm; must be positive"),
        ));
    }
    if precision == Precision::F64 && !dev.info.shader_float64 {
        return Err(Error::invalid(
            "table build",
            format!(
                "{} has no shaderFloat64; build in float32 or on the CPU",
                dev.info.name
            ),
        ));
    }
    Ok(())
}

/// The lookups of every wavelength over the node grid, the shifted texels they reach (as
/// the CPU build computes them) and the jobs, one per `(w, λ)`.
struct Lookups {
    nu: usize,
    nv: usize,
    nx: usize,
    ny: usize,
    /// Mean-centred heights.
    heights: Vec<f64>,
    /// Gaussian window std (texels) along x and y, and its reach, 6σ up.
    sigma: [f64; 2],
    reach: [i64; 2],
    /// Widest band of shifted texels one wavelength reads: columns and rows.
    cmax: i64,
    rmax: i64,
    lambdas: usize,
    /// Lookup positions along x (per wavelength, one per `u` node) and y (one per `v`).
    qx: Vec<f64>,
    qy: Vec<f64>,
    /// Per wavelength: first column, columns, first row and rows of the texels it reads.
    job_int: Vec<i32>,
    /// Per job: phase scale `s = 2πw/λ` and the wavelength's XYZ weight.
    jobs_real: Vec<f64>,
}

impl Lookups {
    fn plan(
        hf: &HeightField,
        coherence_um: f64,
        spec: &TableSpec,
        (nu, nv): (usize, usize),
        samples: &[(f64, [f64; 3])],
        w_nodes: &[f64],
    ) -> Result<Self> {
        let (u, v) = spec.node_coords(nu, nv);
        let (nx, ny, dh) = (hf.nx(), hf.ny(), hf.dh_um());
        let mean = hf.mean();
        let heights: Vec<f64> = hf.heights_um().iter().map(|h| h - mean).collect();
        let sigma_s = coherence_um / 4.0;
        let sigma = |n: usize| n as f64 * dh / (2.0 * PI * sigma_s);
        let (sx, sy) = (sigma(nx), sigma(ny));
        let rx = (6.0 * sx).ceil() as i64;
        let ry = (6.0 * sy).ceil() as i64;
        let lambdas = samples.len();
        let mut qx = Vec::with_capacity(lambdas * nu);
        let mut qy = Vec::with_capacity(lambdas * nv);
        let mut job_int = Vec::with_capacity(lambdas * 4);
        let (mut cmax, mut rmax) = (1i64, 1i64);
        for &(l_nm, _) in samples {
            let lambda_um = l_nm * 1e-3;
            let x: Vec<f64> = u
                .iter()
                .map(|u| (nx / 2) as f64 + u * nx as f64 * dh / lambda_um)
                .collect();
            let y: Vec<f64> = v
                .iter()
                .map(|v| (ny / 2) as f64 + v * ny as f64 * dh / lambda_um)
                .collect();
            let cx0 = x[0].floor() as i64 - rx;
            let cols = x[nu - 1].floor() as i64 + rx - cx0 + 1;
            let cy0 = y[0].floor() as i64 - ry;
            let rows = y[nv - 1].floor() as i64 + ry - cy0 + 1;
            cmax = cmax.max(cols);
            rmax = rmax.max(rows);
            for value in [cx0, cols, cy0, rows] {
                job_int.push(small(value, "lookup texel")?);
            }
            qx.extend(x);
            qy.extend(y);
        }
        let jobs_real: Vec<f64> = w_nodes
            .iter()
            .flat_map(|&w| {
                samples.iter().flat_map(move |&(l_nm, wt)| {
                    let lambda_um = l_nm * 1e-3;
                    [2.0 * PI * w / lambda_um, wt[0], wt[1], wt[2]]
                })
            })
            .collect();
        Ok(Self {
            nu,
            nv,
            nx,
            ny,
            heights,
            sigma: [sx, sy],
            reach: [rx, ry],
            cmax,
            rmax,
            lambdas,
            qx,
            qy,
            job_int,
            jobs_real,
        })
    }
}

/// How many wavelengths one dispatch round transforms: as many as the field buffers (and
/// the descriptor range) hold.
struct Batches {
    /// Complex samples of one job's field.
    slot: u64,
    /// Bytes of one job's field, and of its x-pass output.
    per_job: u64,
    xpass_per_job: u64,
    /// Window taps of one job.
    taps_per_job: u64,
    /// Jobs a round.
    batch: usize,
}

impl Batches {
    fn of(dev: &Arc<Device>, l: &Lookups, precision: Precision) -> Result<Self> {
        let (nx, ny) = (l.nx, l.ny);
        let cplx = 2 * precision.real_bytes();
        let slot = (nx as u64 * ny as u64).max(l.cmax as u64 * ny as u64);
        let range = compute::max_storage_range(dev);
        let per_job = slot * cplx;
        let xpass_per_job = l.rmax as u64 * l.nu as u64 * cplx;
        if per_job > range || xpass_per_job > range {
            return Err(Error::invalid(
                "device table build",
                format!(
                    "a {nx}×{ny} field ({per_job} bytes a job) exceeds the device's storage-buffer range of {range} bytes; build on the CPU"
                ),
            ));
        }
        let batch = (FIELD_BUDGET.min(range) / per_job)
            .min(range / xpass_per_job)
            .clamp(1, l.lambdas.max(1) as u64) as usize;
        small(batch as i64 * slot as i64, "batch elements")?;
        let [rx, ry] = l.reach;
        let taps_per_job = l.nu as u64 * (2 * rx as u64 + 1) + l.nv as u64 * (2 * ry as u64 + 1);
        Ok(Self {
            slot,
            per_job,
            xpass_per_job,
            taps_per_job,
            batch,
        })
    }
}

/// The build's storage buffers, in binding order, and the slice's readback.
struct BuildBuffers {
    heights: Buffer,
    field_a: Buffer,
    field_b: Buffer,
    twiddles_x: Buffer,
    twiddles_y: Buffer,
    jobs: Buffer,
    job_texels: Buffer,
    lookups_x: Buffer,
    lookups_y: Buffer,
    taps: Buffer,
    xpass: Buffer,
    /// The slice being accumulated, and its bytes.
    acc: Buffer,
    acc_bytes: u64,
    constants: Buffer,
    readback: Buffer,
}

impl BuildBuffers {
    fn new(
        dev: &Arc<Device>,
        hf: &HeightField,
        l: &Lookups,
        b: &Batches,
        precision: Precision,
    ) -> Result<Self> {
        let data = |name: &str, bytes: &[u8]| {
            compute::storage_with_data(dev, &format!("table build {name}"), bytes)
        };
        let batch = b.batch as u64;
        let ints: Vec<u8> = l.job_int.iter().flat_map(|v| v.to_le_bytes()).collect();
        let acc_bytes = (l.nu * l.nv * 3) as u64 * precision.real_bytes();
        let norm = 1.0 / (hf.nx() as f64 * hf.ny() as f64);
        Ok(Self {
            heights: data("heights", &precision.reals(&l.heights))?,
            field_a: compute::storage(dev, "table build field A", batch * b.per_job)?,
            field_b: compute::storage(dev, "table build field B", batch * b.per_job)?,
            twiddles_x: data("twiddles x", &precision.reals(&twiddles(l.nx)))?,
            twiddles_y: data("twiddles y", &precision.reals(&twiddles(l.ny)))?,
            jobs: data("jobs", &precision.reals(&l.jobs_real))?,
            job_texels: data("job texels", &ints)?,
            lookups_x: data("lookups x", &precision.reals(&l.qx))?,
            lookups_y: data("lookups y", &precision.reals(&l.qy))?,
            taps: compute::storage(
                dev,
                "table build taps",
                batch * b.taps_per_job * precision.real_bytes(),
            )?,
            xpass: compute::storage(dev, "table build x pass", batch * b.xpass_per_job)?,
            acc: compute::storage(dev, "table build slice", acc_bytes)?,
            acc_bytes,
            constants: data(
                "constants",
                &precision.reals(&[l.sigma[0], l.sigma[1], norm]),
            )?,
            readback: Buffer::new(
                dev,
                "table build readback",
                acc_bytes,
                vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuToCpu,
            )?,
        })
    }

    /// The storage buffers in binding order (glsl/table_build.glsl).
    fn bindings(&self) -> [&Buffer; BINDINGS as usize] {
        [
            &self.heights,
            &self.field_a,
            &self.field_b,
            &self.twiddles_x,
            &self.twiddles_y,
            &self.jobs,
            &self.job_texels,
            &self.lookups_x,
            &self.lookups_y,
            &self.taps,
            &self.xpass,
            &self.acc,
            &self.constants,
        ]
    }
}

/// The pipelines of the build's passes and the radix plans of its transforms.
struct Passes {
    phase: ComputePipeline,
    fft: ComputePipeline,
    gather: ComputePipeline,
    taps: ComputePipeline,
    window_x: ComputePipeline,
    window_y: ComputePipeline,
    plan_x: Vec<usize>,
    plan_y: Vec<usize>,
}

impl Passes {
    fn new(
        dev: &Arc<Device>,
        layout: &ComputeLayout,
        l: &Lookups,
        precision: Precision,
    ) -> Result<Self> {
        let spirv = match precision {
            Precision::F64 => SPIRV_F64,
            Precision::F32 => SPIRV_F32,
        };
        let grid = [
            l.nx,
            l.ny,
            l.nu,
            l.nv,
            l.reach[0] as usize,
            l.reach[1] as usize,
            l.cmax as usize,
            l.rmax as usize,
        ]
        .map(|x| x as u32);
        let pipeline = |pass: Pass, name: &str| {
            let mut spec = vec![pass as u32];
            spec.extend_from_slice(&grid);
            ComputePipeline::new(
                dev,
                &format!("table build {name} ({})", precision.name()),
                layout,
                spirv,
                &spec,
            )
        };
        Ok(Self {
            phase: pipeline(Pass::Phase, "phase")?,
            fft: pipeline(Pass::Fft, "FFT stage")?,
            gather: pipeline(Pass::Gather, "gather columns")?,
            taps: pipeline(Pass::Taps, "window taps")?,
            window_x: pipeline(Pass::WindowX, "window x")?,
            window_y: pipeline(Pass::WindowY, "window y")?,
            plan_x: radices(l.nx),
            plan_y: radices(l.ny),
        })
    }
}

/// What recording one `w` node's slice reads.
struct SliceBuild<'a> {
    dev: &'a Arc<Device>,
    layout: &'a ComputeLayout,
    set: &'a StorageSet,
    passes: &'a Passes,
    lookups: &'a Lookups,
    batches: &'a Batches,
    buffers: &'a BuildBuffers,
}

/// Records the slice of `w` node `k`: the accumulator cleared, then every batch of
/// wavelengths ([`record_batch`]), then the copy of the slice to the readback buffer.
fn record_slice(s: &SliceBuild<'_>, cb: vk::CommandBuffer, k: usize) -> Result<()> {
    let dev = s.dev;
    let acc = &s.buffers.acc;
    let all = vk::AccessFlags::SHADER_READ
        | vk::AccessFlags::SHADER_WRITE
        | vk::AccessFlags::TRANSFER_READ
        | vk::AccessFlags::TRANSFER_WRITE;
    let stages = vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER;
    compute::barrier(dev, cb, (stages, all), (stages, all));
    // SAFETY: cb is recording; acc is a live buffer with TRANSFER_DST usage.
    unsafe { dev.raw().cmd_fill_buffer(cb, acc.raw, 0, vk::WHOLE_SIZE, 0) };
    compute::barrier(
        dev,
        cb,
        (
            vk::PipelineStageFlags::TRANSFER,
            vk::AccessFlags::TRANSFER_WRITE,
        ),
        (
            vk::PipelineStageFlags::COMPUTE_SHADER,
            vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE,
        ),
    );
    let (lambdas, batch) = (s.lookups.lambdas, s.batches.batch);
    for lam0 in (0..lambdas).step_by(batch) {
        let jobs = batch.min(lambdas - lam0);
        let base = Push {
            jobs: jobs as i32,
            job_base: (k * lambdas + lam0) as i32,
            lam_base: lam0 as i32,
            slot: s.batches.slot as i32,
            ..Push::default()
        };
        record_batch(s, cb, base, jobs as u64)?;
    }
    compute::copy_to_host(dev, cb, acc, &s.buffers.readback, s.buffers.acc_bytes);
    Ok(())
}

/// Records one batch of `jobs` wavelengths: the phase fields, their transforms (rows, the
/// gathered columns), the window taps and the two window passes into the slice.
fn record_batch(s: &SliceBuild<'_>, cb: vk::CommandBuffer, base: Push, jobs: u64) -> Result<()> {
    let l = s.lookups;
    let p = s.passes;
    let (nx, ny, nu, nv) = (l.nx, l.ny, l.nu, l.nv);
    let run = |pipeline: &ComputePipeline, push: Push, n: u64| -> Result<()> {
        let push = Push {
            total: u32::try_from(n).map_err(|_| {
                Error::invalid("device table build", "dispatch exceeds 2^32 invocations")
            })?,
            ..push
        };
        s.layout.dispatch(cb, pipeline, s.set, &push.bytes(), n)?;
        compute::compute_barrier(s.dev, cb);
        Ok(())
    };
    run(&p.phase, base, jobs * (nx * ny) as u64)?;
    let mut src = 0;
    // Rows: every row of every job.
    let mut ns = 1;
    for &radix in &p.plan_x {
        let push = Push {
            n: nx as i32,
            ns,
            radix: radix as i32,
            lines: ny as i32,
            axis: 0,
            src,
            ..base
        };
        run(&p.fft, push, jobs * (nx * ny) as u64)?;
        ns *= radix as i32;
        src = 1 - src;
    }
    run(
        &p.gather,
        Push { src, ..base },
        jobs * l.cmax as u64 * ny as u64,
    )?;
    src = 1 - src;
    // Columns: the gathered ones.
    let mut ns = 1;
    for &radix in &p.plan_y {
        let push = Push {
            n: ny as i32,
            ns,
            radix: radix as i32,
            lines: l.cmax as i32,
            axis: 1,
            src,
            ..base
        };
        run(&p.fft, push, jobs * l.cmax as u64 * ny as u64)?;
        ns *= radix as i32;
        src = 1 - src;
    }
    run(&p.taps, base, jobs * (nu + nv) as u64)?;
    run(
        &p.window_x,
        Push { src, ..base },
        jobs * l.rmax as u64 * nu as u64,
    )?;
    run(&p.window_y, base, (nu * nv) as u64)
}

/// The slice read back: the device stores it u-major; [`Slices`] are v-major.
fn read_slice(readback: &Buffer, l: &Lookups, precision: Precision) -> Result<Vec<[f64; 3]>> {
    let (nu, nv) = (l.nu, l.nv);
    let values = precision.read(readback.mapped()?);
    let mut slice = vec![[0.0f64; 3]; nu * nv];
    for (node, c) in values.chunks_exact(3).enumerate() {
        let (i, j) = (node / nv, node % nv);
        slice[j * nu + i] = [c[0], c[1], c[2]];
    }
    Ok(slice)
}

/// Where the table variants sample `G` (`--table-build`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, clap::ValueEnum)]
#[value(rename_all = "kebab-case")]
pub enum TableBuild {
    /// The device when it is a GPU (discrete, integrated or virtual), the CPU when the
    /// Vulkan device itself runs on the CPU (lavapipe), where the CPU build is faster.
    #[default]
    Auto,
    /// The CPU, its sums in float32 (the fast build; its report states its measured
    /// difference from float64).
    Cpu,
    /// The CPU in float64 throughout (the reference).
    CpuF64,
    /// The device: float64 where it has shaderFloat64, else float32.
    Device,
    /// The device in float32, even where it has float64 (to measure float32's error).
    DeviceF32,
}

impl TableBuild {
    /// The device precision this choice builds in on `dev`; `None`: the CPU.
    pub fn on(self, dev: &Device) -> Option<Precision> {
        match self {
            TableBuild::Cpu | TableBuild::CpuF64 => None,
            TableBuild::Device => Some(Precision::best(dev)),
            TableBuild::DeviceF32 => Some(Precision::F32),
            TableBuild::Auto => {
                (dev.info.device_type != vk::PhysicalDeviceType::CPU).then(|| Precision::best(dev))
            }
        }
    }
}

/// How a table's samples were obtained, for the render and profile reports.
#[derive(Debug, Clone, PartialEq)]
pub enum Built {
    /// Built on the CPU in `seconds`; `probe`: a float32 build's largest difference from
    /// float64 over its probe, relative to the probe's peak (`None`: built in float64).
    Cpu { seconds: f64, probe: Option<f64> },
    /// Built on the device `device` in `precision`, in `seconds`.
    Device {
        device: String,
        precision: Precision,
        seconds: f64,
    },
    /// Loaded from the table cache.
    Cached,
}

impl std::fmt::Display for Built {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Built::Cpu {
                seconds,
                probe: Some(e),
            } => write!(
                f,
                "built on CPU (f32 sums, within {e:.1e} of f64 at its peak) in {seconds:.1} s"
            ),
            Built::Cpu {
                seconds,
                probe: None,
            } => write!(f, "built on CPU (f64) in {seconds:.1} s"),
            Built::Device {
                device,
                precision,
                seconds,
            } => {
                // The driver's name up to its first parenthesis ("llvmpipe (LLVM …)").
                let short = device.split(" (").next().unwrap_or(device).trim();
                write!(
                    f,
                    "built on device ({short}, {}) in {seconds:.1} s",
                    precision.name()
                )
            }
            Built::Cached => f.write_str("loaded from cache"),
        }
    }
}

/// The one line every table's report prints, the sun-lit variants' (`table: …`) and the
/// environment's (`environment table: …`) alike: what it holds in the variants' notation
/// (`chebyshev-w K=12 440×997 texel 0.0027 dλ=2 …`), how its samples were obtained
/// ([`Built`], and what came after), its size, then anything particular to it after a `;`.
pub struct TableLine {
    pub label: &'static str,
    pub holds: String,
    pub origin: String,
    pub bytes: usize,
    /// What the bytes are, when not the device's copy (`float32 planes`).
    pub bytes_of: Option<&'static str>,
    pub extra: Option<String>,
}

impl std::fmt::Display for TableLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mb = self.bytes as f64 / 1e6;
        write!(
            f,
            "{}: {}, {}, {mb:.1} MB",
            self.label, self.holds, self.origin
        )?;
        if let Some(of) = self.bytes_of {
            write!(f, " ({of})")?;
        }
        if let Some(extra) = &self.extra {
            write!(f, "; {extra}")?;
        }
        Ok(())
    }
}

/// Samples `G` where `build` says (on `dev` or on the CPU), through the table cache in
/// `dir`. A float64 device build shares the CPU build's cache files: the two agree to
/// ~1e-13 of the slice peak (tests/gpu_table_build.rs), far below the files' float32
/// rounding (6e-8); a float32 device build is cached apart.
#[allow(clippy::too_many_arguments)]
pub fn sample_g_built(
    dev: &Arc<Device>,
    build: TableBuild,
    hf: &HeightField,
    coherence_um: f64,
    spec: &TableSpec,
    w_nodes: &[f64],
    keep: Option<&[usize]>,
    dir: Option<&std::path::Path>,
    report: &dyn crate::report::Report,
    progress: &(dyn Fn() + Sync),
) -> Result<(Slices, Built)> {
    let precision = build.on(dev);
    let start = std::time::Instant::now();
    let sums = match build {
        TableBuild::CpuF64 => crate::brdf::truncation::Precision::F64,
        _ => crate::brdf::truncation::Precision::F32,
    };
    // The fast build's probe, out of the closure the cache calls on a miss.
    let probe = std::cell::Cell::new(None);
    let make = || match precision {
        None => {
            let s = crate::brdf::table::sample_g_kept_in(
                hf,
                coherence_um,
                spec,
                w_nodes,
                keep,
                sums,
                progress,
            )?;
            probe.set(s.probe);
            Ok(s.slices)
        }
        Some(p) => sample_g_device(dev, hf, coherence_um, spec, w_nodes, keep, p, progress),
    };
    let tag = match (precision, sums) {
        (Some(Precision::F32), _) => Some("device f32"),
        (None, crate::brdf::truncation::Precision::F32) => Some("cpu f32 sums"),
        _ => None,
    };
    let (slices, cached) = crate::brdf::table_cache::sample_g_cached_by(
        hf,
        coherence_um,
        spec,
        w_nodes,
        keep,
        dir,
        tag,
        report,
        &make,
    )?;
    let seconds = start.elapsed().as_secs_f64();
    let built = match (cached, precision) {
        (true, _) => Built::Cached,
        (false, None) => Built::Cpu {
            seconds,
            probe: probe.get(),
        },
        (false, Some(precision)) => Built::Device {
            device: dev.info.name.clone(),
            precision,
            seconds,
        },
    };
    Ok((slices, built))
}

/// Runs the device FFT alone (the Stockham stages of the build) on `batch` rows of length
/// `n` in `precision`, for tests against a reference FFT: the `+i` transform without
/// normalisation, in place of `rows` (interleaved re, im).
pub fn fft_rows_device(
    dev: &Arc<Device>,
    n: usize,
    rows: &mut [f64],
    precision: Precision,
) -> Result<()> {
    let lines = rows.len() / (2 * n);
    if lines == 0 || rows.len() != 2 * n * lines {
        return Err(Error::invalid(
            "device FFT",
            "rows must hold whole lines of n complex values",
        ));
    }
    let cplx = 2 * precision.real_bytes();
    let bytes = (n * lines) as u64 * cplx;
    let field_a = compute::storage_with_data(dev, "fft test field A", &precision.reals(rows))?;
    let field_b = compute::storage(dev, "fft test field B", bytes)?;
    let tw = compute::storage_with_data(dev, "fft test twiddles", &precision.reals(&twiddles(n)))?;
    let dummy = compute::storage(dev, "fft test unused", 64)?;
    let readback = Buffer::new(
        dev,
        "fft test readback",
        bytes,
        vk::BufferUsageFlags::TRANSFER_DST,
        MemoryLocation::GpuToCpu,
    )?;
    let layout = ComputeLayout::new(dev, "fft test", BINDINGS, Push::BYTES)?;
    let set = StorageSet::new(
        dev,
        "fft test",
        &layout,
        &[
            &dummy, &field_a, &field_b, &tw, &tw, &dummy, &dummy, &dummy, &dummy, &dummy, &dummy,
            &dummy, &dummy,
        ],
    )?;
    let spirv = match precision {
        Precision::F64 => SPIRV_F64,
        Precision::F32 => SPIRV_F32,
    };
    let spec = [Pass::Fft as u32, n as u32, lines as u32, 1, 1, 0, 0, 1, 1];
    let fft = ComputePipeline::new(dev, "fft test stage", &layout, spirv, &spec)?;
    let mut src = 0;
    dev.submit_once("fft test", |cb| {
        let mut ns = 1;
        for radix in radices(n) {
            let push = Push {
                total: (n * lines) as u32,
                n: n as i32,
                ns,
                radix: radix as i32,
                lines: lines as i32,
                axis: 0,
                src,
                jobs: 1,
                slot: (n * lines) as i32,
                ..Push::default()
            };
            layout.dispatch(cb, &fft, &set, &push.bytes(), (n * lines) as u64)?;
            compute::compute_barrier(dev, cb);
            ns *= radix as i32;
            src = 1 - src;
        }
        let from = if src == 0 { &field_a } else { &field_b };
        compute::copy_to_host(dev, cb, from, &readback, bytes);
        Ok(())
    })?;
    rows.copy_from_slice(&precision.read(readback.mapped()?));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radices_multiply_to_the_length() {
        for n in [
            1usize,
            2,
            3,
            5,
            7,
            11,
            13,
            17,
            64,
            96,
            704,
            960,
            1009,
            2 * 17 * 19,
        ] {
            let r = radices(n);
            assert_eq!(r.iter().product::<usize>(), n.max(1), "{n}: {r:?}");
        }
        assert_eq!(radices(960), vec![4, 4, 4, 3, 5]);
        assert_eq!(radices(704), vec![4, 4, 4, 11]);
        assert_eq!(radices(96), vec![4, 4, 2, 3]);
    }
}
