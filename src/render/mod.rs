//! Frames of the diffraction shaders: turns a prepared material (and a scene) into GPU
//! inputs — the variant's resources ([`variant`]), the colour table, the `Params` uniform
//! block, the specialisation constants — records a pass into a target ([`record`]), and
//! reads the linear result back. The `diffract render` command lives in [`command`].
//!
//! This is where physics meets `gpu`: the layouts here mirror `glsl/interface.glsl`. The
//! renderer knows variants only through their interface; frame recording takes a
//! [`Target`](crate::gpu::target::Target) and does not know whether it draws
//! offscreen or into a window.

mod pass;
mod record;
pub mod table_build;
pub mod variant;

use std::sync::Arc;
use std::time::Instant;

use ash::vk;

pub use pass::{MapView, PassOptions, ScenePass};
pub use variant::{TableFormat, TableOptions, VariantKind, VariantStats};

use crate::brdf;
use crate::brdf::table::{DiscKernel, Region};
use crate::gpu::frames::Frames;
use crate::gpu::memory::{Buffer, Image, ImageDesc, Pod, Sampler};
use crate::gpu::pipeline::{
    Binding, DescriptorSet, Pipeline, PipelineDesc, PipelineLayout, Resource, ShaderModule,
};
use crate::gpu::target::OffscreenTarget;
use crate::gpu::{shaders, Device, StorageFormat};
use crate::material::PreparedMaterial;
use crate::scene::Scene;
use crate::{Error, Result};
use pass::MeshBuffers;
use record::{mesh_vertex_layout, Transforms};
use variant::{DrawSetup, PreparedVariant, SPEC_COUNT};

/// Capacity of the shader's per-term decode table (`MAX_TERMS` in interface.glsl).
pub(crate) const MAX_TERMS: usize = 65;
/// Largest BRDF map side.
pub const MAX_MAP_SIZE: u32 = 4096;
/// `render --brdf-map` side without `--size`.
pub const DEFAULT_MAP_SIZE: u32 = 256;
/// `render --brdf-map` light angle without `--theta-i` (degrees).
pub const DEFAULT_MAP_THETA_I: f64 = 30.0;

/// One rendered picture read back from an offscreen target: linear values, row-major from
/// the top row, with the GPU and wall time it took.
#[derive(Debug, Clone)]
pub struct Picture {
    pub width: u32,
    pub height: u32,
    /// Linear sRGB (scenes), XYZ (BRDF maps) or `ρ_λ` in all channels (spectral maps).
    pub rgb: Vec<[f32; 3]>,
    /// GPU time of the draw from timestamps; `None` where the queue has none.
    pub gpu_ms: Option<f64>,
    /// Wall time of the whole call: variant preparation and pipeline creation (unless
    /// reused from the previous frame), draw and readback.
    pub wall_ms: f64,
    /// The variant that drew it.
    pub variant: VariantStats,
}

impl Picture {
    /// Pixel `(x, y)`, `y` from the top.
    pub fn at(&self, x: u32, y: u32) -> [f32; 3] {
        self.rgb[(y * self.width + x) as usize]
    }
}

/// What the fragment shader writes (`OUTPUT_MODE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum OutputMode {
    Mesh = 0,
    MapXyz = 1,
    MapSpectral = 2,
    /// The viewer's map: linear sRGB × exposure for an sRGB target.
    MapDisplay = 3,
}

/// What a scene frame reads from the user's files — the mesh (in world space) and the
/// texture's pixels — loaded apart from the device, so `render` can report a bad OBJ or
/// PNG before it opens Vulkan.
pub struct SceneInputs {
    pub mesh: crate::mesh::Mesh,
    /// `(width, height, sRGB bytes)` of the scene's texture, when it has one and it is used.
    pub texture: Option<(u32, u32, Vec<[u8; 3]>)>,
}

impl SceneInputs {
    /// Loads `scene`'s mesh (one without triangles is an error) and, with `texture`, its
    /// texture.
    pub fn load(scene: &Scene, texture: bool) -> Result<Self> {
        let mesh = load_scene_mesh(scene)?;
        let texture = match &scene.texture {
            Some(t) if texture => Some(t.load()?),
            _ => None,
        };
        Ok(Self { mesh, texture })
    }
}

/// Mirror of `Params` in glsl/interface.glsl (std140: vec4-sized members only).
#[repr(C)]
#[derive(Clone, Copy)]
pub(crate) struct ParamsUbo {
    eye_world: [f32; 4],
    light_dir_world: [f32; 4],
    lighting: [f32; 4],
    map_wi: [f32; 4],
    map_info: [f32; 4],
    pub spectrum_size: [i32; 4],
    pub band: [i32; 4],
    pub lookup: [f32; 4],
    shading: [f32; 4],
    light_info: [i32; 4],
    pub decode: [[f32; 4]; MAX_TERMS],
    light_disk: [[f32; 4]; crate::light::MAX_DISK_SAMPLES as usize],
}

impl ParamsUbo {
    /// The light's disc: the directions towards it (world space) and their weights, at most
    /// [`crate::light::MAX_DISK_SAMPLES`] (what `Light::disk_samples` gives).
    pub(crate) fn set_light(&mut self, light: &crate::scene::Light) {
        let disk = light.disk_samples();
        let d = light.direction;
        self.light_dir_world = [d[0], d[1], d[2], 0.0];
        self.light_info = [disk.len() as i32, 0, 0, 0];
        for (slot, s) in self.light_disk.iter_mut().zip(&disk) {
            let t = s.towards_light;
            *slot = [t[0], t[1], t[2], s.weight];
        }
    }
}

// SAFETY: repr(C) of 4-byte scalars in 16-byte groups: no padding.
unsafe impl Pod for ParamsUbo {}

