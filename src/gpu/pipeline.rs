//! Shader modules, descriptor-set and pipeline layouts, descriptor sets, and graphics
//! pipelines specialised by constants (one SPIR-V module, many pipelines: the driver removes
//! the code a variant does not use). Generic plumbing: the meaning of the constants and
//! bindings lives with the caller (`render.rs`) and the GLSL.

use std::io::Cursor;
use std::sync::Arc;

use ash::vk;

use super::context::Device;
use super::memory::{Buffer, Image, Sampler};
use crate::{Error, Result};

/// A SPIR-V shader module.
pub struct ShaderModule {
    dev: Arc<Device>,
    pub raw: vk::ShaderModule,
}

impl ShaderModule {
    /// Creates a module from SPIR-V bytes (any alignment: `read_spv` copies into u32 words).
    pub fn new(dev: &Arc<Device>, name: &str, spirv: &[u8]) -> Result<Self> {
        let words = ash::util::read_spv(&mut Cursor::new(spirv))
            .map_err(|e| Error::invalid("SPIR-V", format!("{name}: {e}")))?;
        let info = vk::ShaderModuleCreateInfo::default().code(&words);
        // SAFETY: words is a complete SPIR-V module compiled by build.rs.
        let raw = unsafe { dev.raw.create_shader_module(&info, None) }
            .map_err(Error::vk("vkCreateShaderModule"))?;
        dev.set_name(raw, name);
        Ok(Self {
            dev: dev.clone(),
            raw,
        })
    }
}

impl Drop for ShaderModule {
    fn drop(&mut self) {
        // SAFETY: modules are only needed during pipeline creation.
        unsafe { self.dev.raw.destroy_shader_module(self.raw, None) };
    }
}

/// One descriptor binding of set 0.
#[derive(Debug, Clone, Copy)]
pub struct Binding {
    pub binding: u32,
    pub kind: vk::DescriptorType,
    pub stages: vk::ShaderStageFlags,
}

/// A descriptor-set layout (set 0) and the pipeline layout built on it with one
/// push-constant range.
pub struct PipelineLayout {
    dev: Arc<Device>,
    pub set_layout: vk::DescriptorSetLayout,
    pub raw: vk::PipelineLayout,
    pub bindings: Vec<Binding>,
}

impl PipelineLayout {
    /// `push_constants`: stages and size in bytes of the range at offset 0 (size 0: none).
    pub fn new(
        dev: &Arc<Device>,
        name: &str,
        bindings: &[Binding],
        push_constants: (vk::ShaderStageFlags, u32),
    ) -> Result<Self> {
        let vk_bindings: Vec<_> = bindings
            .iter()
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b.binding)
                    .descriptor_type(b.kind)
                    .descriptor_count(1)
                    .stage_flags(b.stages)
            })
            .collect();
        let info = vk::DescriptorSetLayoutCreateInfo::default().bindings(&vk_bindings);
        // SAFETY: live device, valid create info.
        let set_layout = unsafe { dev.raw.create_descriptor_set_layout(&info, None) }
            .map_err(Error::vk("vkCreateDescriptorSetLayout"))?;
        let mut layout = PipelineLayout {
            dev: dev.clone(),
            set_layout,
            raw: vk::PipelineLayout::null(),
            bindings: bindings.to_vec(),
        };
        dev.set_name(set_layout, name);
        let set_layouts = [set_layout];
        let ranges = [vk::PushConstantRange {
            stage_flags: push_constants.0,
            offset: 0,
            size: push_constants.1,
        }];
        let mut info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
        if push_constants.1 > 0 {
            info = info.push_constant_ranges(&ranges);
        }
        // SAFETY: the set layout is live; the range fits maxPushConstantsSize (≥ 128).
        layout.raw = unsafe { dev.raw.create_pipeline_layout(&info, None) }
            .map_err(Error::vk("vkCreatePipelineLayout"))?;
        dev.set_name(layout.raw, name);
        Ok(layout)
    }
}

