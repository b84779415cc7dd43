//! Variant `pq` (glsl/pq.frag; thesis §1.5.3, Algorithm 5, done right): FLSS's terms, read
//! at the period's DFT bins only (3×3 taps, periodic-sinc weights) and multiplied by the
//! periodic factor of `N` copies, `|F_x F_y|²`. The period comes from the height field's
//! spectrum ([`crate::brdf::pq::estimate_periodicity`]); a field that is not whole copies of
//! one period is refused.

use std::sync::Arc;

use ash::vk;

use super::flss::{prepare_terms, FlssGpu};
use super::{
    CpuModel, DrawSetup, Family, FetchInputs, PreparedVariant, Preset, Stability, Variant,
    VariantStats,
};
use crate::brdf::pq::{estimate_periodicity, Periodicity, TAPS};
use crate::gpu::memory::{Buffer, Pod};
use crate::gpu::pipeline::{Binding, Resource};
use crate::gpu::Device;
use crate::material::PreparedMaterial;
use crate::Result;

pub(crate) struct Pq;

/// Mirror of `PqInfo` in glsl/pq.glsl (std140: 16-byte members only).
#[repr(C)]
#[derive(Clone, Copy)]
struct PqInfoUbo {
    copies: [i32; 4],
    period: [f32; 4],
    factor: [f32; 4],
}

// SAFETY: repr(C) of 4-byte scalars in 16-byte groups: no padding.
unsafe impl Pod for PqInfoUbo {}

impl Variant for Pq {
    fn name(&self) -> &'static str {
        "pq"
    }

    fn summary(&self) -> &'static str {
        "thesis §1.5.3 done right: one period's spectrum from 3×3 periodic-sinc taps × |F_x F_y|² of N copies, N·L = 2√π σs (needs whole copies of one period)"
    }

    fn family(&self) -> Family {
        Family::Terms
    }

    fn table_traits(&self) -> Option<super::table::TableTraits> {
        None
    }

    fn fragment(&self) -> &'static str {
        "pq.frag"
    }

    fn per_vertex(&self) -> Option<&'static str> {
        Some("pq_vertex.vert")
    }

    fn fetches(&self, f: &FetchInputs<'_>) -> usize {
        f.lambdas() * (f.terms + 1) * TAPS.pow(2)
    }

    fn fetch_formula(&self) -> &'static str {
        "λ·(T+1)·9"
    }

    fn profile_presets(&self) -> &'static [Preset] {
        const ROWS: &[Preset] = &[
            Preset::named("pq taylor"),
            Preset {
                lambda_step_nm: 1,
                ..Preset::named("pq taylor 1nm")
            },
        ];
        ROWS
    }

    fn stability(&self) -> Stability {
        Stability::Excluded("integrates one period's spectrum and draws no single wavelength")
    }

    fn prepare(
        &self,
        dev: &Arc<Device>,
        setup: &DrawSetup<'_>,
    ) -> Result<Box<dyn PreparedVariant>> {
        let p = setup.prepared;
        let pq = estimate_periodicity(&p.heightfield, p.material.coherence_um)?;
        if pq.off_lattice > crate::brdf::pq::WARN_OFF_LATTICE {
            setup.report.warn(&format!(
                "pq: {:.1}% of the height field's power lies off the {:.4} µm period's lattice (aliased harmonics or irregularity) and is ignored",
                100.0 * pq.off_lattice,
                pq.axes[0].period_um.max(pq.axes[1].period_um)
            ));
        }
        if pq.area_error() > 0.02 {
            let worst = pq
                .axes
                .iter()
                .max_by(|a, b| {
                    (a.area_ratio() - 1.0)
                        .abs()
                        .total_cmp(&(b.area_ratio() - 1.0).abs())
                })
                .unwrap_or(&pq.axes[0]);
            setup.report.warn(&format!(
                "pq: {} copies of the {:.3} µm period make a lobe {:.1}% off the coherence window's area (N·L should be 2√π·σs = {:.1} µm)",
                worst.copies,
                worst.period_um,
                100.0 * (worst.area_ratio() - 1.0).abs(),
                2.0 * std::f64::consts::PI.sqrt() * p.material.coherence_um / 4.0
            ));
        }
        let mut flss = prepare_terms(dev, setup)?;
        let [ax, ay] = pq.axes;
        let ubo = PqInfoUbo {
            copies: [
                ax.copies_in_patch as i32,
                ay.copies_in_patch as i32,
                ax.taps as i32,
                ay.taps as i32,
            ],
            period: [
                ax.period_um as f32,
                ay.period_um as f32,
                ax.samples_per_period as f32,
                ay.samples_per_period as f32,
            ],
            factor: [
                ax.copies as f32,
                ay.copies as f32,
                (2.0 * std::f64::consts::PI * ax.sigma_s_um) as f32,
                (2.0 * std::f64::consts::PI * ay.sigma_s_um) as f32,
            ],
        };
        let info = Buffer::with_data(
            dev,
            "pq info",
            vk::BufferUsageFlags::UNIFORM_BUFFER,
            std::slice::from_ref(&ubo),
        )?;
        // N = 0: a constant axis, where the coherence window's Gaussian gives the lobe.
        let copies = |n: usize| {
            if n == 0 {
                "gauss".to_string()
            } else {
                n.to_string()
            }
        };
        flss.stats.name = format!(
            "pq L=({:.4}, {:.4}) µm N=({}, {}) {}",
            ax.period_um,
            ay.period_um,
            copies(ax.copies),
            copies(ay.copies),
            flss.stats.name.trim_start_matches("flss ")
        );
        // Per wavelength and term: taps_x · taps_y fetches instead of the window's (2R+1)².
        let per_tap = flss.stats.fetches / (2 * p.window.radius + 1).pow(2);
        flss.stats.fetches = per_tap * ax.taps * ay.taps;
        flss.stats.gpu_bytes += std::mem::size_of::<PqInfoUbo>();
        debug_assert!(ax.taps <= TAPS && ay.taps <= TAPS);
        Ok(Box::new(PqGpu {
            flss,
            info,
            pq: PqModel(pq),
        }))
    }
}

