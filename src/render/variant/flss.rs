//! Variant `flss` (thesis Algorithm 3, glsl/flss.frag): the DFT terms of the material as an
//! image array (one layer per term, the cropped band, in the chosen storage format), the
//! per-term decode table in the uniform block, and the constants `T`, `R`, `Δλ`, expansion
//! and storage. When leaving out, only the texels the draw's region can reach are uploaded
//! and the shader loops over the wavelengths that matter (binding 2 holds only those).

use std::sync::Arc;
use std::time::Instant;

use ash::vk;

use super::{
    CpuModel, DrawSetup, Family, FetchInputs, PreparedVariant, Preset, SpecConstant,
    Specialisation, Stability, Variant, VariantStats,
};
use crate::colour::{LAMBDA_MAX_NM, LAMBDA_MIN_NM};
use crate::gpu::formats::{pack_layers, Layer};
use crate::gpu::memory::{Image, ImageDesc, Sampler};
use crate::gpu::pipeline::{Binding, Resource};
use crate::gpu::{Device, StorageFormat};
use crate::leave_out::{crop, intersect, LeftOut, TexelsLeft, UvBox, WavelengthsLeft};
use crate::material::PreparedMaterial;
use crate::render::{OutputMode, ParamsUbo, MAX_TERMS};
use crate::spectrum::{Band, Expansion, TermStack};
use crate::{Error, Result};

pub(crate) struct Flss;

impl Variant for Flss {
    fn name(&self) -> &'static str {
        "flss"
    }

    fn summary(&self) -> &'static str {
        "thesis Algorithm 3: every wavelength × term × window tap per pixel (exact to its T, R, Δλ)"
    }

    fn family(&self) -> Family {
        Family::Terms
    }

    fn table_traits(&self) -> Option<super::table::TableTraits> {
        None
    }

    fn fragment(&self) -> &'static str {
        "flss.frag"
    }

    fn per_vertex(&self) -> Option<&'static str> {
        Some("flss_vertex.vert")
    }

    fn spectral(&self) -> bool {
        true
    }

    fn fetches(&self, f: &FetchInputs<'_>) -> usize {
        f.lambdas() * (f.terms + 1) * f.taps()
    }

    fn fetch_formula(&self) -> &'static str {
        "λ·(T+1)·(2R+1)² (λ: the wavelengths kept)"
    }

    /// Without leaving out, the whole band is uploaded whatever the draw reaches.
    fn reads_region(&self, leave_out: bool) -> bool {
        leave_out
    }

    /// The thesis setting (Taylor, R = 1), the default, larger R, Chebyshev, the compact
    /// storage formats, and coarser and finer wavelength steps.
    fn profile_presets(&self) -> &'static [Preset] {
        use crate::spectrum::Expansion::Chebyshev;
        use StorageFormat::{Rg16f, Unorm16};
        const ROWS: &[Preset] = &[
            Preset {
                window_radius: 1,
                ..Preset::named("thesis: taylor R=1")
            },
            Preset::named("taylor R=2"),
            Preset {
                leave_out: false,
                ..Preset::named("taylor R=2 keep-all")
            },
            Preset {
                window_radius: 3,
                ..Preset::named("taylor R=3")
            },
            Preset {
                expansion: Chebyshev,
                ..Preset::named("chebyshev R=2")
            },
            Preset {
                storage: Rg16f,
                ..Preset::named("taylor R=2 rg16f")
            },
            Preset {
                storage: Unorm16,
                ..Preset::named("taylor R=2 unorm16")
            },
            Preset {
                lambda_step_nm: 10,
                ..Preset::named("taylor R=2 10nm")
            },
            Preset {
                lambda_step_nm: 1,
                ..Preset::named("taylor R=2 1nm")
            },
        ];
        ROWS
    }

    fn stability(&self) -> Stability {
        Stability::Spectral(|p, shading, wi, wr, lambda_nm| {
            let stack = p.stack.get()?;
            Ok(crate::brdf::model::rho(
                stack,
                p.terms(),
                &p.window,
                shading,
                wi,
                wr,
                lambda_nm,
            ))
        })
    }

    fn prepare(
        &self,
        dev: &Arc<Device>,
        setup: &DrawSetup<'_>,
    ) -> Result<Box<dyn PreparedVariant>> {
        Ok(Box::new(prepare_terms(dev, setup)?))
    }
}

