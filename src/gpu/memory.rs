//! GPU memory objects with RAII: buffers, images (with one view) and samplers. Each owns its
//! gpu-allocator allocation and frees it explicitly in `Drop` after destroying the handle.
//! Also the plain-old-data byte views used to fill them. No knowledge of what the bytes mean.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::context::Device;
use crate::{Error, Result};

/// Types whose every byte is initialised data (no padding, no pointers), so a slice of them
/// may be viewed as bytes.
///
/// # Safety
/// Implementors must be `repr(C)` (or primitive) without padding bytes.
pub unsafe trait Pod: Copy {}

// SAFETY: primitives and arrays of primitives have no padding.
unsafe impl Pod for u8 {}
// SAFETY: as above.
unsafe impl Pod for u16 {}
// SAFETY: as above.
unsafe impl Pod for u32 {}
// SAFETY: as above.
unsafe impl Pod for i32 {}
// SAFETY: as above.
unsafe impl Pod for f32 {}
// SAFETY: arrays of Pod have no padding between elements.
unsafe impl<T: Pod, const N: usize> Pod for [T; N] {}

/// The bytes of a slice of plain-old-data values.
pub fn bytes_of<T: Pod>(data: &[T]) -> &[u8] {
    // SAFETY: T: Pod has no padding, so all size_of_val bytes are initialised; u8 has
    // alignment 1 and the lifetime is tied to `data`.
    unsafe { std::slice::from_raw_parts(data.as_ptr().cast::<u8>(), std::mem::size_of_val(data)) }
}

fn allocate(
    dev: &Device,
    name: &str,
    requirements: vk::MemoryRequirements,
    location: MemoryLocation,
    linear: bool,
) -> Result<Allocation> {
    Ok(dev.allocator().allocate(&AllocationCreateDesc {
        name,
        requirements,
        location,
        linear,
        allocation_scheme: AllocationScheme::GpuAllocatorManaged,
    })?)
}

fn free(dev: &Device, allocation: Option<Allocation>) {
    if let Some(a) = allocation {
        if let Err(e) = dev.allocator().free(a) {
            eprintln!("diffract: freeing GPU memory failed: {e}");
        }
    }
}

/// A buffer with its own allocation.
pub struct Buffer {
    dev: Arc<Device>,
    pub raw: vk::Buffer,
    pub size: u64,
    allocation: Option<Allocation>,
}

impl Buffer {
    /// Creates a buffer of `size` bytes in `location` (`CpuToGpu`/`GpuToCpu` are mapped).
    pub fn new(
        dev: &Arc<Device>,
        name: &str,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
    ) -> Result<Self> {
        let info = vk::BufferCreateInfo::default()
            .size(size.max(4))
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: live device, valid create info.
        let raw =
            unsafe { dev.raw.create_buffer(&info, None) }.map_err(Error::vk("vkCreateBuffer"))?;
        let mut buffer = Buffer {
            dev: dev.clone(),
            raw,
            size,
            allocation: None,
        };
        dev.set_name(raw, name);
        // SAFETY: raw is a live buffer of this device.
        let req = unsafe { dev.raw.get_buffer_memory_requirements(raw) };
        let allocation = allocate(dev, name, req, location, true)?;
        // SAFETY: the allocation satisfies req and is bound once, before any use.
        unsafe {
            dev.raw
                .bind_buffer_memory(raw, allocation.memory(), allocation.offset())
        }
        .map_err(Error::vk("vkBindBufferMemory"))?;
        buffer.allocation = Some(allocation);
        Ok(buffer)
    }

    /// A host-visible buffer filled with `data`.
    pub fn with_data<T: Pod>(
        dev: &Arc<Device>,
        name: &str,
        usage: vk::BufferUsageFlags,
        data: &[T],
    ) -> Result<Self> {
        let bytes = bytes_of(data);
        let mut b = Self::new(
            dev,
            name,
            bytes.len() as u64,
            usage,
            MemoryLocation::CpuToGpu,
        )?;
        b.write(bytes)?;
        Ok(b)
    }

