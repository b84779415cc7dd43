//! A [`ScenePass`]: the objects one kind of picture needs (pipeline layout, descriptor set,
//! pipeline for one render pass, uniform and mesh buffers), built once and recorded into any
//! [`Target`] — the offscreen target of `render` or a swapchain image of the viewer.
//! Camera, light and exposure change through [`ScenePass::set_view`] without rebuilding.
//!
//! The uniform block is written with `vkCmdUpdateBuffer` inside each recorded frame, so
//! frames in flight never race a host write.

use std::sync::Arc;

use ash::vk;

use super::params::{colour_weights, OutputMode, ParamsUbo};
use super::record::mesh_vertex_layout;
use super::record::{begin_pass, end_pass, record_draw, record_pass, Geometry, Transforms};
use super::variant::{PreparedVariant, VariantStats};
use super::variant::{SpecConstant, Specialisation};
use super::Renderer;
use crate::gpu::memory::{bytes_of, Buffer, Image, ImageDesc};
use crate::gpu::pipeline::{
    Binding, DescriptorSet, Pipeline, PipelineDesc, PipelineLayout, Resource, ShaderModule,
};
use crate::gpu::shaders;
use crate::gpu::target::Target;
use crate::gpu::Device;
use crate::material::PreparedMaterial;
use crate::scene::{Camera, Light};
use crate::{Error, Result};

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
    pub(crate) _texture: Arc<Image>,
    pub(crate) mesh: Option<Arc<MeshBuffers>>,
    pub(crate) params: ParamsUbo,
    pub(crate) transforms: Transforms,
    pub(crate) clear: [f32; 4],
    pub(crate) stats: VariantStats,
    /// The variant's images and buffers the descriptor set points at: kept alive here even
    /// when the renderer prepares another variant.
    pub(crate) _variant: Arc<dyn PreparedVariant>,
    pub(crate) _fragment: Arc<ShaderModule>,
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

impl Renderer {
    /// The fragment shader of the current variant, or the vertex shader `name`: the
    /// run-time override when there is one, else the SPIR-V built in. Made once per name
    /// and shared ([`Renderer::set_shader_overrides`] starts afresh).
    pub(super) fn shader(&self, name: &str, built_in: &'static [u8]) -> Result<Arc<ShaderModule>> {
        if let Some(m) = self.modules.lock().ok().and_then(|m| m.get(name).cloned()) {
            return Ok(m);
        }
        let spirv = self
            .shader_overrides
            .get(name)
            .map_or(built_in, Vec::as_slice);
        let module = Arc::new(ShaderModule::new(&self.dev, name, spirv)?);
        if let Ok(mut m) = self.modules.lock() {
            m.insert(name.to_string(), Arc::clone(&module));
        }
        Ok(module)
    }

    /// The 1×1 white texture bound where a scene has none, made on first use and shared.
    fn white(&self) -> Result<Arc<Image>> {
        if let Some(w) = self.white.get() {
            return Ok(Arc::clone(w));
        }
        let w = Arc::new(white_texture(&self.dev)?);
        Ok(Arc::clone(self.white.get_or_init(|| w)))
    }

    /// The current variant's per-vertex stage (thesis §1.5.1), or why it has none.
    pub(super) fn per_vertex_shader(&self) -> Result<Arc<ShaderModule>> {
        let Some(name) = self.variant.per_vertex_file() else {
            return Err(Error::invalid(
                "per-vertex",
                format!(
                    "'{}' has no per-vertex evaluation (its table lookup already costs about as much as a vertex; per-vertex is built for flss, nmm and pq)",
                    self.variant
                ),
            ));
        };
        self.shader(name, built_in(name)?)
    }

