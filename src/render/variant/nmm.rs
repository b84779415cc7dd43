//! Variant `nmm` (glsl/nmm.frag; thesis §1.5.2 done right): FLSS's terms and lookups, but
//! only the wavelengths near the diffraction orders of the grating, weighted by the
//! Jacobian of `λ = d·|t|/ν`. The period comes from the height field's spectrum
//! ([`crate::brdf::nmm::estimate_grating`]); a field without a dominant period is refused.

use std::sync::Arc;

use ash::vk;

use super::flss::{prepare_terms, FlssGpu};
use super::{
    CpuModel, DrawSetup, Family, FetchInputs, PreparedVariant, Preset, Stability, Variant,
    VariantStats,
};
use crate::brdf::nmm::{estimate_grating, Density, Grating};
use crate::gpu::memory::{Buffer, Pod};
use crate::gpu::pipeline::{Binding, Resource};
use crate::gpu::Device;
use crate::material::PreparedMaterial;
use crate::Result;

pub(crate) struct Nmm;

/// Mirror of `NmmInfo` in glsl/nmm.frag (std140: vec4 members only).
#[repr(C)]
#[derive(Clone, Copy)]
struct NmmInfoUbo {
    period: [f32; 4],
    extent: [f32; 4],
    sigma: [f32; 4],
    /// x, y: shortest and longest wavelength sampled (nm): the kept ones when leaving out.
    lambda_range: [f32; 4],
}

// SAFETY: repr(C) of f32 arrays: no padding.
unsafe impl Pod for NmmInfoUbo {}

impl Variant for Nmm {
    fn name(&self) -> &'static str {
        "nmm"
    }

    fn summary(&self) -> &'static str {
        "thesis §1.5.2 done right: FLSS at the wavelengths of the grating's orders only, Jacobian-weighted (needs a dominant period)"
    }

    fn family(&self) -> Family {
        Family::Terms
    }

    fn table_traits(&self) -> Option<super::table::TableTraits> {
        None
    }

    fn fragment(&self) -> &'static str {
        "nmm.frag"
    }

    fn per_vertex(&self) -> Option<&'static str> {
        Some("nmm_vertex.vert")
    }

    fn fetches(&self, f: &FetchInputs<'_>) -> usize {
        let per_lambda = (f.terms + 1) * f.taps();
        let line = 2 * crate::brdf::nmm::HALF_SAMPLES as usize + 1;
        let Some(hf) = f.heightfield else {
            return line * per_lambda;
        };
        let window = crate::spectrum::Window::new(
            hf.nx(),
            hf.ny(),
            hf.dh_um(),
            f.material.coherence_um,
            f.material.window_radius,
        );
        match (estimate_grating(hf), window) {
            (Ok(g), Ok(w)) => {
                let n = lambdas_sampled(&g, &w, hf, &f.region, f.kept_range_nm(), f.lambdas());
                per_lambda * n
            }
            _ => 0,
        }
    }

    fn fetch_formula(&self) -> &'static str {
        "9·orders·(T+1)·(2R+1)² (every kept λ where the region holds specular)"
    }

    fn profile_presets(&self) -> &'static [Preset] {
        const ROWS: &[Preset] = &[Preset::named("nmm taylor R=2")];
        ROWS
    }

    fn stability(&self) -> Stability {
        Stability::Excluded("sums the orders' wavelengths and draws no single one")
    }

    fn prepare(
        &self,
        dev: &Arc<Device>,
        setup: &DrawSetup<'_>,
    ) -> Result<Box<dyn PreparedVariant>> {
        let p = setup.prepared;
        let grating = estimate_grating(&p.heightfield)?;
        let mut flss = prepare_terms(dev, setup)?;
        let (lx, ly) = p.heightfield.extent_um();
        let ubo = NmmInfoUbo {
            period: [
                grating.period_um[0].unwrap_or(0.0) as f32,
                grating.period_um[1].unwrap_or(0.0) as f32,
                0.0,
                0.0,
            ],
            extent: [lx as f32, ly as f32, 0.0, 0.0],
            sigma: [
                p.window.sigma_texels[0] as f32,
                p.window.sigma_texels[1] as f32,
                0.0,
                0.0,
            ],
            lambda_range: match &flss.left_out.wavelengths {
                Some(w) => {
                    let (lo, hi) = w.kept_range_nm();
                    [lo as f32, hi as f32, 0.0, 0.0]
                }
                None => [
                    crate::colour::LAMBDA_MIN_NM as f32,
                    crate::colour::LAMBDA_MAX_NM as f32,
                    0.0,
                    0.0,
                ],
            },
        };
        let info = Buffer::with_data(
            dev,
            "nmm info",
            vk::BufferUsageFlags::UNIFORM_BUFFER,
            std::slice::from_ref(&ubo),
        )?;
        let table: Vec<[f32; 4]> = Density::new()
            .table()
            .iter()
            .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32, 0.0])
            .collect();
        let density = Buffer::with_data(
            dev,
            "cie density (1 nm)",
            vk::BufferUsageFlags::STORAGE_BUFFER,
            &table,
        )?;
        let period = |d: Option<f64>| d.map_or("-".to_string(), |d| format!("{:.4} µm", d));
        flss.stats.name = format!(
            "nmm d=({}, {}) {}",
            period(grating.period_um[0]),
            period(grating.period_um[1]),
            flss.stats.name.trim_start_matches("flss ")
        );
        let per_lambda = flss.stats.fetches / flss.keep.len().max(1);
        let range = (ubo.lambda_range[0] as f64, ubo.lambda_range[1] as f64);
        let lambdas = lambdas_sampled(
            &grating,
            &p.window,
            &p.heightfield,
            &setup.region,
            range,
            flss.keep.len(),
        );
        flss.stats.fetches = per_lambda * lambdas;
        Ok(Box::new(NmmGpu {
            flss,
            info,
            density,
            model: NmmModel {
                grating,
                density: Density::new(),
            },
        }))
    }
}

