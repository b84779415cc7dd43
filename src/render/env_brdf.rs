//! The BRDF that the environment-lit compute stages evaluate: a prepared variant's own
//! descriptor set (set 0: the shared uniform block, the colour weights, its table or DFT
//! terms) bound beside the stages' storage set, and the SPIR-V that build.rs made of the
//! variant's fragment file with glsl/env_map.glsl or glsl/env_scene.glsl as its main().
//! So the light's estimator calls the very `diffractionXyz` the raster pass calls: one
//! BRDF in GLSL, whatever lights it.
//!
//! **Units.** The stages integrate radiance (MODEL §10): `f_r = A_λ·R0·ρ` per wavelength.
//! The variant's `G` holds it over [`EnvBrdf::scale`] (the mirror's luminance-weighted
//! `A_λ·R0`, about 440 for 65 µm with Fresnel), so its values stay those of a relative
//! table (within float16's range), and the stages multiply by the scale.

use std::sync::Arc;

use ash::vk;

use super::params::ParamsUbo;
use super::variant::{PreparedVariant, SpecConstant, Specialisation, VariantKind};
use crate::brdf::table::{ChebyshevW, Response, TableSpec};
use crate::brdf::Shading;
use crate::gpu::memory::{Buffer, Image, Sampler};
use crate::gpu::pipeline::{DescriptorSet, PipelineLayout, Resource};
use crate::gpu::Device;
use crate::{Error, Result};

/// The compute stages build.rs makes of every variant's fragment file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EnvStage {
    /// A BRDF map's pixels (glsl/env_map.glsl).
    Map,
    /// A G-buffer's pixels (glsl/env_scene.glsl).
    Scene,
}

impl EnvStage {
    fn suffix(self) -> &'static str {
        match self {
            EnvStage::Map => "env_map",
            EnvStage::Scene => "env_scene",
        }
    }
}

/// A variant bound for the environment-lit stages ([module notes](self)).
pub struct EnvBrdf {
    kind: VariantKind,
    /// What `diffractionXyz` returns is radiance over this.
    pub scale: f64,
    /// Texel fetches of one evaluation.
    fetches: usize,
    spec: Specialisation,
    set: DescriptorSet,
    layout: PipelineLayout,
    _ubo: Buffer,
    _colour: Buffer,
    _white: Image,
    _sampler: Sampler,
    /// Last among the resources: the set points at its images and buffers.
    variant: Arc<dyn PreparedVariant>,
    /// Another variant that evaluates the point lights ([`EnvBrdf::with_points`]).
    points: Option<Arc<EnvBrdf>>,
}

impl EnvBrdf {
    /// What the variant's report calls it (`flss T=12 R=1 dλ=10`, a table's nodes).
    pub fn variant_name(&self) -> String {
        self.variant.stats().name
    }

    /// `chebyshev-w` drawn from `table` with the spline planes `splines` of its
    /// coefficients (radiance units; the environment's sampling table, so the draw builds
    /// no second one), stored in `format` over `spec`; with `levels` > 1
    /// the scene stage reads the point lights over their footprints (glsl/env_common.glsl,
    /// `setFootprint`) from summed-area planes, as the raster pass reads its fragments
    /// (`levels` levels pre-filtered where the device does not filter float32), and the
    /// samples the spline at their point.
    pub(crate) fn chebyshev_w(
        dev: &Arc<Device>,
        (table, splines): (&ChebyshevW, &[Vec<[f64; 3]>]),
        spec: &TableSpec,
        shading: &Shading,
        scale: f64,
        (format, levels): (super::variant::TableFormat, usize),
    ) -> Result<Self> {
        let scaled = scaled((table, splines), 1.0 / scale);
        let upload = |t: &dyn crate::brdf::table::GTable| {
            super::variant::table::upload_built(VariantKind::ChebyshevW, dev, spec, t, format)
        };
        // The point lights read the box of their footprint from summed-area planes, as
        // the raster pass reads its fragments', where the device filters them; else the
        // level pre-filtered nearest to it.
        let variant = match levels {
            0 | 1 => upload(&scaled)?,
            _ if super::variant::table::sums_filter(dev) => {
                upload(&crate::brdf::table::Summed::new(scaled))?
            }
            n => upload(&crate::brdf::table::Levelled::new(scaled, n))?,
        };
        Self::new(
            dev,
            VariantKind::ChebyshevW,
            Arc::from(variant),
            shading,
            &[[0.0; 4]],
            scale,
        )
    }

