//! Variant `coverage` (glsl/coverage.frag), a debug view: per pixel, where its lookups
//! `(u, v, w)` fall against the table region a table variant would build for the same draw
//! (colour `0.1 + 0.8·(û, v̂, ŵ)` inside, magenta where any lookup falls outside, where a
//! table variant draws black), and in its report line how many lookups each fragment makes
//! (one per direction over the light's disc). It uploads only the region's uniform block.

use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;

use ash::vk;

use super::{
    CpuModel, DrawSetup, Family, FetchInputs, PreparedVariant, Stability, Variant, VariantStats,
};
use crate::brdf::table::Region;
use crate::gpu::memory::{Buffer, Pod};
use crate::gpu::pipeline::{Binding, Resource};
use crate::gpu::Device;
use crate::render::{OutputMode, ParamsUbo};
use crate::Result;

pub(crate) struct Coverage;

impl Variant for Coverage {
    fn name(&self) -> &'static str {
        "coverage"
    }

    fn summary(&self) -> &'static str {
        "debug view: each pixel's (u,v,w) lookups against the table region (0.1 + 0.8·fraction inside, magenta outside) and the lookups per fragment (light-disc directions)"
    }

    fn family(&self) -> Family {
        Family::Debug
    }

    fn table_traits(&self) -> Option<super::table::TableTraits> {
        None
    }

    fn fragment(&self) -> &'static str {
        "coverage.frag"
    }

    fn fetches(&self, _: &FetchInputs<'_>) -> usize {
        0
    }

    fn fetch_formula(&self) -> &'static str {
        "0"
    }

    fn stability(&self) -> Stability {
        Stability::Excluded("is a debug view and draws no BRDF")
    }

    fn prepare(
        &self,
        dev: &Arc<Device>,
        setup: &DrawSetup<'_>,
    ) -> Result<Box<dyn PreparedVariant>> {
        let r = setup.region;
        let e = r.extent();
        let ubo = RegionUbo {
            lo: [r.lo[0] as f32, r.lo[1] as f32, r.lo[2] as f32, 0.0],
            inv_extent: [
                (1.0 / e[0]) as f32,
                (1.0 / e[1]) as f32,
                (1.0 / e[2]) as f32,
                0.0,
            ],
            nodes: [0.0; 4],
            levels: [[0.0; 4]; 1 + crate::brdf::table::MAX_LEVELS],
        };
        let info = Buffer::with_data(
            dev,
            "coverage region",
            vk::BufferUsageFlags::UNIFORM_BUFFER,
            std::slice::from_ref(&ubo),
        )?;
        Ok(Box::new(CoverageGpu {
            region: r,
            mesh: setup.output == OutputMode::Mesh,
            lookups: AtomicU32::new(1),
            info,
        }))
    }
}

/// Mirror of `TableInfo` in glsl/table.glsl (only `lo` and `invExtent` are read; the
/// image's size and its levels stay 0).
#[repr(C)]
#[derive(Clone, Copy)]
struct RegionUbo {
    lo: [f32; 4],
    inv_extent: [f32; 4],
    nodes: [f32; 4],
    levels: [[f32; 4]; 1 + crate::brdf::table::MAX_LEVELS],
}

// SAFETY: repr(C) of f32 arrays: no padding.
unsafe impl Pod for RegionUbo {}

struct CoverageGpu {
    region: Region,
    mesh: bool,
    /// Lookups per fragment: the light's disc directions of the last pass (meshes).
    lookups: AtomicU32,
    info: Buffer,
}

impl PreparedVariant for CoverageGpu {
    fn bindings(&self) -> Vec<Binding> {
        vec![Binding {
            binding: 4,
            kind: vk::DescriptorType::UNIFORM_BUFFER,
            stages: vk::ShaderStageFlags::FRAGMENT,
        }]
    }

    fn resources(&self) -> Vec<(u32, Resource<'_>)> {
        vec![(4, Resource::Uniform(&self.info))]
    }

    fn fill_params(&self, params: &mut ParamsUbo) {
        if self.mesh {
            let n = params.light_info[0].max(1) as u32;
            self.lookups.store(n, Ordering::Relaxed);
        }
    }

    /// A debug view draws no BRDF: nothing to model.
    fn model(&self) -> Option<&dyn CpuModel> {
        None
    }

    fn stats(&self) -> VariantStats {
        let (lo, hi) = (self.region.lo, self.region.hi);
        let n = self.lookups.load(Ordering::Relaxed);
        VariantStats {
            name: format!(
                "coverage of u ∈ [{:.3}, {:.3}], v ∈ [{:.3}, {:.3}], w ∈ [{:.3}, {:.3}], {n} lookup{} per fragment",
                lo[0],
                hi[0],
                lo[1],
                hi[1],
                lo[2],
                hi[2],
                if n == 1 { "" } else { "s" }
            ),
            build_ms: 0.0,
            gpu_bytes: std::mem::size_of::<RegionUbo>(),
            fetches: 0,
            table_build: None,
            disc_prefiltered: false,
        }
    }
}
