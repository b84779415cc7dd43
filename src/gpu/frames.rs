//! Frames in flight: the one way work that repeats is recorded and submitted, by the
//! viewer (two frames, presenting) and by the offscreen renders (one frame, an image
//! target). A frame in flight has its command buffer, fence, image-acquired semaphore (when
//! presenting), timestamp pair and release list.
//!
//! - [`Frames::begin`] waits for that frame's previous submission (its fence), drops what
//!   was retired into it, resets and begins its command buffer and writes the start
//!   timestamp;
//! - [`Frames::submit`] ends it and submits it with the semaphores the caller names (the
//!   swapchain's acquire and render-done semaphores, or none offscreen);
//! - [`Frames::retire`] is deferred release (kajiya's `defer_release`): an object that
//!   frames already submitted may still use (a pipeline, a descriptor set, a buffer, a whole
//!   pass or swapchain) goes into the current frame's release list and is dropped once that
//!   frame's fence has signalled, which orders it after every earlier submission on the
//!   queue (between frames: the frame submitted last). Nothing in a frame waits for the
//!   device to be idle. A frame begun and never submitted (an out-of-date swapchain image)
//!   releases nothing: what was retired meanwhile waits for the next submission.
//!
//! Which surface or target a frame draws into is not known here; timestamps reuse
//! [`GpuTimer`]. Retired objects need not be `Send`: a `Frames` lives on the thread that
//! submits through it (a worker that builds tables makes its own).

use std::any::Any;
use std::collections::VecDeque;
use std::sync::Arc;

use ash::vk;

use super::context::Device;
use super::timer::GpuTimer;
use crate::{Error, Result};

/// One frame in flight.
struct Slot {
    cb: vk::CommandBuffer,
    /// Signalled when this slot's last submission completed.
    fence: vk::Fence,
    /// Signalled by the swapchain's acquire, waited by the submission (presenting only).
    image_acquired: vk::Semaphore,
    timer: Option<GpuTimer>,
    /// The last submission has not been waited for yet.
    pending: bool,
    /// Number of the slot's last submission.
    number: u64,
    /// The timer holds timestamps of a completed submission not yet read.
    timed: bool,
    /// The end timestamp of the recording frame was written.
    timing_ended: bool,
}

/// A retired object and the submission that must complete before it is dropped (`None`:
/// nothing submitted could use it).
type Retired = (Option<u64>, Box<dyn Any>);

/// What [`Frames::begin`] hands the caller.
#[derive(Debug, Clone, Copy)]
pub struct FrameStart {
    /// The frame's command buffer, recording.
    pub cb: vk::CommandBuffer,
    /// The semaphore to pass to `Swapchain::acquire` (null unless presenting).
    pub image_acquired: vk::Semaphore,
    /// GPU time of the previous frame of this slot (ms), now complete; `None` without
    /// timestamps or when it was read already.
    pub previous_gpu_ms: Option<f64>,
}

/// N frames in flight on the device's graphics queue.
pub struct Frames {
    slots: Vec<Slot>,
    pool: vk::CommandPool,
    /// The slot of the last `begin` (where retired objects go).
    current: usize,
    /// `current` was submitted: the next `begin` moves to the next slot.
    advance: bool,
    /// `current` is recording (begun, not submitted).
    recording: bool,
    submitted: u64,
    /// Every submission numbered below this has completed (a fence said so).
    completed: u64,
    /// In order of their submission numbers.
    retired: VecDeque<Retired>,
    /// Objects retired so far.
    retired_total: u64,
    dev: Arc<Device>,
}

