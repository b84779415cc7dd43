//! Presentation, the optional extra of the device layer: a window [`Surface`], a device that
//! presents to it ([`Device::on_surface`]) and a [`Swapchain`] with its render pass (sRGB
//! colour + D32 depth), image views, depth image and framebuffers. Each swapchain image is a
//! [`Target`], so a pass draws into it exactly as into an offscreen target.
//!
//! Acquire and present return typed outcomes ([`Acquired`], [`Presented`]); a lost surface
//! or device is an error ([`Error::SurfaceLost`], [`Error::DeviceLost`]). Recreation passes
//! the old swapchain as `oldSwapchain` and hands it back, for the caller to retire through
//! the frames' deferred release: nothing here waits on the GPU.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;
use raw_window_handle::{RawDisplayHandle, RawWindowHandle};

use super::context::{Device, Instance, Requirements};
use super::memory::{Buffer, Image, ImageDesc};
use super::render_pass::RenderPass;
pub use super::render_pass::DEPTH_FORMAT;
use super::target::Target;
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

impl Device {
    /// Like [`Device::on`], but the graphics queue must also present to `surface`, and
    /// `VK_KHR_swapchain` is enabled. No such device is [`Error::NoPresentation`].
    pub fn on_surface(instance: Arc<Instance>, surface: &Surface) -> Result<Arc<Device>> {
        Device::with_requirements(
            instance,
            &Requirements {
                queue_family: &|pd, family| surface.supported_by(pd, family),
                extensions: &[ash::khr::swapchain::NAME],
                unmet: &|| {
                    Error::NoPresentation(
                        "no Vulkan device can present to this window (graphics queue with \
                         surface support and VK_KHR_swapchain)"
                            .into(),
                    )
                },
            },
        )
    }
}

/// What `vkAcquireNextImageKHR` gave.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Acquired {
    /// Image `index` is ours; `suboptimal`: it can be drawn and presented, but the
    /// swapchain should be recreated after this frame.
    Image { index: u32, suboptimal: bool },
    /// `VK_ERROR_OUT_OF_DATE_KHR`: nothing was acquired (the semaphore stays unsignalled);
    /// recreate the swapchain.
    OutOfDate,
}

impl Acquired {
    /// Sorts the results `vkAcquireNextImageKHR` can return (spec: SUCCESS, SUBOPTIMAL_KHR,
    /// ERROR_OUT_OF_DATE_KHR, ERROR_SURFACE_LOST_KHR, ERROR_DEVICE_LOST, out of memory;
    /// TIMEOUT and NOT_READY cannot happen with an infinite timeout). `ash` returns
    /// SUBOPTIMAL_KHR as `Ok((index, true))`.
    pub fn from_result(r: std::result::Result<(u32, bool), vk::Result>) -> Result<Self> {
        match r {
            Ok((index, suboptimal)) => Ok(Acquired::Image { index, suboptimal }),
            Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => Ok(Acquired::OutOfDate),
            Err(e) => Err(Error::vk("vkAcquireNextImageKHR")(e)),
        }
    }
}

/// What `vkQueuePresentKHR` gave.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Presented {
    Ok,
    /// Presented, but the swapchain no longer matches the surface: recreate it.
    Suboptimal,
    /// Not presented (the surface changed): recreate the swapchain.
    OutOfDate,
}

impl Presented {
    /// Sorts the results `vkQueuePresentKHR` can return (spec: SUCCESS, SUBOPTIMAL_KHR,
    /// ERROR_OUT_OF_DATE_KHR, ERROR_SURFACE_LOST_KHR, ERROR_DEVICE_LOST, out of memory).
    /// `ash` returns SUBOPTIMAL_KHR as `Ok(true)`.
    pub fn from_result(r: std::result::Result<bool, vk::Result>) -> Result<Self> {
        match r {
            Ok(false) => Ok(Presented::Ok),
            Ok(true) => Ok(Presented::Suboptimal),
            Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => Ok(Presented::OutOfDate),
            Err(e) => Err(Error::vk("vkQueuePresentKHR")(e)),
        }
    }
}

