//! The viewer's environment-lit picture: the scene lit by an environment map (and its disc
//! lights and the sun) the way `render --env` lights it, accumulated over frames.
//!
//! The radiance-weighted table ([`EnvLighting::build_cached`], on disk after the first
//! build) is prepared on a worker thread; the sun-lit passes draw meanwhile. Once it is
//! there, the device objects that stay while the environment, the material and the
//! switches stay ([`EnvKernel`]: the `chebyshev-w` table as its shader reads it, the
//! environment, densities, pipelines) are made once;
//! each change of the view (camera, light, exposure, map, rotation, window) rasterises a
//! new G-buffer on the CPU and binds a new [`Picture`]. Every frame then adds a small batch
//! of samples per pixel to the running sums and resolves them into the window with a
//! compute pass (glsl/env_resolve.comp) whose texels are copied into the swapchain image:
//! the sums stay on the device, and the frame needs no readback and no graphics pipeline.
//! Accumulation stops at the cap (`--env-samples`).

use std::sync::mpsc::{channel, Receiver};
use std::sync::Arc;
use std::time::Instant;

use ash::vk;

use super::input::ViewState;
use crate::brdf::table::TableSpec;
use crate::gpu::compute::{self, ComputeLayout, ComputePipeline, StorageSet};
use crate::gpu::frames::Frames;
use crate::gpu::memory::Buffer;
use crate::gpu::swapchain::Swapchain;
use crate::gpu::Device;
use crate::light::env::{EnvMap, EnvSource};
use crate::material::PreparedMaterial;
use crate::mesh::Mesh;
use crate::render::env::{map_lights, Dispatch, EnvKernel, EnvLighting, EnvTarget};
use crate::render::env_brdf::{EnvBrdf, EnvStage};
use crate::render::env_scene::{scene_lights, Albedo, NOISE_BATCH, SCENE_OUTPUTS};
use crate::render::gbuffer::GBufferPass;
use crate::render::variant::VariantKind;
use crate::scene::Scene;
use crate::{Error, Result};

/// The picture's light samples are exactly their share at every multiple of this many
/// samples (and at the cap): [`crate::light::set::light_every`].
const EXACT_EVERY: u32 = 8;
const RESOLVE_SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/env_resolve.comp.spv"));
/// Push-constant bytes of env_resolve.comp.
const RESOLVE_PUSH: u32 = 52;
/// Samples per pixel a frame adds at most.
const MAX_BATCH: u32 = 16;
/// GPU time a frame aims at: the batch doubles below half of it and halves above twice it.
const FRAME_MS: f64 = 30.0;

/// What `view` was asked for: the environments `E` cycles through and how they are lit.
pub(super) struct EnvSettings {
    /// `None`: the sun-lit passes (no environment); the rest are maps.
    pub entries: Vec<Option<EnvSource>>,
    /// The entry shown first.
    pub first: usize,
    pub intensity: f64,
    pub rotate_deg: f64,
    /// The cap of the accumulation (samples per pixel).
    pub samples: u32,
    pub sun: bool,
    /// Without an environment the scene is still drawn in radiance units (disc lights,
    /// `--no-sun`), under a black map.
    pub lit_without_map: bool,
    pub spec: TableSpec,
    pub cache_dir: Option<std::path::PathBuf>,
    /// The scene's texture, when it has one.
    pub texture: Option<Texels>,
}

impl EnvSettings {
    /// The name of entry `i` in the title and the log.
    pub fn name(&self, i: usize) -> String {
        match &self.entries[i] {
            None if self.lit_without_map => "no environment".into(),
            None => "sun".into(),
            Some(EnvSource::File(p)) => p.file_name().map_or(p.display().to_string(), |n| {
                n.to_string_lossy().into_owned()
            }),
            Some(s) => s.name().trim_start_matches("builtin:").to_string(),
        }
    }
}

/// What the table is built for: the material (its identity) and the Fresnel switch.
type LightingKey = (usize, bool);

/// The objects of one environment, material and set of switches.
struct Kernels {
    /// The lighting, the map, shadowing (a specialisation constant of the stages) and the
    /// variant drawn.
    key: (LightingKey, usize, bool, VariantKind),
    scene: EnvKernel,
    map: EnvKernel,
    albedo: Option<Albedo>,
    /// The G-buffer's pipeline and mesh on the device, and whether it holds the albedo.
    gbuffer: Option<(bool, GBufferPass)>,
}

/// One accumulated picture: its sums (an [`EnvTarget`], the point lights apart from the
/// samples) and what the resolve reads per pixel of its rectangle.
struct Picture {
    target: EnvTarget,
    _pixels: Buffer,
    set: StorageSet,
    rect: vk::Rect2D,
    outputs: u32,
    exposure: f32,
    filmic: bool,
    inv_scale: f32,
    /// The filmic curve's white point.
    white: f32,
}

