//! Render targets. A [`FrameTarget`] is what frame code draws into (render pass,
//! framebuffer, extent): it does not know whether the image behind it is offscreen or a
//! swapchain image. [`OffscreenTarget`] is the headless one: an RGBA32F colour image (linear
//! values, no clamping), a D32 depth image, and a host-visible readback buffer.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::context::Device;
use super::memory::{Buffer, Image, ImageDesc};
use crate::{Error, Result};

/// What a frame is recorded against.
#[derive(Debug, Clone, Copy)]
pub struct FrameTarget {
    pub render_pass: vk::RenderPass,
    pub framebuffer: vk::Framebuffer,
    pub extent: vk::Extent2D,
}

/// Headless colour + depth target with readback.
pub struct OffscreenTarget {
    // Field order is drop order: framebuffer users first, images after.
    dev: Arc<Device>,
    pub render_pass: vk::RenderPass,
    pub framebuffer: vk::Framebuffer,
    pub extent: vk::Extent2D,
    readback: Buffer,
    depth: Image,
    pub colour: Image,
}

impl OffscreenTarget {
    /// Linear float colour: HDR values survive to the EXR writer.
    pub const COLOUR_FORMAT: vk::Format = vk::Format::R32G32B32A32_SFLOAT;
    pub const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

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
        let mut target = OffscreenTarget {
            dev: dev.clone(),
            render_pass: vk::RenderPass::null(),
            framebuffer: vk::Framebuffer::null(),
            extent: vk::Extent2D { width, height },
            readback,
            depth,
            colour,
        };

        let attachments = [
            vk::AttachmentDescription::default()
                .format(Self::COLOUR_FORMAT)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::STORE)
                .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
                .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
                .initial_layout(vk::ImageLayout::UNDEFINED)
                .final_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL),
            vk::AttachmentDescription::default()
                .format(Self::DEPTH_FORMAT)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::DONT_CARE)
                .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
                .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
                .initial_layout(vk::ImageLayout::UNDEFINED)
                .final_layout(vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL),
        ];
        let colour_ref = [vk::AttachmentReference {
            attachment: 0,
            layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
        }];
        let depth_ref = vk::AttachmentReference {
            attachment: 1,
            layout: vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL,
        };
        let subpass = [vk::SubpassDescription::default()
            .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
            .color_attachments(&colour_ref)
            .depth_stencil_attachment(&depth_ref)];
        // In: earlier use of the images (a previous frame) finishes before the clears.
        // Out: colour writes are visible to the readback copy after the final transition.
        let dependencies = [
            vk::SubpassDependency::default()
                .src_subpass(vk::SUBPASS_EXTERNAL)
                .dst_subpass(0)
                .src_stage_mask(
                    vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT
                        | vk::PipelineStageFlags::LATE_FRAGMENT_TESTS
                        | vk::PipelineStageFlags::TRANSFER,
                )
                .dst_stage_mask(
                    vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT
                        | vk::PipelineStageFlags::EARLY_FRAGMENT_TESTS,
                )
                .src_access_mask(
                    vk::AccessFlags::COLOR_ATTACHMENT_WRITE
                        | vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_WRITE,
                )
                .dst_access_mask(
                    vk::AccessFlags::COLOR_ATTACHMENT_WRITE
                        | vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_WRITE
                        | vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_READ,
                ),
            vk::SubpassDependency::default()
                .src_subpass(0)
                .dst_subpass(vk::SUBPASS_EXTERNAL)
                .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
                .dst_stage_mask(vk::PipelineStageFlags::TRANSFER)
                .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                .dst_access_mask(vk::AccessFlags::TRANSFER_READ),
        ];
        let rp_info = vk::RenderPassCreateInfo::default()
            .attachments(&attachments)
            .subpasses(&subpass)
            .dependencies(&dependencies);
        // SAFETY: live device; the descriptions reference valid attachment indices.
        target.render_pass = unsafe { dev.raw.create_render_pass(&rp_info, None) }
            .map_err(Error::vk("vkCreateRenderPass"))?;
        dev.set_name(target.render_pass, "offscreen render pass");
        let views = [target.colour.view, target.depth.view];
        let fb_info = vk::FramebufferCreateInfo::default()
            .render_pass(target.render_pass)
            .attachments(&views)
            .width(width)
            .height(height)
            .layers(1);
        // SAFETY: the views match the render pass's attachment formats and the extent.
        target.framebuffer = unsafe { dev.raw.create_framebuffer(&fb_info, None) }
            .map_err(Error::vk("vkCreateFramebuffer"))?;
        dev.set_name(target.framebuffer, "offscreen framebuffer");
        Ok(target)
    }

    /// The frame-code view of this target.
    pub fn frame(&self) -> FrameTarget {
        FrameTarget {
            render_pass: self.render_pass,
            framebuffer: self.framebuffer,
            extent: self.extent,
        }
    }

    /// Records the copy of the colour image (in `TRANSFER_SRC_OPTIMAL` after the render
    /// pass) into the readback buffer, made visible to the host.
    pub fn record_readback(&self, cb: vk::CommandBuffer) {
        let region = vk::BufferImageCopy::default()
            .image_subresource(vk::ImageSubresourceLayers {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                mip_level: 0,
                base_array_layer: 0,
                layer_count: 1,
            })
            .image_extent(vk::Extent3D {
                width: self.extent.width,
                height: self.extent.height,
                depth: 1,
            });
        let to_host = vk::BufferMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .buffer(self.readback.raw)
            .offset(0)
            .size(vk::WHOLE_SIZE);
        // SAFETY: cb is recording outside a render pass; the buffer holds width·height
        // RGBA32F texels; the render pass left the image in TRANSFER_SRC_OPTIMAL.
        unsafe {
            self.dev.raw.cmd_copy_image_to_buffer(
                cb,
                self.colour.raw,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                self.readback.raw,
                &[region],
            );
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

    /// The read-back pixels, row-major from the top row (after the submission completed).
    pub fn read_rgba(&self) -> Result<Vec<[f32; 4]>> {
        let bytes = self.readback.mapped()?;
        let n = self.extent.width as usize * self.extent.height as usize;
        if bytes.len() < n * 16 {
            return Err(Error::invalid("readback", "buffer smaller than the image"));
        }
        Ok(bytes[..n * 16]
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
        // SAFETY: submissions are waited on, so nothing uses these; framebuffer before the
        // render pass and before the image views it references (the images drop after).
        unsafe {
            if self.framebuffer != vk::Framebuffer::null() {
                self.dev.raw.destroy_framebuffer(self.framebuffer, None);
            }
            if self.render_pass != vk::RenderPass::null() {
                self.dev.raw.destroy_render_pass(self.render_pass, None);
            }
        }
    }
}