/// What [`Swapchain::recreate`] did.
pub enum Recreated {
    /// The surface has zero area (a minimised window): the swapchain was kept; skip frames.
    Minimised,
    /// Replaced; the old swapchain (with its views, depth image, framebuffers and
    /// semaphores) may still be used by frames in flight: retire it.
    Replaced(Box<Swapchain>),
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
    usage: vk::ImageUsageFlags,
    /// Independent of the extent: shared with the next swapchain while the format stays the
    /// same, so pipelines built for it stay valid.
    render_pass: Arc<RenderPass>,
    images: Vec<vk::Image>,
    views: Vec<vk::ImageView>,
    framebuffers: Vec<vk::Framebuffer>,
    /// One per image: signalled by the frame's submission, waited on by the present.
    render_done: Vec<vk::Semaphore>,
    depth: Option<Image>,
}

/// What a swapchain of a surface is made with: its capabilities, the extent (the window's,
/// clamped where the surface leaves it to the application), an 8-bit sRGB format, the
/// present mode `vsync` asks for where offered, one image more than the minimum, colour
/// attachment and copy-source usage (copy-target too where offered), and opaque composition where offered.
struct SurfaceChoice {
    caps: vk::SurfaceCapabilitiesKHR,
    extent: vk::Extent2D,
    format: vk::SurfaceFormatKHR,
    present_mode: vk::PresentModeKHR,
    image_count: u32,
    usage: vk::ImageUsageFlags,
    composite: vk::CompositeAlphaFlagsKHR,
}

impl SurfaceChoice {
    /// `Ok(None)` when the surface has zero area (a minimised window).
    fn query(
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
        let mut usage = vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC;
        if !caps.supported_usage_flags.contains(usage) {
            return Err(Error::NoPresentation(
                "swapchain images cannot be colour attachments and copy sources".into(),
            ));
        }
        // The viewer's environment-lit picture is resolved by a compute pass and copied in.
        if caps
            .supported_usage_flags
            .contains(vk::ImageUsageFlags::TRANSFER_DST)
        {
            usage |= vk::ImageUsageFlags::TRANSFER_DST;
        }
        let composite = if caps
            .supported_composite_alpha
            .contains(vk::CompositeAlphaFlagsKHR::OPAQUE)
        {
            vk::CompositeAlphaFlagsKHR::OPAQUE
        } else {
            vk::CompositeAlphaFlagsKHR::INHERIT
        };
        Ok(Some(Self {
            caps,
            extent,
            format,
            present_mode,
            image_count,
            usage,
            composite,
        }))
    }
}

impl Swapchain {
    /// A swapchain of `surface` sized `want` (used when the surface leaves the extent to the
    /// application). `Ok(None)` when the surface has zero area (a minimised window).
    pub fn new(
        dev: &Arc<Device>,
        surface: &Surface,
        want: vk::Extent2D,
        vsync: Vsync,
    ) -> Result<Option<Self>> {
        Self::create(dev, surface, want, vsync, None)
    }