/// Map pixel `(i, j)` of an `S×S` BRDF map → `ωr`, exactly as the fragment shader computes
/// it in float32 (README: BRDF maps); `None` outside the unit disk.
pub fn map_direction(i: u32, j: u32, size: u32) -> Option<[f64; 3]> {
    let s = size as f32;
    let x = 2.0 * (i as f32 + 0.5) / s - 1.0;
    let y = 1.0 - 2.0 * (j as f32 + 0.5) / s;
    let r2 = x * x + y * y;
    (r2 < 1.0).then(|| [x as f64, y as f64, (1.0 - r2).sqrt() as f64])
}

/// Identity of a prepared variant: rebuilt only when one of these changes.
#[derive(Debug, Clone, PartialEq)]
struct PreparedKey {
    kind: VariantKind,
    material: crate::material::Material,
    heightfield: (usize, usize, u64, u64),
    region: Option<[u64; 6]>,
    storage: StorageFormat,
    table: TableOptions,
    keep_model: bool,
    leave_out: bool,
    /// The disc kernel pre-filtered into a table (its axes' bits).
    disc: Option<[u64; 4]>,
}

/// What a BRDF map pass is built for: the objects of a [`MapPass`] are reused while
/// none of these change (a new `θi`, `φi` or `λ` only rewrites the uniform block).
#[derive(Debug, Clone, PartialEq)]
struct MapKey {
    /// Address of the prepared variant the descriptor set points at (the pass holds an
    /// `Arc` of it, so the address cannot be reused while the key lives).
    variant: usize,
    output: OutputMode,
    options: PassOptions,
    size: u32,
    /// The colour table as uploaded (`λ` and weights).
    colour: Vec<[f32; 4]>,
}

/// The last BRDF map's objects: pass (pipeline, descriptor set, buffers), offscreen target
/// and its frame (command buffer, fence, timestamps). Creating and destroying them for every
/// map cost time (most of lavapipe's 135 ms a 16² frame went to the pipeline) and, with the
/// validation layer on, ~11 KB of its bookkeeping a frame (README: soak).
struct MapPass {
    key: MapKey,
    frames: Frames,
    pass: ScenePass,
    target: OffscreenTarget,
}

/// Owns the GPU device, what every frame shares (vertex shaders, the texture sampler), the
/// last prepared variant, which later frames of the same material reuse, and the last BRDF
/// map's pass and target, which later maps of the same size and variant reuse.
pub struct Renderer {
    /// First: its descriptor set points at the sampler and the prepared variant below.
    map: Option<MapPass>,
    storage: StorageFormat,
    variant: VariantKind,
    table: TableOptions,
    keep_models: bool,
    /// Leave out what a draw cannot need (issue #8; off by default, `render` and `view`
    /// switch it on).
    leave_out: bool,
    /// Mesh frames evaluate the BRDF per vertex (thesis §1.5.1; `flss`, `nmm`, `pq`).
    per_vertex: bool,
    cache_dir: Option<std::path::PathBuf>,
    /// Where warnings and progress of the work go (stderr unless the owner says otherwise).
    report: Arc<dyn crate::report::Report>,
    prepared: Option<(PreparedKey, Arc<dyn PreparedVariant>)>,
    /// Table variants: when positive, built for the needed region widened by this much and
    /// reused while later regions fall inside it (the viewer); 0: built for exactly the region.
    region_margin: f64,
    table_region: Option<Region>,
    /// Run-time SPIR-V by glsl file name (`flss.frag`, `diffraction.vert`, ...) that
    /// replaces the SPIR-V built in (hot reload).
    shader_overrides: std::collections::HashMap<String, Vec<u8>>,
    linear: Sampler,
    vert_map: ShaderModule,
    vert_mesh: ShaderModule,
    /// Last: everything above holds handles of this device.
    dev: Arc<Device>,
}

impl Renderer {
    /// Opens the preferred Vulkan device. `validation` enables the Khronos validation layer;
    /// its WARNING/ERROR messages are counted in [`Renderer::validation_messages`]. Draws
    /// with `flss` until [`Renderer::set_variant`] says otherwise.
    pub fn new(validation: bool) -> Result<Self> {
        Self::on(Device::new(validation)?)
    }

    /// A renderer on an existing device (the viewer's, which can present).
    pub fn on(dev: Arc<Device>) -> Result<Self> {
        Ok(Self {
            map: None,
            storage: StorageFormat::default(),
            variant: VariantKind::Flss,
            table: TableOptions::default(),
            keep_models: false,
            leave_out: false,
            per_vertex: false,
            cache_dir: None,
            report: Arc::new(crate::report::Stderr),
            prepared: None,
            region_margin: 0.0,
            table_region: None,
            shader_overrides: Default::default(),
            linear: Sampler::new(
                &dev,
                "surface texture (linear)",
                vk::Filter::LINEAR,
                vk::SamplerAddressMode::REPEAT,
            )?,
            vert_map: ShaderModule::new(&dev, "brdfmap.vert", shaders::BRDFMAP_VERT)?,
            vert_mesh: ShaderModule::new(&dev, "diffraction.vert", shaders::DIFFRACTION_VERT)?,
            dev,
        })
    }

    /// Name of the Vulkan device in use.
    pub fn device_name(&self) -> &str {
        &self.dev.info.name
    }

