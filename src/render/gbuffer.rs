//! The G-buffer of a scene's environment-lit pixels, drawn by the Vulkan raster pipeline
//! (glsl/gbuffer.vert, glsl/gbuffer.frag): the mesh as the sun-lit pass draws it (the
//! same vertex layout, transforms, depth test and no culling, so the same pixels are
//! covered), per pixel the frame made orthonormal, `ωr` towards the eye in it and the
//! texture's albedo. A colour attachment holds four floats, so the G-buffer's sixteen are
//! four RGBA32F attachments of one pass (an [`OffscreenTarget`] of four colours), read
//! back in the same submission; the host then
//! keeps the covered pixels ([`GBuffer`]) for the compute stages. [`GBufferPass`] keeps
//! the pipeline and the mesh on the device between draws.

use std::sync::Arc;

use ash::vk;

use super::env_scene::{Albedo, GBuffer};
use super::record::{mesh_vertex_layout, record_pass, Geometry, Transforms};
use crate::gpu::memory::{Buffer, Image, ImageDesc, Sampler};
use crate::gpu::pipeline::{
    Binding, DescriptorSet, Pipeline, PipelineDesc, PipelineLayout, Resource, ShaderModule,
};
use crate::gpu::render_pass::RenderPass;
use crate::gpu::target::OffscreenTarget;
use crate::gpu::{shaders, Device};
use crate::mesh::Mesh;
use crate::scene::Camera;
use crate::{Error, Result};

/// Mirror of `Camera` in glsl/gbuffer.frag.
#[repr(C)]
#[derive(Clone, Copy)]
struct EyeUbo {
    eye: [f32; 4],
}

// SAFETY: repr(C) of 4-byte scalars in one 16-byte group: no padding.
unsafe impl crate::gpu::memory::Pod for EyeUbo {}

/// Colour attachments of the G-buffer: four floats each, sixteen a pixel.
const QUARTERS: u32 = 4;

/// Rasterises `mesh` (world space) as `camera` sees it at `width`×`height` on `dev`,
/// `ss`×`ss` pixels to an output pixel (the key of each pixel's sequence,
/// [`GBuffer::data`]), with the texture's albedo from `albedo` (zero without one).
pub fn rasterise(
    dev: &Arc<Device>,
    mesh: &Mesh,
    camera: &Camera,
    size: (u32, u32, u32),
    albedo: Option<&Albedo>,
) -> Result<GBuffer> {
    GBufferPass::new(dev, mesh, albedo)?.draw(camera, size)
}

/// The objects of the G-buffer's draw that outlive one view: the mesh and the albedo on
/// the device, the pipeline (compiled once: lavapipe compiles its shaders when a pipeline
/// is made) and a target kept for the last size drawn. The viewer keeps one and draws it
/// at each change of the view.
pub struct GBufferPass {
    // Field order is drop order: the users of the layout and the pass first.
    target: Option<OffscreenTarget>,
    set: DescriptorSet,
    eye: Buffer,
    pipeline: Pipeline,
    /// What the pipeline was made for; each target's own pass of the same attachments is
    /// compatible with it.
    _render_pass: RenderPass,
    layout: PipelineLayout,
    _modules: [ShaderModule; 2],
    _sampler: Sampler,
    _texture: Image,
    vertices: Buffer,
    indices: Buffer,
    index_count: u32,
    dev: Arc<Device>,
}