/// Every picture of the window for one view, and the texels they resolve into.
struct View {
    extent: vk::Extent2D,
    texels: Buffer,
    mesh: Picture,
    map: Option<Picture>,
    /// Samples per pixel in the sums.
    done: u32,
    /// Frames that added samples.
    frames: u32,
    /// Frames that drew this picture (added samples or resolved it).
    recorded: u32,
    /// The cap was reached and said.
    reported: bool,
    cleared: bool,
    started: Instant,
}

/// The viewer's environment state ([module notes](self)).
pub(super) struct EnvView {
    pub settings: EnvSettings,
    /// The entry shown.
    pub current: usize,
    maps: Vec<Option<EnvMap>>,
    lighting: Option<(LightingKey, Arc<EnvLighting>)>,
    building: Option<(LightingKey, Receiver<Result<EnvLighting>>, Instant)>,
    kernels: Option<Kernels>,
    resolve: Option<(ComputeLayout, ComputePipeline)>,
    view: Option<View>,
    /// Samples per pixel the next frame adds.
    batch: u32,
    /// The swapchain's texels are B8G8R8A8 (else R8G8B8A8).
    bgra: bool,
    /// The map's turn about +Y shown (degrees).
    turned_deg: f64,
    /// Builds the variants other than `chebyshev-w` for the stages (made on first use;
    /// `chebyshev-w` draws from the environment table itself). Last: what it built is held
    /// by the kernels above.
    variants: Option<crate::render::Renderer>,
}

/// What the resolve reads per pixel of a rectangle (glsl/env_resolve.comp): the
/// background `bg` and, as the bits of `w`, the index of the picture's pixel among the
/// `covered` ones (`0xffffffff`: background).
fn resolve_pixels(bg: &[[f32; 3]], covered: &[u32]) -> Vec<[f32; 4]> {
    let mut pixels: Vec<[f32; 4]> = bg
        .iter()
        .map(|c| [c[0], c[1], c[2], f32::from_bits(u32::MAX)])
        .collect();
    for (k, &i) in covered.iter().enumerate() {
        pixels[i as usize][3] = f32::from_bits(k as u32);
    }
    pixels
}

impl EnvView {
    pub fn new(settings: EnvSettings, first_map: Option<EnvMap>) -> Self {
        let turned_deg = settings.rotate_deg;
        let mut maps: Vec<Option<EnvMap>> = settings.entries.iter().map(|_| None).collect();
        maps[settings.first] = first_map;
        EnvView {
            current: settings.first,
            settings,
            maps,
            lighting: None,
            building: None,
            kernels: None,
            resolve: None,
            view: None,
            batch: 1,
            bgra: true,
            turned_deg,
            variants: None,
        }
    }

    /// Whether the environment path draws the current entry.
    pub fn on(&self) -> bool {
        self.settings.entries[self.current].is_some() || self.settings.lit_without_map
    }

    /// `E`: the next entry. Returns the line to print.
    pub fn cycle(&mut self, frames: &mut Frames) -> String {
        self.current = (self.current + 1) % self.settings.entries.len();
        self.reset(frames);
        format!("environment → {}", self.settings.name(self.current))
    }

    /// Anything changed: the accumulation starts again (said when it had begun).
    pub fn reset(&mut self, frames: &mut Frames) {
        if let Some(v) = self.view.take() {
            if v.done > 0 {
                println!(
                    "{}: accumulation restarts (was {}/{} spp)",
                    self.settings.name(self.current),
                    v.done,
                    self.settings.samples
                );
            }
            frames.retire(v);
        }
    }

    /// A failure: back to the first entry without a map (the sun-lit passes).
    pub fn switch_off(&mut self, frames: &mut Frames) {
        self.reset_kernels(frames);
        self.building = None;
        self.settings.lit_without_map = false;
        self.current = self
            .settings
            .entries
            .iter()
            .position(Option::is_none)
            .unwrap_or(0);
    }

    /// The switches or the material changed: the kernels are made again.
    pub fn reset_kernels(&mut self, frames: &mut Frames) {
        self.reset(frames);
        if let Some(k) = self.kernels.take() {
            frames.retire(k);
        }
    }

    /// Whether the picture is still being prepared or accumulated (the frame is not
    /// settled).
    pub fn busy(&self) -> bool {
        self.on()
            && self
                .view
                .as_ref()
                .is_none_or(|v| v.done < self.settings.samples)
    }