    /// `variant` (of `kind`) with the colour weights `colour` (binding 2: per line the XYZ
    /// weight in radiance over `scale`, and `λ`), Fresnel and shadowing as `shading` says.
    pub(crate) fn new(
        dev: &Arc<Device>,
        kind: VariantKind,
        variant: Arc<dyn PreparedVariant>,
        shading: &Shading,
        colour: &[[f32; 4]],
        scale: f64,
    ) -> Result<Self> {
        if !(scale.is_finite() && scale > 0.0) {
            return Err(Error::invalid("environment BRDF", format!("scale {scale}")));
        }
        let mut bindings = super::pass::pass_bindings(variant.as_ref(), false);
        for b in &mut bindings {
            b.stages = vk::ShaderStageFlags::COMPUTE;
        }
        let name = format!("{kind} under the environment");
        let layout =
            PipelineLayout::new(dev, &name, &bindings, (vk::ShaderStageFlags::COMPUTE, 0))?;
        let mut params = ParamsUbo::shared(shading);
        variant.fill_params(&mut params);
        let ubo = Buffer::with_data(
            dev,
            &format!("{name} params"),
            vk::BufferUsageFlags::UNIFORM_BUFFER,
            std::slice::from_ref(&params),
        )?;
        let colour = Buffer::with_data(
            dev,
            &format!("{name} colour weights"),
            vk::BufferUsageFlags::STORAGE_BUFFER,
            if colour.is_empty() {
                &[[0.0f32; 4]]
            } else {
                colour
            },
        )?;
        let white = super::pass::white_texture(dev)?;
        let sampler = Sampler::new(
            dev,
            "no texture (nearest)",
            vk::Filter::NEAREST,
            vk::SamplerAddressMode::REPEAT,
        )?;
        let mut resources = vec![
            (0, Resource::Uniform(&ubo)),
            (2, Resource::Storage(&colour)),
            (3, Resource::Sampled(&white, &sampler)),
        ];
        resources.extend(variant.resources());
        let set = DescriptorSet::new(dev, &name, &layout, &resources)?;
        drop(resources);
        let mut spec = Specialisation::default();
        spec[SpecConstant::Shadowing] = u32::from(shading.shadowing);
        spec[SpecConstant::Fresnel] = u32::from(shading.fresnel);
        variant.specialise(&mut spec);
        Ok(EnvBrdf {
            kind,
            scale,
            fetches: variant.stats().fetches,
            spec,
            set,
            layout,
            _ubo: ubo,
            _colour: colour,
            _white: white,
            _sampler: sampler,
            variant,
            points: None,
        })
    }

    /// This variant for the samples, `points` for the point lights (the sun's directions),
    /// which a pixel evaluates once each and sees unblurred: the stages' default draws its
    /// samples with `volume` and the point lights with `chebyshev-w`'s splines
    /// ([`scene_variant`]).
    pub fn with_points(mut self, points: Arc<EnvBrdf>) -> Self {
        self.points = Some(points);
        self
    }

    /// The variant that evaluates the point lights, where it is another.
    pub fn points(&self) -> Option<&Arc<EnvBrdf>> {
        self.points.as_ref()
    }

    /// What the report calls the pair: the variant, and the point lights' where another.
    pub fn report_name(&self) -> String {
        match &self.points {
            Some(p) => format!(
                "{} with the point lights by {}",
                self.variant_name(),
                p.variant_name()
            ),
            None => self.variant_name(),
        }
    }

