//! A [`ScenePass`]: the objects one kind of picture needs (pipeline layout, descriptor set,
//! pipeline for one render pass, uniform and mesh buffers), built once and recorded into any
//! [`Target`] — the offscreen target of `render` or a swapchain image of the viewer.
//! Camera, light and exposure change through [`ScenePass::set_view`] without rebuilding.
//!
//! The uniform block is written with `vkCmdUpdateBuffer` inside each recorded frame, so
//! frames in flight never race a host write.

use std::sync::Arc;

use ash::vk;

use super::record::{begin_pass, end_pass, record_draw, record_pass, Geometry, Transforms};
use super::variant::{PreparedVariant, VariantStats};
use super::ParamsUbo;
use crate::gpu::memory::{bytes_of, Buffer, Image};
use crate::gpu::pipeline::{DescriptorSet, Pipeline, PipelineLayout, ShaderModule};
use crate::gpu::target::Target;
use crate::gpu::Device;
use crate::scene::{Camera, Light};

/// Feature switches a pass is specialised for (the viewer toggles them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PassOptions {
    pub fresnel: bool,
    pub shadowing: bool,
    /// Blend the scene's texture (ignored when the scene has none).
    pub texture_blending: bool,
}

/// What a BRDF-map pass of the viewer draws: the light `wi` (tangent frame), the map's side
/// in pixels and the exposure of its displayable colour.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapView {
    pub wi: [f64; 3],
    pub size: u32,
    pub exposure: f32,
}

/// Mesh buffers a pass owns.
pub(crate) struct MeshBuffers {
    pub vertices: Buffer,
    pub indices: Buffer,
    pub index_count: u32,
}

/// One picture's objects, built once, recordable into any target with a compatible render
/// pass. Field order is drop order: the pipeline and set before the resources they use.
pub struct ScenePass {
    pub(crate) pipeline: Pipeline,
    pub(crate) set: DescriptorSet,
    pub(crate) layout: PipelineLayout,
    pub(crate) ubo: Buffer,
    pub(crate) _colour: Buffer,
    pub(crate) _texture: Image,
    pub(crate) mesh: Option<MeshBuffers>,
    pub(crate) params: ParamsUbo,
    pub(crate) transforms: Transforms,
    pub(crate) clear: [f32; 4],
    pub(crate) stats: VariantStats,
    /// The variant's images and buffers the descriptor set points at: kept alive here even
    /// when the renderer prepares another variant.
    pub(crate) _variant: Arc<dyn PreparedVariant>,
    pub(crate) _fragment: ShaderModule,
    pub(crate) dev: Arc<Device>,
}

impl ScenePass {
    /// The variant this pass draws.
    pub fn stats(&self) -> &VariantStats {
        &self.stats
    }

    /// Moves the camera and the light (its direction and disc) and sets the exposure; takes
    /// effect in the next recorded frame. `aspect` is the target's width/height. Mesh passes
    /// only (a BRDF map has no camera).
    pub fn set_view(&mut self, camera: &Camera, light: &Light, aspect: f32, exposure: f32) {
        let eye = camera.eye;
        self.params.eye_world = [eye[0], eye[1], eye[2], 1.0];
        self.params.set_light(light);
        self.params.lighting[1] = exposure;
        self.transforms.view_proj = camera.view_proj(aspect).to_cols_array();
    }

    /// Sets the light of a BRDF-map pass ([`Renderer::brdf_map_pass`](super::Renderer::
    /// brdf_map_pass)): `wi` in the tangent frame (as `ωi` of the map), the map's side `size`
    /// in pixels (it fills the top-left `size`² pixels of the target) and the exposure its
    /// XYZ → linear sRGB values are multiplied by. Takes effect in the next recorded frame.
    pub fn set_map(&mut self, wi: [f32; 3], size: u32, exposure: f32) {
        self.params.map_wi = [wi[0], wi[1], wi[2], self.params.map_wi[3]];
        self.params.map_info[0] = size as f32;
        self.params.lighting[1] = exposure;
    }

    /// Records the pass into `target`: the uniform update (ordered after earlier frames'
    /// reads and before this frame's), then clear, bind, draw. `target`'s render pass must be
    /// compatible with the one the pass was built for.
    pub fn record(&self, cb: vk::CommandBuffer, target: &Target) {
        self.record_uniforms(cb);
        record_pass(
            &self.dev,
            cb,
            target,
            &self.pipeline,
            &self.layout,
            &self.set,
            &self.geometry(),
            self.clear,
        );
    }

    /// Records several passes into one render pass of `target`, each confined to its rectangle
    /// (the viewer's mesh beside its BRDF map): every pass's uniform update, then one render
    /// pass cleared to the first pass's clear colour, then the draws in order. As
    /// [`ScenePass::record`], it does not know whether `target` is a swapchain image.
    pub fn record_views(
        cb: vk::CommandBuffer,
        target: &Target,
        views: &[(&ScenePass, vk::Rect2D)],
    ) {
        let Some((first, _)) = views.first() else {
            return;
        };
        for (pass, _) in views {
            pass.record_uniforms(cb);
        }
        begin_pass(&first.dev, cb, target, first.clear);
        for (pass, rect) in views {
            record_draw(
                &pass.dev,
                cb,
                &pass.pipeline,
                &pass.layout,
                &pass.set,
                &pass.geometry(),
                *rect,
            );
        }
        end_pass(&first.dev, cb);
    }

    fn geometry(&self) -> Geometry<'_> {
        match &self.mesh {
            None => Geometry::FullScreen,
            Some(m) => Geometry::Mesh {
                vertices: &m.vertices,
                indices: &m.indices,
                index_count: m.index_count,
                transforms: self.transforms,
            },
        }
    }

    /// The uniform block's update, outside a render pass.
    fn record_uniforms(&self, cb: vk::CommandBuffer) {
        let raw = self.dev.raw();
        let shaders =
            vk::PipelineStageFlags::VERTEX_SHADER | vk::PipelineStageFlags::FRAGMENT_SHADER;
        let before = vk::BufferMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::UNIFORM_READ)
            .dst_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .buffer(self.ubo.raw)
            .offset(0)
            .size(vk::WHOLE_SIZE);
        let after = vk::BufferMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::UNIFORM_READ)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .buffer(self.ubo.raw)
            .offset(0)
            .size(vk::WHOLE_SIZE);
        // SAFETY: cb records outside a render pass; the uniform block is 4-byte aligned and
        // under the 65536-byte limit of vkCmdUpdateBuffer (VUID-vkCmdUpdateBuffer-dataSize-
        // 00037); the buffer has TRANSFER_DST usage. The first barrier orders the write after
        // earlier submissions' uniform reads (write-after-read), the second makes it visible.
        unsafe {
            raw.cmd_pipeline_barrier(
                cb,
                shaders,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[before],
                &[],
            );
            raw.cmd_update_buffer(
                cb,
                self.ubo.raw,
                0,
                bytes_of(std::slice::from_ref(&self.params)),
            );
            raw.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::TRANSFER,
                shaders,
                vk::DependencyFlags::empty(),
                &[],
                &[after],
                &[],
            );
        }
    }
}