    /// Copies `bytes` to the start of a mapped buffer.
    pub fn write(&mut self, bytes: &[u8]) -> Result<()> {
        self.write_at(0, bytes)
    }

    /// Copies `bytes` into the mapped memory from byte `offset` (host-visible buffers only).
    pub fn write_at(&mut self, offset: usize, bytes: &[u8]) -> Result<()> {
        let slice = self
            .allocation
            .as_mut()
            .and_then(|a| a.mapped_slice_mut())
            .ok_or_else(|| Error::invalid("buffer write", "the buffer is not host-visible"))?;
        let end = offset
            .checked_add(bytes.len())
            .filter(|&e| e <= slice.len());
        let Some(end) = end else {
            return Err(Error::invalid(
                "buffer write",
                format!(
                    "{} bytes at {offset} into a {}-byte buffer",
                    bytes.len(),
                    slice.len()
                ),
            ));
        };
        slice[offset..end].copy_from_slice(bytes);
        Ok(())
    }

    /// The contents of a mapped buffer (valid after the GPU writes are complete and made
    /// visible to the host).
    pub fn mapped(&self) -> Result<&[u8]> {
        let slice = self
            .allocation
            .as_ref()
            .and_then(|a| a.mapped_slice())
            .ok_or_else(|| Error::invalid("buffer read", "the buffer is not host-visible"))?;
        Ok(&slice[..(self.size as usize).min(slice.len())])
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        // SAFETY: no pending GPU work uses the buffer: users wait for their submissions, or
        // retire the owner through the frames' deferred release.
        unsafe { self.dev.raw.destroy_buffer(self.raw, None) };
        free(&self.dev, self.allocation.take());
    }
}

/// How to create an [`Image`].
#[derive(Debug, Clone, Copy)]
pub struct ImageDesc {
    pub format: vk::Format,
    pub width: u32,
    pub height: u32,
    /// Array layers (1 for a plain 2D image), or the depth of a 3D image.
    pub layers: u32,
    pub usage: vk::ImageUsageFlags,
    pub aspect: vk::ImageAspectFlags,
    /// `TYPE_2D`, `TYPE_2D_ARRAY` or `TYPE_3D`.
    pub view_type: vk::ImageViewType,
}

impl ImageDesc {
    fn is_3d(&self) -> bool {
        self.view_type == vk::ImageViewType::TYPE_3D
    }

    /// Extent of mip level 0 (depth 1 unless 3D).
    fn extent(&self) -> vk::Extent3D {
        vk::Extent3D {
            width: self.width,
            height: self.height,
            depth: if self.is_3d() { self.layers } else { 1 },
        }
    }

    /// Array layers of the image (1 for 3D).
    fn array_layers(&self) -> u32 {
        if self.is_3d() {
            1
        } else {
            self.layers
        }
    }
}

/// A 2D (array) or 3D image with one view covering all of it (every mip level), in GPU
/// memory.
pub struct Image {
    dev: Arc<Device>,
    pub raw: vk::Image,
    pub view: vk::ImageView,
    pub desc: ImageDesc,
    /// Mip levels: 1, or a chain that halves each side down to 1×1.
    mips: u32,
    allocation: Option<Allocation>,
}

impl Image {
    pub fn new(dev: &Arc<Device>, name: &str, desc: ImageDesc) -> Result<Self> {
        Self::with_mips(dev, name, desc, 1)
    }

