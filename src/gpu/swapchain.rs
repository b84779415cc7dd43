//! Presentation, the optional extra of the device layer: a window [`Surface`] and a
//! [`Swapchain`] with its render pass (sRGB colour + D32 depth), image views, depth image and
//! framebuffers. Each swapchain image is a [`FrameTarget`], so frame code draws into it
//! exactly as into an offscreen target.
//!
//! This module does not know about windows beyond raw handles, nor about frames in flight
//! (the viewer owns those); it never waits on the GPU except in `Drop`/recreation, where the
//! caller has already waited.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;
use raw_window_handle::{RawDisplayHandle, RawWindowHandle};

use super::context::{Device, Instance};
use super::memory::{Buffer, Image, ImageDesc};
use super::target::FrameTarget;
use crate::{Error, Result};

/// A `VkSurfaceKHR` for one window. The window must outlive it (the owner drops the surface
/// first).
pub struct Surface {
    /// Keeps the instance alive until the surface is destroyed.
    _instance: Arc<Instance>,
    pub(crate) loader: ash::khr::surface::Instance,
    pub raw: vk::SurfaceKHR,
}

impl Surface {
    /// Creates the surface of `window` on `instance` (made with
    /// [`Instance::with_surface_extensions`] for the same display).
    ///
    /// # Safety
    /// `display` and `window` must be valid handles of a live window that outlives the
    /// returned surface (VUID-VkXlibSurfaceCreateInfoKHR-window-parameter and friends).
    pub unsafe fn new(
        instance: &Arc<Instance>,
        display: RawDisplayHandle,
        window: RawWindowHandle,
    ) -> Result<Self> {
        // SAFETY: the caller guarantees live handles; the instance has the extensions
        // ash_window asks for (with_surface_extensions).
        let raw = unsafe {
            ash_window::create_surface(instance.entry(), &instance.raw, display, window, None)
        }
        .map_err(|e| Error::NoPresentation(format!("vkCreate*SurfaceKHR failed: {e}")))?;
        Ok(Self {
            _instance: instance.clone(),
            loader: ash::khr::surface::Instance::new(instance.entry(), &instance.raw),
            raw,
        })
    }

    /// Whether queue family `family` of `pd` can present to this surface.
    pub fn supported_by(&self, pd: vk::PhysicalDevice, family: u32) -> bool {
        // SAFETY: pd belongs to the instance the surface was created on.
        unsafe {
            self.loader
                .get_physical_device_surface_support(pd, family, self.raw)
        }
        .unwrap_or(false)
    }
}

impl Drop for Surface {
    fn drop(&mut self) {
        // SAFETY: every swapchain of this surface holds a borrow-free handle only while the
        // owner keeps the surface; owners drop swapchains first (VUID-vkDestroySurfaceKHR-
        // surface-01266). The instance is alive through our Arc.
        unsafe { self.loader.destroy_surface(self.raw, None) };
    }
}

/// How frames are paced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Vsync {
    /// FIFO: wait for the display (always available).
    On,
    /// MAILBOX, else IMMEDIATE, else FIFO.
    Off,
}

/// A swapchain and everything drawn into it: render pass, image views, depth, framebuffers.
pub struct Swapchain {
    dev: Arc<Device>,
    loader: ash::khr::swapchain::Device,
    pub raw: vk::SwapchainKHR,
    pub format: vk::Format,
    pub extent: vk::Extent2D,
    pub present_mode: vk::PresentModeKHR,
    /// Independent of the extent: survives recreation while the format stays the same, so
    /// pipelines built for it stay valid.
    pub render_pass: vk::RenderPass,
    images: Vec<vk::Image>,
    views: Vec<vk::ImageView>,
    framebuffers: Vec<vk::Framebuffer>,
    /// One per image: signalled by the frame's submission, waited on by the present. Per
    /// image, not per frame in flight: the present engine may hold a semaphore until the
    /// image is acquired again.
    pub render_done: Vec<vk::Semaphore>,
    depth: Option<Image>,
}

pub const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