    /// The device, for callers that record their own frames (the viewer).
    pub fn device(&self) -> &Arc<Device> {
        &self.dev
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

    /// Storage format of the DFT terms (flss) for the next frames (default RG32F).
    pub fn set_storage_format(&mut self, storage: StorageFormat) {
        self.storage = storage;
    }

    /// The storage format in use.
    pub fn storage_format(&self) -> StorageFormat {
        self.storage
    }

    /// The variant of the next frames (`default` resolves to [`VariantKind::DEFAULT`]).
    pub fn set_variant(&mut self, variant: VariantKind) {
        self.variant = variant.resolve();
    }

    /// The variant in use.
    pub fn variant(&self) -> VariantKind {
        self.variant
    }

    /// How the table variants sample `G`.
    pub fn set_table_options(&mut self, table: TableOptions) {
        self.table = table;
    }

    /// Where the table variants cache their sampled tables (none: always build). The
    /// device's pipeline cache is read from and saved to the same directory.
    pub fn set_cache_dir(&mut self, dir: Option<std::path::PathBuf>) {
        if let Some(d) = &dir {
            self.dev.load_pipeline_cache(d);
        }
        self.cache_dir = dir;
    }

    /// Where the renderer's warnings and progress bars go (a table coarsened to fit its
    /// budget, a table build's progress, a cache that could not be read): stderr by default.
    pub fn set_report(&mut self, report: Arc<dyn crate::report::Report>) {
        self.report = report;
    }

    /// Table variants: build for the needed `(u, v, w)` region widened by `margin` and reuse
    /// the table while later frames' regions fall inside it (0, the default: build for
    /// exactly each frame's region).
    pub fn set_region_margin(&mut self, margin: f64) {
        self.region_margin = margin.max(0.0);
    }

    /// Table variants (and the `coverage` view): tabulate `region` whatever the draw reaches
    /// (`None`, the default: the region each draw reaches). Lookups outside it draw black
    /// (magenta in `coverage`).
    pub fn set_table_region(&mut self, region: Option<Region>) {
        self.table_region = region;
    }

    /// Replaces built-in SPIR-V by glsl file name (e.g. `flss.frag`) for the passes built
    /// from now on; an empty map restores the built-in shaders.
    pub fn set_shader_overrides(&mut self, spirv: std::collections::HashMap<String, Vec<u8>>) {
        self.map = None;
        self.shader_overrides = spirv;
    }

    /// Keep the f64 tables of table variants on the CPU (for [`Renderer::table_model`]);
    /// off by default, since they take as much memory again as the GPU copy in f64.
    pub fn set_keep_models(&mut self, keep: bool) {
        self.keep_models = keep;
    }

    /// Leave out, from the next prepared variant on, what its draws cannot need at the
    /// material's tolerance: wavelengths whose colour weight cannot matter (per pixel for
    /// `flss`/`nmm`, in the build of the tables) and DFT texels outside the `(u, v)` band
    /// the draw's directions reach (`flss`/`nmm`). Off (the default): keep everything.
    pub fn set_leave_out(&mut self, leave_out: bool) {
        self.leave_out = leave_out;
    }

    /// What the last prepared variant left out (`None` before the first frame).
    pub fn left_out(&self) -> Option<crate::leave_out::LeftOut> {
        self.prepared.as_ref().and_then(|(_, v)| v.left_out())
    }

    /// Mesh frames from now on evaluate the BRDF per vertex and interpolate the colour
    /// (thesis §1.5.1). Variants without a per-vertex stage refuse mesh frames then; BRDF
    /// maps (no vertices) are drawn per pixel.
    pub fn set_per_vertex(&mut self, per_vertex: bool) {
        self.per_vertex = per_vertex;
    }

    /// Whether mesh frames are evaluated per vertex.
    pub fn per_vertex(&self) -> bool {
        self.per_vertex
    }

    /// The periodic structure `pq` found for the last frame (when it drew).
    pub fn pq_periodicity(&self) -> Option<crate::brdf::pq::Periodicity> {
        self.prepared.as_ref().and_then(|(_, v)| v.periodicity())
    }

    /// The grating period `nmm` estimated for the last frame (when it drew).
    pub fn nmm_grating(&self) -> Option<crate::brdf::nmm::Grating> {
        self.prepared.as_ref().and_then(|(_, v)| v.grating())
    }

    /// The f64 CPU model of the table the last frame used, if the variant has one and
    /// [`Renderer::set_keep_models`] was on when it was built.
    pub fn table_model(&self) -> Option<&dyn crate::brdf::table::GTable> {
        self.prepared.as_ref().and_then(|(_, v)| v.table_model())
    }

    /// A BRDF map (thesis §5): an S×S image of the hemisphere of view directions, pixel
    /// `(i, j)` (row `j` from the top) at `x = 2(i+½)/S − 1`, `y = 1 − 2(j+½)/S`,
    /// `ωr = (x, y, √(1−x²−y²))`, black outside the unit disk; light from `(θi, φi)`.
    /// Channels: linear XYZ, or `ρ_λ` in all three with `lambda_nm` (flss only).
    pub fn render_brdf_map(
        &mut self,
        prepared: &PreparedMaterial,
        theta_i_deg: f64,
        phi_i_deg: f64,
        size: u32,
        lambda_nm: Option<f64>,
    ) -> Result<Picture> {
        let start = Instant::now();
        check_map_args(theta_i_deg, phi_i_deg, size, lambda_nm)?;
        let wi = brdf::direction(theta_i_deg, phi_i_deg);
        let output = if lambda_nm.is_some() {
            OutputMode::MapSpectral
        } else {
            OutputMode::MapXyz
        };
        // The shader sees ωi in float32: the table must cover what it computes from it.
        let wi32 = wi.map(|c| c as f32 as f64);
        let region = Region::brdf_map(wi32).widened(1e-5);
        self.prepare_variant(prepared, region, output, None)?;
        let mut params = self.params(prepared);
        params.map_wi = [
            wi32[0] as f32,
            wi32[1] as f32,
            wi32[2] as f32,
            lambda_nm.map_or(0.0, |l| (l * 1e-3) as f32),
        ];
        params.map_info = [size as f32, 0.0, 0.0, 0.0];
        let options = PassOptions {
            fresnel: prepared.shading.fresnel,
            shadowing: prepared.shading.shadowing,
            texture_blending: false,
        };
        let Some((_, variant)) = &self.prepared else {
            return Err(Error::invalid("variant", "no variant prepared"));
        };
        let key = MapKey {
            variant: Arc::as_ptr(variant) as *const () as usize,
            output,
            options,
            size,
            colour: colour_weights(prepared, variant.as_ref()),
        };
        // Taken out while it draws: a failed frame drops it rather than leave a pass in an
        // unknown state for the next one.
        let mut map = match self.map.take() {
            Some(m) if m.key == key => m,
            old => {
                // The old objects go before the new ones are made.
                drop(old);
                let target = OffscreenTarget::new(&self.dev, size, size)?;
                let pass = self.build_pass(
                    prepared,
                    params,
                    output,
                    options,
                    None,
                    [0.0; 4],
                    None,
                    target.render_pass(),
                )?;
                MapPass {
                    key,
                    frames: Frames::single(&self.dev, "brdf map frame")?,
                    pass,
                    target,
                }
            }
        };
        map.pass.params = params;
        let mut frame = self.draw(&map.pass, &map.target, &mut map.frames)?;
        self.map = Some(map);
        frame.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(frame)
    }

    /// Renders `scene`'s mesh with the diffraction shader (thesis Algorithms 2–4) using
    /// `prepared` as the material (callers prepare `scene.material`, possibly overridden).
    /// Pixels are linear sRGB already multiplied by the light intensity, `cosθi` and the
    /// scene's exposure; uncovered pixels hold the background colour as given.
    pub fn render_scene(&mut self, scene: &Scene, prepared: &PreparedMaterial) -> Result<Picture> {
        let inputs = SceneInputs::load(scene, true)?;
        self.render_scene_with(scene, &inputs, prepared)
    }

    /// [`render_scene`](Self::render_scene) with the scene's files already loaded.
    pub fn render_scene_with(
        &mut self,
        scene: &Scene,
        inputs: &SceneInputs,
        prepared: &PreparedMaterial,
    ) -> Result<Picture> {
        let start = Instant::now();
        let out = &scene.output;
        let options = PassOptions {
            fresnel: prepared.shading.fresnel,
            shadowing: prepared.shading.shadowing,
            texture_blending: true,
        };
        let target = OffscreenTarget::new(&self.dev, out.width, out.height)?;
        let pass = self.scene_pass_of(
            scene,
            inputs,
            prepared,
            options,
            target.render_pass(),
            out.aspect(),
        )?;
        let mut frames = Frames::single(&self.dev, "diffraction frame")?;
        let mut frame = self.draw(&pass, &target, &mut frames)?;
        frame.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(frame)
    }

    /// `scene` as `diffract render` writes it, at the output size: drawn at the supersampled
    /// size ([`crate::scene::Output::render_size`]) with unit exposure, box-filtered in linear
    /// light, then exposed and, with `tone`, tone-mapped ([`crate::scene::Output::resolve`]);
    /// without `tone` (EXR) it stays linear after the exposure. The background is drawn
    /// divided by the exposure, so it comes out as given (before the tone curve).
    /// `inputs`: the scene's files already loaded ([`SceneInputs`]), else they are loaded here.
    pub fn render_output(
        &mut self,
        scene: &Scene,
        inputs: Option<&SceneInputs>,
        prepared: &PreparedMaterial,
        tone: bool,
    ) -> Result<Picture> {
        let out = &scene.output;
        let (rw, rh) = out.render_size();
        let mut big = scene.clone();
        big.output.width = rw;
        big.output.height = rh;
        big.output.exposure = 1.0;
        big.output.background = out.background.map(|c| c / out.exposure);
        let mut frame = match inputs {
            Some(inputs) => self.render_scene_with(&big, inputs, prepared)?,
            None => self.render_scene(&big, prepared)?,
        };
        frame.rgb = if tone {
            out.resolve(&frame.rgb)?
        } else {
            let (_, _, px) =
                crate::image_io::box_downsample(rw, rh, &frame.rgb, out.supersample.max(1))?;
            px.into_iter()
                .map(|p| p.map(|c| c * out.exposure))
                .collect()
        };
        frame.width = out.width;
        frame.height = out.height;
        Ok(frame)
    }

    /// The objects of `scene`'s frames (mesh, uniforms, pipeline), built for `render_pass`
    /// and the target aspect `aspect`: record it into any compatible target, move the camera
    /// with [`ScenePass::set_view`]. The viewer uses this with its swapchain.
    pub fn scene_pass(
        &mut self,
        scene: &Scene,
        prepared: &PreparedMaterial,
        options: PassOptions,
        render_pass: vk::RenderPass,
        aspect: f32,
    ) -> Result<ScenePass> {
        let inputs = SceneInputs::load(scene, options.texture_blending)?;
        self.scene_pass_of(scene, &inputs, prepared, options, render_pass, aspect)
    }

    /// Whether the prepared table covers what `scene`'s view needs, so a pass built now
    /// would reuse it (always true for flss, which reads the whole band).
    pub fn covers_view(&self, scene: &Scene) -> Result<bool> {
        let Some((key, _)) = &self.prepared else {
            return Ok(false);
        };
        let Some(built) = key.region else {
            return Ok(true);
        };
        let mesh = load_scene_mesh(scene)?;
        let need = scene_region(scene, &mesh, None, false).unwrap_or(Region::ALL);
        Ok(region_contains(&built.map(f64::from_bits), &need))
    }

    /// The viewer's BRDF map (thesis §5, as [`Renderer::render_brdf_map`] draws it) as a pass
    /// for `render_pass`: light from `map.wi` (tangent frame, `z ≥ 0`), drawn into the
    /// top-left `map.size`² pixels of whatever target it is recorded into, as displayable
    /// colour: the shader turns the map's XYZ into linear sRGB and multiplies it by
    /// `map.exposure`
    /// (`OUTPUT_MODE` = MODE_MAP_DISPLAY) and the sRGB target applies the transfer curve, as
    /// `render --brdf-map --png --exposure E` does on the CPU. Move the light and resize with
    /// [`ScenePass::set_map`]. Table variants are prepared for the map's region joined with
    /// the view of `beside` (the mesh drawn next to the map), so that the two passes share
    /// one table and neither makes the other rebuild it.
    pub fn brdf_map_pass(
        &mut self,
        prepared: &PreparedMaterial,
        map: MapView,
        options: PassOptions,
        beside: Option<&Scene>,
        render_pass: vk::RenderPass,
    ) -> Result<ScenePass> {
        let MapView { wi, size, exposure } = map;
        if size == 0 || size > MAX_MAP_SIZE {
            return Err(Error::invalid(
                "BRDF map size",
                format!("{size}; expected 1..={MAX_MAP_SIZE} pixels"),
            ));
        }
        if !(wi.iter().all(|c| c.is_finite()) && wi[2] >= 0.0) {
            return Err(Error::invalid(
                "BRDF map light",
                format!("{wi:?}; expected a finite direction with z ≥ 0"),
            ));
        }
        let wi32 = wi.map(|c| c as f32 as f64);
        let mut region = Region::brdf_map(wi32).widened(1e-5);
        if let Some(scene) = beside {
            let mesh = load_scene_mesh(scene)?;
            if let Some(r) = scene_region(scene, &mesh, None, false) {
                region = Region {
                    lo: std::array::from_fn(|a| region.lo[a].min(r.lo[a])),
                    hi: std::array::from_fn(|a| region.hi[a].max(r.hi[a])),
                };
            }
        }
        self.prepare_variant(prepared, region, OutputMode::MapDisplay, None)?;
        let mut params = self.params(prepared);
        params.map_wi = [wi32[0] as f32, wi32[1] as f32, wi32[2] as f32, 0.0];
        params.map_info = [size as f32, 0.0, 0.0, 0.0];
        params.lighting[1] = exposure;
        let options = PassOptions {
            texture_blending: false,
            ..options
        };
        self.build_pass(
            prepared,
            params,
            OutputMode::MapDisplay,
            options,
            None,
            [0.0; 4],
            None,
            render_pass,
        )
    }

    /// Whether the prepared table covers a BRDF map under light `wi` (tangent frame), so a
    /// [`Renderer::brdf_map_pass`] built now would reuse it (always true for flss).
    pub fn covers_brdf_map(&self, wi: [f64; 3]) -> bool {
        let Some((key, _)) = &self.prepared else {
            return false;
        };
        let Some(built) = key.region else {
            return true;
        };
        let need = Region::brdf_map(wi.map(|c| c as f32 as f64)).widened(1e-5);
        region_contains(&built.map(f64::from_bits), &need)
    }

    fn scene_pass_of(
        &mut self,
        scene: &Scene,
        inputs: &SceneInputs,
        prepared: &PreparedMaterial,
        options: PassOptions,
        render_pass: vk::RenderPass,
        aspect: f32,
    ) -> Result<ScenePass> {
        let out = &scene.output;
        if self.per_vertex {
            // Before any table is built for nothing.
            self.per_vertex_shader()?;
        }
        let mesh = &inputs.mesh;
        // `render` (no covering margin) fits the table to what its frame shows and, for the
        // table variants, pre-filters the sun's disc into it; the viewer keeps every lit
        // vertex and the per-direction loop (its BRDF map shares the table).
        let fitted = self.region_margin == 0.0;
        let disc = if fitted && !self.per_vertex && self.variant.is_table() {
            scene_disc(scene, mesh, aspect)
        } else {
            None
        };
        let region = scene_region(scene, mesh, fitted.then_some(aspect), disc.is_some())
            .unwrap_or(Region::ALL);
        self.prepare_variant(prepared, region, OutputMode::Mesh, disc)?;
        let mut params = self.params(prepared);
        let eye = scene.camera.eye;
        params.eye_world = [eye[0], eye[1], eye[2], 1.0];
        params.set_light(&scene.light);
        // Algorithm 4's weight, the sky's ambient light on the skin, the texture's gain.
        let (w_diffuse, ambient, gain) = scene
            .texture
            .as_ref()
            .map_or((0.0, 0.0, 1.0), |t| (t.w_diffuse, t.ambient, t.gain));
        params.lighting = [scene.light.intensity, out.exposure, w_diffuse, ambient];
        params.shading[1] = gain;
        let bg = out.background;

        let texture = match (&scene.texture, &inputs.texture) {
            (Some(t), Some(pixels)) if options.texture_blending => {
                Some(self.upload_texture(t, pixels)?)
            }
            _ => None,
        };
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
            view_proj: scene.camera.view_proj(aspect).to_cols_array(),
        };
        self.build_pass(
            prepared,
            params,
            OutputMode::Mesh,
            options,
            Some((
                MeshBuffers {
                    vertices,
                    indices,
                    index_count: mesh.indices.len() as u32,
                },
                transforms,
            )),
            [bg[0], bg[1], bg[2], 1.0],
            texture,
            render_pass,
        )
    }

