//! A reusable submission for work that repeats (a BRDF map per frame): one command pool,
//! command buffer and fence, reset and re-recorded for each submission, which waits for
//! completion like [`Device::submit_once`]. `submit_once` allocates and frees a command
//! buffer and creates and destroys a fence per call; with synchronisation validation on
//! (VVL 1.3.239) that left ~4 KB of the layer's bookkeeping behind per submission, which
//! reusing them avoids (README: soak).

use std::sync::Arc;

use ash::vk;

use super::context::Device;
use crate::{Error, Result};

/// One command buffer and its fence, recorded and submitted again and again.
pub struct Submitter {
    dev: Arc<Device>,
    pool: vk::CommandPool,
    cb: vk::CommandBuffer,
    fence: vk::Fence,
}

impl Submitter {
    /// A pool on the device's graphics queue family whose one buffer can be reset alone.
    pub fn new(dev: &Arc<Device>, name: &str) -> Result<Self> {
        let raw = dev.raw();
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(dev.queue_family())
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: live device; the family index is the device's graphics family.
        let pool = unsafe { raw.create_command_pool(&pool_info, None) }
            .map_err(Error::vk("vkCreateCommandPool"))?;
        let mut s = Self {
            dev: dev.clone(),
            pool,
            cb: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
        };
        dev.set_name(pool, name);
        let alloc_info = vk::CommandBufferAllocateInfo::default()
            .command_pool(pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool was just created on this device and is used by this owner only.
        s.cb = unsafe { raw.allocate_command_buffers(&alloc_info) }
            .map_err(Error::vk("vkAllocateCommandBuffers"))?[0];
        dev.set_name(s.cb, name);
        // SAFETY: live device.
        s.fence = unsafe { raw.create_fence(&vk::FenceCreateInfo::default(), None) }
            .map_err(Error::vk("vkCreateFence"))?;
        dev.set_name(s.fence, name);
        Ok(s)
    }

    /// Records commands with `record`, submits them and waits for completion. Everything
    /// the commands used may be destroyed or rewritten once this returns.
    pub fn submit_and_wait(
        &self,
        label: &str,
        record: impl FnOnce(vk::CommandBuffer) -> Result<()>,
    ) -> Result<()> {
        let raw = self.dev.raw();
        // Held from recording to the end of the wait, like submit_once: the queue needs
        // external synchronisation and the buffer is not pending while unlocked.
        let _guard = self.dev.queue_lock();
        // SAFETY: the buffer is not pending (every submission was waited for, or the device
        // idled after a failed one); its pool allows resetting it alone.
        unsafe { raw.reset_command_buffer(self.cb, vk::CommandBufferResetFlags::empty()) }
            .map_err(Error::vk("vkResetCommandBuffer"))?;
        let begin = vk::CommandBufferBeginInfo::default()
            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: the buffer was just reset to the initial state.
        unsafe { raw.begin_command_buffer(self.cb, &begin) }
            .map_err(Error::vk("vkBeginCommandBuffer"))?;
        self.dev.begin_label(self.cb, label);
        record(self.cb)?;
        self.dev.end_label(self.cb);
        // SAFETY: the buffer is recording.
        unsafe { raw.end_command_buffer(self.cb) }.map_err(Error::vk("vkEndCommandBuffer"))?;
        // SAFETY: the fence is not in use by a pending submission (see above).
        unsafe { raw.reset_fences(&[self.fence]) }.map_err(Error::vk("vkResetFences"))?;
        let cbs = [self.cb];
        let submit = [vk::SubmitInfo::default().command_buffers(&cbs)];
        // SAFETY: the buffer is executable; the queue is used under its lock; the fence is
        // unsignalled.
        let result = unsafe { raw.queue_submit(self.dev.queue(), &submit, self.fence) }
            .map_err(Error::vk("vkQueueSubmit"))
            .and_then(|()| {
                // SAFETY: the fence was submitted above.
                unsafe { raw.wait_for_fences(&[self.fence], true, u64::MAX) }
                    .map_err(Error::vk("vkWaitForFences"))
            });
        if result.is_err() {
            // Nothing may still run when the caller frees resources or resets the buffer.
            // SAFETY: live device; the error path is already being reported.
            let _ = unsafe { raw.device_wait_idle() };
        }
        result
    }
}

impl Drop for Submitter {
    fn drop(&mut self) {
        let raw = self.dev.raw();
        // SAFETY: every submission was waited for (or the device idled), so neither the
        // fence nor the buffer is in use; destroying the pool frees the buffer.
        unsafe {
            if self.fence != vk::Fence::null() {
                raw.destroy_fence(self.fence, None);
            }
            raw.destroy_command_pool(self.pool, None);
        }
    }
}