impl Frames {
    /// `count` frames in flight, named `name` for validation messages. `present`: each has
    /// an image-acquired semaphore for a swapchain.
    pub fn new(dev: &Arc<Device>, name: &str, count: usize, present: bool) -> Result<Self> {
        if count == 0 {
            return Err(Error::invalid("frames in flight", "0; expected at least 1"));
        }
        let raw = dev.raw();
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(dev.queue_family())
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: live device; the family index is the device's graphics family.
        let pool = unsafe { raw.create_command_pool(&pool_info, None) }
            .map_err(Error::vk("vkCreateCommandPool"))?;
        dev.set_name(pool, &format!("{name} command pool"));
        let mut frames = Frames {
            slots: Vec::with_capacity(count),
            pool,
            current: 0,
            advance: false,
            recording: false,
            submitted: 0,
            completed: 0,
            retired: VecDeque::new(),
            retired_total: 0,
            dev: dev.clone(),
        };
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(count as u32);
        // SAFETY: the pool was just created on this device and is used by this owner only.
        let cbs = unsafe { raw.allocate_command_buffers(&alloc) }
            .map_err(Error::vk("vkAllocateCommandBuffers"))?;
        for (i, cb) in cbs.into_iter().enumerate() {
            dev.set_name(cb, &format!("{name} {i}"));
            // Slots are pushed as their objects are made, so Drop destroys what exists.
            frames.slots.push(Slot {
                cb,
                fence: vk::Fence::null(),
                image_acquired: vk::Semaphore::null(),
                timer: None,
                pending: false,
                number: 0,
                timed: false,
                timing_ended: false,
            });
            let slot = &mut frames.slots[i];
            // SAFETY: live device.
            slot.fence = unsafe { raw.create_fence(&vk::FenceCreateInfo::default(), None) }
                .map_err(Error::vk("vkCreateFence"))?;
            dev.set_name(slot.fence, &format!("{name} {i} done"));
            if present {
                // SAFETY: live device.
                slot.image_acquired =
                    unsafe { raw.create_semaphore(&vk::SemaphoreCreateInfo::default(), None) }
                        .map_err(Error::vk("vkCreateSemaphore"))?;
                dev.set_name(slot.image_acquired, &format!("{name} {i} image acquired"));
            }
            slot.timer = GpuTimer::new(dev, &format!("{name} {i} timestamps"))?;
        }
        Ok(frames)
    }

    /// One frame, no presentation: the offscreen renders.
    pub fn single(dev: &Arc<Device>, name: &str) -> Result<Self> {
        Self::new(dev, name, 1, false)
    }

    /// Frames in flight.
    pub fn count(&self) -> usize {
        self.slots.len()
    }

    /// Frames submitted so far.
    pub fn submitted(&self) -> u64 {
        self.submitted
    }

    /// Starts the next frame: waits for its slot's previous submission, drops what was
    /// retired into it, and begins its command buffer (with the start timestamp). A frame
    /// begun and never submitted (e.g. its swapchain image was out of date) is begun again
    /// in the same slot.
    pub fn begin(&mut self) -> Result<FrameStart> {
        if self.advance {
            self.current = (self.current + 1) % self.slots.len();
            self.advance = false;
        }
        let previous_gpu_ms = self.complete(self.current)?;
        let raw = self.dev.raw();
        let slot = &mut self.slots[self.current];
        // SAFETY: the slot's last submission completed (complete() waited on its fence), so
        // the buffer is not pending; the pool allows resetting it alone.
        unsafe { raw.reset_command_buffer(slot.cb, vk::CommandBufferResetFlags::empty()) }
            .map_err(Error::vk("vkResetCommandBuffer"))?;
        let begin = vk::CommandBufferBeginInfo::default()
            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: the buffer was just reset to the initial state.
        unsafe { raw.begin_command_buffer(slot.cb, &begin) }
            .map_err(Error::vk("vkBeginCommandBuffer"))?;
        self.recording = true;
        slot.timing_ended = false;
        if let Some(t) = &slot.timer {
            t.record_start(slot.cb);
        }
        Ok(FrameStart {
            cb: slot.cb,
            image_acquired: slot.image_acquired,
            previous_gpu_ms,
        })
    }

    /// Writes the end timestamp of the recording frame (outside a render pass): work
    /// recorded after it (a readback copy) is not timed. [`Frames::submit`] writes it when
    /// this was not called.
    pub fn end_timing(&mut self) {
        let slot = &mut self.slots[self.current];
        if self.recording && !slot.timing_ended {
            if let Some(t) = &slot.timer {
                t.record_end(slot.cb);
            }
            slot.timing_ended = true;
        }
    }

    /// Ends the recording frame and submits it: it waits for `waits` (semaphore, stage) and
    /// signals `signals` and the frame's fence.
    pub fn submit(
        &mut self,
        waits: &[(vk::Semaphore, vk::PipelineStageFlags)],
        signals: &[vk::Semaphore],
    ) -> Result<()> {
        if !self.recording {
            return Err(Error::invalid("frame", "submitted without begin"));
        }
        self.end_timing();
        self.recording = false;
        let raw = self.dev.raw();
        let slot = &mut self.slots[self.current];
        // SAFETY: the buffer is recording (begin).
        unsafe { raw.end_command_buffer(slot.cb) }.map_err(Error::vk("vkEndCommandBuffer"))?;
        // SAFETY: the fence is not in use: its last submission was waited for in begin().
        unsafe { raw.reset_fences(&[slot.fence]) }.map_err(Error::vk("vkResetFences"))?;
        let (wait_sems, stages): (Vec<_>, Vec<_>) = waits.iter().copied().unzip();
        let cbs = [slot.cb];
        let submit = [vk::SubmitInfo::default()
            .wait_semaphores(&wait_sems)
            .wait_dst_stage_mask(&stages)
            .command_buffers(&cbs)
            .signal_semaphores(signals)];
        {
            let _queue = self.dev.queue_lock();
            // SAFETY: the buffer is executable; the caller's wait semaphores have pending
            // signals (an acquire) and its signal semaphores are unsignalled; the fence is
            // unsignalled; the queue is externally synchronised by the lock.
            unsafe { raw.queue_submit(self.dev.queue(), &submit, slot.fence) }
                .map_err(Error::vk("vkQueueSubmit"))?;
        }
        slot.pending = true;
        slot.number = self.submitted;
        slot.timed = slot.timer.is_some();
        self.advance = true;
        self.submitted += 1;
        Ok(())
    }