    /// Whether the next frame draws the environment-lit picture.
    pub fn drawing(&self) -> bool {
        self.on() && self.view.is_some()
    }

    /// The GPU time read as a frame begins, that of the frame `frames_in_flight` before it:
    /// the batch follows it where that frame drew the picture (the picture's first frames
    /// read the times of frames that drew the passes instead).
    pub fn frame_gpu_ms(&mut self, ms: f64, frames_in_flight: usize) {
        let timed_picture = self
            .view
            .as_ref()
            .is_some_and(|v| v.recorded as usize >= frames_in_flight);
        if !self.drawing() || !timed_picture {
            return;
        }
        if ms < 0.5 * FRAME_MS {
            self.batch = (self.batch * 2).min(MAX_BATCH);
        } else if ms > 2.0 * FRAME_MS {
            self.batch = (self.batch / 2).max(1);
        }
    }

    /// The title's part: the environment and the samples so far, or that it is prepared.
    pub fn title(&self) -> Option<String> {
        if !self.on() {
            return None;
        }
        let mut name = self.settings.name(self.current);
        if self.turned_deg != 0.0 {
            name = format!("{name} {}°", self.turned_deg);
        }
        Some(match (&self.building, &self.view) {
            (Some((_, _, t)), _) => format!(
                "{name} · preparing the environment, {:.0} s",
                t.elapsed().as_secs_f64()
            ),
            (None, Some(v)) => format!("{name} · {}/{} spp", v.done, self.settings.samples),
            (None, None) => format!("{name} · 0/{} spp", self.settings.samples),
        })
    }

    /// Brings the table, the map and the kernels up to date for `material` and the
    /// switches of `state` without blocking (a table build starts on a worker thread);
    /// binds a picture for the view when there is none. `mesh`: the scene's mesh in world
    /// space; `rects`: where the mesh and the BRDF map (with its light, tangent space) go.
    #[allow(clippy::too_many_arguments)]
    pub fn update(
        &mut self,
        dev: &Arc<Device>,
        frames: &mut Frames,
        material: &Arc<PreparedMaterial>,
        scene: &Scene,
        state: &ViewState,
        mesh: &Mesh,
        extent: vk::Extent2D,
        rects: (vk::Rect2D, Option<(vk::Rect2D, [f64; 3])>),
        (variant, table): (VariantKind, crate::render::TableOptions),
    ) -> Result<()> {
        if !self.on() {
            return Ok(());
        }
        let key = (Arc::as_ptr(material) as usize, state.fresnel);
        let Some(lighting) = self.lighting_for(key, material, state.fresnel, frames)? else {
            return Ok(());
        };
        self.load_map(state)?;
        // A debug view draws no BRDF: the environment shows the default variant's.
        let variant = match crate::render::env_brdf::env_spirv(
            variant.resolve(),
            crate::render::env_brdf::EnvStage::Map,
        ) {
            Ok(_) => variant.resolve(),
            Err(_) => VariantKind::DEFAULT,
        };
        let kernel_key = (key, self.current, state.shadowing, variant);
        if self.kernels.as_ref().is_none_or(|k| k.key != kernel_key) {
            self.reset_kernels(frames);
            let mut shading = material.material.shading();
            shading.fresnel = state.fresnel;
            shading.shadowing = state.shadowing;
            let brdf = self.brdf_for(dev, (variant, table), material, &lighting, &shading)?;
            self.kernels = Some(self.make_kernels(dev, &lighting, kernel_key, &brdf)?);
        }
        self.make_resolve(dev)?;
        if self.view.is_none() {
            let view = self.bind_view(dev, &lighting, scene, state, mesh, extent, rects)?;
            self.view = Some(view);
        }
        Ok(())
    }

