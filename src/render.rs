//! Frames of the diffraction shaders: turns a prepared material (and a scene) into GPU
//! inputs — the term image array, the colour table, the `Params` uniform block, the
//! specialisation constants of the variant — records one frame into a target, and reads
//! the linear result back. Also the `diffract render` command.
//!
//! This is where physics meets `gpu`: the layouts here mirror `glsl/interface.glsl`. Frame
//! recording (`record_frame`) takes a [`FrameTarget`] and does not know whether it draws
//! offscreen or into a window.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use ash::vk;

use crate::brdf;
use crate::gpu::formats::{pack_layers, Layer};
use crate::gpu::memory::{Buffer, Image, ImageDesc, Pod, Sampler};
use crate::gpu::pipeline::{
    Binding, DescriptorSet, Pipeline, PipelineDesc, PipelineLayout, Resource, ShaderModule,
    VertexLayout,
};
use crate::gpu::target::{FrameTarget, OffscreenTarget};
use crate::gpu::timer::GpuTimer;
use crate::gpu::{shaders, Device, StorageFormat};
use crate::material::{MaterialArgs, PreparedMaterial};
use crate::mesh::Vertex;
use crate::scene::Scene;
use crate::spectrum::Expansion;
use crate::{Error, Result};

/// Capacity of the shader's per-term decode table (`MAX_TERMS` in interface.glsl).
const MAX_TERMS: usize = 65;
/// Largest BRDF map side.
pub const MAX_MAP_SIZE: u32 = 4096;

/// One rendered image, linear values, row-major from the top row.
#[derive(Debug, Clone)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// Linear sRGB (scenes), XYZ (BRDF maps) or `ρ_λ` in all channels (spectral maps).
    pub rgb: Vec<[f32; 3]>,
    /// GPU time of the draw from timestamps; `None` where the queue has none.
    pub gpu_ms: Option<f64>,
    /// Wall time of the whole call: uploads, pipeline creation, draw and readback.
    pub wall_ms: f64,
}

impl Frame {
    /// Pixel `(x, y)`, `y` from the top.
    pub fn at(&self, x: u32, y: u32) -> [f32; 3] {
        self.rgb[(y * self.width + x) as usize]
    }
}

/// What the fragment shader writes (`OUTPUT_MODE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum OutputMode {
    Mesh = 0,
    MapXyz = 1,
    MapSpectral = 2,
}

/// Mirror of `Params` in glsl/interface.glsl (std140: vec4-sized members only).
#[repr(C)]
#[derive(Clone, Copy)]
struct ParamsUbo {
    eye_world: [f32; 4],
    light_dir_world: [f32; 4],
    lighting: [f32; 4],
    map_wi: [f32; 4],
    map_info: [f32; 4],
    spectrum_size: [i32; 4],
    band: [i32; 4],
    lookup: [f32; 4],
    shading: [f32; 4],
    decode: [[f32; 4]; MAX_TERMS],
}

// SAFETY: repr(C) of 4-byte scalars in 16-byte groups: no padding.
unsafe impl Pod for ParamsUbo {}

/// Mirror of the push-constant block of diffraction.vert.
#[repr(C)]
#[derive(Clone, Copy)]
struct Transforms {
    model: [f32; 16],
    view_proj: [f32; 16],
}

// SAFETY: repr(C) of f32 arrays: no padding.
unsafe impl Pod for Transforms {}

// SAFETY: mesh::Vertex is repr(C) with 12 f32 fields (48 bytes, asserted there): no padding.
unsafe impl Pod for Vertex {}

/// The specialisation constants of one pipeline (constant ids 0..=8 of interface.glsl).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Variant {
    terms: u32,
    window_radius: u32,
    lambda_step_nm: u32,
    expansion: Expansion,
    shadowing: bool,
    fresnel: bool,
    texture_blending: bool,
    storage: StorageFormat,
    output: OutputMode,
}

impl Variant {
    fn of(prepared: &PreparedMaterial, storage: StorageFormat, output: OutputMode) -> Self {
        Variant {
            terms: prepared
                .terms()
                .min(prepared.stack.term_count().saturating_sub(1)) as u32,
            window_radius: prepared.window.radius as u32,
            lambda_step_nm: prepared.colour.step_nm,
            expansion: prepared.stack.expansion,
            shadowing: prepared.shading.shadowing,
            fresnel: prepared.shading.fresnel,
            texture_blending: false,
            storage,
            output,
        }
    }

