//! Render targets. A [`Target`] is what a pass is recorded into (render pass,
//! framebuffer, extent, colour attachments): it does not know whether the images behind it
//! are offscreen or a swapchain image. [`OffscreenTarget`] is the headless one: RGBA32F
//! colour images (linear values, no clamping; one, or the G-buffer's four), a D32 depth
//! image, and a host-visible buffer that receives the colour images side by side.

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
    /// Colour attachments (attachments `0..colours`; depth after them).
    pub colours: u32,
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
    colours: Vec<Image>,
}

impl OffscreenTarget {
    /// Linear float colour: HDR values survive to the EXR writer.
    pub const COLOUR_FORMAT: vk::Format = vk::Format::R32G32B32A32_SFLOAT;
    pub const DEPTH_FORMAT: vk::Format = DEPTH_FORMAT;

    pub fn new(dev: &Arc<Device>, width: u32, height: u32) -> Result<Self> {
        Self::with_colours(dev, width, height, 1)
    }

    /// A target of `colours` colour attachments (fragment outputs `0..colours`), all
    /// cleared, drawn and read back together.
    pub fn with_colours(dev: &Arc<Device>, width: u32, height: u32, colours: u32) -> Result<Self> {
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
        let image = |what: &str, format, usage, aspect| {
            Image::new(
                dev,
                what,
                ImageDesc {
                    format,
                    width,
                    height,
                    layers: 1,
                    usage,
                    aspect,
                    view_type: vk::ImageViewType::TYPE_2D,
                },
            )
        };
        let colour_images = (0..colours.max(1))
            .map(|_| {
                image(
                    "offscreen colour",
                    Self::COLOUR_FORMAT,
                    vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
                    vk::ImageAspectFlags::COLOR,
                )
            })
            .collect::<Result<Vec<_>>>()?;
        let depth = image(
            "offscreen depth",
            Self::DEPTH_FORMAT,
            vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
            vk::ImageAspectFlags::DEPTH,
        )?;
        let readback = Buffer::new(
            dev,
            "offscreen readback",
            u64::from(width) * u64::from(height) * 16 * colour_images.len() as u64,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
        )?;
        let pass = RenderPass::with_colours(
            dev,
            "offscreen render pass",
            colour_images.len() as u32,
            Self::COLOUR_FORMAT,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
        )?;
        let views: Vec<vk::ImageView> = colour_images
            .iter()
            .map(|c| c.view)
            .chain([depth.view])
            .collect();
        let framebuffer = pass.framebuffer(
            "offscreen framebuffer",
            &views,
            vk::Extent2D { width, height },
        )?;
        Ok(OffscreenTarget {
            dev: dev.clone(),
            framebuffer,
            pass,
            extent: vk::Extent2D { width, height },
            readback,
            _depth: depth,
            colours: colour_images,
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
            colours: self.colours.len() as u32,
        }
    }

    /// Records the copies of the colour images (in `TRANSFER_SRC_OPTIMAL` after the render
    /// pass) side by side into the readback buffer, made visible to the host.
    pub fn record_readback(&self, cb: vk::CommandBuffer) {
        let bytes = u64::from(self.extent.width) * u64::from(self.extent.height) * 16;
        let to_host = host_read(&self.readback);
        // SAFETY: cb is recording outside a render pass; the buffer holds every colour
        // image's width·height RGBA32F texels side by side; the render pass left them in
        // TRANSFER_SRC_OPTIMAL.
        unsafe {
            for (k, image) in self.colours.iter().enumerate() {
                let region = colour_copy(self.extent).buffer_offset(bytes * k as u64);
                self.dev.raw.cmd_copy_image_to_buffer(
                    cb,
                    image.raw,
                    vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                    self.readback.raw,
                    &[region],
                );
            }
            self.dev.raw.cmd_pipeline_barrier(
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

    /// The read-back pixels of the first colour image, row-major from the top row (after
    /// the submission completed).
    pub fn read_rgba(&self) -> Result<Vec<[f32; 4]>> {
        self.read_rgba_at(0)
    }

    /// [`Self::read_rgba`] of colour image `k`.
    pub fn read_rgba_at(&self, k: usize) -> Result<Vec<[f32; 4]>> {
        let bytes = self.readback.mapped()?;
        let n = self.extent.width as usize * self.extent.height as usize;
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
}

impl Drop for OffscreenTarget {
    fn drop(&mut self) {
        // SAFETY: submissions are waited on, so nothing uses it; the framebuffer goes before
        // the render pass and the image views it references (fields, dropped after).
        unsafe { self.dev.raw.destroy_framebuffer(self.framebuffer, None) };
    }
}

/// The barrier that makes a transfer's writes into `buffer` visible to the host.
pub(crate) fn host_read(buffer: &Buffer) -> vk::BufferMemoryBarrier<'static> {
    vk::BufferMemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
        .dst_access_mask(vk::AccessFlags::HOST_READ)
        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .buffer(buffer.raw)
        .offset(0)
        .size(vk::WHOLE_SIZE)
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