/// FLSS in f64 (MODEL §4): the same series, window and wavelengths as the shader.
struct FlssModel;

impl CpuModel for FlssModel {
    fn xyz(
        &self,
        p: &PreparedMaterial,
        colour: &crate::colour::ColourTable,
        wi: [f64; 3],
        wr: [f64; 3],
    ) -> Result<[f64; 3]> {
        let stack = p.stack.get()?;
        Ok(crate::brdf::model::xyz(
            stack,
            p.terms(),
            &p.window,
            &p.shading,
            colour,
            wi,
            wr,
        ))
    }
}

/// The DFT terms and lookup constants of a material on the GPU: FLSS's resources, which
/// `nmm` reuses. Leaving out (`setup.leave_out`): only the wavelengths whose weight matters
/// at the material's tolerance, and only the texels lookups from `setup.region` at those
/// wavelengths can read.
pub(super) fn prepare_terms(dev: &Arc<Device>, setup: &DrawSetup<'_>) -> Result<FlssGpu> {
    let start = Instant::now();
    let prepared = setup.prepared;
    let stack = prepared.load_terms(setup.report)?;
    let (selection, wavelengths) = WavelengthsLeft::of(
        &setup.colour(&prepared.colour),
        setup.leave_out_tolerance(),
        "per pixel",
    );
    // A single-wavelength map may ask for any λ; the scene's colour only for the kept ones.
    let lambda_nm = if setup.output == OutputMode::MapSpectral {
        (LAMBDA_MIN_NM as f64, LAMBDA_MAX_NM as f64)
    } else {
        wavelengths.kept_range_nm()
    };
    let uv = UvBox::of_region(&setup.region);
    let band = if setup.leave_out {
        let reach = uv.band(
            stack.nx,
            stack.ny,
            stack.dh_um,
            lambda_nm.0 * 1e-3,
            lambda_nm.1 * 1e-3,
            prepared.window.radius,
        );
        intersect(&reach, &stack.band)
    } else {
        stack.band
    };
    let (terms, decode) = upload_terms(dev, stack, setup.storage, &band)?;
    let t = prepared.terms().min(stack.term_count().saturating_sub(1));
    let name = format!(
        "flss T={t} R={} dλ={} {} {}",
        prepared.window.radius, prepared.colour.step_nm, stack.expansion, setup.storage
    );
    let taps = (2 * prepared.window.radius + 1).pow(2);
    let bytes = |b: &Band| stack.term_count() * b.width * b.height * setup.storage.texel_bytes();
    let left_out = LeftOut {
        texels: Some(TexelsLeft {
            uv,
            lambda_nm,
            kept: band,
            stored: stack.band,
        }),
        wavelengths: Some(wavelengths),
        terms: None,
        gpu_bytes: bytes(&band),
        gpu_bytes_keep_all: bytes(&stack.band),
    };
    Ok(FlssGpu {
        stats: VariantStats {
            name,
            build_ms: start.elapsed().as_secs_f64() * 1e3,
            gpu_bytes: bytes(&band),
            fetches: selection.keep.len() * (t + 1) * taps,
            table_build: None,
            disc_prefiltered: false,
        },
        spec: [
            (SpecConstant::Terms, t as u32),
            (SpecConstant::WindowRadius, prepared.window.radius as u32),
            (SpecConstant::LambdaStepNm, prepared.colour.step_nm),
            (
                SpecConstant::Expansion,
                match stack.expansion {
                    Expansion::Taylor => 0,
                    Expansion::Chebyshev => 1,
                },
            ),
            (SpecConstant::Storage, setup.storage.spec_value()),
        ],
        params: lookup_params(prepared, stack, &band, &decode),
        sampler: Sampler::new(
            dev,
            "dft terms (nearest)",
            vk::Filter::NEAREST,
            vk::SamplerAddressMode::CLAMP_TO_EDGE,
        )?,
        terms,
        keep: selection.keep,
        left_out,
    })
}

