//! Frames of the diffraction shaders: turns a prepared material (and a scene) into GPU
//! inputs — the variant's resources ([`variant`]), the colour table, the `Params` uniform
//! block, the specialisation constants — records a pass into a target ([`record`]), and
//! reads the linear result back. The rooms: [`Renderer`]'s settings and the variant and
//! scene preparation here; the `Params` block and the colour table in `params`; pass
//! building (layout, descriptor set, shaders, pipeline) in `pass`; the offscreen draws and
//! their read-back in `offscreen`; the `(u, v, w)` region and light disc a scene needs in
//! `region`. The `diffract render` command lives at the command line's edge
//! (`crate::cli::render`).
//!
//! This is where physics meets `gpu`: the layouts here mirror `glsl/interface.glsl`. The
//! renderer knows variants only through their interface; frame recording takes a
//! [`Target`](crate::gpu::target::Target) and does not know whether it draws
//! offscreen or into a window.

mod background;
pub mod env;
pub mod env_brdf;
pub mod env_scene;
pub mod gbuffer;
mod offscreen;
mod params;
mod pass;
mod record;
mod region;
pub mod table_build;
pub mod variant;

use std::sync::Arc;

use ash::vk;

pub use background::{Arrived, BuildProgress, Readiness};
pub use offscreen::{median, Picture};
pub(crate) use params::{OutputMode, ParamsUbo, MAX_TERMS};
pub use pass::{MapView, PassOptions, ScenePass};
pub use variant::{TableFormat, TableOptions, VariantKind, VariantStats};

use crate::brdf::table::{DiscKernel, Region, Response};
use crate::gpu::memory::{Buffer, Image, ImageDesc, Sampler};
use crate::gpu::pipeline::ShaderModule;
use crate::gpu::{shaders, Device, StorageFormat};
use crate::material::PreparedMaterial;
use crate::scene::Scene;
use crate::{Error, Result};
use background::{Background, BuildOptions};
use offscreen::MapPass;
use pass::MeshBuffers;
use record::Transforms;
use region::{load_scene_mesh, region_contains, scene_disc, scene_region, widen};
use variant::PreparedVariant;

/// Largest BRDF map side.
pub const MAX_MAP_SIZE: u32 = 4096;
/// `render --brdf-map` side without `--size`.
pub const DEFAULT_MAP_SIZE: u32 = 256;
/// `render --brdf-map` light angle without `--theta-i` (degrees).
pub const DEFAULT_MAP_THETA_I: f64 = 30.0;

/// Map pixel `(i, j)` of an `S×S` BRDF map → `ωr`, exactly as the fragment shader computes
/// it in float32 (README: BRDF maps); `None` outside the unit disk.
pub fn map_direction(i: u32, j: u32, size: u32) -> Option<[f64; 3]> {
    let s = size as f32;
    let x = 2.0 * (i as f32 + 0.5) / s - 1.0;
    let y = 1.0 - 2.0 * (j as f32 + 0.5) / s;
    let r2 = x * x + y * y;
    (r2 < 1.0).then(|| [x as f64, y as f64, (1.0 - r2).sqrt() as f64])
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

/// The variant a draw asks for: its key, the region it would be built for and the region
/// the draw needs.
struct WantedVariant {
    key: PreparedKey,
    region: Region,
    needed: Region,
    /// Built with a covering margin: a variant built for another region that holds
    /// `needed` serves as well.
    covering: bool,
}

impl WantedVariant {
    /// Whether a variant built under `held` serves this draw: the same key or, covering,
    /// the same but for a region that holds the needed one and a disc footprint close to
    /// this one.
    fn served_by(&self, held: &PreparedKey) -> bool {
        *held == self.key
            || (self.covering
                && self.same_but_region(held)
                && discs_close(held.disc, self.key.disc)
                && held
                    .region
                    .is_some_and(|r| region_contains(&r.map(f64::from_bits), &self.needed)))
    }

    /// Whether `held` differs from this key in its region and disc footprint at most (the
    /// same variant, material and settings).
    fn same_but_region(&self, held: &PreparedKey) -> bool {
        PreparedKey {
            region: held.region,
            disc: held.disc,
            ..self.key.clone()
        } == *held
    }
}

/// Largest change of a disc footprint's covariance (relative, Frobenius) for which a table
/// pre-filtered with one still serves the other while the viewer moves the light: the
/// footprint's width then moves by about half of it, 10 %.
const DISC_TOLERANCE: f64 = 0.2;

/// Whether two disc keys are the same or, both present, within [`DISC_TOLERANCE`].
fn discs_close(a: Option<[u64; 4]>, b: Option<[u64; 4]>) -> bool {
    let cov = |k: [u64; 4]| {
        let [a, b, c, d] = k.map(f64::from_bits);
        DiscKernel {
            axes: [[a, b], [c, d]],
        }
        .covariance()
    };
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => {
            let (ca, cb) = (cov(a), cov(b));
            let norm = |m: [[f64; 2]; 2]| m.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
            let diff = [0, 1].map(|i| [0, 1].map(|j| ca[i][j] - cb[i][j]));
            norm(diff) <= DISC_TOLERANCE * norm(ca).max(norm(cb))
        }
        _ => false,
    }
}

