//! Recording a pass: clear, bind, draw into a [`Target`]. Knows nothing about
//! where the target's image lives (offscreen or a swapchain) nor which variant is bound.

use ash::vk;

use crate::gpu::memory::{Buffer, Pod};
use crate::gpu::pipeline::{DescriptorSet, Pipeline, PipelineLayout, VertexLayout};
use crate::gpu::target::Target;
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

/// Records one pass into `target`: clear, bind, draw. Knows nothing about where the
/// target's image lives (offscreen or swapchain).
#[allow(clippy::too_many_arguments)]
pub(crate) fn record_pass(
    dev: &Device,
    cb: vk::CommandBuffer,
    target: &Target,
    pipeline: &Pipeline,
    layout: &PipelineLayout,
    set: &DescriptorSet,
    geometry: &Geometry<'_>,
    clear: [f32; 4],
) {
    let whole = vk::Rect2D {
        offset: vk::Offset2D { x: 0, y: 0 },
        extent: target.extent,
    };
    begin_pass(dev, cb, target, clear);
    record_draw(dev, cb, pipeline, layout, set, geometry, whole);
    end_pass(dev, cb);
}

/// Begins `target`'s render pass over the whole target, clearing every colour attachment
/// to `clear` and depth to 1. Draws follow with [`record_draw`], then [`end_pass`].
pub(crate) fn begin_pass(dev: &Device, cb: vk::CommandBuffer, target: &Target, clear: [f32; 4]) {
    let colour = vk::ClearValue {
        color: vk::ClearColorValue { float32: clear },
    };
    let mut clears = vec![colour; target.colours as usize];
    clears.push(vk::ClearValue {
        depth_stencil: vk::ClearDepthStencilValue {
            depth: 1.0,
            stencil: 0,
        },
    });
    let area = vk::Rect2D {
        offset: vk::Offset2D { x: 0, y: 0 },
        extent: target.extent,
    };
    let begin = vk::RenderPassBeginInfo::default()
        .render_pass(target.render_pass)
        .framebuffer(target.framebuffer)
        .render_area(area)
        .clear_values(&clears);
    dev.begin_label(cb, "diffraction pass");
    // SAFETY: cb is recording outside a render pass; the framebuffer belongs to the render
    // pass and lives until the submission completes (the caller waits).
    unsafe {
        dev.raw()
            .cmd_begin_render_pass(cb, &begin, vk::SubpassContents::INLINE)
    };
}

/// One draw inside the render pass begun by [`begin_pass`], confined to `rect` of the
/// target (viewport and scissor).
pub(crate) fn record_draw(
    dev: &Device,
    cb: vk::CommandBuffer,
    pipeline: &Pipeline,
    layout: &PipelineLayout,
    set: &DescriptorSet,
    geometry: &Geometry<'_>,
    rect: vk::Rect2D,
) {
    let raw = dev.raw();
    let viewport = vk::Viewport {
        x: rect.offset.x as f32,
        y: rect.offset.y as f32,
        width: rect.extent.width as f32,
        height: rect.extent.height as f32,
        min_depth: 0.0,
        max_depth: 1.0,
    };
    // SAFETY: cb is inside a render pass (begin_pass); every bound object is live until the
    // submission completes (the caller waits), and the pipeline was built for a compatible
    // render pass and this layout (viewport and scissor are dynamic state).
    unsafe {
        raw.cmd_bind_pipeline(cb, vk::PipelineBindPoint::GRAPHICS, pipeline.raw);
        raw.cmd_set_viewport(cb, 0, &[viewport]);
        raw.cmd_set_scissor(cb, 0, &[rect]);
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
    }
}

/// Ends the render pass begun by [`begin_pass`].
pub(crate) fn end_pass(dev: &Device, cb: vk::CommandBuffer) {
    // SAFETY: cb is inside the render pass begun by begin_pass.
    unsafe { dev.raw().cmd_end_render_pass(cb) };
    dev.end_label(cb);
}