    fn spec(&self) -> [u32; 9] {
        [
            self.terms,
            self.window_radius,
            self.lambda_step_nm,
            match self.expansion {
                Expansion::Taylor => 0,
                Expansion::Chebyshev => 1,
            },
            self.shadowing as u32,
            self.fresnel as u32,
            self.texture_blending as u32,
            self.storage.spec_value(),
            self.output as u32,
        ]
    }

    fn name(&self) -> String {
        format!(
            "diffraction {:?} T={} R={} dλ={} {} {}{}{}{}",
            self.output,
            self.terms,
            self.window_radius,
            self.lambda_step_nm,
            self.expansion,
            self.storage,
            if self.fresnel { " fresnel" } else { "" },
            if self.shadowing { " shadowing" } else { "" },
            if self.texture_blending {
                " texture"
            } else {
                ""
            },
        )
    }
}

/// GPU copies of a prepared material.
struct MaterialGpu {
    terms: Image,
    colour: Buffer,
    decode: Vec<[f32; 4]>,
}

/// Geometry of one draw.
enum Geometry<'a> {
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

/// Map pixel `(i, j)` of an `S×S` BRDF map → `ωr`, exactly as the fragment shader computes
/// it in float32 (README: BRDF maps); `None` outside the unit disk.
pub fn map_direction(i: u32, j: u32, size: u32) -> Option<[f64; 3]> {
    let s = size as f32;
    let x = 2.0 * (i as f32 + 0.5) / s - 1.0;
    let y = 1.0 - 2.0 * (j as f32 + 0.5) / s;
    let r2 = x * x + y * y;
    (r2 < 1.0).then(|| [x as f64, y as f64, (1.0 - r2).sqrt() as f64])
}

/// Owns the GPU device and what every frame shares (shaders, layouts, samplers).
pub struct Renderer {
    storage: StorageFormat,
    nearest: Sampler,
    linear: Sampler,
    frag: ShaderModule,
    vert_map: ShaderModule,
    vert_mesh: ShaderModule,
    layout: PipelineLayout,
    /// Last: everything above holds handles of this device.
    dev: Arc<Device>,
}