impl GBufferPass {
    /// Uploads `mesh` and `albedo` and makes the pipeline.
    pub fn new(dev: &Arc<Device>, mesh: &Mesh, albedo: Option<&Albedo>) -> Result<Self> {
        let buffer = |what: &str, usage, bytes: &[u8]| {
            // An empty mesh draws nothing; its buffers hold a placeholder.
            Buffer::with_data(
                dev,
                &format!("{} {what} (G-buffer)", mesh.name),
                usage,
                if bytes.is_empty() {
                    &[0u8; 64][..]
                } else {
                    bytes
                },
            )
        };
        let vertices = buffer(
            "vertices",
            vk::BufferUsageFlags::VERTEX_BUFFER,
            crate::gpu::memory::bytes_of(&mesh.vertices),
        )?;
        let indices = buffer(
            "indices",
            vk::BufferUsageFlags::INDEX_BUFFER,
            crate::gpu::memory::bytes_of(&mesh.indices),
        )?;
        let texture = albedo_image(dev, albedo)?;
        let sampler = Sampler::trilinear(
            dev,
            "G-buffer albedo (trilinear)",
            vk::SamplerAddressMode::REPEAT,
        )?;
        let layout = PipelineLayout::new(
            dev,
            "G-buffer layout",
            &[
                Binding {
                    binding: 0,
                    kind: vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
                    stages: vk::ShaderStageFlags::FRAGMENT,
                },
                Binding {
                    binding: 1,
                    kind: vk::DescriptorType::UNIFORM_BUFFER,
                    stages: vk::ShaderStageFlags::FRAGMENT,
                },
            ],
            (
                vk::ShaderStageFlags::VERTEX,
                std::mem::size_of::<Transforms>() as u32,
            ),
        )?;
        let vertex = ShaderModule::new(dev, "gbuffer.vert", shaders::GBUFFER_VERT)?;
        let fragment = ShaderModule::new(dev, "gbuffer.frag", shaders::GBUFFER_FRAG)?;
        let render_pass = RenderPass::with_colours(
            dev,
            "G-buffer render pass",
            QUARTERS,
            OffscreenTarget::COLOUR_FORMAT,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
        )?;
        let pipeline = Pipeline::new(
            dev,
            &PipelineDesc {
                name: "G-buffer",
                vertex: &vertex,
                fragment: &fragment,
                spec: &[],
                vertex_layout: Some(&mesh_vertex_layout()),
                layout: &layout,
                render_pass: render_pass.raw,
                depth_test: true,
                colours: QUARTERS,
            },
        )?;
        let eye = Buffer::with_data(
            dev,
            "G-buffer eye",
            vk::BufferUsageFlags::UNIFORM_BUFFER,
            &[EyeUbo { eye: [0.0; 4] }],
        )?;
        let set = DescriptorSet::new(
            dev,
            "G-buffer set",
            &layout,
            &[
                (0, Resource::Sampled(&texture, &sampler)),
                (1, Resource::Uniform(&eye)),
            ],
        )?;
        Ok(GBufferPass {
            target: None,
            set,
            eye,
            pipeline,
            _render_pass: render_pass,
            layout,
            _modules: [vertex, fragment],
            _sampler: sampler,
            _texture: texture,
            vertices,
            indices,
            index_count: mesh.indices.len() as u32,
            dev: Arc::clone(dev),
        })
    }

    /// The G-buffer as `camera` sees the mesh at `width`×`height`, `ss`×`ss` pixels to an
    /// output pixel: one pass writes the four quarters, read back in the same submission.
    pub fn draw(
        &mut self,
        camera: &Camera,
        (width, height, ss): (u32, u32, u32),
    ) -> Result<GBuffer> {
        if self.index_count == 0 {
            return Ok(GBuffer {
                width,
                height,
                covered: Vec::new(),
                data: Vec::new(),
            });
        }
        let fits = |t: &OffscreenTarget| t.extent.width == width && t.extent.height == height;
        if !self.target.as_ref().is_some_and(fits) {
            self.target = None;
            self.target = Some(OffscreenTarget::with_colours(
                &self.dev, width, height, QUARTERS,
            )?);
        }
        let e = camera.eye;
        self.eye.write(crate::gpu::memory::bytes_of(&[EyeUbo {
            eye: [e[0], e[1], e[2], 1.0],
        }]))?;
        let transforms = Transforms {
            model: glam::Mat4::IDENTITY.to_cols_array(),
            view_proj: camera
                .view_proj(width as f32 / height as f32)
                .to_cols_array(),
        };
        let target = self
            .target
            .as_ref()
            .ok_or_else(|| Error::invalid("G-buffer", "no target"))?;
        let dev = &self.dev;
        dev.submit_once("G-buffer", |cb| {
            // Zero marks an uncovered pixel.
            record_pass(
                dev,
                cb,
                &target.target(),
                &self.pipeline,
                &self.layout,
                &self.set,
                &Geometry::Mesh {
                    vertices: &self.vertices,
                    indices: &self.indices,
                    index_count: self.index_count,
                    transforms,
                },
                [0.0; 4],
            );
            target.record_readback(cb);
            Ok(())
        })?;
        let quarters = (0..QUARTERS as usize)
            .map(|k| target.read_rgba_at(k))
            .collect::<Result<Vec<_>>>()?;
        Ok(assemble(width, height, ss, &quarters))
    }
}