impl Drop for PipelineLayout {
    fn drop(&mut self) {
        // SAFETY: pipelines and sets using these layouts are gone or idle; reverse order.
        unsafe {
            if self.raw != vk::PipelineLayout::null() {
                self.dev.raw.destroy_pipeline_layout(self.raw, None);
            }
            self.dev
                .raw
                .destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

/// What a descriptor binding points at.
pub enum Resource<'a> {
    Uniform(&'a Buffer),
    Storage(&'a Buffer),
    Sampled(&'a Image, &'a Sampler),
}

/// One descriptor set with its own pool (destroying the pool frees the set).
pub struct DescriptorSet {
    dev: Arc<Device>,
    pool: vk::DescriptorPool,
    pub raw: vk::DescriptorSet,
}

impl DescriptorSet {
    /// Allocates a set of `layout` and points binding `i` at `resources[i]`.
    pub fn new(
        dev: &Arc<Device>,
        name: &str,
        layout: &PipelineLayout,
        resources: &[(u32, Resource<'_>)],
    ) -> Result<Self> {
        let sizes: Vec<_> = layout
            .bindings
            .iter()
            .map(|b| vk::DescriptorPoolSize {
                ty: b.kind,
                descriptor_count: 1,
            })
            .collect();
        let set = Self::allocate(dev, name, layout.set_layout, &sizes)?;

        let mut buffer_infos = Vec::new();
        let mut image_infos = Vec::new();
        for (_, r) in resources {
            match r {
                Resource::Uniform(b) | Resource::Storage(b) => {
                    buffer_infos.push([vk::DescriptorBufferInfo {
                        buffer: b.raw,
                        offset: 0,
                        range: vk::WHOLE_SIZE,
                    }])
                }
                Resource::Sampled(i, s) => image_infos.push([vk::DescriptorImageInfo {
                    sampler: s.raw,
                    image_view: i.view,
                    image_layout: vk::ImageLayout::SHADER_READ_ONLY_OPTIMAL,
                }]),
            }
        }
        let (mut bi, mut ii) = (0, 0);
        let writes: Vec<_> = resources
            .iter()
            .map(|(binding, r)| {
                let w = vk::WriteDescriptorSet::default()
                    .dst_set(set.raw)
                    .dst_binding(*binding);
                match r {
                    Resource::Uniform(_) | Resource::Storage(_) => {
                        let kind = if matches!(r, Resource::Uniform(_)) {
                            vk::DescriptorType::UNIFORM_BUFFER
                        } else {
                            vk::DescriptorType::STORAGE_BUFFER
                        };
                        bi += 1;
                        w.descriptor_type(kind).buffer_info(&buffer_infos[bi - 1])
                    }
                    Resource::Sampled(..) => {
                        ii += 1;
                        w.descriptor_type(vk::DescriptorType::COMBINED_IMAGE_SAMPLER)
                            .image_info(&image_infos[ii - 1])
                    }
                }
            })
            .collect();
        // SAFETY: all infos outlive the call; the resources are live and match the layout.
        unsafe { dev.raw.update_descriptor_sets(&writes, &[]) };
        Ok(set)
    }
}

impl DescriptorSet {
    /// One set of `set_layout` from a pool of its own that holds `sizes` (the graphics
    /// passes' sets and the compute builds' storage sets alike).
    pub(crate) fn allocate(
        dev: &Arc<Device>,
        name: &str,
        set_layout: vk::DescriptorSetLayout,
        sizes: &[vk::DescriptorPoolSize],
    ) -> Result<Self> {
        let info = vk::DescriptorPoolCreateInfo::default()
            .max_sets(1)
            .pool_sizes(sizes);
        // SAFETY: live device, valid create info.
        let pool = unsafe { dev.raw.create_descriptor_pool(&info, None) }
            .map_err(Error::vk("vkCreateDescriptorPool"))?;
        let mut set = DescriptorSet {
            dev: dev.clone(),
            pool,
            raw: vk::DescriptorSet::null(),
        };
        dev.set_name(pool, name);
        let layouts = [set_layout];
        let alloc = vk::DescriptorSetAllocateInfo::default()
            .descriptor_pool(pool)
            .set_layouts(&layouts);
        // SAFETY: the pool has room for exactly this set.
        set.raw = unsafe { dev.raw.allocate_descriptor_sets(&alloc) }
            .map_err(Error::vk("vkAllocateDescriptorSets"))?[0];
        dev.set_name(set.raw, name);
        Ok(set)
    }
}

impl Drop for DescriptorSet {
    fn drop(&mut self) {
        // SAFETY: no pending GPU work uses the set (submissions are waited on).
        unsafe { self.dev.raw.destroy_descriptor_pool(self.pool, None) };
    }
}

/// Vertex input: one interleaved binding.
#[derive(Debug, Clone)]
pub struct VertexLayout {
    pub stride: u32,
    /// `(location, format, offset)` of each attribute.
    pub attributes: Vec<(u32, vk::Format, u32)>,
}

/// How to build a graphics pipeline.
pub struct PipelineDesc<'a> {
    pub name: &'a str,
    pub vertex: &'a ShaderModule,
    pub fragment: &'a ShaderModule,
    /// Specialisation constants `constant_id = i` ↦ `spec[i]` (ints and VkBool32 are both
    /// 4 bytes), applied to both stages.
    pub spec: &'a [u32],
    /// `None`: no vertex buffers (e.g. a full-screen triangle from `gl_VertexIndex`).
    pub vertex_layout: Option<&'a VertexLayout>,
    pub layout: &'a PipelineLayout,
    pub render_pass: vk::RenderPass,
    pub depth_test: bool,
    /// Colour attachments the fragment stage writes (outputs `0..n`), none blended.
    pub colours: u32,
}

/// A graphics pipeline (viewport and scissor are dynamic).
pub struct Pipeline {
    dev: Arc<Device>,
    pub raw: vk::Pipeline,
}

impl Pipeline {
    pub fn new(dev: &Arc<Device>, desc: &PipelineDesc<'_>) -> Result<Self> {
        let entries: Vec<_> = (0..desc.spec.len() as u32)
            .map(|i| vk::SpecializationMapEntry {
                constant_id: i,
                offset: 4 * i,
                size: 4,
            })
            .collect();
        let spec_bytes = super::memory::bytes_of(desc.spec);
        let spec = vk::SpecializationInfo::default()
            .map_entries(&entries)
            .data(spec_bytes);
        let stages = [
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::VERTEX)
                .module(desc.vertex.raw)
                .name(c"main")
                .specialization_info(&spec),
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::FRAGMENT)
                .module(desc.fragment.raw)
                .name(c"main")
                .specialization_info(&spec),
        ];
        let (vb, va): (Vec<_>, Vec<_>) = match desc.vertex_layout {
            Some(l) => (
                vec![vk::VertexInputBindingDescription {
                    binding: 0,
                    stride: l.stride,
                    input_rate: vk::VertexInputRate::VERTEX,
                }],
                l.attributes
                    .iter()
                    .map(
                        |&(location, format, offset)| vk::VertexInputAttributeDescription {
                            location,
                            binding: 0,
                            format,
                            offset,
                        },
                    )
                    .collect(),
            ),
            None => (Vec::new(), Vec::new()),
        };
        let vertex_input = vk::PipelineVertexInputStateCreateInfo::default()
            .vertex_binding_descriptions(&vb)
            .vertex_attribute_descriptions(&va);
        let input_assembly = vk::PipelineInputAssemblyStateCreateInfo::default()
            .topology(vk::PrimitiveTopology::TRIANGLE_LIST);
        let viewport = vk::PipelineViewportStateCreateInfo::default()
            .viewport_count(1)
            .scissor_count(1);
        // No culling: open meshes show their back faces, which the shader leaves unlit.
        let raster = vk::PipelineRasterizationStateCreateInfo::default()
            .polygon_mode(vk::PolygonMode::FILL)
            .cull_mode(vk::CullModeFlags::NONE)
            .front_face(vk::FrontFace::COUNTER_CLOCKWISE)
            .line_width(1.0);
        let multisample = vk::PipelineMultisampleStateCreateInfo::default()
            .rasterization_samples(vk::SampleCountFlags::TYPE_1);
        let depth = vk::PipelineDepthStencilStateCreateInfo::default()
            .depth_test_enable(desc.depth_test)
            .depth_write_enable(desc.depth_test)
            .depth_compare_op(vk::CompareOp::LESS);
        let attachments = vec![
            vk::PipelineColorBlendAttachmentState::default()
                .color_write_mask(vk::ColorComponentFlags::RGBA);
            desc.colours.max(1) as usize
        ];
        let blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&attachments);
        let dynamic_states = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
        let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
        let info = vk::GraphicsPipelineCreateInfo::default()
            .stages(&stages)
            .vertex_input_state(&vertex_input)
            .input_assembly_state(&input_assembly)
            .viewport_state(&viewport)
            .rasterization_state(&raster)
            .multisample_state(&multisample)
            .depth_stencil_state(&depth)
            .color_blend_state(&blend)
            .dynamic_state(&dynamic)
            .layout(desc.layout.raw)
            .render_pass(desc.render_pass)
            .subpass(0);
        // SAFETY: all state structs outlive the call; modules, layout and render pass are
        // live and compatible (subpass 0 has one colour and one depth attachment); the cache
        // is the device's.
        let raw = dev
            .with_pipeline_cache(|cache| unsafe {
                dev.raw.create_graphics_pipelines(cache, &[info], None)
            })
            .map_err(|(_, e)| Error::vk("vkCreateGraphicsPipelines")(e))?[0];
        dev.set_name(raw, desc.name);
        Ok(Self {
            dev: dev.clone(),
            raw,
        })
    }
}

impl Drop for Pipeline {
    fn drop(&mut self) {
        // SAFETY: no pending GPU work uses the pipeline (submissions are waited on, or the
        // owner was retired through the frames' deferred release).
        unsafe { self.dev.raw.destroy_pipeline(self.raw, None) };
    }
}
