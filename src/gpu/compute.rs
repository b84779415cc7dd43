//! Compute plumbing: a compute pipeline layout over storage buffers (bindings `0..n` of
//! set 0, or of the set after the caller's own) with one push-constant range, compute pipelines specialised by constants, the
//! descriptor set that points the bindings at buffers, device-local buffers filled through
//! a staging copy, and the recording helpers (dispatch over a 1D range of invocations,
//! barriers). Knows Vulkan, not what the shaders compute.

use std::io::Cursor;
use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::context::Device;
use super::memory::Buffer;
use super::pipeline::DescriptorSet;
use crate::{Error, Result};

/// Invocations per workgroup that [`ComputeLayout::dispatch`] assumes
/// (`local_size_x` of the shaders; y and z are 1).
pub const LOCAL_SIZE: u32 = 64;

/// A descriptor-set layout of `bindings` storage buffers (compute stage) and the pipeline
/// layout with one push-constant range of `push_bytes`; the storage set is set 0, or comes
/// after sets the caller owns ([`ComputeLayout::after`]).
pub struct ComputeLayout {
    dev: Arc<Device>,
    set_layout: vk::DescriptorSetLayout,
    raw: vk::PipelineLayout,
    bindings: u32,
    push_bytes: u32,
    /// The storage set's index: the number of sets before it.
    first_set: u32,
}

impl ComputeLayout {
    pub fn new(dev: &Arc<Device>, name: &str, bindings: u32, push_bytes: u32) -> Result<Self> {
        Self::after(dev, name, &[], bindings, push_bytes)
    }

    /// A layout whose sets `0..leading.len()` are the caller's (bound with
    /// [`ComputeLayout::dispatch_after`]) and whose storage set follows them.
    pub fn after(
        dev: &Arc<Device>,
        name: &str,
        leading: &[vk::DescriptorSetLayout],
        bindings: u32,
        push_bytes: u32,
    ) -> Result<Self> {
        let vk_bindings: Vec<_> = (0..bindings)
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let info = vk::DescriptorSetLayoutCreateInfo::default().bindings(&vk_bindings);
        // SAFETY: live device, valid create info.
        let set_layout = unsafe { dev.raw.create_descriptor_set_layout(&info, None) }
            .map_err(Error::vk("vkCreateDescriptorSetLayout"))?;
        let mut layout = Self {
            dev: dev.clone(),
            set_layout,
            raw: vk::PipelineLayout::null(),
            bindings,
            push_bytes,
            first_set: leading.len() as u32,
        };
        dev.set_name(set_layout, name);
        let set_layouts: Vec<_> = leading.iter().copied().chain([set_layout]).collect();
        let ranges = [vk::PushConstantRange {
            stage_flags: vk::ShaderStageFlags::COMPUTE,
            offset: 0,
            size: push_bytes,
        }];
        let mut info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
        if push_bytes > 0 {
            info = info.push_constant_ranges(&ranges);
        }
        // SAFETY: the set layout is live; callers keep push_bytes within 128 (the minimum
        // maxPushConstantsSize).
        layout.raw = unsafe { dev.raw.create_pipeline_layout(&info, None) }
            .map_err(Error::vk("vkCreatePipelineLayout"))?;
        dev.set_name(layout.raw, name);
        Ok(layout)
    }

    /// Records `pipeline` over `invocations` invocations (workgroups of [`LOCAL_SIZE`],
    /// spread over x and y when x would exceed 65 535 groups; the shader recovers the flat
    /// index and skips those past the end), with `set` bound and `push` as push constants.
    pub fn dispatch(
        &self,
        cb: vk::CommandBuffer,
        pipeline: &ComputePipeline,
        set: &StorageSet,
        push: &[u8],
        invocations: u64,
    ) -> Result<()> {
        self.dispatch_after(cb, pipeline, &[], set, push, invocations)
    }

    /// [`ComputeLayout::dispatch`] with the caller's sets `leading` bound before the
    /// storage set (one per leading layout of [`ComputeLayout::after`]).
    pub fn dispatch_after(
        &self,
        cb: vk::CommandBuffer,
        pipeline: &ComputePipeline,
        leading: &[vk::DescriptorSet],
        set: &StorageSet,
        push: &[u8],
        invocations: u64,
    ) -> Result<()> {
        if leading.len() as u32 != self.first_set {
            return Err(Error::invalid(
                "compute dispatch",
                format!(
                    "{} sets before the storage set, layout has {}",
                    leading.len(),
                    self.first_set
                ),
            ));
        }
        if push.len() as u32 != self.push_bytes {
            return Err(Error::invalid(
                "compute dispatch",
                format!(
                    "{} push-constant bytes, layout has {}",
                    push.len(),
                    self.push_bytes
                ),
            ));
        }
        let groups = invocations.div_ceil(u64::from(LOCAL_SIZE));
        let x = groups.clamp(1, 65_535);
        let y = groups.div_ceil(x);
        if y > 65_535 {
            return Err(Error::invalid(
                "compute dispatch",
                format!("{invocations} invocations exceed 65 535² workgroups"),
            ));
        }
        let raw = &self.dev.raw;
        // SAFETY: cb is recording; pipeline and set were made for this layout and outlive
        // the submission (callers wait before dropping them); push matches the range.
        unsafe {
            raw.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, pipeline.raw);
            raw.cmd_bind_descriptor_sets(
                cb,
                vk::PipelineBindPoint::COMPUTE,
                self.raw,
                0,
                &leading
                    .iter()
                    .copied()
                    .chain([set.set.raw])
                    .collect::<Vec<_>>(),
                &[],
            );
            if !push.is_empty() {
                raw.cmd_push_constants(cb, self.raw, vk::ShaderStageFlags::COMPUTE, 0, push);
            }
            raw.cmd_dispatch(cb, x as u32, y as u32, 1);
        }
        Ok(())
    }
}

