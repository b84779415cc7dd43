//! GPU timestamps around a piece of recorded work: a two-query pool, read after the fence
//! with `WAIT | TYPE_64`, masked to `timestampValidBits` and scaled by `timestampPeriod`.

use std::sync::Arc;

use ash::vk;

use super::context::Device;
use crate::{Error, Result};

/// A start/end timestamp pair.
pub struct GpuTimer {
    dev: Arc<Device>,
    pool: vk::QueryPool,
}

impl GpuTimer {
    /// `None` when the graphics queue has no timestamps (`timestampValidBits = 0` or no
    /// `timestampComputeAndGraphics`).
    pub fn new(dev: &Arc<Device>, name: &str) -> Result<Option<Self>> {
        if dev.info.timestamp_valid_bits == 0 || dev.info.timestamp_period <= 0.0 {
            return Ok(None);
        }
        let info = vk::QueryPoolCreateInfo::default()
            .query_type(vk::QueryType::TIMESTAMP)
            .query_count(2);
        // SAFETY: live device, valid create info.
        let pool = unsafe { dev.raw.create_query_pool(&info, None) }
            .map_err(Error::vk("vkCreateQueryPool"))?;
        dev.set_name(pool, name);
        Ok(Some(Self {
            dev: dev.clone(),
            pool,
        }))
    }

    /// Resets the queries and writes the start timestamp (outside a render pass).
    pub fn record_start(&self, cb: vk::CommandBuffer) {
        // SAFETY: cb is recording outside a render pass; queries 0..2 exist.
        unsafe {
            self.dev.raw.cmd_reset_query_pool(cb, self.pool, 0, 2);
            self.dev
                .raw
                .cmd_write_timestamp(cb, vk::PipelineStageFlags::TOP_OF_PIPE, self.pool, 0);
        }
    }

    /// Writes the end timestamp once all previous work has finished.
    pub fn record_end(&self, cb: vk::CommandBuffer) {
        // SAFETY: cb is recording; query 1 was reset by record_start in the same buffer.
        unsafe {
            self.dev.raw.cmd_write_timestamp(
                cb,
                vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                self.pool,
                1,
            );
        }
    }

    /// Milliseconds between the two timestamps (after the submission completed).
    pub fn elapsed_ms(&self) -> Result<f64> {
        let mut ticks = [0u64; 2];
        // SAFETY: both queries were written by a completed submission; WAIT makes the call
        // block until they are available anyway.
        unsafe {
            self.dev.raw.get_query_pool_results(
                self.pool,
                0,
                &mut ticks,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .map_err(Error::vk("vkGetQueryPoolResults"))?;
        let bits = self.dev.info.timestamp_valid_bits;
        let mask = if bits >= 64 {
            u64::MAX
        } else {
            (1u64 << bits) - 1
        };
        let delta = (ticks[1] & mask).wrapping_sub(ticks[0] & mask) & mask;
        Ok(delta as f64 * self.dev.info.timestamp_period * 1e-6)
    }
}

impl Drop for GpuTimer {
    fn drop(&mut self) {
        // SAFETY: submissions using the pool were waited on.
        unsafe { self.dev.raw.destroy_query_pool(self.pool, None) };
    }
}