    /// Waits for the last submitted frame (a readback or screenshot needs its result) and
    /// drops what was retired into it. Returns its GPU time in ms (`None` without
    /// timestamps).
    pub fn wait(&mut self) -> Result<Option<f64>> {
        self.complete(self.current)
    }

    /// Waits for slot `i`'s submission if pending, reads its timestamps, drops what no
    /// pending submission can use any more.
    fn complete(&mut self, i: usize) -> Result<Option<f64>> {
        let raw = self.dev.raw();
        let slot = &mut self.slots[i];
        if slot.pending {
            // SAFETY: the fence belongs to this device and was submitted.
            unsafe { raw.wait_for_fences(&[slot.fence], true, u64::MAX) }
                .map_err(Error::vk("vkWaitForFences"))?;
            slot.pending = false;
            self.completed = self.completed.max(slot.number + 1);
        }
        self.release();
        let slot = &mut self.slots[i];
        let mut gpu_ms = None;
        if slot.timed {
            slot.timed = false;
            if let Some(t) = &slot.timer {
                gpu_ms = Some(t.elapsed_ms()?);
            }
        }
        Ok(gpu_ms)
    }

    /// Drops what frames whose fences have signalled were the last to use, without
    /// waiting. Returns how many objects were dropped.
    pub fn release_completed(&mut self) -> Result<usize> {
        let raw = self.dev.raw();
        for slot in &mut self.slots {
            if slot.pending {
                // SAFETY: the fence belongs to this device.
                let done = unsafe { raw.get_fence_status(slot.fence) }
                    .map_err(Error::vk("vkGetFenceStatus"))?;
                if done {
                    slot.pending = false;
                    self.completed = self.completed.max(slot.number + 1);
                }
            }
        }
        Ok(self.release())
    }

    /// Drops the retired objects whose last possible user has completed.
    fn release(&mut self) -> usize {
        let mut dropped = 0;
        while self
            .retired
            .front()
            .is_some_and(|(after, _)| after.is_none_or(|n| n < self.completed))
        {
            self.retired.pop_front();
            dropped += 1;
        }
        dropped
    }

    /// Deferred release: `obj` (an RAII owner of Vulkan objects that frames already
    /// submitted may use) is dropped once the current frame's fence has signalled: the
    /// frame being recorded, or between frames the last one submitted.
    pub fn retire<T: 'static>(&mut self, obj: T) {
        let after = if self.recording {
            Some(self.submitted)
        } else {
            self.submitted.checked_sub(1)
        };
        self.retired.push_back((after, Box::new(obj)));
        self.retired_total += 1;
    }

    /// Retires an object that a queued presentation may still use (an old swapchain with its
    /// semaphores): presentation signals no fence, so the object is kept until the next
    /// submission, queued after those presentations, has completed. Until then (a minimised
    /// window submits nothing) it stays; teardown waits for the device.
    pub fn retire_after_present<T: 'static>(&mut self, obj: T) {
        self.retired
            .push_back((Some(self.submitted), Box::new(obj)));
        self.retired_total += 1;
    }

    /// Objects waiting for their frames.
    pub fn awaiting_release(&self) -> usize {
        self.retired.len()
    }

    /// Objects retired so far (released or not).
    pub fn retired_total(&self) -> u64 {
        self.retired_total
    }
}

impl Drop for Frames {
    fn drop(&mut self) {
        let raw = self.dev.raw();
        for slot in &self.slots {
            if slot.pending {
                // SAFETY: the fence was submitted; a failure (device lost) leaves nothing
                // running either.
                let _ = unsafe { raw.wait_for_fences(&[slot.fence], true, u64::MAX) };
            }
        }
        self.retired.clear();
        for slot in &mut self.slots {
            slot.timer = None;
            // SAFETY: no submission of this slot is pending; null handles are ignored.
            unsafe {
                raw.destroy_fence(slot.fence, None);
                raw.destroy_semaphore(slot.image_acquired, None);
            }
        }
        // SAFETY: no buffer of the pool is pending; destroying the pool frees them.
        unsafe { raw.destroy_command_pool(self.pool, None) };
    }
}
