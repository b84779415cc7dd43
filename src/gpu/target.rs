//! Render targets. A [`Target`] is what a pass is recorded into (render pass,
//! framebuffer, extent): it does not know whether the image behind it is offscreen or a
//! swapchain image. [`OffscreenTarget`] is the headless one: an RGBA32F colour image (linear
//! values, no clamping), a D32 depth image, and a host-visible readback buffer.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::context::Device;
use super::memory::{Buffer, Image, ImageDesc};
use super::render_pass::{RenderPass, DEPTH_FORMAT};
use crate::{Error, Result};

/// What a pass is recorded into.
#[derive(Debug, Clone, Copy)]
pub struct Target {
    pub render_pass: vk::RenderPass,
    pub framebuffer: vk::Framebuffer,
    pub extent: vk::Extent2D,
}

/// Headless colour + depth target with readback.
pub struct OffscreenTarget {
    // Field order is drop order: framebuffer users first, images after.
    dev: Arc<Device>,
    pub framebuffer: vk::Framebuffer,
    pass: RenderPass,
    pub extent: vk::Extent2D,
    readback: Buffer,
    _depth: Image,
    pub colour: Image,
}

impl OffscreenTarget {
    /// Linear float colour: HDR values survive to the EXR writer.
    pub const COLOUR_FORMAT: vk::Format = vk::Format::R32G32B32A32_SFLOAT;
    pub const DEPTH_FORMAT: vk::Format = DEPTH_FORMAT;

    pub fn new(dev: &Arc<Device>, width: u32, height: u32) -> Result<Self> {
        let max = dev.info.max_image_dimension_2d;
        if width == 0 || height == 0 || width > max || height > max {
            return Err(Error::invalid(
                "image size",
                format!("{width}×{height}; each side must be 1..={max} on this device"),
            ));
        }
        for (format, feature) in [
            (
                Self::COLOUR_FORMAT,
                vk::FormatFeatureFlags::COLOR_ATTACHMENT | vk::FormatFeatureFlags::TRANSFER_SRC,
            ),
            (
                Self::DEPTH_FORMAT,
                vk::FormatFeatureFlags::DEPTH_STENCIL_ATTACHMENT,
            ),
        ] {
            if !dev.supports_format(format, feature) {
                return Err(Error::invalid(
                    "render target",
                    format!("{} cannot render to {format:?}", dev.info.name),
                ));
            }
        }
        let colour = Image::new(
            dev,
            "offscreen colour",
            ImageDesc {
                format: Self::COLOUR_FORMAT,
                width,
                height,
                layers: 1,
                usage: vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
                aspect: vk::ImageAspectFlags::COLOR,
                view_type: vk::ImageViewType::TYPE_2D,
            },
        )?;
        let depth = Image::new(
            dev,
            "offscreen depth",
            ImageDesc {
                format: Self::DEPTH_FORMAT,
                width,
                height,
                layers: 1,
                usage: vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
                aspect: vk::ImageAspectFlags::DEPTH,
                view_type: vk::ImageViewType::TYPE_2D,
            },
        )?;
        let readback = Buffer::new(
            dev,
            "offscreen readback",
            width as u64 * height as u64 * 16,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
        )?;
        let pass = RenderPass::new(
            dev,
            "offscreen render pass",
            Self::COLOUR_FORMAT,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
        )?;
        let framebuffer = pass.framebuffer(
            "offscreen framebuffer",
            &[colour.view, depth.view],
            vk::Extent2D { width, height },
        )?;
        Ok(OffscreenTarget {
            dev: dev.clone(),
            framebuffer,
            pass,
            extent: vk::Extent2D { width, height },
            readback,
            _depth: depth,
            colour,
        })
    }

    /// The render pass pipelines for this target are built for.
    pub fn render_pass(&self) -> vk::RenderPass {
        self.pass.raw
    }

    /// This target as passes see it.
    pub fn target(&self) -> Target {
        Target {
            render_pass: self.pass.raw,
            framebuffer: self.framebuffer,
            extent: self.extent,
        }
    }

    /// Records the copy of the colour image (in `TRANSFER_SRC_OPTIMAL` after the render
    /// pass) into the readback buffer, made visible to the host.
    pub fn record_readback(&self, cb: vk::CommandBuffer) {
        record_readbacks(
            &self.dev,
            cb,
            &[self.colour.raw],
            self.extent,
            &self.readback,
        );
    }

    /// The read-back pixels, row-major from the top row (after the submission completed).
    pub fn read_rgba(&self) -> Result<Vec<[f32; 4]>> {
        read_rgba_at(&self.readback, self.extent, 0)
    }
}

/// Records the copies of RGBA32F `images` of `extent` (each in `TRANSFER_SRC_OPTIMAL` after
/// its render pass) side by side into `readback`, made visible to the host.
pub(crate) fn record_readbacks(
    dev: &Device,
    cb: vk::CommandBuffer,
    images: &[vk::Image],
    extent: vk::Extent2D,
    readback: &Buffer,
) {
    let bytes = u64::from(extent.width) * u64::from(extent.height) * 16;
    let to_host = vk::BufferMemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
        .dst_access_mask(vk::AccessFlags::HOST_READ)
        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .buffer(readback.raw)
        .offset(0)
        .size(vk::WHOLE_SIZE);
    // SAFETY: cb is recording outside a render pass; the buffer holds the images'
    // width·height RGBA32F texels side by side (its callers size it so); the render passes
    // left the images in TRANSFER_SRC_OPTIMAL.
    unsafe {
        for (k, &image) in images.iter().enumerate() {
            let region = colour_copy(extent).buffer_offset(bytes * k as u64);
            dev.raw.cmd_copy_image_to_buffer(
                cb,
                image,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                readback.raw,
                &[region],
            );
        }
        dev.raw.cmd_pipeline_barrier(
            cb,
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::HOST,
            vk::DependencyFlags::empty(),
            &[],
            &[to_host],
            &[],
        );
    }
}

/// Image `k` of those [`record_readbacks`] copied into `readback` (after the submission
/// completed), row-major from the top row.
pub(crate) fn read_rgba_at(
    readback: &Buffer,
    extent: vk::Extent2D,
    k: usize,
) -> Result<Vec<[f32; 4]>> {
    let bytes = readback.mapped()?;
    let n = extent.width as usize * extent.height as usize;
    let part = bytes
        .get(k * n * 16..(k + 1) * n * 16)
        .ok_or_else(|| Error::invalid("readback", "buffer smaller than the image"))?;
    Ok(part
        .chunks_exact(16)
        .map(|c| {
            let f = |i: usize| f32::from_ne_bytes([c[i], c[i + 1], c[i + 2], c[i + 3]]);
            [f(0), f(4), f(8), f(12)]
        })
        .collect())
}

impl Drop for OffscreenTarget {
    fn drop(&mut self) {
        // SAFETY: submissions are waited on, so nothing uses it; the framebuffer goes before
        // the render pass and the image views it references (fields, dropped after).
        unsafe { self.dev.raw.destroy_framebuffer(self.framebuffer, None) };
    }
}

/// The copy between a buffer of tightly packed texels and the whole colour image of
/// `extent` (one level, one layer), the region of a readback or an upload.
pub(crate) fn colour_copy(extent: vk::Extent2D) -> vk::BufferImageCopy {
    vk::BufferImageCopy::default()
        .image_subresource(vk::ImageSubresourceLayers {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            mip_level: 0,
            base_array_layer: 0,
            layer_count: 1,
        })
        .image_extent(vk::Extent3D {
            width: extent.width,
            height: extent.height,
            depth: 1,
        })
}