impl Swapchain {
    /// A swapchain of `surface` sized `want` (used when the surface leaves the extent to the
    /// application). `Ok(None)` when the surface has zero area (a minimised window).
    pub fn new(
        dev: &Arc<Device>,
        surface: &Surface,
        want: vk::Extent2D,
        vsync: Vsync,
    ) -> Result<Option<Self>> {
        let pd = dev.physical();
        // SAFETY: pd and the surface belong to the same live instance.
        let caps = unsafe {
            surface
                .loader
                .get_physical_device_surface_capabilities(pd, surface.raw)
        }
        .map_err(Error::vk("vkGetPhysicalDeviceSurfaceCapabilitiesKHR"))?;
        let extent = if caps.current_extent.width == u32::MAX {
            vk::Extent2D {
                width: want
                    .width
                    .clamp(caps.min_image_extent.width, caps.max_image_extent.width),
                height: want
                    .height
                    .clamp(caps.min_image_extent.height, caps.max_image_extent.height),
            }
        } else {
            caps.current_extent
        };
        if extent.width == 0 || extent.height == 0 {
            return Ok(None);
        }
        // SAFETY: as above.
        let formats = unsafe {
            surface
                .loader
                .get_physical_device_surface_formats(pd, surface.raw)
        }
        .map_err(Error::vk("vkGetPhysicalDeviceSurfaceFormatsKHR"))?;
        // An sRGB format applies the transfer curve the offscreen path applies on the CPU.
        let format = formats
            .iter()
            .find(|f| {
                matches!(
                    f.format,
                    vk::Format::B8G8R8A8_SRGB | vk::Format::R8G8B8A8_SRGB
                ) && f.color_space == vk::ColorSpaceKHR::SRGB_NONLINEAR
            })
            .copied()
            .ok_or_else(|| {
                Error::NoPresentation(format!(
                    "the surface offers no 8-bit sRGB format (has {:?})",
                    formats.iter().map(|f| f.format).collect::<Vec<_>>()
                ))
            })?;
        // SAFETY: as above.
        let modes = unsafe {
            surface
                .loader
                .get_physical_device_surface_present_modes(pd, surface.raw)
        }
        .map_err(Error::vk("vkGetPhysicalDeviceSurfacePresentModesKHR"))?;
        let present_mode = match vsync {
            Vsync::On => vk::PresentModeKHR::FIFO,
            Vsync::Off => [vk::PresentModeKHR::MAILBOX, vk::PresentModeKHR::IMMEDIATE]
                .into_iter()
                .find(|m| modes.contains(m))
                .unwrap_or(vk::PresentModeKHR::FIFO),
        };
        let mut image_count = caps.min_image_count + 1;
        if caps.max_image_count > 0 {
            image_count = image_count.min(caps.max_image_count);
        }
        // Screenshots copy out of the swapchain image.
        let usage = vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC;
        if !caps.supported_usage_flags.contains(usage) {
            return Err(Error::NoPresentation(
                "swapchain images cannot be colour attachments and copy sources".into(),
            ));
        }
        let composite = if caps
            .supported_composite_alpha
            .contains(vk::CompositeAlphaFlagsKHR::OPAQUE)
        {
            vk::CompositeAlphaFlagsKHR::OPAQUE
        } else {
            vk::CompositeAlphaFlagsKHR::INHERIT
        };
        let loader = ash::khr::swapchain::Device::new(&dev.instance().raw, dev.raw());
        let info = vk::SwapchainCreateInfoKHR::default()
            .surface(surface.raw)
            .min_image_count(image_count)
            .image_format(format.format)
            .image_color_space(format.color_space)
            .image_extent(extent)
            .image_array_layers(1)
            .image_usage(usage)
            .image_sharing_mode(vk::SharingMode::EXCLUSIVE)
            .pre_transform(caps.current_transform)
            .composite_alpha(composite)
            .present_mode(present_mode)
            .clipped(true);
        // SAFETY: the device was created with VK_KHR_swapchain on a queue family that
        // presents to this surface (Device::on_surface); the values come from the caps.
        let raw = unsafe { loader.create_swapchain(&info, None) }
            .map_err(Error::vk("vkCreateSwapchainKHR"))?;
        dev.set_name(raw, "swapchain");
        let mut sc = Swapchain {
            dev: dev.clone(),
            loader,
            raw,
            format: format.format,
            extent,
            present_mode,
            render_pass: vk::RenderPass::null(),
            images: Vec::new(),
            views: Vec::new(),
            framebuffers: Vec::new(),
            render_done: Vec::new(),
            depth: None,
        };
        sc.render_pass = create_render_pass(dev, sc.format)?;
        sc.build_images()?;
        Ok(Some(sc))
    }