    /// Builds a pass: layout, uniform and colour buffers, descriptor set and a pipeline for
    /// `render_pass` specialised for `output` and `options`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn build_pass(
        &self,
        prepared: &PreparedMaterial,
        params: ParamsUbo,
        output: OutputMode,
        options: PassOptions,
        mesh: Option<(Arc<MeshBuffers>, Transforms)>,
        clear: [f32; 4],
        texture: Option<Arc<Image>>,
        render_pass: vk::RenderPass,
    ) -> Result<ScenePass> {
        let dev = &self.dev;
        let Some((key, variant)) = &self.prepared else {
            return Err(Error::invalid("variant", "no variant prepared"));
        };
        let per_vertex = self.per_vertex && mesh.is_some();
        let bindings = pass_bindings(variant.as_ref(), per_vertex);
        let mut stats = variant.stats();
        if per_vertex {
            stats.name = format!("{} per-vertex", stats.name);
        }
        let layout = PipelineLayout::new(
            dev,
            &format!("{} layout", stats.name),
            &bindings,
            (
                vk::ShaderStageFlags::VERTEX,
                std::mem::size_of::<Transforms>() as u32,
            ),
        )?;
        let colour = colour_weights(prepared, variant.as_ref(), &key.table.response);
        let (ubo, colour) = pass_buffers(dev, &colour, &params)?;
        let texture_blending = texture.is_some();
        // The texture binding is statically used by the shader, so it always needs an
        // image; a scene without a texture gets 1×1 white (the variant never samples it).
        let texture = match texture {
            Some(t) => t,
            None => self.white()?,
        };
        let mut resources = vec![
            (0, Resource::Uniform(&ubo)),
            (2, Resource::Storage(&colour)),
            (3, Resource::Sampled(&texture, &self.linear)),
        ];
        resources.extend(variant.resources());
        let set = DescriptorSet::new(dev, "diffraction set", &layout, &resources)?;
        let (pipeline, fragment) = self.pass_pipeline(
            variant.as_ref(),
            output,
            options,
            PipelineShape {
                per_vertex,
                mesh: mesh.is_some(),
                texture_blending,
            },
            &layout,
            render_pass,
        )?;
        let no_transforms = Transforms {
            model: [0.0; 16],
            view_proj: [0.0; 16],
        };
        let (mesh, transforms) = mesh.map_or((None, no_transforms), |(m, t)| (Some(m), t));
        Ok(ScenePass {
            pipeline,
            set,
            layout,
            ubo,
            _colour: colour,
            _texture: texture,
            mesh,
            params,
            transforms,
            clear,
            stats,
            _variant: Arc::clone(variant),
            _fragment: fragment,
            dev: dev.clone(),
        })
    }

    /// The pipeline of a pass and its fragment module: the vertex stage (the map's, the
    /// mesh's, per-vertex evaluation or a hot-reloaded one), the variant's fragment stage,
    /// and the specialisation constants of `output`, `options` and `shape`.
    fn pass_pipeline(
        &self,
        variant: &dyn PreparedVariant,
        output: OutputMode,
        options: PassOptions,
        shape: PipelineShape,
        layout: &PipelineLayout,
        render_pass: vk::RenderPass,
    ) -> Result<(Pipeline, Arc<ShaderModule>)> {
        let (vertex_name, vertex_layout, depth_test) = match shape.mesh {
            false => ("brdfmap.vert", None, false),
            true => ("diffraction.vert", Some(mesh_vertex_layout()), true),
        };
        let override_vertex = if shape.per_vertex {
            Some(self.per_vertex_shader()?)
        } else if self.shader_overrides.contains_key(vertex_name) {
            Some(self.shader(vertex_name, &[])?)
        } else {
            None
        };
        let vertex = match (&override_vertex, shape.mesh) {
            (Some(v), _) => v,
            (None, false) => &self.vert_map,
            (None, true) => &self.vert_mesh,
        };
        let mut spec = Specialisation::default();
        spec[SpecConstant::Shadowing] = options.shadowing as u32;
        spec[SpecConstant::Fresnel] = options.fresnel as u32;
        spec[SpecConstant::TextureBlending] = shape.texture_blending as u32;
        spec[SpecConstant::OutputMode] = output as u32;
        variant.specialise(&mut spec);
        let fragment = if shape.per_vertex {
            self.shader("per_vertex.frag", shaders::PER_VERTEX_FRAG)?
        } else {
            let file = self.variant.fragment_file();
            self.shader(file, built_in(file)?)?
        };
        let name = format!(
            "{} {output:?}{}{}{}",
            variant.pipeline_name(),
            if options.fresnel { " fresnel" } else { "" },
            if options.shadowing { " shadowing" } else { "" },
            if shape.texture_blending {
                " texture"
            } else {
                ""
            },
        );
        let pipeline = Pipeline::new(
            &self.dev,
            &PipelineDesc {
                name: &name,
                vertex,
                fragment: &fragment,
                spec: spec.values(),
                vertex_layout: vertex_layout.as_ref(),
                layout,
                render_pass,
                depth_test,
                colours: 1,
            },
        )?;
        Ok((pipeline, fragment))
    }
}