    /// Builds (or reuses) the current variant's resources for `prepared` over `region`.
    fn prepare_variant(
        &mut self,
        prepared: &PreparedMaterial,
        region: Region,
        output: OutputMode,
        disc: Option<DiscKernel>,
    ) -> Result<()> {
        self.variant.check_output(output)?;
        let region = self.table_region.unwrap_or(region);
        let per_region = self.variant.implementation().reads_region(self.leave_out);
        let covering = self.region_margin > 0.0 && per_region;
        let needed = region;
        let region = if covering {
            widen(&region, self.region_margin)
        } else {
            region
        };
        let hf = &prepared.heightfield;
        let (lo, hi) = hf.range();
        let key = PreparedKey {
            kind: self.variant,
            material: prepared.material.clone(),
            heightfield: (hf.nx(), hf.ny(), lo.to_bits(), hi.to_bits()),
            region: per_region.then(|| {
                [
                    region.lo[0],
                    region.lo[1],
                    region.lo[2],
                    region.hi[0],
                    region.hi[1],
                    region.hi[2],
                ]
                .map(f64::to_bits)
            }),
            storage: self.storage,
            table: self.table,
            keep_model: self.keep_models,
            leave_out: self.leave_out,
            disc: disc.map(|k| {
                let a = k.axes;
                [a[0][0], a[0][1], a[1][0], a[1][1]].map(f64::to_bits)
            }),
        };
        if self.prepared.as_ref().is_some_and(|(k, _)| *k == key) {
            return Ok(());
        }
        if covering {
            if let Some((k, _)) = &self.prepared {
                let same_but_region = PreparedKey {
                    region: k.region,
                    ..key.clone()
                } == *k;
                if same_but_region
                    && k.region
                        .is_some_and(|r| region_contains(&r.map(f64::from_bits), &needed))
                {
                    return Ok(());
                }
            }
        }
        // Free the old resources (and the map pass that points at them) before building new
        // ones.
        self.map = None;
        self.prepared = None;
        let setup = DrawSetup {
            prepared,
            region,
            output,
            storage: self.storage,
            table: &self.table,
            keep_model: self.keep_models,
            cache_dir: self.cache_dir.as_deref(),
            leave_out: self.leave_out,
            disc,
            report: self.report.as_ref(),
        };
        let built = self.variant.implementation().prepare(&self.dev, &setup)?;
        self.prepared = Some((key, Arc::from(built)));
        Ok(())
    }