impl Drop for ComputeLayout {
    fn drop(&mut self) {
        // SAFETY: pipelines and sets made with this layout are gone or idle.
        unsafe {
            if self.raw != vk::PipelineLayout::null() {
                self.dev.raw.destroy_pipeline_layout(self.raw, None);
            }
            self.dev
                .raw
                .destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

/// A compute pipeline from SPIR-V bytes (entry `main`), specialised by constants
/// `constant_id = i` ↦ `spec[i]` (32-bit each).
pub struct ComputePipeline {
    dev: Arc<Device>,
    raw: vk::Pipeline,
}

impl ComputePipeline {
    pub fn new(
        dev: &Arc<Device>,
        name: &str,
        layout: &ComputeLayout,
        spirv: &[u8],
        spec: &[u32],
    ) -> Result<Self> {
        let words = ash::util::read_spv(&mut Cursor::new(spirv))
            .map_err(|e| Error::invalid("SPIR-V", format!("{name}: {e}")))?;
        let info = vk::ShaderModuleCreateInfo::default().code(&words);
        // SAFETY: words is a complete SPIR-V module compiled by build.rs.
        let module = unsafe { dev.raw.create_shader_module(&info, None) }
            .map_err(Error::vk("vkCreateShaderModule"))?;
        dev.set_name(module, name);
        let entries: Vec<_> = (0..spec.len() as u32)
            .map(|i| vk::SpecializationMapEntry {
                constant_id: i,
                offset: 4 * i,
                size: 4,
            })
            .collect();
        let spec_bytes: Vec<u8> = spec.iter().flat_map(|v| v.to_le_bytes()).collect();
        let spec_info = vk::SpecializationInfo::default()
            .map_entries(&entries)
            .data(&spec_bytes);
        let stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module)
            .name(c"main")
            .specialization_info(&spec_info);
        let info = vk::ComputePipelineCreateInfo::default()
            .stage(stage)
            .layout(layout.raw);
        // SAFETY: module and layout are live; the spec data outlives the call.
        let result = unsafe {
            dev.raw
                .create_compute_pipelines(vk::PipelineCache::null(), &[info], None)
        };
        // SAFETY: the module is only needed during pipeline creation.
        unsafe { dev.raw.destroy_shader_module(module, None) };
        let raw = result.map_err(|(_, e)| Error::vk("vkCreateComputePipelines")(e))?[0];
        dev.set_name(raw, name);
        Ok(Self {
            dev: dev.clone(),
            raw,
        })
    }
}

impl Drop for ComputePipeline {
    fn drop(&mut self) {
        // SAFETY: no pending GPU work uses the pipeline (submissions are waited on).
        unsafe { self.dev.raw.destroy_pipeline(self.raw, None) };
    }
}

/// One descriptor set of a [`ComputeLayout`] with its own pool, binding `i` pointing at
/// the whole of `buffers[i]`.
pub struct StorageSet {
    set: DescriptorSet,
}

impl StorageSet {
    pub fn new(
        dev: &Arc<Device>,
        name: &str,
        layout: &ComputeLayout,
        buffers: &[&Buffer],
    ) -> Result<Self> {
        if buffers.len() as u32 != layout.bindings {
            return Err(Error::invalid(
                "storage set",
                format!("{} buffers for {} bindings", buffers.len(), layout.bindings),
            ));
        }
        let sizes = [vk::DescriptorPoolSize {
            ty: vk::DescriptorType::STORAGE_BUFFER,
            descriptor_count: layout.bindings,
        }];
        let set = DescriptorSet::allocate(dev, name, layout.set_layout, &sizes)?;
        let infos: Vec<[vk::DescriptorBufferInfo; 1]> = buffers
            .iter()
            .map(|b| {
                [vk::DescriptorBufferInfo {
                    buffer: b.raw,
                    offset: 0,
                    range: vk::WHOLE_SIZE,
                }]
            })
            .collect();
        let writes: Vec<_> = infos
            .iter()
            .enumerate()
            .map(|(i, info)| {
                vk::WriteDescriptorSet::default()
                    .dst_set(set.raw)
                    .dst_binding(i as u32)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .buffer_info(info)
            })
            .collect();
        // SAFETY: the infos outlive the call; the buffers are live storage buffers.
        unsafe { dev.raw.update_descriptor_sets(&writes, &[]) };
        Ok(Self { set })
    }
}

/// A device-local storage buffer holding `bytes` (copied through a staging buffer; the
/// copy has finished when this returns; it can be copied from). Empty data still makes a
/// 4-byte buffer.
pub fn storage_with_data(dev: &Arc<Device>, name: &str, bytes: &[u8]) -> Result<Buffer> {
    let size = (bytes.len() as u64).max(4);
    let buffer = Buffer::new(
        dev,
        name,
        size,
        vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::TRANSFER_DST
            | vk::BufferUsageFlags::TRANSFER_SRC,
        MemoryLocation::GpuOnly,
    )?;
    if bytes.is_empty() {
        return Ok(buffer);
    }
    let staging = Buffer::with_data(
        dev,
        &format!("{name} staging"),
        vk::BufferUsageFlags::TRANSFER_SRC,
        bytes,
    )?;
    dev.submit_once(&format!("upload {name}"), |cb| {
        let region = vk::BufferCopy {
            src_offset: 0,
            dst_offset: 0,
            size: bytes.len() as u64,
        };
        // SAFETY: cb is recording; both buffers are live and large enough.
        unsafe {
            dev.raw
                .cmd_copy_buffer(cb, staging.raw, buffer.raw, &[region]);
        }
        barrier(
            dev,
            cb,
            (
                vk::PipelineStageFlags::TRANSFER,
                vk::AccessFlags::TRANSFER_WRITE,
            ),
            (
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::AccessFlags::SHADER_READ,
            ),
        );
        Ok(())
    })?;
    Ok(buffer)
}

/// A device-local storage buffer of `size` bytes whose contents the shaders write (it can
/// also be filled and copied from).
pub fn storage(dev: &Arc<Device>, name: &str, size: u64) -> Result<Buffer> {
    Buffer::new(
        dev,
        name,
        size.max(4),
        vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::TRANSFER_DST
            | vk::BufferUsageFlags::TRANSFER_SRC,
        MemoryLocation::GpuOnly,
    )
}

/// A global memory barrier between `src` and `dst` (stage, access) pairs.
pub fn barrier(
    dev: &Device,
    cb: vk::CommandBuffer,
    src: (vk::PipelineStageFlags, vk::AccessFlags),
    dst: (vk::PipelineStageFlags, vk::AccessFlags),
) {
    let mb = [vk::MemoryBarrier::default()
        .src_access_mask(src.1)
        .dst_access_mask(dst.1)];
    // SAFETY: cb is recording (callers only call this while recording).
    unsafe {
        dev.raw.cmd_pipeline_barrier(
            cb,
            src.0,
            dst.0,
            vk::DependencyFlags::empty(),
            &mb,
            &[],
            &[],
        );
    }
}

/// Records the copy of the first `bytes` of `from`, written by compute shaders, into the
/// host-visible `to`, with the barriers before (shader writes → transfer) and after
/// (transfer → host read): once the submission has finished, the host reads `to`.
pub fn copy_to_host(dev: &Device, cb: vk::CommandBuffer, from: &Buffer, to: &Buffer, bytes: u64) {
    barrier(
        dev,
        cb,
        (
            vk::PipelineStageFlags::COMPUTE_SHADER,
            vk::AccessFlags::SHADER_WRITE,
        ),
        (
            vk::PipelineStageFlags::TRANSFER,
            vk::AccessFlags::TRANSFER_READ,
        ),
    );
    let region = vk::BufferCopy {
        src_offset: 0,
        dst_offset: 0,
        size: bytes,
    };
    // SAFETY: cb is recording; both buffers are live and at least `bytes` long.
    unsafe { dev.raw.cmd_copy_buffer(cb, from.raw, to.raw, &[region]) };
    barrier(
        dev,
        cb,
        (
            vk::PipelineStageFlags::TRANSFER,
            vk::AccessFlags::TRANSFER_WRITE,
        ),
        (vk::PipelineStageFlags::HOST, vk::AccessFlags::HOST_READ),
    );
}

/// The barrier between two compute dispatches where the second reads or overwrites what
/// the first wrote.
pub fn compute_barrier(dev: &Device, cb: vk::CommandBuffer) {
    let rw = vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE;
    barrier(
        dev,
        cb,
        (vk::PipelineStageFlags::COMPUTE_SHADER, rw),
        (vk::PipelineStageFlags::COMPUTE_SHADER, rw),
    );
}

/// Largest storage-buffer range a descriptor may cover on this device (bytes).
pub fn max_storage_range(dev: &Device) -> u64 {
    // SAFETY: the physical device belongs to the live instance.
    let props = unsafe {
        dev.instance()
            .raw
            .get_physical_device_properties(dev.physical())
    };
    u64::from(props.limits.max_storage_buffer_range)
}