struct PqGpu {
    flss: FlssGpu,
    info: Buffer,
    pq: PqModel,
}

/// PQ in f64: one period's spectrum times the periodic factor, for the periodicity the
/// shader was given.
struct PqModel(Periodicity);

impl CpuModel for PqModel {
    fn xyz(
        &self,
        p: &PreparedMaterial,
        colour: &crate::colour::ColourTable,
        wi: [f64; 3],
        wr: [f64; 3],
    ) -> Result<[f64; 3]> {
        Ok(crate::brdf::pq::xyz(
            p.stack.get()?,
            p.terms(),
            &self.0,
            &p.shading,
            colour,
            wi,
            wr,
            crate::brdf::pq::Form::Intensity,
        ))
    }
}

impl PreparedVariant for PqGpu {
    fn base(&self) -> Option<&dyn PreparedVariant> {
        Some(&self.flss)
    }

    fn bindings(&self) -> Vec<Binding> {
        let mut b = self.flss.bindings();
        b.push(Binding {
            binding: 4,
            kind: vk::DescriptorType::UNIFORM_BUFFER,
            stages: vk::ShaderStageFlags::FRAGMENT,
        });
        b
    }

    fn resources(&self) -> Vec<(u32, Resource<'_>)> {
        let mut r = self.flss.resources();
        r.push((4, Resource::Uniform(&self.info)));
        r
    }

    fn stats(&self) -> VariantStats {
        self.flss.stats()
    }

    fn model(&self) -> Option<&dyn CpuModel> {
        Some(&self.pq)
    }

    /// FLSS's record, with the memory of pq's own uniform block (as its stats count it).
    fn left_out(&self) -> Option<crate::leave_out::LeftOut> {
        let mut left = self.flss.left_out()?;
        let ubo = std::mem::size_of::<PqInfoUbo>();
        left.gpu_bytes += ubo;
        left.gpu_bytes_keep_all += ubo;
        Some(left)
    }
}