    /// The table for `key`: the one at hand, or `None` while a build runs (one starts when
    /// none runs for it; an arrived one is taken).
    fn lighting_for(
        &mut self,
        key: LightingKey,
        material: &Arc<PreparedMaterial>,
        fresnel: bool,
        frames: &mut Frames,
    ) -> Result<Option<Arc<EnvLighting>>> {
        if let Some((k, l)) = &self.lighting {
            if *k == key {
                return Ok(Some(Arc::clone(l)));
            }
        }
        if let Some((k, rx, started)) = &self.building {
            if *k == key {
                return match rx.try_recv() {
                    Ok(Ok(l)) => {
                        println!(
                            "environment table ready in {:.0} ms ({:.1} s on the worker)",
                            started.elapsed().as_secs_f64() * 1e3,
                            l.build_ms / 1e3
                        );
                        self.building = None;
                        self.reset_kernels(frames);
                        let l = Arc::new(l);
                        self.lighting = Some((key, Arc::clone(&l)));
                        Ok(Some(l))
                    }
                    Ok(Err(e)) => {
                        self.building = None;
                        Err(e)
                    }
                    Err(std::sync::mpsc::TryRecvError::Empty) => Ok(None),
                    Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                        self.building = None;
                        Err(Error::invalid("environment table", "the build stopped"))
                    }
                };
            }
        }
        // A new build; a superseded one finishes unheard on its thread.
        let (tx, rx) = channel();
        let m = Arc::clone(material);
        let spec = self.settings.spec;
        let dir = self.settings.cache_dir.clone();
        let mut shading = m.material.shading();
        shading.fresnel = fresnel;
        println!("building the environment table in the background");
        std::thread::spawn(move || {
            let built = EnvLighting::build_cached(
                &m.heightfield,
                m.material.coherence_um,
                &shading,
                &spec,
                dir.as_deref(),
                &crate::report::Stderr,
            )
            .map(|(l, _)| l);
            let _ = tx.send(built);
        });
        self.building = Some((key, rx, Instant::now()));
        Ok(None)
    }

    /// Loads the current entry's map (once) at the rotation of `state`.
    fn load_map(&mut self, state: &ViewState) -> Result<()> {
        let i = self.current;
        let turned = self.settings.rotate_deg + state.env_rotate_deg;
        if turned != self.turned_deg {
            println!("environment turned to {turned}°");
            self.turned_deg = turned;
        }
        let rotate = turned.to_radians();
        if self.maps[i].is_none() {
            let map = match &self.settings.entries[i] {
                Some(source) => EnvMap::load(source, self.settings.intensity, 0.0)?,
                None => EnvMap::from_pixels(2, 1, vec![[0.0; 3]; 2], "no environment")?,
            };
            self.maps[i] = Some(map);
        }
        if let Some(m) = &mut self.maps[i] {
            m.rotate_rad = rotate;
        }
        Ok(())
    }

    /// The resolve's layout and pipeline, made once.
    fn make_resolve(&mut self, dev: &Arc<Device>) -> Result<()> {
        if self.resolve.is_none() {
            let layout = ComputeLayout::new(dev, "env resolve", 3, RESOLVE_PUSH)?;
            let pipeline = ComputePipeline::new(dev, "env resolve", &layout, RESOLVE_SPIRV, &[])?;
            self.resolve = Some((layout, pipeline));
        }
        Ok(())
    }

    /// `variant` bound for the stages with `shading` (the lighting's Fresnel, the view's
    /// shadowing): `chebyshev-w` from the environment table itself (float32, with the view's
    /// levels for the point lights' footprints), any other built now by the view's own
    /// renderer with the view's table options (a table variant's build takes seconds; it is
    /// said). The view's default is `chebyshev-w`, not `render`'s default pair
    /// ([`crate::render::env_brdf::scene_variant`]), whose `volume` would be a second table
    /// to build before the first environment-lit frame (8 s cold at 256²).
    fn brdf_for(
        &mut self,
        dev: &Arc<Device>,
        (variant, table): (VariantKind, crate::render::TableOptions),
        material: &PreparedMaterial,
        lighting: &EnvLighting,
        shading: &crate::brdf::Shading,
    ) -> Result<Arc<EnvBrdf>> {
        if variant == VariantKind::ChebyshevW {
            let format = crate::render::variant::TableFormat::Rgba32f;
            return Ok(Arc::new(lighting.brdf_in(
                dev,
                shading,
                format,
                table.levels,
            )?));
        }
        println!("environment: building {variant} for the environment's stages");
        let renderer = match &mut self.variants {
            Some(r) => r,
            None => {
                let mut r = crate::render::Renderer::on(Arc::clone(dev))?;
                r.set_cache_dir(self.settings.cache_dir.clone());
                self.variants.insert(r)
            }
        };
        renderer.set_variant(variant);
        renderer.set_table_options(table);
        renderer.env_brdf(material, lighting, shading)
    }

    /// The stages of the scene and the map for the lighting and map of `key`, evaluating
    /// `brdf`.
    fn make_kernels(
        &self,
        dev: &Arc<Device>,
        lighting: &EnvLighting,
        key: (LightingKey, usize, bool, VariantKind),
        brdf: &Arc<EnvBrdf>,
    ) -> Result<Kernels> {
        let env = self.maps[self.current]
            .as_ref()
            .ok_or_else(|| Error::invalid("environment", "not loaded"))?;
        let brdf = Arc::clone(brdf);
        let scene = EnvKernel::new(
            dev,
            lighting,
            env,
            &brdf,
            EnvStage::Scene,
            "viewer env scene",
        )?;
        let map = EnvKernel::new(dev, lighting, env, &brdf, EnvStage::Map, "viewer env map")?;
        Ok(Kernels {
            key,
            scene,
            map,
            albedo: None,
            gbuffer: None,
        })
    }
}

