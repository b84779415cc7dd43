//! The one render-pass builder: one subpass, a cleared colour attachment and a cleared D32
//! depth attachment. Offscreen targets and swapchains differ only in the colour format and
//! in the layout the colour image is left in (`TRANSFER_SRC_OPTIMAL` for the readback,
//! `PRESENT_SRC_KHR` for presentation); every pipeline is built for a pass of this shape, so
//! a pass recorded offscreen and into a window is the same code.

use std::sync::Arc;

use ash::vk;

use super::context::Device;
use crate::{Error, Result};

/// Depth format of every target.
pub const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

/// A `VkRenderPass`, destroyed on drop.
pub struct RenderPass {
    dev: Arc<Device>,
    pub raw: vk::RenderPass,
    /// Format of the colour attachment (passes of the same formats are compatible).
    pub colour_format: vk::Format,
}

impl RenderPass {
    /// Colour of `colour_format` (cleared, stored, left in `colour_final`) and depth
    /// (cleared, not stored).
    pub fn new(
        dev: &Arc<Device>,
        name: &str,
        colour_format: vk::Format,
        colour_final: vk::ImageLayout,
    ) -> Result<Self> {
        Self::with_colours(dev, name, 1, colour_format, colour_final)
    }

    /// [`Self::new`] with `colours` colour attachments of one format (attachments
    /// `0..colours`, fragment outputs `0..colours`), depth after them.
    pub fn with_colours(
        dev: &Arc<Device>,
        name: &str,
        colours: u32,
        colour_format: vk::Format,
        colour_final: vk::ImageLayout,
    ) -> Result<Self> {
        let colour = vk::AttachmentDescription::default()
            .format(colour_format)
            .samples(vk::SampleCountFlags::TYPE_1)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
            .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
            .initial_layout(vk::ImageLayout::UNDEFINED)
            .final_layout(colour_final);
        let mut attachments = vec![colour; colours as usize];
        attachments.push(
            vk::AttachmentDescription::default()
                .format(DEPTH_FORMAT)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::DONT_CARE)
                .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
                .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
                .initial_layout(vk::ImageLayout::UNDEFINED)
                .final_layout(vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL),
        );
        let colour_ref: Vec<vk::AttachmentReference> = (0..colours)
            .map(|attachment| vk::AttachmentReference {
                attachment,
                layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
            })
            .collect();
        let depth_ref = vk::AttachmentReference {
            attachment: colours,
            layout: vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL,
        };
        let subpass = [vk::SubpassDescription::default()
            .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
            .color_attachments(&colour_ref)
            .depth_stencil_attachment(&depth_ref)];
        // In: earlier use of the images finishes before this pass's clears: an earlier
        // frame's colour and depth writes (the depth image is shared by the frames in flight)
        // and its readback or screenshot copy (TRANSFER). A swapchain's acquire semaphore is
        // waited at COLOR_ATTACHMENT_OUTPUT, which this dependency's source stage includes,
        // so the layout transition comes after it.
        // Out: colour writes are visible to a copy (readback, screenshot) after the final
        // transition.
        let dependencies = [
            vk::SubpassDependency::default()
                .src_subpass(vk::SUBPASS_EXTERNAL)
                .dst_subpass(0)
                .src_stage_mask(
                    vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT
                        | vk::PipelineStageFlags::EARLY_FRAGMENT_TESTS
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
        let info = vk::RenderPassCreateInfo::default()
            .attachments(&attachments)
            .subpasses(&subpass)
            .dependencies(&dependencies);
        // SAFETY: live device; the descriptions reference valid attachment indices.
        let raw = unsafe { dev.raw().create_render_pass(&info, None) }
            .map_err(Error::vk("vkCreateRenderPass"))?;
        dev.set_name(raw, name);
        Ok(Self {
            dev: dev.clone(),
            raw,
            colour_format,
        })
    }

    /// A framebuffer of this pass over `views` (the colours, then depth) of `extent`.
    pub fn framebuffer(
        &self,
        name: &str,
        views: &[vk::ImageView],
        extent: vk::Extent2D,
    ) -> Result<vk::Framebuffer> {
        let info = vk::FramebufferCreateInfo::default()
            .render_pass(self.raw)
            .attachments(views)
            .width(extent.width)
            .height(extent.height)
            .layers(1);
        // SAFETY: the views match this pass's attachment formats and the extent.
        let fb = unsafe { self.dev.raw().create_framebuffer(&info, None) }
            .map_err(Error::vk("vkCreateFramebuffer"))?;
        self.dev.set_name(fb, name);
        Ok(fb)
    }
}

impl Drop for RenderPass {
    fn drop(&mut self) {
        // SAFETY: owners destroy their framebuffers first and retire a pass only through the
        // frames' deferred release (or after waiting), so no pending work uses it.
        unsafe { self.dev.raw().destroy_render_pass(self.raw, None) };
    }
}