    /// [`Swapchain::new`], replacing `old` (passed as `oldSwapchain`, whose render pass is
    /// reused when the format is the same).
    fn create(
        dev: &Arc<Device>,
        surface: &Surface,
        want: vk::Extent2D,
        vsync: Vsync,
        old: Option<&Swapchain>,
    ) -> Result<Option<Self>> {
        let Some(choice) = SurfaceChoice::query(dev, surface, want, vsync)? else {
            return Ok(None);
        };
        let SurfaceChoice {
            caps,
            extent,
            format,
            present_mode,
            image_count,
            usage,
            composite,
        } = choice;
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
            .clipped(true)
            .old_swapchain(old.map_or(vk::SwapchainKHR::null(), |o| o.raw));
        // SAFETY: the device was created with VK_KHR_swapchain on a queue family that
        // presents to this surface (Device::on_surface); the values come from the caps; the
        // old swapchain (if any) belongs to the same surface and is not yet retired.
        let raw = unsafe { loader.create_swapchain(&info, None) }
            .map_err(Error::vk("vkCreateSwapchainKHR"))?;
        dev.set_name(raw, "swapchain");
        let render_pass = match old {
            Some(o) if o.format == format.format => o.render_pass.clone(),
            _ => {
                let pass = RenderPass::new(
                    dev,
                    "swapchain render pass",
                    format.format,
                    vk::ImageLayout::PRESENT_SRC_KHR,
                );
                match pass {
                    Ok(p) => Arc::new(p),
                    Err(e) => {
                        // SAFETY: just created, never used.
                        unsafe { loader.destroy_swapchain(raw, None) };
                        return Err(e);
                    }
                }
            }
        };
        let mut sc = Swapchain {
            dev: dev.clone(),
            loader,
            raw,
            format: format.format,
            extent,
            present_mode,
            usage,
            render_pass,
            images: Vec::new(),
            views: Vec::new(),
            framebuffers: Vec::new(),
            render_done: Vec::new(),
            depth: None,
        };
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
            let fb = self.render_pass.framebuffer(
                &format!("swapchain framebuffer {i}"),
                &[view, depth.view],
                self.extent,
            )?;
            self.framebuffers.push(fb);
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

    /// Destroys the per-image objects (no pending work may use them).
    fn destroy_images(&mut self) {
        let raw = self.dev.raw();
        // SAFETY: a swapchain is dropped only once no frame in flight uses it (retired through
        // the frames' deferred release, or after an idle wait at teardown).
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

    /// Replaces the swapchain after a resize or OUT_OF_DATE/SUBOPTIMAL, passing the current
    /// one as `oldSwapchain`. No wait: the old swapchain comes back in
    /// [`Recreated::Replaced`] for the caller to retire until the frames that used it are
    /// done.
    pub fn recreate(
        &mut self,
        surface: &Surface,
        want: vk::Extent2D,
        vsync: Vsync,
    ) -> Result<Recreated> {
        let Some(new) = Swapchain::create(&self.dev, surface, want, vsync, Some(self))? else {
            return Ok(Recreated::Minimised);
        };
        Ok(Recreated::Replaced(Box::new(std::mem::replace(self, new))))
    }

    /// The render pass pipelines drawing into this swapchain are built for.
    pub fn render_pass(&self) -> vk::RenderPass {
        self.render_pass.raw
    }

    /// Image `index` as passes see it.
    pub fn target(&self, index: u32) -> Target {
        Target {
            render_pass: self.render_pass.raw,
            framebuffer: self.framebuffers[index as usize],
            extent: self.extent,
            colours: 1,
        }
    }

    /// `vkAcquireNextImageKHR` signalling `signal`.
    pub fn acquire(&self, signal: vk::Semaphore) -> Result<Acquired> {
        // SAFETY: signal is unsignalled with no pending operation (the frame's fence was
        // waited on before reuse, and an OUT_OF_DATE acquire leaves it unsignalled), as
        // VUID-vkAcquireNextImageKHR-semaphore-01286 requires.
        Acquired::from_result(unsafe {
            self.loader
                .acquire_next_image(self.raw, u64::MAX, signal, vk::Fence::null())
        })
    }

    /// The semaphore a frame drawing into image `index` signals and its present waits on.
    /// One per image, not per frame in flight: the present engine may hold a semaphore
    /// until the image is acquired again.
    pub fn render_done(&self, index: u32) -> vk::Semaphore {
        self.render_done[index as usize]
    }

    /// Queues image `index` for presentation after `render_done(index)`.
    pub fn present(&self, index: u32) -> Result<Presented> {
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
        Presented::from_result(unsafe { self.loader.queue_present(self.dev.queue(), &info) })
    }

    /// Records, after a frame's render pass left image `index` in PRESENT_SRC_KHR, a copy of
    /// it into `readback` (4 bytes per texel, the swapchain's format) and the transition back.
    pub fn record_copy(&self, cb: vk::CommandBuffer, index: u32, readback: &Buffer) {
        let image = self.images[index as usize];
        // The render pass's outgoing dependency made the colour writes and the transition to
        // PRESENT_SRC_KHR available to TRANSFER; this barrier chains on it.
        let to_src = colour_barrier(
            image,
            (vk::AccessFlags::empty(), vk::ImageLayout::PRESENT_SRC_KHR),
            (
                vk::AccessFlags::TRANSFER_READ,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            ),
        );
        let to_present = colour_barrier(
            image,
            (
                vk::AccessFlags::TRANSFER_READ,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            ),
            (vk::AccessFlags::empty(), vk::ImageLayout::PRESENT_SRC_KHR),
        );
        let to_host = super::target::host_read(readback);
        let region = super::target::colour_copy(self.extent);
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

    /// Whether [`Swapchain::record_upload`] can write the images (they are copy targets).
    pub fn uploadable(&self) -> bool {
        self.usage.contains(vk::ImageUsageFlags::TRANSFER_DST)
    }

    /// Records, instead of a render pass, the copy of `texels` (4 bytes per texel in the
    /// swapchain's format, row-major, written by compute shaders) into image `index`, left in
    /// PRESENT_SRC_KHR and available to TRANSFER (as the render pass leaves it, so
    /// [`Swapchain::record_copy`] can follow).
    pub fn record_upload(&self, cb: vk::CommandBuffer, index: u32, texels: &Buffer) {
        let image = self.images[index as usize];
        // The frame's submission waits for the acquire at COLOR_ATTACHMENT_OUTPUT: the
        // transition chains on that stage.
        let to_dst = colour_barrier(
            image,
            (vk::AccessFlags::empty(), vk::ImageLayout::UNDEFINED),
            (
                vk::AccessFlags::TRANSFER_WRITE,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            ),
        );
        let to_present = colour_barrier(
            image,
            (
                vk::AccessFlags::TRANSFER_WRITE,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
            ),
            (
                vk::AccessFlags::TRANSFER_READ,
                vk::ImageLayout::PRESENT_SRC_KHR,
            ),
        );
        let from_shader = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE)
            .dst_access_mask(vk::AccessFlags::TRANSFER_READ);
        let region = super::target::colour_copy(self.extent);
        let raw = self.dev.raw();
        // SAFETY: cb records outside a render pass; the image was acquired by this frame;
        // texels holds w·h·4 bytes.
        unsafe {
            raw.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT
                    | vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[from_shader],
                &[],
                &[to_dst],
            );
            raw.cmd_copy_buffer_to_image(
                cb,
                texels.raw,
                image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &[region],
            );
            raw.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::TRANSFER | vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                vk::DependencyFlags::empty(),
                &[],
                &[],
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
        // SAFETY: as destroy_images: no frame in flight uses it. The render pass (shared
        // with a newer swapchain of the same format) drops with its last owner.
        unsafe { self.loader.destroy_swapchain(self.raw, None) };
    }
}

/// The layout transition of a swapchain image's one colour level and layer, from
/// `(access, layout)` to `(access, layout)`, on the same queue family.
fn colour_barrier(
    image: vk::Image,
    from: (vk::AccessFlags, vk::ImageLayout),
    to: (vk::AccessFlags, vk::ImageLayout),
) -> vk::ImageMemoryBarrier<'static> {
    let range = vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: 0,
        layer_count: 1,
    };
    vk::ImageMemoryBarrier::default()
        .src_access_mask(from.0)
        .dst_access_mask(to.0)
        .old_layout(from.1)
        .new_layout(to.1)
        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .image(image)
        .subresource_range(range)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn acquire_results_are_sorted() {
        assert_eq!(
            Acquired::from_result(Ok((2, false))).unwrap(),
            Acquired::Image {
                index: 2,
                suboptimal: false
            }
        );
        assert_eq!(
            Acquired::from_result(Ok((0, true))).unwrap(),
            Acquired::Image {
                index: 0,
                suboptimal: true
            }
        );
        assert_eq!(
            Acquired::from_result(Err(vk::Result::ERROR_OUT_OF_DATE_KHR)).unwrap(),
            Acquired::OutOfDate
        );
        assert!(matches!(
            Acquired::from_result(Err(vk::Result::ERROR_SURFACE_LOST_KHR)),
            Err(Error::SurfaceLost { .. })
        ));
        assert!(matches!(
            Acquired::from_result(Err(vk::Result::ERROR_DEVICE_LOST)),
            Err(Error::DeviceLost { .. })
        ));
        assert!(matches!(
            Acquired::from_result(Err(vk::Result::ERROR_OUT_OF_DEVICE_MEMORY)),
            Err(Error::OutOfMemory { device: true, .. })
        ));
    }

    #[test]
    fn present_results_are_sorted() {
        assert_eq!(Presented::from_result(Ok(false)).unwrap(), Presented::Ok);
        assert_eq!(
            Presented::from_result(Ok(true)).unwrap(),
            Presented::Suboptimal
        );
        assert_eq!(
            Presented::from_result(Err(vk::Result::ERROR_OUT_OF_DATE_KHR)).unwrap(),
            Presented::OutOfDate
        );
        assert!(matches!(
            Presented::from_result(Err(vk::Result::ERROR_SURFACE_LOST_KHR)),
            Err(Error::SurfaceLost { .. })
        ));
        assert!(matches!(
            Presented::from_result(Err(vk::Result::ERROR_DEVICE_LOST)),
            Err(Error::DeviceLost { .. })
        ));
    }
}