impl Kernels {
    /// The G-buffer of `mesh` as `camera` sees it at `w`×`h`, with the texture's albedo
    /// when `blend` gives one (decoded once for these kernels), drawn by the pass kept here
    /// (made again when whether the albedo is blended changes).
    fn gbuffer(
        &mut self,
        dev: &Arc<Device>,
        mesh: &Mesh,
        camera: &crate::scene::Camera,
        (w, h): (u32, u32),
        blend: Option<(&crate::scene::TextureSpec, &Texels)>,
        lighting: &EnvLighting,
    ) -> Result<crate::render::env_scene::GBuffer> {
        if let (Some((spec, (tw, th, bytes))), None) = (blend, &self.albedo) {
            let scale = f64::from(spec.gain) * lighting.mirror_scale;
            self.albedo = Some(Albedo::from_srgb8(*tw, *th, bytes, scale));
        }
        let albedo = blend.and(self.albedo.as_ref());
        let pass = match self.gbuffer.take() {
            Some((blended, pass)) if blended == albedo.is_some() => pass,
            _ => GBufferPass::new(dev, mesh, albedo)?,
        };
        self.gbuffer
            .insert((albedo.is_some(), pass))
            .1
            .draw(camera, (w, h, 1))
    }
}

/// A texture as loaded: width, height, sRGB bytes.
type Texels = (u32, u32, Vec<[u8; 3]>);

/// Where a picture goes and what it is drawn with.
struct PictureSpec<'a> {
    kernel: &'a mut EnvKernel,
    dispatch: Dispatch<'a>,
    /// Per pixel of the rectangle: the background and the index into the picture.
    pixels: Vec<[f32; 4]>,
    rect: vk::Rect2D,
    exposure: f32,
    filmic: bool,
}

impl EnvView {
    /// Binds the pictures of one view: the mesh's G-buffer rasterised at its rectangle,
    /// the BRDF map's when it is shown.
    #[allow(clippy::too_many_arguments)]
    fn bind_view(
        &mut self,
        dev: &Arc<Device>,
        lighting: &EnvLighting,
        scene: &Scene,
        state: &ViewState,
        mesh: &Mesh,
        extent: vk::Extent2D,
        (mesh_rect, map): (vk::Rect2D, Option<(vk::Rect2D, [f64; 3])>),
    ) -> Result<View> {
        let view_scene = state.apply(scene);
        let s = &self.settings;
        let env_on = s.entries[self.current].is_some();
        let env = self.maps[self.current]
            .as_ref()
            .ok_or_else(|| Error::invalid("environment", "not loaded"))?;
        let kernels = self
            .kernels
            .as_mut()
            .ok_or_else(|| Error::invalid("environment", "no kernels"))?;
        let blend = view_scene
            .texture
            .as_ref()
            .zip(s.texture.as_ref())
            .filter(|_| state.texture);
        let mut shading = view_scene.material.shading();
        shading.fresnel = state.fresnel;
        shading.shadowing = state.shadowing;
        let (w, h) = (mesh_rect.extent.width, mesh_rect.extent.height);
        let mut camera_scene = view_scene.clone();
        camera_scene.output.width = w;
        camera_scene.output.height = h;
        let g = kernels.gbuffer(dev, mesh, &view_scene.camera, (w, h), blend, lighting)?;
        let bg = crate::render::env_scene::background(
            &camera_scene,
            env_on.then_some(env),
            w,
            h,
            lighting.mirror_scale,
        );
        let pixels = resolve_pixels(&bg, &g.covered);
        let lights = scene_lights(&view_scene, s.sun, lighting.white);
        let gbytes = g.device_bytes();
        let texels = compute::storage(
            dev,
            "viewer env texels",
            u64::from(extent.width) * u64::from(extent.height) * 4,
        )?;
        let resolve = &self
            .resolve
            .as_ref()
            .ok_or_else(|| Error::invalid("env", "no resolve"))?
            .0;
        let mesh_picture = picture(
            dev,
            lighting,
            resolve,
            &texels,
            PictureSpec {
                kernel: &mut kernels.scene,
                dispatch: Dispatch {
                    env,
                    lights: &lights,
                    shading,
                    samples: s.samples,
                    first: EXACT_EVERY.min(s.samples),
                    seed: 0,
                    w_diffuse: blend.map(|(spec, _)| f64::from(spec.w_diffuse)),
                    pixels: g.covered.len() as u64,
                    map_side: 0,
                    outputs: SCENE_OUTPUTS,
                    extra: Some(if gbytes.is_empty() { &[0; 64] } else { &gbytes }),
                    stride: 1,
                    batch: NOISE_BATCH,
                    stage: EnvStage::Scene,
                    brdf: None,
                    name: "viewer env scene",
                    per_dispatch: None,
                },
                pixels,
                rect: mesh_rect,
                exposure: state.exposure,
                filmic: matches!(view_scene.output.tone, crate::image_io::Tone::Filmic),
            },
            view_scene.output.white,
        )?;
        let map_picture = match map {
            None => None,
            Some((rect, wi)) => {
                let side = rect.extent.width;
                let lights = map_lights(lighting, s.sun.then_some((wi, 1.0)));
                let pixels = (0..side * side)
                    .map(|i| [0.0, 0.0, 0.0, f32::from_bits(i)])
                    .collect();
                Some(picture(
                    dev,
                    lighting,
                    resolve,
                    &texels,
                    PictureSpec {
                        kernel: &mut kernels.map,
                        dispatch: Dispatch {
                            first: EXACT_EVERY.min(s.samples),
                            ..Dispatch::map(
                                env,
                                &lights,
                                shading,
                                s.samples,
                                side,
                                "viewer env map",
                            )
                        },
                        pixels,
                        rect,
                        exposure: state.map_exposure,
                        filmic: false,
                    },
                    1.0,
                )?)
            }
        };
        Ok(View {
            extent,
            texels,
            mesh: mesh_picture,
            map: map_picture,
            done: 0,
            frames: 0,
            recorded: 0,
            reported: false,
            cleared: false,
            started: Instant::now(),
        })
    }