/// The SPIR-V build.rs compiled from glsl/`file`; an error names a stage a variant declares
/// but glsl/ does not have (the registry test renders every variant, so it shows there).
pub(super) fn built_in(file: &str) -> Result<&'static [u8]> {
    shaders::spirv(file).ok_or_else(|| {
        Error::invalid(
            "shader",
            format!("glsl/{file} was not compiled into this build"),
        )
    })
}

/// The descriptor bindings of a pass: the uniform block (0), the colour table (2), the
/// texture (3) and the variant's own; with `per_vertex` the vertex stage reads the colour
/// table and the variant's resources too.
pub(super) fn pass_bindings(variant: &dyn PreparedVariant, per_vertex: bool) -> Vec<Binding> {
    let stages = vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT;
    let mut bindings = vec![
        Binding {
            binding: 0,
            kind: vk::DescriptorType::UNIFORM_BUFFER,
            stages,
        },
        Binding {
            binding: 2,
            kind: vk::DescriptorType::STORAGE_BUFFER,
            stages: vk::ShaderStageFlags::FRAGMENT,
        },
        Binding {
            binding: 3,
            kind: vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
            stages: vk::ShaderStageFlags::FRAGMENT,
        },
    ];
    bindings.extend(variant.bindings().into_iter().map(|mut b| {
        if per_vertex {
            b.stages |= vk::ShaderStageFlags::VERTEX;
        }
        b
    }));
    if per_vertex {
        bindings[1].stages |= vk::ShaderStageFlags::VERTEX;
    }
    bindings
}

/// A pass's uniform block (binding 0, holding `params`) and colour table (binding 2).
fn pass_buffers(
    dev: &Arc<Device>,
    colour: &[[f32; 4]],
    params: &ParamsUbo,
) -> Result<(Buffer, Buffer)> {
    // Device-written per frame (ScenePass::record), so TRANSFER_DST too.
    let ubo = Buffer::with_data(
        dev,
        "params",
        vk::BufferUsageFlags::UNIFORM_BUFFER | vk::BufferUsageFlags::TRANSFER_DST,
        std::slice::from_ref(params),
    )?;
    let colour = Buffer::with_data(
        dev,
        "colour weights",
        vk::BufferUsageFlags::STORAGE_BUFFER,
        colour,
    )?;
    Ok((ubo, colour))
}

/// The 1×1 white texture bound where a scene has none (the binding is statically used, so
/// it always needs an image; the variant never samples it then).
pub(super) fn white_texture(dev: &Arc<Device>) -> Result<Image> {
    Image::sampled_with_data(
        dev,
        "no texture (1×1 white)",
        ImageDesc {
            format: vk::Format::R8G8B8A8_UNORM,
            width: 1,
            height: 1,
            layers: 1,
            usage: vk::ImageUsageFlags::SAMPLED,
            aspect: vk::ImageAspectFlags::COLOR,
            view_type: vk::ImageViewType::TYPE_2D,
        },
        4,
        &[255u8; 4],
    )
}

/// What a pass's pipeline is specialised for besides the output and the options.
#[derive(Debug, Clone, Copy)]
struct PipelineShape {
    /// The variant evaluates per vertex (a mesh only).
    per_vertex: bool,
    /// A mesh (depth-tested, the mesh's vertex layout) rather than a BRDF map.
    mesh: bool,
    texture_blending: bool,
}
