//! Recording one frame: clear, bind, draw into a [`FrameTarget`]. Knows nothing about
//! where the target's image lives (offscreen or a swapchain) nor which variant is bound.

use ash::vk;

use crate::gpu::memory::{Buffer, Pod};
use crate::gpu::pipeline::{DescriptorSet, Pipeline, PipelineLayout, VertexLayout};
use crate::gpu::target::FrameTarget;
use crate::gpu::Device;
use crate::mesh::Vertex;

/// Mirror of the push-constant block of diffraction.vert.
#[repr(C)]
#[derive(Clone, Copy)]
pub(crate) struct Transforms {
    pub model: [f32; 16],
    pub view_proj: [f32; 16],
}

// SAFETY: repr(C) of f32 arrays: no padding.
unsafe impl Pod for Transforms {}

// SAFETY: mesh::Vertex is repr(C) with 12 f32 fields (48 bytes, asserted there): no padding.
unsafe impl Pod for Vertex {}

/// Geometry of one draw.
pub(crate) enum Geometry<'a> {
    /// Full-screen triangle (BRDF maps).
    FullScreen,
    /// Indexed triangles with their transforms.
    Mesh {
        vertices: &'a Buffer,
        indices: &'a Buffer,
        index_count: u32,
        transforms: Transforms,
    },
}

/// Vertex attributes of `mesh::Vertex` (position, normal, tangent, uv; 48 bytes).
pub(crate) fn mesh_vertex_layout() -> VertexLayout {
    VertexLayout {
        stride: 48,
        attributes: vec![
            (0, vk::Format::R32G32B32_SFLOAT, 0),
            (1, vk::Format::R32G32B32_SFLOAT, 12),
            (2, vk::Format::R32G32B32A32_SFLOAT, 24),
            (3, vk::Format::R32G32_SFLOAT, 40),
        ],
    }
}

/// Records one frame into `target`: clear, bind, draw. Knows nothing about where the
/// target's image lives (offscreen or swapchain).
#[allow(clippy::too_many_arguments)]
pub(crate) fn record_frame(
    dev: &Device,
    cb: vk::CommandBuffer,
    target: &FrameTarget,
    pipeline: &Pipeline,
    layout: &PipelineLayout,
    set: &DescriptorSet,
    geometry: &Geometry<'_>,
    clear: [f32; 4],
) {
    let raw = dev.raw();
    let clears = [
        vk::ClearValue {
            color: vk::ClearColorValue { float32: clear },
        },
        vk::ClearValue {
            depth_stencil: vk::ClearDepthStencilValue {
                depth: 1.0,
                stencil: 0,
            },
        },
    ];
    let area = vk::Rect2D {
        offset: vk::Offset2D { x: 0, y: 0 },
        extent: target.extent,
    };
    let begin = vk::RenderPassBeginInfo::default()
        .render_pass(target.render_pass)
        .framebuffer(target.framebuffer)
        .render_area(area)
        .clear_values(&clears);
    let viewport = vk::Viewport {
        x: 0.0,
        y: 0.0,
        width: target.extent.width as f32,
        height: target.extent.height as f32,
        min_depth: 0.0,
        max_depth: 1.0,
    };
    dev.begin_label(cb, "diffraction pass");
    // SAFETY: cb is recording outside a render pass; every bound object is live until the
    // submission completes (the caller waits), and the pipeline was built for this render
    // pass and layout.
    unsafe {
        raw.cmd_begin_render_pass(cb, &begin, vk::SubpassContents::INLINE);
        raw.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, pipeline.raw);
        raw.cmd_set_viewport(cb, 0, &[viewport]);
        raw.cmd_set_scissor(cb, 0, &[area]);
        raw.cmd_bind_descriptor_sets(
            cb,
            vk::PipelineBindPoint::GRAPHICS,
            layout.raw,
            0,
            &[set.raw],
            &[],
        );
        match geometry {
            Geometry::FullScreen => raw.cmd_draw(cb, 3, 1, 0, 0),
            Geometry::Mesh {
                vertices,
                indices,
                index_count,
                transforms,
            } => {
                raw.cmd_push_constants(
                    cb,
                    layout.raw,
                    vk::ShaderStageFlags::VERTEX,
                    0,
                    crate::gpu::memory::bytes_of(std::slice::from_ref(transforms)),
                );
                raw.cmd_bind_vertex_buffers(cb, 0, &[vertices.raw], &[0]);
                raw.cmd_bind_index_buffer(cb, indices.raw, 0, vk::IndexType::UINT32);
                raw.cmd_draw_indexed(cb, *index_count, 1, 0, 0, 0);
            }
        }
        raw.cmd_end_render_pass(cb);
    }
    dev.end_label(cb);
}