impl Renderer {
    /// Opens the preferred Vulkan device. `validation` enables the Khronos validation layer;
    /// its WARNING/ERROR messages are counted in [`Renderer::validation_messages`].
    pub fn new(validation: bool) -> Result<Self> {
        let dev = Device::new(validation)?;
        let stages = vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT;
        let layout = PipelineLayout::new(
            &dev,
            "diffraction layout",
            &[
                Binding {
                    binding: 0,
                    kind: vk::DescriptorType::UNIFORM_BUFFER,
                    stages,
                },
                Binding {
                    binding: 1,
                    kind: vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
                    stages: vk::ShaderStageFlags::FRAGMENT,
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
            ],
            (
                vk::ShaderStageFlags::VERTEX,
                std::mem::size_of::<Transforms>() as u32,
            ),
        )?;
        Ok(Self {
            storage: StorageFormat::default(),
            nearest: Sampler::new(
                &dev,
                "dft terms (nearest)",
                vk::Filter::NEAREST,
                vk::SamplerAddressMode::CLAMP_TO_EDGE,
            )?,
            linear: Sampler::new(
                &dev,
                "surface texture (linear)",
                vk::Filter::LINEAR,
                vk::SamplerAddressMode::REPEAT,
            )?,
            frag: ShaderModule::new(&dev, "diffraction.frag", shaders::DIFFRACTION_FRAG)?,
            vert_map: ShaderModule::new(&dev, "brdfmap.vert", shaders::BRDFMAP_VERT)?,
            vert_mesh: ShaderModule::new(&dev, "diffraction.vert", shaders::DIFFRACTION_VERT)?,
            layout,
            dev,
        })
    }

    /// Name of the Vulkan device in use.
    pub fn device_name(&self) -> &str {
        &self.dev.info.name
    }

    /// Validation WARNING/ERROR messages seen so far (0 without validation).
    pub fn validation_messages(&self) -> usize {
        self.dev.validation_messages()
    }

    /// The validation canary, which stays readable after the renderer is dropped: teardown
    /// messages (objects left alive at vkDestroyDevice) land there too.
    pub fn canary(&self) -> std::sync::Arc<crate::gpu::Canary> {
        self.dev.canary()
    }

    /// The first validation messages, for reports.
    pub fn validation_report(&self) -> Vec<String> {
        self.dev.validation_report()
    }

    /// Storage format of the DFT terms for the next frames (default RG32F).
    pub fn set_storage_format(&mut self, storage: StorageFormat) {
        self.storage = storage;
    }

    /// The storage format in use.
    pub fn storage_format(&self) -> StorageFormat {
        self.storage
    }

    /// A BRDF map (thesis §5): an S×S image of the hemisphere of view directions, pixel
    /// `(i, j)` (row `j` from the top) at `x = 2(i+½)/S − 1`, `y = 1 − 2(j+½)/S`,
    /// `ωr = (x, y, √(1−x²−y²))`, black outside the unit disk; light from `(θi, φi)`.
    /// Channels: linear XYZ, or `ρ_λ` in all three with `lambda_nm`.
    pub fn render_brdf_map(
        &mut self,
        prepared: &PreparedMaterial,
        theta_i_deg: f64,
        phi_i_deg: f64,
        size: u32,
        lambda_nm: Option<f64>,
    ) -> Result<Frame> {
        let start = Instant::now();
        if size == 0 || size > MAX_MAP_SIZE {
            return Err(Error::invalid(
                "BRDF map size",
                format!("{size}; expected 1..={MAX_MAP_SIZE} pixels"),
            ));
        }
        if !(theta_i_deg.is_finite() && (0.0..=90.0).contains(&theta_i_deg)) {
            return Err(Error::invalid(
                "theta-i",
                format!("{theta_i_deg}°; expected 0..=90° from the normal"),
            ));
        }
        if !phi_i_deg.is_finite() {
            return Err(Error::invalid("phi-i", format!("{phi_i_deg}°")));
        }
        let lo = crate::colour::LAMBDA_MIN_NM as f64;
        let hi = crate::colour::LAMBDA_MAX_NM as f64;
        if let Some(l) = lambda_nm {
            if !(l.is_finite() && (lo..=hi).contains(&l)) {
                return Err(Error::invalid(
                    "wavelength",
                    format!("{l} nm; expected {lo}..={hi} nm"),
                ));
            }
        }
        let wi = brdf::direction(theta_i_deg, phi_i_deg);
        let output = if lambda_nm.is_some() {
            OutputMode::MapSpectral
        } else {
            OutputMode::MapXyz
        };
        let material = self.upload_material(prepared)?;
        let mut params = self.params(prepared, &material);
        params.map_wi = [
            wi[0] as f32,
            wi[1] as f32,
            wi[2] as f32,
            lambda_nm.map_or(0.0, |l| (l * 1e-3) as f32),
        ];
        params.map_info = [size as f32, 0.0, 0.0, 0.0];
        let variant = Variant::of(prepared, self.storage, output);
        let mut frame = self.draw(
            &material,
            &params,
            &variant,
            Geometry::FullScreen,
            (size, size),
            [0.0; 4],
            None,
        )?;
        frame.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(frame)
    }

    /// Renders `scene`'s mesh with the diffraction shader (thesis Algorithms 2–4) using
    /// `prepared` as the material (callers prepare `scene.material`, possibly overridden).
    /// Pixels are linear sRGB already multiplied by the light intensity, `cosθi` and the
    /// scene's exposure; uncovered pixels hold the background colour as given.
    pub fn render_scene(&mut self, scene: &Scene, prepared: &PreparedMaterial) -> Result<Frame> {
        let start = Instant::now();
        // World space: the placement is already applied, so the model matrix is identity.
        let mesh = scene.mesh.load()?;
        if mesh.indices.is_empty() {
            return Err(Error::invalid(
                "mesh",
                format!("'{}' has no triangles", mesh.name),
            ));
        }
        let out = &scene.output;
        let material = self.upload_material(prepared)?;
        let mut params = self.params(prepared, &material);
        let eye = scene.camera.eye;
        params.eye_world = [eye[0], eye[1], eye[2], 1.0];
        let d = scene.light.direction;
        params.light_dir_world = [d[0], d[1], d[2], 0.0];
        let w_diffuse = scene.texture.as_ref().map_or(0.0, |t| t.w_diffuse);
        params.lighting = [scene.light.intensity, out.exposure, w_diffuse, 0.0];
        let bg = out.background;

        let texture = match &scene.texture {
            Some(t) => Some(self.upload_texture(t)?),
            None => None,
        };
        let mut variant = Variant::of(prepared, self.storage, OutputMode::Mesh);
        variant.texture_blending = texture.is_some();

        let vertices = Buffer::with_data(
            &self.dev,
            &format!("{} vertices", mesh.name),
            vk::BufferUsageFlags::VERTEX_BUFFER,
            &mesh.vertices,
        )?;
        let indices = Buffer::with_data(
            &self.dev,
            &format!("{} indices", mesh.name),
            vk::BufferUsageFlags::INDEX_BUFFER,
            &mesh.indices,
        )?;
        let transforms = Transforms {
            model: glam::Mat4::IDENTITY.to_cols_array(),
            view_proj: scene.camera.view_proj(out.aspect()).to_cols_array(),
        };
        let mut frame = self.draw(
            &material,
            &params,
            &variant,
            Geometry::Mesh {
                vertices: &vertices,
                indices: &indices,
                index_count: mesh.indices.len() as u32,
                transforms,
            },
            (out.width, out.height),
            [bg[0], bg[1], bg[2], 1.0],
            texture.as_ref(),
        )?;
        frame.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(frame)
    }

    /// Loads a scene texture (sRGB PNG) into an `R8G8B8A8_SRGB` image, so sampling returns
    /// linear colour.
    fn upload_texture(&self, spec: &crate::scene::TextureSpec) -> Result<Image> {
        let (w, h, rgb) = spec.load()?;
        let max = self.dev.info.max_image_dimension_2d;
        if w == 0 || h == 0 || w > max || h > max {
            return Err(Error::Image {
                path: spec.path.clone(),
                msg: format!("{w}×{h} texture; each side must be 1..={max} on this device"),
            });
        }
        let bytes: Vec<u8> = rgb.iter().flat_map(|p| [p[0], p[1], p[2], 255]).collect();
        Image::sampled_with_data(
            &self.dev,
            "surface texture",
            ImageDesc {
                format: vk::Format::R8G8B8A8_SRGB,
                width: w,
                height: h,
                layers: 1,
                usage: vk::ImageUsageFlags::SAMPLED,
                aspect: vk::ImageAspectFlags::COLOR,
                view_type: vk::ImageViewType::TYPE_2D,
            },
            4,
            &bytes,
        )
    }

    /// Uploads the term stack (cropped band, one layer per term, in the storage format) and
    /// the colour table.
    fn upload_material(&self, prepared: &PreparedMaterial) -> Result<MaterialGpu> {
        let stack = &prepared.stack;
        let layers = stack.term_count();
        if layers == 0 || layers > MAX_TERMS {
            return Err(Error::invalid(
                "terms",
                format!("{layers} term layers; the shader holds 1..={MAX_TERMS}"),
            ));
        }
        let (w, h) = (stack.band.width as u32, stack.band.height as u32);
        let info = &self.dev.info;
        if w > info.max_image_dimension_2d
            || h > info.max_image_dimension_2d
            || layers as u32 > info.max_image_array_layers
        {
            return Err(Error::invalid(
                "terms",
                format!(
                    "{w}×{h}×{layers} texels exceed the device limits ({} a side, {} layers)",
                    info.max_image_dimension_2d, info.max_image_array_layers
                ),
            ));
        }
        let format = self.storage.vk_format();
        if !self
            .dev
            .supports_format(format, vk::FormatFeatureFlags::SAMPLED_IMAGE)
        {
            return Err(Error::invalid(
                "storage format",
                format!("{} cannot sample {format:?}", info.name),
            ));
        }
        let texels: Vec<Vec<[f64; 2]>> = stack
            .terms
            .iter()
            .map(|t| t.iter().map(|c| [c.re, c.im]).collect())
            .collect();
        let packed: Vec<Layer<'_>> = texels
            .iter()
            .zip(&stack.extrema)
            .map(|(t, e)| Layer {
                texels: t,
                extrema: [e.re_min, e.re_max, e.im_min, e.im_max],
            })
            .collect();
        let (bytes, decode) = pack_layers(&packed, self.storage);
        let terms = Image::sampled_with_data(
            &self.dev,
            "dft terms",
            ImageDesc {
                format,
                width: w,
                height: h,
                layers: layers as u32,
                usage: vk::ImageUsageFlags::SAMPLED,
                aspect: vk::ImageAspectFlags::COLOR,
                view_type: vk::ImageViewType::TYPE_2D_ARRAY,
            },
            self.storage.texel_bytes(),
            &bytes,
        )?;
        let table = &prepared.colour;
        let weights: Vec<[f32; 4]> = table
            .weights
            .iter()
            .zip(&table.lambdas_nm)
            .map(|(w, l)| [w[0] as f32, w[1] as f32, w[2] as f32, *l as f32])
            .collect();
        let colour = Buffer::with_data(
            &self.dev,
            "colour weights",
            vk::BufferUsageFlags::STORAGE_BUFFER,
            &weights,
        )?;
        Ok(MaterialGpu {
            terms,
            colour,
            decode,
        })
    }

    /// The material part of the uniform block; callers fill in the scene or map part.
    fn params(&self, prepared: &PreparedMaterial, material: &MaterialGpu) -> ParamsUbo {
        let s = &prepared.stack;
        let sigma = prepared.window.sigma_texels;
        let inv2 = |s: f64| (1.0 / (2.0 * s * s)) as f32;
        let mut decode = [[0.0f32; 4]; MAX_TERMS];
        for (d, m) in decode.iter_mut().zip(&material.decode) {
            *d = *m;
        }
        ParamsUbo {
            eye_world: [0.0; 4],
            light_dir_world: [0.0, 0.0, -1.0, 0.0],
            lighting: [1.0, 1.0, 0.0, 0.0],
            map_wi: [0.0, 0.0, 1.0, 0.0],
            map_info: [0.0; 4],
            spectrum_size: [
                s.nx as i32,
                s.ny as i32,
                s.centre_x() as i32,
                s.centre_y() as i32,
            ],
            band: [
                s.band.x0 as i32,
                s.band.y0 as i32,
                s.band.width as i32,
                s.band.height as i32,
            ],
            lookup: [
                s.dh_um as f32,
                inv2(sigma[0]),
                inv2(sigma[1]),
                s.half_range_um as f32,
            ],
            shading: [brdf::schlick_r0(prepared.shading.ior) as f32, 0.0, 0.0, 0.0],
            decode,
        }
    }

    /// Creates the per-frame objects, records and submits one frame, reads it back.
    #[allow(clippy::too_many_arguments)]
    fn draw(
        &mut self,
        material: &MaterialGpu,
        params: &ParamsUbo,
        variant: &Variant,
        geometry: Geometry<'_>,
        (width, height): (u32, u32),
        clear: [f32; 4],
        texture: Option<&Image>,
    ) -> Result<Frame> {
        let dev = &self.dev;
        let ubo = Buffer::with_data(
            dev,
            "params",
            vk::BufferUsageFlags::UNIFORM_BUFFER,
            std::slice::from_ref(params),
        )?;
        // The texture binding is statically used by the shader, so it always needs an
        // image; a scene without a texture gets 1×1 white (the variant never samples it).
        let dummy;
        let texture = match texture {
            Some(t) => t,
            None => {
                dummy = Image::sampled_with_data(
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
                )?;
                &dummy
            }
        };
        let set = DescriptorSet::new(
            dev,
            "diffraction set",
            &self.layout,
            &[
                (0, Resource::Uniform(&ubo)),
                (1, Resource::Sampled(&material.terms, &self.nearest)),
                (2, Resource::Storage(&material.colour)),
                (3, Resource::Sampled(texture, &self.linear)),
            ],
        )?;
        let target = OffscreenTarget::new(dev, width, height)?;
        let (vertex, vertex_layout, depth_test) = match geometry {
            Geometry::FullScreen => (&self.vert_map, None, false),
            Geometry::Mesh { .. } => (&self.vert_mesh, Some(mesh_vertex_layout()), true),
        };
        let name = variant.name();
        let spec = variant.spec();
        let pipeline = Pipeline::new(
            dev,
            &PipelineDesc {
                name: &name,
                vertex,
                fragment: &self.frag,
                spec: &spec,
                vertex_layout: vertex_layout.as_ref(),
                layout: &self.layout,
                render_pass: target.render_pass,
                depth_test,
            },
        )?;
        let timer = GpuTimer::new(dev, "frame timestamps")?;
        dev.submit_once("diffraction frame", |cb| {
            if let Some(t) = &timer {
                t.record_start(cb);
            }
            record_frame(
                dev,
                cb,
                &target.frame(),
                &pipeline,
                &self.layout,
                &set,
                &geometry,
                clear,
            );
            if let Some(t) = &timer {
                t.record_end(cb);
            }
            target.record_readback(cb);
            Ok(())
        })?;
        let gpu_ms = match &timer {
            Some(t) => Some(t.elapsed_ms()?),
            None => None,
        };
        let rgb = target
            .read_rgba()?
            .into_iter()
            .map(|p| [p[0], p[1], p[2]])
            .collect();
        Ok(Frame {
            width,
            height,
            rgb,
            gpu_ms,
            wall_ms: 0.0,
        })
    }
}

/// Vertex attributes of `mesh::Vertex` (position, normal, tangent, uv; 48 bytes).
fn mesh_vertex_layout() -> VertexLayout {
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
fn record_frame(
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

/// `diffract render`: a scene (or a BRDF map) to an image.
#[derive(Debug, Clone, clap::Args)]
pub struct RenderArgs {
    /// Scene file (TOML); the embedded default scene when omitted.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Output image: .png (8-bit sRGB) or .exr (linear float).
    #[arg(short, long, default_value = "diffract.png")]
    pub out: PathBuf,
    /// Image width in pixels (overrides the scene).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels (overrides the scene).
    #[arg(long)]
    pub height: Option<u32>,
    /// Render a BRDF map (hemisphere of view directions) instead of the scene.
    #[arg(long)]
    pub brdf_map: bool,
    /// BRDF map: polar angle of the light from the normal (degrees).
    #[arg(long, default_value_t = 30.0)]
    pub theta_i: f64,
    /// BRDF map: azimuth of the light from +x, the height-field columns (degrees).
    #[arg(long, default_value_t = 0.0)]
    pub phi_i: f64,
    /// BRDF map side in pixels.
    #[arg(long, default_value_t = 256)]
    pub size: u32,
    /// BRDF map: the spectral reflectance at this wavelength (nm) instead of XYZ colour.
    #[arg(long)]
    pub lambda_nm: Option<f64>,
    /// BRDF map: also write an sRGB PNG beside the EXR output.
    #[arg(long)]
    pub png: bool,
    /// Exposure (linear multiplier before the sRGB curve): overrides the scene's; for BRDF
    /// maps it scales the PNG only (the EXR keeps the raw values).
    #[arg(long)]
    pub exposure: Option<f32>,
    /// Storage format of the DFT terms on the GPU.
    #[arg(long, value_enum, default_value_t = StorageFormat::Rg32f)]
    pub storage: StorageFormat,
    #[command(flatten)]
    pub material: MaterialArgs,
    /// Directory of the DFT term cache (default: $DIFFRACT_CACHE or ~/.cache/diffract).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Do not read or write the term cache.
    #[arg(long)]
    pub no_cache: bool,
}

/// Whether to enable Vulkan validation: always in debug builds, or with
/// `DIFFRACT_VALIDATION=1`.
pub fn validation_requested() -> bool {
    cfg!(debug_assertions) || std::env::var("DIFFRACT_VALIDATION").is_ok_and(|v| v == "1")
}

/// Runs `diffract render`: renders, writes the image(s), prints one line with the device,
/// GPU and wall time.
pub fn run(args: &RenderArgs) -> Result<()> {
    let mut scene = match &args.scene {
        Some(p) => Scene::load(p)?,
        None => Scene::default_scene(),
    };
    if let Some(e) = args.exposure {
        if !(e.is_finite() && e > 0.0) {
            return Err(Error::invalid(
                "exposure",
                format!("{e}; must be finite and > 0"),
            ));
        }
        scene.output.exposure = e;
    }
    crate::image_io::output_format(&args.out)?;
    // The device first: a machine without Vulkan fails before the term precompute.
    let mut renderer = Renderer::new(validation_requested())?;
    renderer.set_storage_format(args.storage);
    let material = args.material.apply(scene.material.clone());
    let cache_dir = if args.no_cache {
        None
    } else {
        args.cache_dir
            .clone()
            .or_else(crate::material::default_cache_dir)
    };
    let prepared = material.prepare(cache_dir.as_deref())?;

    let (frame, what) = if args.brdf_map {
        let frame = renderer.render_brdf_map(
            &prepared,
            args.theta_i,
            args.phi_i,
            args.size,
            args.lambda_nm,
        )?;
        write_map(args, &frame)?;
        let what = match args.lambda_nm {
            Some(l) => format!("BRDF map ρ at {l} nm"),
            None => "BRDF map (XYZ)".to_string(),
        };
        (frame, what)
    } else {
        if let Some(w) = args.width {
            scene.output.width = w;
        }
        if let Some(h) = args.height {
            scene.output.height = h;
        }
        for (what, v) in [
            ("width", scene.output.width),
            ("height", scene.output.height),
        ] {
            if !(1..=8192).contains(&v) {
                return Err(Error::invalid(
                    "image size",
                    format!("{what} {v}; expected 1..=8192"),
                ));
            }
        }
        let frame = renderer.render_scene(&scene, &prepared)?;
        // The shader already applied the exposure.
        crate::image_io::write_image(&args.out, frame.width, frame.height, &frame.rgb, 1.0)?;
        (frame, "scene".to_string())
    };
    let gpu = frame
        .gpu_ms
        .map_or("n/a".to_string(), |ms| format!("{ms:.2}"));
    println!(
        "{}: {what} {}×{} → {}: GPU {gpu} ms, wall {:.1} ms",
        renderer.device_name(),
        frame.width,
        frame.height,
        args.out.display(),
        frame.wall_ms
    );
    let n = renderer.validation_messages();
    if n > 0 {
        return Err(Error::Validation(n));
    }
    Ok(())
}

/// Writes a BRDF map: an EXR holds the raw channels (XYZ or ρ); a PNG shows XYZ as sRGB
/// (or ρ as grey). `--png` with an EXR output adds the PNG beside it.
fn write_map(args: &RenderArgs, frame: &Frame) -> Result<()> {
    let exposure = args.exposure.unwrap_or(1.0);
    let viewable = || -> Vec<[f32; 3]> {
        if args.lambda_nm.is_some() {
            frame.rgb.clone()
        } else {
            frame
                .rgb
                .iter()
                .map(|p| crate::colour::xyz_to_linear_srgb(p.map(|c| c as f64)).map(|c| c as f32))
                .collect()
        }
    };
    match crate::image_io::output_format(&args.out)? {
        crate::image_io::OutputFormat::Exr => {
            crate::image_io::write_exr(&args.out, frame.width, frame.height, &frame.rgb)?;
            if args.png {
                let png = args.out.with_extension("png");
                crate::image_io::write_png_srgb(
                    &png,
                    frame.width,
                    frame.height,
                    &viewable(),
                    exposure,
                )?;
            }
            Ok(())
        }
        _ => crate::image_io::write_image(
            &args.out,
            frame.width,
            frame.height,
            &viewable(),
            exposure,
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn map_direction_is_inside_the_disk_and_symmetric() {
        assert!(map_direction(0, 0, 64).is_none());
        let c = map_direction(32, 31, 64).unwrap();
        assert!(c[2] > 0.99);
        let a = map_direction(10, 20, 64).unwrap();
        let b = map_direction(53, 43, 64).unwrap();
        assert!((a[0] + b[0]).abs() < 1e-6 && (a[1] + b[1]).abs() < 1e-6);
    }
}