    /// The layout of set 0, which the stages' pipeline layout starts with.
    pub fn set_layout(&self) -> vk::DescriptorSetLayout {
        self.layout.set_layout
    }

    /// Set 0, bound before the stages' storage set.
    pub fn set(&self) -> vk::DescriptorSet {
        self.set.raw
    }

    /// The specialisation constants of the variant's stages, in `constant_id` order.
    pub fn spec(&self) -> &[u32] {
        self.spec.values()
    }

    /// A bound on the loop iterations one sample takes in the stages: two evaluations of
    /// the BRDF (the BRDF's sample and the lights'), each at most two iterations a texel
    /// fetch, plus the samplers' binary searches and `discs` disc lights tested twice.
    pub fn iterations_per_sample(&self, discs: usize) -> u64 {
        4 * self.fetches as u64 + 128 + 4 * discs as u64
    }

    /// The SPIR-V of `stage` made of the variant's fragment file.
    pub fn spirv(&self, stage: EnvStage) -> Result<&'static [u8]> {
        env_spirv(self.kind, stage)
    }
}

/// The variant that draws a scene's environment-lit pixels for `--variant requested`, where
/// light is `sampled` (an environment or disc lights) or not (the sun's directions alone,
/// `--shading compute`). The default is `volume` where light is sampled: one trilinear
/// fetch a sample against `chebyshev-w`'s twenty bilinear ones, so a sample costs about half
/// as much. Its bilinear lobes would shift the colour of the sun's glints, which the point
/// lights see unblurred, so the default draws the point lights with `chebyshev-w`'s splines
/// ([`default_pair`]); its picture stays within [`VOLUME_BIAS_P99`] of `chebyshev-w`'s
/// (both converged), the unbiased row, named with `--variant chebyshev-w`. With point
/// lights alone a pixel takes one evaluation a light, and the default stays `chebyshev-w`,
/// the raster pass's own.
pub fn scene_variant(requested: VariantKind, sampled: bool) -> VariantKind {
    match requested {
        VariantKind::Default if sampled => VariantKind::Volume,
        k => k.resolve(),
    }
}

/// The CIEDE2000 99th percentile that a converged environment-lit scene drawn by the
/// default pair ([`default_pair`]) keeps from the same scene drawn by `chebyshev-w`, the
/// two converged at 4096 samples a pixel with independent sequences (what is left of
/// their noise included): `tests/env_scene.rs` checks it on the default scene.
pub const VOLUME_BIAS_P99: f64 = 0.3;

/// The variants of `candidates` that can be lit by an environment, each once, the default
/// first when it is among them.
pub fn lightable(candidates: &[VariantKind]) -> Vec<VariantKind> {
    let default = std::iter::once(VariantKind::DEFAULT).filter(|k| candidates.contains(k));
    let mut kinds: Vec<VariantKind> = Vec::new();
    for k in default.chain(candidates.iter().copied()) {
        if env_spirv(k, EnvStage::Map).is_ok() && !kinds.contains(&k) {
            kinds.push(k);
        }
    }
    kinds
}

/// The SPIR-V of `stage` that build.rs made of `kind`'s fragment file, or why there is
/// none (a debug view draws no BRDF).
pub fn env_spirv(kind: VariantKind, stage: EnvStage) -> Result<&'static [u8]> {
    let stem = kind
        .fragment_file()
        .strip_suffix(".frag")
        .unwrap_or_default();
    let file = format!("{stem}.{}", stage.suffix());
    crate::gpu::shaders::spirv(&file).ok_or_else(|| {
        Error::invalid(
            "variant",
            format!(
                "'{kind}' cannot be lit by an environment: it draws no BRDF that the environment's stages can evaluate ({} has no shade.glsl main() for build.rs to replace)",
                kind.fragment_file()
            ),
        )
    })
}