    /// Records this frame's samples and the resolve into swapchain image `index` (instead
    /// of the passes).
    pub fn record(
        &mut self,
        dev: &Arc<Device>,
        cb: vk::CommandBuffer,
        sc: &Swapchain,
        index: u32,
    ) -> Result<()> {
        self.bgra = sc.format == vk::Format::B8G8R8A8_SRGB;
        if self.view.as_ref().is_some_and(|v| v.extent != sc.extent) {
            return Err(Error::invalid(
                "viewer frame",
                "the picture is for another window size",
            ));
        }
        let texels = self.record_resolved(dev, cb)?;
        sc.record_upload(cb, index, texels);
        Ok(())
    }

    /// Records this frame's samples and the resolve into the view's texels (4 bytes a
    /// pixel of the window, the swapchain's order), which it returns.
    fn record_resolved(&mut self, dev: &Arc<Device>, cb: vk::CommandBuffer) -> Result<&Buffer> {
        let bgra = self.bgra;
        let (Some(view), Some(kernels), Some((layout, pipeline))) =
            (&mut self.view, &self.kernels, &self.resolve)
        else {
            return Err(Error::invalid(
                "viewer frame",
                "no environment picture to draw",
            ));
        };
        view.recorded += 1;
        let raw = dev.raw();
        let pictures: Vec<(&Picture, &EnvKernel)> = std::iter::once((&view.mesh, &kernels.scene))
            .chain(view.map.as_ref().map(|m| (m, &kernels.map)))
            .collect();
        if !view.cleared {
            // SAFETY: cb is recording outside a render pass; texels is a live transfer target.
            unsafe { raw.cmd_fill_buffer(cb, view.texels.raw, 0, vk::WHOLE_SIZE, 0xff00_0000) };
            view.cleared = true;
        }
        let cap = self.settings.samples;
        let n = self.batch.min(cap - view.done);
        if n > 0 {
            for (p, k) in &pictures {
                k.record(cb, &p.target, view.done, n)?;
            }
            let before = view.done;
            view.done += n;
            view.frames += 1;
            // Said at each power of two below the cap.
            if view.done < cap && before.leading_zeros() != view.done.leading_zeros() {
                println!(
                    "{}: {}/{cap} spp",
                    self.settings.name(self.current),
                    view.done
                );
            }
        } else if !view.reported {
            // The frame after the last samples: they have been drawn (but for the frame
            // in flight).
            view.reported = true;
            let s = view.started.elapsed().as_secs_f64();
            println!(
                "{}: {cap}/{cap} spp in {} frames, {:.0} ms ({:.1} ms a frame, {:.0} spp/s)",
                self.settings.name(self.current),
                view.frames,
                s * 1e3,
                s * 1e3 / f64::from(view.frames.max(1)),
                f64::from(cap) / s.max(1e-9)
            );
        }
        // The previous frame's copy out of the texels is done before they are written.
        compute::barrier(
            dev,
            cb,
            (
                vk::PipelineStageFlags::TRANSFER,
                vk::AccessFlags::TRANSFER_READ | vk::AccessFlags::TRANSFER_WRITE,
            ),
            (
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::AccessFlags::SHADER_WRITE,
            ),
        );
        for (p, _) in &pictures {
            let r = p.rect;
            let push: Vec<u8> = [
                r.offset.x,
                r.offset.y,
                r.extent.width as i32,
                r.extent.height as i32,
                view.extent.width as i32,
                p.outputs as i32,
                i32::from(bgra),
                i32::from(p.filmic),
            ]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .chain(
                [
                    view.done as f32,
                    cap as f32,
                    p.exposure,
                    p.inv_scale,
                    p.white,
                ]
                .iter()
                .flat_map(|v| v.to_le_bytes()),
            )
            .collect();
            let count = u64::from(r.extent.width) * u64::from(r.extent.height);
            layout.dispatch(cb, pipeline, &p.set, &push, count)?;
        }
        Ok(&view.texels)
    }
}