/// Wavelengths a pixel sums at most over `region`: per order and axis 2·HALF_SAMPLES + 1
/// instead of the whole table, for the orders reaching the wavelengths in `range` at the
/// region's largest |u| and |v|; near specular (where the region holds it) every one of
/// the `kept` wavelengths instead.
fn lambdas_sampled(
    grating: &Grating,
    window: &crate::spectrum::Window,
    hf: &crate::heightfield::HeightField,
    region: &crate::brdf::table::Region,
    range: (f64, f64),
    kept: usize,
) -> usize {
    let (lx, ly) = hf.extent_um();
    let t_max = [0, 1].map(|a| region.lo[a].abs().max(region.hi[a].abs()));
    let samples = crate::brdf::nmm::max_samples(grating, window, [lx, ly], t_max, range);
    let specular = (0..2).all(|a| region.lo[a] <= 0.0 && region.hi[a] >= 0.0);
    let n = if specular { samples.max(kept) } else { samples };
    n.max(1)
}

struct NmmGpu {
    flss: FlssGpu,
    info: Buffer,
    density: Buffer,
    model: NmmModel,
}

/// NMM in f64: FLSS's series at the orders' wavelengths, Jacobian-weighted, for the
/// grating the shader was given.
struct NmmModel {
    grating: Grating,
    density: Density,
}

impl CpuModel for NmmModel {
    fn xyz(
        &self,
        p: &PreparedMaterial,
        colour: &crate::colour::ColourTable,
        wi: [f64; 3],
        wr: [f64; 3],
    ) -> Result<[f64; 3]> {
        Ok(crate::brdf::nmm::xyz(
            p.stack.get()?,
            p.terms(),
            &p.window,
            &p.shading,
            colour,
            &self.grating,
            &self.density,
            wi,
            wr,
            true,
        ))
    }
}

impl PreparedVariant for NmmGpu {
    fn base(&self) -> Option<&dyn PreparedVariant> {
        Some(&self.flss)
    }

    fn bindings(&self) -> Vec<Binding> {
        let mut b = self.flss.bindings();
        for (binding, kind) in [
            (4, vk::DescriptorType::UNIFORM_BUFFER),
            (5, vk::DescriptorType::STORAGE_BUFFER),
        ] {
            b.push(Binding {
                binding,
                kind,
                stages: vk::ShaderStageFlags::FRAGMENT,
            });
        }
        b
    }

    fn resources(&self) -> Vec<(u32, Resource<'_>)> {
        let mut r = self.flss.resources();
        r.push((4, Resource::Uniform(&self.info)));
        r.push((5, Resource::Storage(&self.density)));
        r
    }

    fn stats(&self) -> VariantStats {
        self.flss.stats()
    }

    fn model(&self) -> Option<&dyn CpuModel> {
        Some(&self.model)
    }
}