/// A scene's files and their device copies, kept by the renderer so later scene passes of
/// the same mesh and texture (the viewer's switches) neither read nor upload them again.
struct SceneUploads {
    key: (
        crate::scene::MeshSpec,
        Option<crate::scene::TextureSpec>,
        bool,
    ),
    inputs: Arc<SceneInputs>,
    mesh: Arc<MeshBuffers>,
    texture: Option<Arc<Image>>,
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
    /// Leave out what a draw cannot need (off by default; `render` and `view` switch it
    /// on).
    leave_out: bool,
    /// Mesh frames evaluate the BRDF per vertex (thesis §1.5.1; `flss`, `nmm`, `pq`).
    per_vertex: bool,
    cache_dir: Option<std::path::PathBuf>,
    /// Where warnings and progress of the work go (stderr unless the owner says otherwise).
    report: Arc<dyn crate::report::Report>,
    prepared: Option<(PreparedKey, Arc<dyn PreparedVariant>)>,
    /// A variant build on a worker thread (the viewer's); declared after `prepared` so it
    /// is stopped and joined before the device goes.
    background: Option<Background>,
    /// Superseded builds told to stop, until their workers have (joined when dropped).
    cancelled: Vec<Background>,
    builds_cancelled: u64,
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
    /// Shader modules by glsl file name, made once and shared by every pass built from
    /// them (a variant or switch change rebuilds only what differs); emptied when the
    /// run-time SPIR-V changes.
    modules: std::sync::Mutex<std::collections::HashMap<String, Arc<ShaderModule>>>,
    /// The 1×1 white texture of passes without a scene texture, made once.
    white: std::sync::OnceLock<Arc<Image>>,
    /// The last scene pass's files and device copies, reused while the mesh and texture
    /// stay the same.
    scene_uploads: Option<SceneUploads>,
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
        // The inputs were checked before the device opened: the held notes may show.
        crate::report::work_begins();
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
            background: None,
            cancelled: Vec::new(),
            builds_cancelled: 0,
            region_margin: 0.0,
            table_region: None,
            shader_overrides: Default::default(),
            linear: Sampler::trilinear(
                &dev,
                "surface texture (trilinear)",
                vk::SamplerAddressMode::REPEAT,
            )?,
            vert_map: ShaderModule::new(&dev, "brdfmap.vert", shaders::BRDFMAP_VERT)?,
            vert_mesh: ShaderModule::new(&dev, "diffraction.vert", shaders::DIFFRACTION_VERT)?,
            modules: Default::default(),
            white: Default::default(),
            scene_uploads: None,
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
        if let Ok(mut m) = self.modules.lock() {
            m.clear();
        }
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

    /// The f64 CPU model of the variant the last frame used (for a table variant, only if
    /// [`Renderer::set_keep_models`] was on when its table was built; none for a debug view).
    pub fn model(&self) -> Option<&dyn variant::CpuModel> {
        self.prepared.as_ref().and_then(|(_, v)| v.model())
    }

    /// The table options the next builds use.
    pub fn table_options(&self) -> TableOptions {
        self.table
    }

    /// What the prepared variant reports about itself (`None` before a draw).
    pub fn prepared_stats(&self) -> Option<variant::VariantStats> {
        self.prepared.as_ref().map(|(_, v)| v.stats())
    }