/// `table`, with the spline planes `splines` of its coefficients, times `factor` (the
/// series and its splines are linear in `G`).
fn scaled((table, splines): (&ChebyshevW, &[Vec<[f64; 3]>]), factor: f64) -> ChebyshevW {
    let mul = |planes: &[Vec<[f64; 3]>]| -> Vec<Vec<[f64; 3]>> {
        planes
            .iter()
            .map(|p| p.iter().map(|t| t.map(|x| x * factor)).collect())
            .collect()
    };
    ChebyshevW {
        region: table.region,
        nu: table.nu,
        nv: table.nv,
        coeffs: mul(&table.coeffs),
        splines: mul(splines),
    }
}

impl super::Renderer {
    /// The current variant bound for the environment-lit stages of `lighting` (its region,
    /// its scale to radiance), evaluated with `shading`. `chebyshev-w` draws from the
    /// lighting's own table (one table samples and draws); any other variant is built here
    /// with its table in radiance units ([`Response::radiance`] with `shading`) or its
    /// colour weights carrying them, over the lighting's region and at its `(u, v)`
    /// spacing and wavelength step unless the table options name others. Nothing is left
    /// out: the stages reach every `(u, v)` of the region. The renderer's own settings and
    /// the variant it draws with are left as they were.
    pub fn env_brdf(
        &self,
        prepared: &crate::material::PreparedMaterial,
        lighting: &super::env::EnvLighting,
        shading: &Shading,
    ) -> Result<Arc<EnvBrdf>> {
        self.env_brdf_owned(prepared, lighting, shading)
            .map(Arc::new)
    }

    /// [`Self::env_brdf`] not yet shared, for [`default_pair`] to complete.
    pub fn env_brdf_owned(
        &self,
        prepared: &crate::material::PreparedMaterial,
        lighting: &super::env::EnvLighting,
        shading: &Shading,
    ) -> Result<EnvBrdf> {
        let kind = self.variant().resolve();
        env_spirv(kind, EnvStage::Map)?;
        if kind == VariantKind::ChebyshevW {
            return lighting.brdf(self.device(), shading);
        }
        // Built here with its own options, not through the renderer's prepared variant: the
        // renderer's settings and the variant it draws with stay as they are. The stages
        // need no f64 model (it would hold the whole region in f64), and nothing is left
        // out: they reach every `(u, v)` of the region.
        self.variant.check_output(super::params::OutputMode::Mesh)?;
        let table = super::variant::TableOptions {
            texel_uv: self.table.texel_uv.or(Some(lighting.spec.texel_uv)),
            step_nm: self.table.step_nm.or(Some(lighting.spec.step_nm)),
            response: Response::radiance(prepared.material.coherence_um, shading),
            ..self.table
        };
        let options = super::background::BuildOptions {
            region: lighting.spec.region,
            output: super::params::OutputMode::Mesh,
            storage: self.storage,
            table,
            keep_model: false,
            cache_dir: self.cache_dir.clone(),
            leave_out: false,
            disc: None,
        };
        let built = self
            .variant
            .implementation()
            .prepare(&self.dev, &options.setup(prepared, self.report.as_ref()))?;
        let variant: Arc<dyn super::variant::PreparedVariant> = Arc::from(built);
        let weights = super::params::colour_weights(prepared, variant.as_ref(), &table.response);
        EnvBrdf::new(
            self.device(),
            kind,
            variant,
            shading,
            &weights,
            lighting.mirror_scale,
        )
    }
}

/// The stages' default where light is sampled ([`scene_variant`]): `samples` (`volume`)
/// draws the samples, and `chebyshev-w` from `lighting`'s own table, stored in `format`
/// and read over each pixel's footprint where `levels` > 1 ([`EnvBrdf::chebyshev_w`]), the
/// point lights.
pub fn default_pair(
    dev: &Arc<crate::gpu::Device>,
    lighting: &super::env::EnvLighting,
    shading: &Shading,
    (format, levels): (super::variant::TableFormat, usize),
    samples: EnvBrdf,
) -> Result<EnvBrdf> {
    let points = lighting.brdf_in(dev, shading, format, levels)?;
    Ok(samples.with_points(Arc::new(points)))
}