/// Binds one picture: its sums, the buffer of its point lights, the per-pixel buffer and
/// the resolve's set over them and `texels`.
fn picture(
    dev: &Arc<Device>,
    lighting: &EnvLighting,
    resolve: &ComputeLayout,
    texels: &Buffer,
    spec: PictureSpec<'_>,
    white: f32,
) -> Result<Picture> {
    let d = &spec.dispatch;
    let target = spec.kernel.bind(lighting, d, true)?;
    let bytes: Vec<u8> = spec
        .pixels
        .iter()
        .flatten()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let pixels = Buffer::with_data(
        dev,
        "viewer env pixels",
        vk::BufferUsageFlags::STORAGE_BUFFER,
        &bytes,
    )?;
    let set = StorageSet::new(
        dev,
        "viewer env resolve",
        resolve,
        &[&target.out, &pixels, texels],
    )?;
    Ok(Picture {
        target,
        _pixels: pixels,
        set,
        rect: spec.rect,
        outputs: d.outputs as u32,
        exposure: spec.exposure,
        filmic: spec.filmic,
        inv_scale: (1.0 / lighting.mirror_scale) as f32,
        white,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::table::Region;
    use crate::colour::{linear_to_srgb8, xyz_to_linear_srgb};
    use crate::heightfield::HeightField;
    use crate::light::env::EnvSource;
    use crate::render::env::{render_env_brdf_map, EnvMapRequest};
    use crate::render::env_scene::{render_env_scene, EnvScene};

    fn device() -> Option<Arc<Device>> {
        match Device::new(true) {
            Ok(d) => Some(d),
            Err(Error::NoVulkan(m)) if std::env::var_os("DIFFRACT_REQUIRE_VULKAN").is_none() => {
                eprintln!("SKIPPED: no Vulkan device ({m})");
                None
            }
            Err(e) => panic!("cannot create a validated device: {e}"),
        }
    }

    /// The window's texels of the view after one frame of 8 of 16 samples: the mesh's
    /// 16×16 square on the right, the BRDF map's on the left.
    fn halfway_texels(
        dev: &Arc<Device>,
        view: &mut EnvView,
        lighting: &EnvLighting,
        scene: &Scene,
        wi: [f64; 3],
    ) -> Vec<u8> {
        let state = ViewState::from_scene(scene);
        let mesh = scene.mesh.load().unwrap();
        view.load_map(&state).unwrap();
        let brdf = Arc::new(lighting.brdf(dev, &scene.material.shading()).unwrap());
        view.kernels = Some(
            view.make_kernels(
                dev,
                lighting,
                ((0, true), 0, true, VariantKind::ChebyshevW),
                &brdf,
            )
            .unwrap(),
        );
        view.make_resolve(dev).unwrap();
        let rect = |x: i32| vk::Rect2D {
            offset: vk::Offset2D { x, y: 0 },
            extent: vk::Extent2D {
                width: 16,
                height: 16,
            },
        };
        let extent = vk::Extent2D {
            width: 32,
            height: 16,
        };
        let rects = (rect(16), Some((rect(0), wi)));
        let bound = view
            .bind_view(dev, lighting, scene, &state, &mesh, extent, rects)
            .unwrap();
        view.view = Some(bound);
        view.batch = 8;
        let bytes = 32 * 16 * 4;
        let readback = Buffer::new(
            dev,
            "test texels",
            bytes,
            vk::BufferUsageFlags::TRANSFER_DST,
            gpu_allocator::MemoryLocation::GpuToCpu,
        )
        .unwrap();
        dev.submit_once("test resolve", |cb| {
            let texels = view.record_resolved(dev, cb)?;
            compute::copy_to_host(dev, cb, texels, &readback, bytes);
            Ok(())
        })
        .unwrap();
        assert_eq!(view.view.as_ref().map(|v| v.done), Some(8));
        readback.mapped().unwrap().to_vec()
    }

    /// Halfway to the cap (8 of 16 samples) the window shows the offscreen pictures of 8
    /// samples (the map's and the scene's, exposed, tone-mapped and encoded as the viewer
    /// does): the point lights, added once weighted by the cap, are corrected to the
    /// samples taken. The default scene's sun lights its skin texture, so an uncorrected
    /// point-light part would come out twice as bright.
    #[test]
    fn halfway_the_picture_is_the_offscreen_picture_of_its_samples() {
        let Some(dev) = device() else { return };
        let mut scene = Scene::default_scene();
        (scene.output.width, scene.output.height) = (16, 16);
        scene.output.supersample = 1;
        // A flat patch: a table of the specular lobe alone builds in a moment.
        let hf = HeightField::new(64, 64, 65.0 / 64.0, vec![0.0; 64 * 64]).unwrap();
        let spec = TableSpec {
            region: Region {
                lo: [-0.04, -0.04, -2.0],
                hi: [0.04, 0.04, 0.0],
            },
            texel_uv: 0.002,
            w_nodes: 4,
            step_nm: 20,
            response: crate::brdf::table::Response::Relative,
        };
        let shading = scene.material.shading();
        let lighting = EnvLighting::build(&hf, 65.0, &shading, &spec).unwrap();
        let texture = scene.texture.as_ref().map(|t| t.load().unwrap());
        let settings = EnvSettings {
            entries: vec![Some(EnvSource::Sky)],
            first: 0,
            intensity: 1.0,
            rotate_deg: 0.0,
            samples: 16,
            sun: true,
            lit_without_map: false,
            spec,
            cache_dir: None,
            texture: texture.clone(),
        };
        let mut view = EnvView::new(settings, None);
        let wi = crate::brdf::direction(30.0, 90.0);
        let texels = halfway_texels(&dev, &mut view, &lighting, &scene, wi);
        let sky = EnvMap::load(&EnvSource::Sky, 1.0, 0.0).unwrap();
        let map = render_env_brdf_map(
            &dev,
            &lighting,
            &EnvMapRequest {
                env: &sky,
                shading,
                samples: 8,
                size: 16,
                sun: Some((wi, 1.0)),
                seed: 0,
                brdf: None,
                per_dispatch: None,
            },
        )
        .unwrap();
        let lights = scene_lights(&scene, true, lighting.white);
        let mesh = scene.mesh.load().unwrap();
        let frame = render_env_scene(
            &dev,
            &lighting,
            &EnvScene {
                scene: &scene,
                mesh: &mesh,
                texture: texture.as_ref(),
                env: Some(&sky),
                lights: &lights,
                shading,
                samples: 8,
                seed: 0,
                noise: None,
                brdf: None,
            },
        )
        .unwrap();
        let gain = f64::from(crate::view::input::DEFAULT_MAP_EXPOSURE) / lighting.mirror_scale;
        let map_px: Vec<[u8; 3]> = map
            .xyz
            .iter()
            .map(|p| linear_to_srgb8(xyz_to_linear_srgb(p.map(f64::from)), gain))
            .collect();
        let mesh_px: Vec<[u8; 3]> = scene
            .output
            .resolve(&frame.rgb)
            .unwrap()
            .iter()
            .map(|p| linear_to_srgb8(p.map(f64::from), 1.0))
            .collect();
        assert!(mesh_px.iter().flatten().any(|&c| c > 40), "the mesh is lit");
        let (mut worst, mut off) = (0i32, 0);
        for y in 0..16 {
            for x in 0..32 {
                let t = &texels[(y * 32 + x) * 4..][..4];
                let got = [t[2], t[1], t[0]]; // B8G8R8A8
                let want = if x < 16 {
                    map_px[y * 16 + x]
                } else {
                    mesh_px[y * 16 + x - 16]
                };
                let d = (0..3)
                    .map(|c| (i32::from(got[c]) - i32::from(want[c])).abs())
                    .max()
                    .unwrap();
                worst = worst.max(d);
                off += usize::from(d > 0);
            }
        }
        eprintln!("halfway: {off} of 512 texels off by up to {worst}");
        assert!(worst <= 1, "{off} texels off, by up to {worst}");
        assert_eq!(dev.validation_messages(), 0);
        let mut frames = Frames::single(&dev, "test").unwrap();
        view.reset_kernels(&mut frames);
        dev.wait_idle().unwrap();
    }
}