    /// Uploads a scene texture's pixels (sRGB bytes) into an `R8G8B8A8_SRGB` image, so
    /// sampling returns linear colour.
    fn upload_texture(
        &self,
        spec: &crate::scene::TextureSpec,
        (w, h, rgb): &(u32, u32, Vec<[u8; 3]>),
    ) -> Result<Image> {
        let (w, h) = (*w, *h);
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

    /// The shared part of the uniform block plus the variant's; callers fill in the scene
    /// or map part.
    fn params(&self, prepared: &PreparedMaterial) -> ParamsUbo {
        let mut params = ParamsUbo {
            eye_world: [0.0; 4],
            light_dir_world: [0.0, 0.0, -1.0, 0.0],
            lighting: [1.0, 1.0, 0.0, 0.0],
            map_wi: [0.0, 0.0, 1.0, 0.0],
            map_info: [0.0; 4],
            spectrum_size: [0; 4],
            band: [0; 4],
            lookup: [0.0; 4],
            shading: [brdf::schlick_r0(prepared.shading.ior) as f32, 1.0, 0.0, 0.0],
            light_info: [1, 0, 0, 0],
            decode: [[0.0; 4]; MAX_TERMS],
            light_disk: [[0.0, 0.0, 1.0, 1.0]; crate::light::MAX_DISK_SAMPLES as usize],
        };
        if let Some((_, v)) = &self.prepared {
            v.fill_params(&mut params);
        }
        params
    }

    /// The fragment shader of the current variant, or the vertex shader `name`: the
    /// run-time override when there is one, else the SPIR-V built in.
    fn shader(&self, name: &str, built_in: &'static [u8]) -> Result<ShaderModule> {
        let spirv = self
            .shader_overrides
            .get(name)
            .map_or(built_in, Vec::as_slice);
        ShaderModule::new(&self.dev, name, spirv)
    }

    /// The current variant's per-vertex stage (thesis §1.5.1), or why it has none.
    fn per_vertex_shader(&self) -> Result<ShaderModule> {
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
    fn build_pass(
        &self,
        prepared: &PreparedMaterial,
        params: ParamsUbo,
        output: OutputMode,
        options: PassOptions,
        mesh: Option<(MeshBuffers, Transforms)>,
        clear: [f32; 4],
        texture: Option<Image>,
        render_pass: vk::RenderPass,
    ) -> Result<ScenePass> {
        let dev = &self.dev;
        let Some((_, variant)) = &self.prepared else {
            return Err(Error::invalid("variant", "no variant prepared"));
        };
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
        let per_vertex = self.per_vertex && mesh.is_some();
        bindings.extend(variant.bindings().into_iter().map(|mut b| {
            if per_vertex {
                b.stages |= vk::ShaderStageFlags::VERTEX;
            }
            b
        }));
        if per_vertex {
            bindings[1].stages |= vk::ShaderStageFlags::VERTEX;
        }
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
        // Device-written per frame (ScenePass::record), so TRANSFER_DST too.
        let ubo = Buffer::with_data(
            dev,
            "params",
            vk::BufferUsageFlags::UNIFORM_BUFFER | vk::BufferUsageFlags::TRANSFER_DST,
            std::slice::from_ref(&params),
        )?;
        let weights = colour_weights(prepared, variant.as_ref());
        let colour = Buffer::with_data(
            dev,
            "colour weights",
            vk::BufferUsageFlags::STORAGE_BUFFER,
            &weights,
        )?;
        let texture_blending = texture.is_some();
        // The texture binding is statically used by the shader, so it always needs an
        // image; a scene without a texture gets 1×1 white (the variant never samples it).
        let texture = match texture {
            Some(t) => t,
            None => Image::sampled_with_data(
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
            )?,
        };
        let mut resources = vec![
            (0, Resource::Uniform(&ubo)),
            (2, Resource::Storage(&colour)),
            (3, Resource::Sampled(&texture, &self.linear)),
        ];
        resources.extend(variant.resources());
        let set = DescriptorSet::new(dev, "diffraction set", &layout, &resources)?;
        let (vertex_name, vertex_layout, depth_test) = match mesh {
            None => ("brdfmap.vert", None, false),
            Some(_) => ("diffraction.vert", Some(mesh_vertex_layout()), true),
        };
        let override_vertex = if per_vertex {
            Some(self.per_vertex_shader()?)
        } else if self.shader_overrides.contains_key(vertex_name) {
            Some(self.shader(vertex_name, &[])?)
        } else {
            None
        };
        let vertex = match (&override_vertex, mesh.is_some()) {
            (Some(v), _) => v,
            (None, false) => &self.vert_map,
            (None, true) => &self.vert_mesh,
        };
        let mut spec = [0u32; SPEC_COUNT];
        spec[4] = options.shadowing as u32;
        spec[5] = options.fresnel as u32;
        spec[6] = texture_blending as u32;
        spec[8] = output as u32;
        variant.specialise(&mut spec);
        let fragment = if per_vertex {
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
            if texture_blending { " texture" } else { "" },
        );
        let pipeline = Pipeline::new(
            dev,
            &PipelineDesc {
                name: &name,
                vertex,
                fragment: &fragment,
                spec: &spec,
                vertex_layout: vertex_layout.as_ref(),
                layout: &layout,
                render_pass,
                depth_test,
            },
        )?;
        let (mesh, transforms) = match mesh {
            Some((m, t)) => (Some(m), t),
            None => (
                None,
                Transforms {
                    model: [0.0; 16],
                    view_proj: [0.0; 16],
                },
            ),
        };
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

    /// Records `pass` into the offscreen `target` as a frame of `frames` (timed when the
    /// queue has timestamps), submits, waits and reads the linear result back.
    fn draw(
        &self,
        pass: &ScenePass,
        target: &OffscreenTarget,
        frames: &mut Frames,
    ) -> Result<Picture> {
        let cb = frames.begin()?.cb;
        pass.record(cb, &target.target());
        frames.end_timing();
        target.record_readback(cb);
        frames.submit(&[], &[])?;
        let gpu_ms = frames.wait()?;
        let rgb = target
            .read_rgba()?
            .into_iter()
            .map(|p| [p[0], p[1], p[2]])
            .collect();
        Ok(Picture {
            width: target.extent.width,
            height: target.extent.height,
            rgb,
            gpu_ms,
            wall_ms: 0.0,
            variant: pass.stats.clone(),
        })
    }
}

/// The SPIR-V build.rs compiled from glsl/`file`; an error names a stage a variant declares
/// but glsl/ does not have (the registry test renders every variant, so it shows there).
fn built_in(file: &str) -> Result<&'static [u8]> {
    shaders::spirv(file).ok_or_else(|| {
        Error::invalid(
            "shader",
            format!("glsl/{file} was not compiled into this build"),
        )
    })
}

/// The colour table as the shader reads it: the XYZ weights and `λ` of each line.
/// The colour table as binding 2 holds it: per spectral sample the CIE weight and `λ`, only
/// the samples the variant keeps (all of them when it leaves none out).
fn colour_weights(prepared: &PreparedMaterial, variant: &dyn PreparedVariant) -> Vec<[f32; 4]> {
    let table = &prepared.colour;
    let sample = |i: usize| {
        let w = table.weights[i];
        [
            w[0] as f32,
            w[1] as f32,
            w[2] as f32,
            table.lambdas_nm[i] as f32,
        ]
    };
    match variant.kept_wavelengths() {
        Some(kept) => kept.iter().map(|&i| sample(i)).collect(),
        None => (0..table.len()).map(sample).collect(),
    }
}

/// A scene's mesh in world space (the placement is already applied, so the model matrix is
/// identity); a mesh without triangles is an error.
fn load_scene_mesh(scene: &Scene) -> Result<crate::mesh::Mesh> {
    let mesh = scene.mesh.load()?;
    if mesh.indices.is_empty() {
        return Err(Error::invalid(
            "mesh",
            format!("'{}' has no triangles", mesh.name),
        ));
    }
    Ok(mesh)
}

/// `r` widened by `margin` on every side, within what is physically possible.
fn widen(r: &Region, margin: f64) -> Region {
    let all = Region::ALL;
    Region {
        lo: std::array::from_fn(|i| (r.lo[i] - margin).max(all.lo[i])),
        hi: std::array::from_fn(|i| (r.hi[i] + margin).min(all.hi[i])),
    }
}

/// Whether the box `[lo0, lo1, lo2, hi0, hi1, hi2]` contains `need`.
fn region_contains(built: &[f64; 6], need: &Region) -> bool {
    (0..3).all(|i| built[i] <= need.lo[i] && need.hi[i] <= built[i + 3])
}

/// Range checks of a BRDF map's arguments.
fn check_map_args(
    theta_i_deg: f64,
    phi_i_deg: f64,
    size: u32,
    lambda_nm: Option<f64>,
) -> Result<()> {
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
    Ok(())
}

/// Per vertex of `scene`'s mesh: its tangent frame `(T, B, N)` (as the shaders build it)
/// and `ωr` in that frame.
fn vertex_frames(scene: &Scene, mesh: &crate::mesh::Mesh) -> Vec<([glam::Vec3; 3], glam::Vec3)> {
    use glam::Vec3;
    let eye = Vec3::from(scene.camera.eye);
    mesh.vertices
        .iter()
        .map(|v| {
            let n = Vec3::from(v.normal).normalize_or(Vec3::Z);
            let t0 = Vec3::new(v.tangent[0], v.tangent[1], v.tangent[2]);
            let t = (t0 - n * n.dot(t0)).normalize_or(n.any_orthonormal_vector());
            let b = if v.tangent[3] < 0.0 { -1.0 } else { 1.0 } * n.cross(t);
            let frame = [t, b, n];
            let d = eye - Vec3::from(v.position);
            let wr = Vec3::new(d.dot(t), d.dot(b), d.dot(n)).normalize_or(Vec3::Z);
            (frame, wr)
        })
        .collect()
}

/// Whether each triangle of `mesh` may show in the frame of `scene`'s camera at `aspect`
/// (not wholly outside one side of the view volume, with 5 % slack); all of them without
/// an aspect.
fn triangles_in_view(scene: &Scene, mesh: &crate::mesh::Mesh, aspect: Option<f32>) -> Vec<bool> {
    let Some(aspect) = aspect else {
        return vec![true; mesh.indices.len() / 3];
    };
    let m = scene.camera.view_proj(aspect);
    let clip: Vec<glam::Vec4> = mesh
        .vertices
        .iter()
        .map(|v| m * glam::Vec3::from(v.position).extend(1.0))
        .collect();
    mesh.indices
        .chunks_exact(3)
        .map(|tri| {
            let c = [tri[0], tri[1], tri[2]].map(|i| clip[i as usize]);
            let out = |f: &dyn Fn(glam::Vec4) -> bool| c.iter().all(|&p| f(p));
            !(out(&|p| p.w <= 0.0)
                || out(&|p| p.x > 1.05 * p.w)
                || out(&|p| p.x < -1.05 * p.w)
                || out(&|p| p.y > 1.05 * p.w)
                || out(&|p| p.y < -1.05 * p.w))
        })
        .collect()
}

/// The `(u, v, w)` a scene's mesh can reach: the tangent-frame `−ωi − ωr` of every vertex of
/// a triangle that has a lit, visible vertex (as the shaders compute them), for every
/// direction over the light's disc (only its centre when the table holds the disc,
/// `centre_only`), with a margin for the renormalised interpolation between vertices.
/// With an `aspect`, only triangles inside the camera's frame count. `None` when nothing
/// is lit.
fn scene_region(
    scene: &Scene,
    mesh: &crate::mesh::Mesh,
    aspect: Option<f32>,
    centre_only: bool,
) -> Option<Region> {
    use glam::Vec3;
    let lights: Vec<Vec3> = if centre_only {
        vec![scene.light.towards_light()]
    } else {
        scene
            .light
            .disk_samples()
            .iter()
            .map(|s| Vec3::from(s.towards_light))
            .collect()
    };
    // Per vertex: whether any direction lights it (and the eye sees it), and its points.
    let uvw: Vec<(bool, Vec<[f64; 3]>)> = vertex_frames(scene, mesh)
        .iter()
        .map(|&([t, b, n], wr)| {
            let frame = |d: Vec3| Vec3::new(d.dot(t), d.dot(b), d.dot(n));
            let mut lit = false;
            let points = lights
                .iter()
                .map(|&l| {
                    let wi = frame(l).normalize_or(Vec3::Z);
                    lit |= wi.z > 0.0 && wr.z > 0.0;
                    [
                        -(wi.x + wr.x) as f64,
                        -(wi.y + wr.y) as f64,
                        -(wi.z + wr.z) as f64,
                    ]
                })
                .collect();
            (lit, points)
        })
        .collect();
    let shown = triangles_in_view(scene, mesh, aspect);
    let points = mesh
        .indices
        .chunks_exact(3)
        .zip(shown)
        .flat_map(|(tri, shown)| {
            let any_lit = shown && tri.iter().any(|&i| uvw[i as usize].0);
            tri.iter()
                .filter(move |_| any_lit)
                .flat_map(|&i| uvw[i as usize].1.iter().copied())
                .collect::<Vec<_>>()
        });
    Region::around(points, 0.02)
}

/// The footprint in `(u, v)` of the light's disc for a table to pre-filter: the
/// covariance-mean of the exact footprints ([`DiscKernel::footprint`]) at the lit vertices
/// of the triangles in the camera's frame at `aspect`. `None` for a point light.
fn scene_disc(scene: &Scene, mesh: &crate::mesh::Mesh, aspect: f32) -> Option<DiscKernel> {
    use glam::Vec3;
    let light = &scene.light;
    let radius = f64::from(light.angular_diameter_deg).to_radians() / 2.0;
    if light.disk_samples().len() < 2 || radius.is_nan() || radius <= 0.0 {
        return None;
    }
    let l = light.towards_light();
    let frames = vertex_frames(scene, mesh);
    let shown = triangles_in_view(scene, mesh, Some(aspect));
    let mut seen = vec![false; frames.len()];
    for (tri, shown) in mesh.indices.chunks_exact(3).zip(shown) {
        if shown {
            for &i in tri {
                seen[i as usize] = true;
            }
        }
    }
    let kernels: Vec<DiscKernel> = frames
        .iter()
        .zip(seen)
        .filter_map(|(&([t, b, n], wr), seen)| {
            let wi = Vec3::new(l.dot(t), l.dot(b), l.dot(n)).normalize_or(Vec3::Z);
            (seen && wi.z > 0.0 && wr.z > 0.0)
                .then(|| DiscKernel::footprint([wi.x, wi.y, wi.z].map(f64::from), radius))
        })
        .collect();
    DiscKernel::mean(&kernels)
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