    /// An image of `mips` levels, level `k` `max(1, width >> k) × max(1, height >> k)`.
    fn with_mips(dev: &Arc<Device>, name: &str, desc: ImageDesc, mips: u32) -> Result<Self> {
        let image_type = if desc.is_3d() {
            vk::ImageType::TYPE_3D
        } else {
            vk::ImageType::TYPE_2D
        };
        let info = vk::ImageCreateInfo::default()
            .image_type(image_type)
            .format(desc.format)
            .extent(desc.extent())
            .mip_levels(mips)
            .array_layers(desc.array_layers())
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(desc.usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: live device; callers checked format support and limits.
        let raw =
            unsafe { dev.raw.create_image(&info, None) }.map_err(Error::vk("vkCreateImage"))?;
        let mut image = Image {
            dev: dev.clone(),
            raw,
            view: vk::ImageView::null(),
            desc,
            mips,
            allocation: None,
        };
        dev.set_name(raw, name);
        // SAFETY: raw is a live image of this device.
        let req = unsafe { dev.raw.get_image_memory_requirements(raw) };
        let allocation = allocate(dev, name, req, MemoryLocation::GpuOnly, false)?;
        // SAFETY: the allocation satisfies req and is bound once, before any use.
        unsafe {
            dev.raw
                .bind_image_memory(raw, allocation.memory(), allocation.offset())
        }
        .map_err(Error::vk("vkBindImageMemory"))?;
        image.allocation = Some(allocation);
        let view_info = vk::ImageViewCreateInfo::default()
            .image(raw)
            .view_type(desc.view_type)
            .format(desc.format)
            .subresource_range(image.range());
        // SAFETY: the image is bound to memory; the range lies within it.
        image.view = unsafe { dev.raw.create_image_view(&view_info, None) }
            .map_err(Error::vk("vkCreateImageView"))?;
        dev.set_name(image.view, name);
        Ok(image)
    }

    /// All mip levels and layers of the image.
    pub fn range(&self) -> vk::ImageSubresourceRange {
        vk::ImageSubresourceRange {
            aspect_mask: self.desc.aspect,
            base_mip_level: 0,
            level_count: self.mips,
            base_array_layer: 0,
            layer_count: self.desc.array_layers(),
        }
    }

    /// Creates a sampled image and fills it from `bytes` (tightly packed texels of
    /// `texel_bytes` each, layer after layer) through a staging buffer; the image ends in
    /// `SHADER_READ_ONLY_OPTIMAL`.
    pub fn sampled_with_data(
        dev: &Arc<Device>,
        name: &str,
        desc: ImageDesc,
        texel_bytes: usize,
        bytes: &[u8],
    ) -> Result<Self> {
        Self::sampled_with_mips(dev, name, desc, texel_bytes, &[bytes])
    }

    /// [`Self::sampled_with_data`] for a mip chain: `levels[k]` holds level `k`'s texels
    /// (`max(1, width >> k) × max(1, height >> k)`, layer after layer), the image first.
    pub fn sampled_with_mips(
        dev: &Arc<Device>,
        name: &str,
        mut desc: ImageDesc,
        texel_bytes: usize,
        levels: &[&[u8]],
    ) -> Result<Self> {
        let size = |k: usize| ((desc.width >> k).max(1), (desc.height >> k).max(1));
        let mut offsets = Vec::with_capacity(levels.len());
        let mut total = 0usize;
        for (k, bytes) in levels.iter().enumerate() {
            let (w, h) = size(k);
            let expected = w as usize * h as usize * desc.layers as usize * texel_bytes;
            if bytes.len() != expected {
                // The copy would read past the staging buffer (or leave texels undefined).
                return Err(Error::invalid(
                    "image upload",
                    format!(
                        "{name}: {} bytes for level {k}'s {w}×{h}×{} texels of {texel_bytes} bytes",
                        bytes.len(),
                        desc.layers
                    ),
                ));
            }
            offsets.push(total);
            total += bytes.len();
        }
        let full = 32 - desc.width.max(desc.height).max(1).leading_zeros();
        if levels.is_empty() || levels.len() as u32 > full || (levels.len() > 1 && desc.is_3d()) {
            return Err(Error::invalid(
                "image upload",
                format!("{name}: {} mip levels of {full}", levels.len()),
            ));
        }
        desc.usage |= vk::ImageUsageFlags::SAMPLED | vk::ImageUsageFlags::TRANSFER_DST;
        let image = Image::with_mips(dev, name, desc, levels.len() as u32)?;
        // Each level straight into the mapped staging memory, at its offset.
        let mut staging = Buffer::new(
            dev,
            &format!("{name} staging"),
            total as u64,
            vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::CpuToGpu,
        )?;
        for (bytes, &at) in levels.iter().zip(&offsets) {
            staging.write_at(at, bytes)?;
        }
        let range = image.range();
        dev.submit_once(&format!("upload {name}"), |cb| {
            let to_dst = vk::ImageMemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::empty())
                .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .old_layout(vk::ImageLayout::UNDEFINED)
                .new_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(image.raw)
                .subresource_range(range);
            let regions: Vec<vk::BufferImageCopy> = offsets
                .iter()
                .enumerate()
                .map(|(k, &at)| {
                    let (w, h) = size(k);
                    vk::BufferImageCopy::default()
                        .buffer_offset(at as u64)
                        .image_subresource(vk::ImageSubresourceLayers {
                            aspect_mask: desc.aspect,
                            mip_level: k as u32,
                            base_array_layer: 0,
                            layer_count: desc.array_layers(),
                        })
                        .image_extent(vk::Extent3D {
                            width: w,
                            height: h,
                            ..desc.extent()
                        })
                })
                .collect();
            let to_read = vk::ImageMemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(vk::AccessFlags::SHADER_READ)
                .old_layout(vk::ImageLayout::TRANSFER_DST_OPTIMAL)
                .new_layout(vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(image.raw)
                .subresource_range(range);
            // SAFETY: cb is recording; the staging buffer holds every level's texels
            // (checked above) and outlives the submission.
            unsafe {
                dev.raw.cmd_pipeline_barrier(
                    cb,
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[to_dst],
                );
                dev.raw.cmd_copy_buffer_to_image(
                    cb,
                    staging.raw,
                    image.raw,
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    &regions,
                );
                dev.raw.cmd_pipeline_barrier(
                    cb,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::PipelineStageFlags::FRAGMENT_SHADER,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[to_read],
                );
            }
            Ok(())
        })?;
        Ok(image)
    }
}

impl Drop for Image {
    fn drop(&mut self) {
        // SAFETY: GPU work using the image finished (waited for, or the owner was retired
        // through the frames' deferred release); view before image.
        unsafe {
            if self.view != vk::ImageView::null() {
                self.dev.raw.destroy_image_view(self.view, None);
            }
            self.dev.raw.destroy_image(self.raw, None);
        }
        free(&self.dev, self.allocation.take());
    }
}

/// A sampler.
pub struct Sampler {
    dev: Arc<Device>,
    pub raw: vk::Sampler,
}

impl Sampler {
    /// `filter` for both magnification and minification, `address` on every axis; the
    /// image's first mip level alone.
    pub fn new(
        dev: &Arc<Device>,
        name: &str,
        filter: vk::Filter,
        address: vk::SamplerAddressMode,
    ) -> Result<Self> {
        Self::create(dev, name, filter, address, false)
    }