    /// Views, depth, framebuffers and per-image semaphores for the current swapchain.
    fn build_images(&mut self) -> Result<()> {
        let dev = &self.dev;
        // SAFETY: raw is a live swapchain of this device.
        self.images = unsafe { self.loader.get_swapchain_images(self.raw) }
            .map_err(Error::vk("vkGetSwapchainImagesKHR"))?;
        let depth = Image::new(
            dev,
            "swapchain depth",
            ImageDesc {
                format: DEPTH_FORMAT,
                width: self.extent.width,
                height: self.extent.height,
                layers: 1,
                usage: vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
                aspect: vk::ImageAspectFlags::DEPTH,
                view_type: vk::ImageViewType::TYPE_2D,
            },
        )?;
        for (i, &image) in self.images.iter().enumerate() {
            dev.set_name(image, &format!("swapchain image {i}"));
            let info = vk::ImageViewCreateInfo::default()
                .image(image)
                .view_type(vk::ImageViewType::TYPE_2D)
                .format(self.format)
                .subresource_range(vk::ImageSubresourceRange {
                    aspect_mask: vk::ImageAspectFlags::COLOR,
                    base_mip_level: 0,
                    level_count: 1,
                    base_array_layer: 0,
                    layer_count: 1,
                });
            // SAFETY: image is a live swapchain image created with this format.
            let view = unsafe { dev.raw().create_image_view(&info, None) }
                .map_err(Error::vk("vkCreateImageView"))?;
            self.views.push(view);
            dev.set_name(view, &format!("swapchain view {i}"));
            let attachments = [view, depth.view];
            let fb = vk::FramebufferCreateInfo::default()
                .render_pass(self.render_pass)
                .attachments(&attachments)
                .width(self.extent.width)
                .height(self.extent.height)
                .layers(1);
            // SAFETY: the views match the render pass's formats and the extent.
            let fb = unsafe { dev.raw().create_framebuffer(&fb, None) }
                .map_err(Error::vk("vkCreateFramebuffer"))?;
            self.framebuffers.push(fb);
            dev.set_name(fb, &format!("swapchain framebuffer {i}"));
            // SAFETY: live device.
            let sem = unsafe {
                dev.raw()
                    .create_semaphore(&vk::SemaphoreCreateInfo::default(), None)
            }
            .map_err(Error::vk("vkCreateSemaphore"))?;
            dev.set_name(sem, &format!("render done {i}"));
            self.render_done.push(sem);
        }
        self.depth = Some(depth);
        Ok(())
    }

    /// Destroys the per-image objects (the device must be idle for them).
    fn destroy_images(&mut self) {
        let raw = self.dev.raw();
        // SAFETY: callers wait for the device to be idle first, so no submission uses these.
        unsafe {
            for fb in self.framebuffers.drain(..) {
                raw.destroy_framebuffer(fb, None);
            }
            for v in self.views.drain(..) {
                raw.destroy_image_view(v, None);
            }
            for s in self.render_done.drain(..) {
                raw.destroy_semaphore(s, None);
            }
        }
        self.depth = None;
        self.images.clear();
    }

    /// Replaces the swapchain after a resize or OUT_OF_DATE/SUBOPTIMAL. The caller waits for
    /// the device to be idle first. `Ok(false)` when the surface has zero area (minimised):
    /// the old swapchain is kept and frames should be skipped.
    pub fn recreate(
        &mut self,
        surface: &Surface,
        want: vk::Extent2D,
        vsync: Vsync,
    ) -> Result<bool> {
        let Some(mut new) = Swapchain::new(&self.dev, surface, want, vsync)? else {
            return Ok(false);
        };
        std::mem::swap(self, &mut new);
        // Keep the render pass pipelines were built with while the format is unchanged (the
        // new one is compatible, so the new framebuffers work with it).
        if self.format == new.format {
            std::mem::swap(&mut self.render_pass, &mut new.render_pass);
        }
        // `new` is now the old swapchain and is dropped here; the device is idle.
        Ok(true)
    }

    /// The frame-code view of image `index`.
    pub fn frame_target(&self, index: u32) -> FrameTarget {
        FrameTarget {
            render_pass: self.render_pass,
            framebuffer: self.framebuffers[index as usize],
            extent: self.extent,
        }
    }

    /// `vkAcquireNextImageKHR`: the image index and whether the swapchain is suboptimal.
    /// `Err(ERROR_OUT_OF_DATE_KHR)` means recreate.
    pub fn acquire(&self, signal: vk::Semaphore) -> std::result::Result<(u32, bool), vk::Result> {
        // SAFETY: signal is unsignalled with no pending operation (the frame's fence was
        // waited on before reuse), as VUID-vkAcquireNextImageKHR-semaphore-01286 requires.
        unsafe {
            self.loader
                .acquire_next_image(self.raw, u64::MAX, signal, vk::Fence::null())
        }
    }

    /// Queues image `index` for presentation after `render_done[index]`. `Ok(true)` when the
    /// swapchain is suboptimal; `Err(ERROR_OUT_OF_DATE_KHR)` means recreate.
    pub fn present(&self, index: u32) -> std::result::Result<bool, vk::Result> {
        let waits = [self.render_done[index as usize]];
        let swapchains = [self.raw];
        let indices = [index];
        let info = vk::PresentInfoKHR::default()
            .wait_semaphores(&waits)
            .swapchains(&swapchains)
            .image_indices(&indices);
        let _queue = self.dev.queue_lock();
        // SAFETY: index was acquired and a submission that signals waits[0] was queued; the
        // queue is externally synchronised by the lock.
        unsafe { self.loader.queue_present(self.dev.queue(), &info) }
    }