    /// The f64 table of the last frame's table variant (see [`Renderer::model`]).
    pub fn table_model(&self) -> Option<&dyn crate::brdf::table::GTable> {
        self.model().and_then(|m| m.table())
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
        let key = (
            scene.mesh.clone(),
            scene.texture.clone(),
            options.texture_blending,
        );
        let kept = self.scene_uploads.as_ref().filter(|u| u.key == key);
        let (inputs, uploads) = match kept {
            Some(u) => (
                Arc::clone(&u.inputs),
                (Arc::clone(&u.mesh), u.texture.clone()),
            ),
            None => {
                self.scene_uploads = None;
                let inputs = Arc::new(SceneInputs::load(scene, options.texture_blending)?);
                let (mesh, texture) = self.upload_scene(scene, &inputs, options)?;
                self.scene_uploads = Some(SceneUploads {
                    key,
                    inputs: Arc::clone(&inputs),
                    mesh: Arc::clone(&mesh),
                    texture: texture.clone(),
                });
                (inputs, (mesh, texture))
            }
        };
        self.scene_pass_of(
            scene,
            &inputs.mesh,
            uploads,
            prepared,
            options,
            render_pass,
            aspect,
        )
    }

    /// The device copies of a scene's inputs: its mesh's vertex and index buffers and, when
    /// the pass blends it, its texture.
    pub(super) fn upload_scene(
        &self,
        scene: &Scene,
        inputs: &SceneInputs,
        options: PassOptions,
    ) -> Result<(Arc<MeshBuffers>, Option<Arc<Image>>)> {
        let mesh = &inputs.mesh;
        let texture = match (&scene.texture, &inputs.texture) {
            (Some(t), Some(pixels)) if options.texture_blending => {
                Some(Arc::new(self.upload_texture(t, pixels)?))
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
        let buffers = MeshBuffers {
            vertices,
            indices,
            index_count: mesh.indices.len() as u32,
        };
        Ok((Arc::new(buffers), texture))
    }

    /// `scene`'s mesh: the one the last scene pass loaded, while the scene names the same
    /// mesh (the viewer asks on every view change), else loaded now.
    fn scene_mesh(&self, scene: &Scene) -> Result<std::borrow::Cow<'_, crate::mesh::Mesh>> {
        match &self.scene_uploads {
            Some(u) if u.key.0 == scene.mesh => Ok(std::borrow::Cow::Borrowed(&u.inputs.mesh)),
            _ => load_scene_mesh(scene).map(std::borrow::Cow::Owned),
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn scene_pass_of(
        &mut self,
        scene: &Scene,
        mesh: &crate::mesh::Mesh,
        (buffers, texture): (Arc<MeshBuffers>, Option<Arc<Image>>),
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
        // `render` (no covering margin) fits the table to what its frame shows and, for the
        // table variants, pre-filters the sun's disc into it; the viewer keeps every lit
        // vertex, and the disc its build chose ([`Renderer::prepare_in_background`]: none
        // while the BRDF map, which shares the table, is shown).
        let fitted = self.region_margin == 0.0;
        let disc = if fitted && !self.per_vertex && self.variant.is_table() {
            scene_disc(scene, mesh, aspect)
        } else if !fitted {
            self.prepared_disc()
        } else {
            None
        };
        // The triangles in the camera's frame: `render` fits its table to them, the viewer
        // covers them with a margin.
        let region = match scene_region(scene, mesh, Some(aspect), disc.is_some()) {
            Some(r) => r,
            None => {
                self.report.warn(&format!(
                    "no triangle of '{}' in the camera's frame is lit and seen from its front: the image shows no diffraction",
                    mesh.name
                ));
                region::unlit()
            }
        };
        self.prepare_variant(prepared, region, OutputMode::Mesh, disc)?;
        let mut params = self.params(prepared);
        let eye = scene.camera.eye;
        params.eye_world = [eye[0], eye[1], eye[2], 1.0];
        params.set_light(&scene.light);
        // Algorithm 4's weight, the scene's ambient light (a uniform sky), the texture's
        // gain, and the picture's scale (radiance over S, MODEL §10).
        let (w_diffuse, ambient, gain) = scene
            .texture
            .as_ref()
            .map_or((0.0, 0.0, 1.0), |t| (t.w_diffuse, t.ambient, t.gain));
        let sky = crate::light::sky::UniformSky::of_ambient(
            f64::from(ambient),
            f64::from(scene.light.intensity),
        );
        let light = scene.light.intensity;
        params.lighting = [light, out.exposure, w_diffuse, sky.radiance as f32];
        params.shading[1] = gain;
        if let Some((key, _)) = &self.prepared {
            params.shading[2] = (1.0 / key.table.response.scale()) as f32;
        }
        let bg = out.background;

        let transforms = Transforms {
            model: glam::Mat4::IDENTITY.to_cols_array(),
            view_proj: scene.camera.view_proj(aspect).to_cols_array(),
        };
        self.build_pass(
            prepared,
            params,
            OutputMode::Mesh,
            options,
            Some((buffers, transforms)),
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
        let Some((key, region)) = self.plan_variant(prepared, region, output, disc)? else {
            return Ok(());
        };
        // Free the old resources (and the map pass that points at them) before building new
        // ones.
        self.map = None;
        self.prepared = None;
        let options = self.build_options(region, output, disc, key.table);
        let built = self
            .variant
            .implementation()
            .prepare(&self.dev, &options.setup(prepared, self.report.as_ref()))?;
        self.prepared = Some((key, Arc::from(built)));
        Ok(())
    }

    /// What [`Renderer::prepare_variant`] would build: `None` when the prepared variant
    /// already serves `region` (the same key, or with a covering margin a region that holds
    /// it), else the key and the region to build for.
    fn plan_variant(
        &self,
        prepared: &PreparedMaterial,
        region: Region,
        output: OutputMode,
        disc: Option<DiscKernel>,
    ) -> Result<Option<(PreparedKey, Region)>> {
        let wanted = self.wanted_variant(prepared, region, output, disc)?;
        if let Some((k, _)) = &self.prepared {
            if wanted.served_by(k) {
                return Ok(None);
            }
        }
        Ok(Some((wanted.key, wanted.region)))
    }

    /// The key of the variant `region` needs, and the region it would be built for (widened
    /// by the covering margin where the variant reads the region).
    fn wanted_variant(
        &self,
        prepared: &PreparedMaterial,
        region: Region,
        output: OutputMode,
        disc: Option<DiscKernel>,
    ) -> Result<WantedVariant> {
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
            table: self.table_for(prepared, output),
            keep_model: self.keep_models,
            leave_out: self.leave_out,
            disc: disc.map(|k| {
                let a = k.axes;
                [a[0][0], a[0][1], a[1][0], a[1][1]].map(f64::to_bits)
            }),
        };
        Ok(WantedVariant {
            key,
            region,
            needed,
            covering,
        })
    }

    /// The disc footprint the prepared variant holds (a table with the sun's disc
    /// pre-filtered).
    fn prepared_disc(&self) -> Option<DiscKernel> {
        let bits = self.prepared.as_ref()?.0.disc?;
        let [a, b, c, d] = bits.map(f64::from_bits);
        Some(DiscKernel {
            axes: [[a, b], [c, d]],
        })
    }

    /// The table options a draw of `output` builds with: what `G` answers follows the
    /// picture (MODEL §10). A scene, and the viewer's map beside it (they share one table),
    /// is radiance ([`Response::radiance`]); a BRDF map written for the thesis comparisons
    /// is the relative reflectance of MODEL §2. Options that name a response keep it.
    fn table_for(&self, prepared: &PreparedMaterial, output: OutputMode) -> TableOptions {
        let radiance = matches!(output, OutputMode::Mesh | OutputMode::MapDisplay);
        let response = match self.table.response {
            Response::Relative if radiance => {
                Response::radiance(prepared.material.coherence_um, &prepared.shading)
            }
            r => r,
        };
        TableOptions {
            response,
            ..self.table
        }
    }

    /// The settings a variant is built with, owned (a background build takes them to its
    /// thread).
    fn build_options(
        &self,
        region: Region,
        output: OutputMode,
        disc: Option<DiscKernel>,
        table: TableOptions,
    ) -> BuildOptions {
        BuildOptions {
            region,
            output,
            storage: self.storage,
            table,
            keep_model: self.keep_models,
            cache_dir: self.cache_dir.clone(),
            leave_out: self.leave_out,
            disc,
        }
    }

    /// Uploads a scene texture's pixels (sRGB bytes) into an `R8G8B8A8_SRGB` image, so
    /// sampling returns linear colour, with its mip chain averaged in linear colour
    /// ([`crate::image_io::mip_levels`]): a pixel that covers many texels reads their mean.
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
        let lut = crate::colour::srgb8_decode_table();
        let below = crate::image_io::mip_levels(w, h, |i| rgb[i].map(|c| lut[usize::from(c)]));
        let levels: Vec<Vec<u8>> =
            std::iter::once(rgb.iter().flat_map(|p| [p[0], p[1], p[2], 255]).collect())
                .chain(below.iter().map(|(_, _, px)| {
                    use rayon::prelude::*;
                    px.par_iter()
                        .flat_map_iter(|p| {
                            let c = crate::colour::linear_to_srgb8(p.map(f64::from), 1.0);
                            [c[0], c[1], c[2], 255]
                        })
                        .collect()
                }))
                .collect();
        let levels: Vec<&[u8]> = levels.iter().map(Vec::as_slice).collect();
        Image::sampled_with_mips(
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
            &levels,
        )
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