    /// Linear filtering between texels and between mip levels (trilinear), `address` on
    /// every axis: a pixel reads the mip level of its footprint.
    pub fn trilinear(
        dev: &Arc<Device>,
        name: &str,
        address: vk::SamplerAddressMode,
    ) -> Result<Self> {
        Self::create(dev, name, vk::Filter::LINEAR, address, true)
    }

    fn create(
        dev: &Arc<Device>,
        name: &str,
        filter: vk::Filter,
        address: vk::SamplerAddressMode,
        mips: bool,
    ) -> Result<Self> {
        let (mode, max_lod) = if mips {
            (vk::SamplerMipmapMode::LINEAR, vk::LOD_CLAMP_NONE)
        } else {
            (vk::SamplerMipmapMode::NEAREST, 0.0)
        };
        let info = vk::SamplerCreateInfo::default()
            .mag_filter(filter)
            .min_filter(filter)
            .mipmap_mode(mode)
            .address_mode_u(address)
            .address_mode_v(address)
            .address_mode_w(address)
            .max_lod(max_lod);
        // SAFETY: live device, valid create info.
        let raw =
            unsafe { dev.raw.create_sampler(&info, None) }.map_err(Error::vk("vkCreateSampler"))?;
        dev.set_name(raw, name);
        Ok(Sampler {
            dev: dev.clone(),
            raw,
        })
    }
}

impl Drop for Sampler {
    fn drop(&mut self) {
        // SAFETY: no pending GPU work uses the sampler (submissions are waited on).
        unsafe { self.dev.raw.destroy_sampler(self.raw, None) };
    }
}