    /// Records, after a frame's render pass left image `index` in PRESENT_SRC_KHR, a copy of
    /// it into `readback` (4 bytes per texel, the swapchain's format) and the transition back.
    pub fn record_copy(&self, cb: vk::CommandBuffer, index: u32, readback: &Buffer) {
        let image = self.images[index as usize];
        let range = vk::ImageSubresourceRange {
            aspect_mask: vk::ImageAspectFlags::COLOR,
            base_mip_level: 0,
            level_count: 1,
            base_array_layer: 0,
            layer_count: 1,
        };
        // The render pass's outgoing dependency made the colour writes and the transition to
        // PRESENT_SRC_KHR available to TRANSFER; this barrier chains on it.
        let to_src = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::empty())
            .dst_access_mask(vk::AccessFlags::TRANSFER_READ)
            .old_layout(vk::ImageLayout::PRESENT_SRC_KHR)
            .new_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(image)
            .subresource_range(range);
        let to_present = vk::ImageMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::TRANSFER_READ)
            .dst_access_mask(vk::AccessFlags::empty())
            .old_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
            .new_layout(vk::ImageLayout::PRESENT_SRC_KHR)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(image)
            .subresource_range(range);
        let to_host = vk::BufferMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .buffer(readback.raw)
            .offset(0)
            .size(vk::WHOLE_SIZE);
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
        let raw = self.dev.raw();
        // SAFETY: cb records outside a render pass; the image was acquired by this frame and
        // is in PRESENT_SRC_KHR after the render pass; readback holds w·h·4 bytes.
        unsafe {
            raw.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_src],
            );
            raw.cmd_copy_image_to_buffer(
                cb,
                image,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                readback.raw,
                &[region],
            );
            raw.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::BOTTOM_OF_PIPE | vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &[],
                &[to_host],
                &[to_present],
            );
        }
    }

    /// A host-visible buffer for [`Swapchain::record_copy`].
    pub fn readback_buffer(&self) -> Result<Buffer> {
        Buffer::new(
            &self.dev,
            "screenshot readback",
            self.extent.width as u64 * self.extent.height as u64 * 4,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
        )
    }

    /// Converts read-back texels of this swapchain's format to RGB8 (sRGB-encoded, as a
    /// PNG stores them), row-major from the top.
    pub fn texels_to_rgb8(&self, bytes: &[u8]) -> Vec<[u8; 3]> {
        let n = self.extent.width as usize * self.extent.height as usize;
        let bgra = self.format == vk::Format::B8G8R8A8_SRGB;
        bytes[..n * 4]
            .chunks_exact(4)
            .map(|c| {
                if bgra {
                    [c[2], c[1], c[0]]
                } else {
                    [c[0], c[1], c[2]]
                }
            })
            .collect()
    }
}

impl Drop for Swapchain {
    fn drop(&mut self) {
        self.destroy_images();
        // SAFETY: owners wait for the device to be idle before dropping a swapchain, so no
        // submission or present uses it; the render pass's framebuffers are gone above.
        unsafe {
            self.loader.destroy_swapchain(self.raw, None);
            self.dev.raw().destroy_render_pass(self.render_pass, None);
        }
    }
}

/// The swapchain render pass: colour cleared and left in PRESENT_SRC_KHR, depth cleared.
fn create_render_pass(dev: &Arc<Device>, format: vk::Format) -> Result<vk::RenderPass> {
    let attachments = [
        vk::AttachmentDescription::default()
            .format(format)
            .samples(vk::SampleCountFlags::TYPE_1)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
            .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
            .initial_layout(vk::ImageLayout::UNDEFINED)
            .final_layout(vk::ImageLayout::PRESENT_SRC_KHR),
        vk::AttachmentDescription::default()
            .format(DEPTH_FORMAT)
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
    // In: the acquire semaphore is waited at COLOR_ATTACHMENT_OUTPUT, so the layout
    // transition must come after that stage; the depth image is shared by the frames in
    // flight, so the previous frame's depth clear and writes finish before this frame's.
    // Out: a screenshot copy (TRANSFER) after the final transition to PRESENT_SRC_KHR.
    let dependencies = [
        vk::SubpassDependency::default()
            .src_subpass(vk::SUBPASS_EXTERNAL)
            .dst_subpass(0)
            .src_stage_mask(
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT
                    | vk::PipelineStageFlags::EARLY_FRAGMENT_TESTS
                    | vk::PipelineStageFlags::LATE_FRAGMENT_TESTS,
            )
            .dst_stage_mask(
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT
                    | vk::PipelineStageFlags::EARLY_FRAGMENT_TESTS,
            )
            .src_access_mask(vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_WRITE)
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
    let rp = unsafe { dev.raw().create_render_pass(&info, None) }
        .map_err(Error::vk("vkCreateRenderPass"))?;
    dev.set_name(rp, "swapchain render pass");
    Ok(rp)
}