/// The covered pixels (the last quarter's `w` is 1 there, 0 where the clear stayed) and
/// their sixteen floats, with each pixel's key.
fn assemble(width: u32, height: u32, ss: u32, q: &[Vec<[f32; 4]>]) -> GBuffer {
    let covered: Vec<u32> = (0..width * height)
        .filter(|&i| q[3][i as usize][3] > 0.5)
        .collect();
    let ss = ss.max(1);
    let mut data = Vec::with_capacity(covered.len() * 16);
    for &i in &covered {
        let p = i as usize;
        let (x, y) = (i % width, i / width);
        let out = (y / ss) * (width / ss) + x / ss;
        let key = f32::from_bits((out << 4) | ((y % ss) * ss + x % ss));
        let [a, b, c, d] = [q[0][p], q[1][p], q[2][p], q[3][p]];
        data.extend_from_slice(&a);
        data.extend_from_slice(&b);
        data.extend_from_slice(&c);
        data.extend_from_slice(&[d[0], d[1], d[2], key]);
    }
    GBuffer {
        width,
        height,
        covered,
        data,
    }
}

/// The albedo as a linear float texture (float32 where the device filters it, else
/// float16), or a 1×1 black one.
fn albedo_image(dev: &Arc<Device>, albedo: Option<&Albedo>) -> Result<Image> {
    let (w, h, rgb): (u32, u32, Vec<[f32; 3]>) = match albedo {
        Some(a) => (a.width, a.height, a.rgb.clone()),
        None => (1, 1, vec![[0.0; 3]]),
    };
    let max = dev.info.max_image_dimension_2d;
    if w == 0 || h == 0 || w > max || h > max {
        return Err(Error::invalid(
            "texture size",
            format!("{w}×{h}; each side must be 1..={max} on this device"),
        ));
    }
    let linear = vk::FormatFeatureFlags::SAMPLED_IMAGE_FILTER_LINEAR;
    let wide = dev.supports_format(vk::Format::R32G32B32A32_SFLOAT, linear);
    let encode = |px: &[[f32; 3]]| -> Vec<u8> {
        let texels = px.iter().flat_map(|p| [p[0], p[1], p[2], 1.0]);
        if wide {
            texels.flat_map(f32::to_le_bytes).collect()
        } else {
            texels
                .flat_map(|x| crate::gpu::formats::f32_to_f16(x).to_le_bytes())
                .collect()
        }
    };
    let (format, texel) = if wide {
        (vk::Format::R32G32B32A32_SFLOAT, 16)
    } else {
        (vk::Format::R16G16B16A16_SFLOAT, 8)
    };
    // The mip chain, so a G-buffer pixel reads the albedo over its footprint.
    let levels: Vec<Vec<u8>> = std::iter::once(encode(&rgb))
        .chain(
            crate::image_io::mip_levels(w, h, |i| rgb[i])
                .iter()
                .map(|(_, _, px)| encode(px)),
        )
        .collect();
    let levels: Vec<&[u8]> = levels.iter().map(Vec::as_slice).collect();
    Image::sampled_with_mips(
        dev,
        "G-buffer albedo",
        ImageDesc {
            format,
            width: w,
            height: h,
            layers: 1,
            usage: vk::ImageUsageFlags::SAMPLED,
            aspect: vk::ImageAspectFlags::COLOR,
            view_type: vk::ImageViewType::TYPE_2D,
        },
        texel,
        &levels,
    )
}