pub(super) struct FlssGpu {
    pub(super) stats: VariantStats,
    /// T, R, Δλ, expansion and storage.
    spec: [(SpecConstant, u32); 5],
    /// spectrumSize, band, lookup and decode of the uniform block.
    params: ([i32; 4], [i32; 4], [f32; 4], Vec<[f32; 4]>),
    sampler: Sampler,
    terms: Image,
    /// Colour-table indices of the wavelengths the shader loops over.
    pub(super) keep: Vec<usize>,
    pub(super) left_out: LeftOut,
}

impl PreparedVariant for FlssGpu {
    fn bindings(&self) -> Vec<Binding> {
        vec![Binding {
            binding: 1,
            kind: vk::DescriptorType::COMBINED_IMAGE_SAMPLER,
            stages: vk::ShaderStageFlags::FRAGMENT,
        }]
    }

    fn resources(&self) -> Vec<(u32, Resource<'_>)> {
        vec![(1, Resource::Sampled(&self.terms, &self.sampler))]
    }

    fn specialise(&self, spec: &mut Specialisation) {
        for (c, v) in self.spec {
            spec[c] = v;
        }
    }

    fn fill_params(&self, params: &mut ParamsUbo) {
        let (size, band, lookup, decode) = &self.params;
        params.spectrum_size = *size;
        params.band = *band;
        params.lookup = *lookup;
        for (d, m) in params.decode.iter_mut().zip(decode) {
            *d = *m;
        }
    }

    fn stats(&self) -> VariantStats {
        self.stats.clone()
    }

    fn model(&self) -> Option<&dyn CpuModel> {
        Some(&FlssModel)
    }

    fn kept_wavelengths(&self) -> Option<&[usize]> {
        Some(&self.keep)
    }

    fn left_out(&self) -> Option<LeftOut> {
        Some(self.left_out.clone())
    }
}

/// The spectrum geometry, window and Chebyshev range of the uniform block.
fn lookup_params(
    prepared: &PreparedMaterial,
    s: &TermStack,
    band: &Band,
    decode: &[[f32; 4]],
) -> ([i32; 4], [i32; 4], [f32; 4], Vec<[f32; 4]>) {
    let sigma = prepared.window.sigma_texels;
    let inv2 = |s: f64| (1.0 / (2.0 * s * s)) as f32;
    (
        [
            s.nx as i32,
            s.ny as i32,
            s.centre_x() as i32,
            s.centre_y() as i32,
        ],
        [
            band.x0 as i32,
            band.y0 as i32,
            band.width as i32,
            band.height as i32,
        ],
        [
            s.dh_um as f32,
            inv2(sigma[0]),
            inv2(sigma[1]),
            s.half_range_um as f32,
        ],
        decode.to_vec(),
    )
}

/// Uploads the term stack over `band` (within the stored band; one layer per term, in the
/// storage format); also returns the per-term decode rows of thesis eq. 1.1.
fn upload_terms(
    dev: &Arc<Device>,
    stack: &TermStack,
    storage: StorageFormat,
    band: &Band,
) -> Result<(Image, Vec<[f32; 4]>)> {
    let layers = stack.term_count();
    if layers == 0 || layers > MAX_TERMS {
        return Err(Error::invalid(
            "terms",
            format!("{layers} term layers; the shader holds 1..={MAX_TERMS}"),
        ));
    }
    let (w, h) = (band.width as u32, band.height as u32);
    let info = &dev.info;
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
    let format = storage.vk_format();
    if !dev.supports_format(format, vk::FormatFeatureFlags::SAMPLED_IMAGE) {
        return Err(Error::invalid(
            "storage format",
            format!("{} cannot sample {format:?}", info.name),
        ));
    }
    // The stack's extrema still bound a cropped layer (eq. 1.1 only needs bounds).
    let texels: Vec<Vec<[f64; 2]>> = stack
        .terms
        .iter()
        .map(|t| {
            crop(t, &stack.band, band)
                .iter()
                .map(|c| [c.re, c.im])
                .collect()
        })
        .collect();
    let packed: Vec<Layer<'_>> = texels
        .iter()
        .zip(&stack.extrema)
        .map(|(t, e)| Layer {
            texels: t,
            extrema: [e.re_min, e.re_max, e.im_min, e.im_max],
        })
        .collect();
    let (bytes, decode) = pack_layers(&packed, storage);
    let terms = Image::sampled_with_data(
        dev,
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
        storage.texel_bytes(),
        &bytes,
    )?;
    Ok((terms, decode))
}
