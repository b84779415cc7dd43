//! Variant `volume` (glsl/volume.frag): `G(u, v, w)` sampled in f64 on uniform slices of
//! the reachable box, stored as a 3D image, one trilinear fetch per pixel.

use std::sync::Arc;

use super::table::{prepare, Layout, TableLayout, TableTraits};
use super::TableFormat;
use super::{
    DrawSetup, Family, FetchInputs, Mirrored, PreparedVariant, Preset, Stability, Variant,
};
use crate::brdf::table;
use crate::gpu::Device;
use crate::Result;

pub(crate) struct Volume;

impl Variant for Volume {
    fn name(&self) -> &'static str {
        "volume"
    }

    fn summary(&self) -> &'static str {
        "G(u,v,w) in a 3D texture from f64 tables: one trilinear fetch (the floor)"
    }

    fn family(&self) -> Family {
        Family::Table
    }

    fn fragment(&self) -> &'static str {
        "volume.frag"
    }

    fn table_traits(&self) -> Option<TableTraits> {
        Some(TableTraits {
            w_nodes: 32,
            follows_field: false,
            layout: TableLayout {
                layout: Layout::Volume,
                ghosts: 0,
                fitted: false,
            },
        })
    }

    fn fetches(&self, f: &FetchInputs<'_>) -> usize {
        super::table::fetches(Self::KIND, f)
    }

    fn fetch_formula(&self) -> &'static str {
        "1 (one trilinear fetch)"
    }

    fn profile_presets(&self) -> &'static [Preset] {
        const ROWS: &[Preset] = &[
            Preset::named("volume"),
            Preset {
                table_format: Some(TableFormat::Rgba16f),
                ..Preset::named("volume rgba16f")
            },
        ];
        ROWS
    }

    fn stability(&self) -> Stability {
        Stability::Table(|hf, coherence_um, spec, _| {
            let v = table::Volume::build(hf, coherence_um, spec, &|| ())?;
            Ok(Mirrored::Eval(Box::new(move |t, w| g_f32(&v, t, w))))
        })
    }

    fn prepare(
        &self,
        dev: &Arc<Device>,
        setup: &DrawSetup<'_>,
    ) -> Result<Box<dyn PreparedVariant>> {
        prepare(
            Self::KIND,
            dev,
            setup,
            Layout::Volume,
            table::Volume::nodes,
            |r, s| Ok((table::Volume::from_slices(r, s), None)),
        )
    }
}

/// `G` at `(u, v)` node `t` and `w` as glsl/volume.frag's trilinear fetch gives it there:
/// linear between the two slices around `w`, in float32, clamped to `G ≥ 0`.
pub(crate) fn g_f32(v: &table::Volume, t: usize, w: f64) -> [f64; 3] {
    let n = v.slices.data.len();
    let (lo, hi) = (v.region.lo[2], v.region.hi[2]);
    let f = ((w - lo) / (hi - lo)) as f32 * (n - 1) as f32;
    let k = (f.max(0.0).floor() as usize).min(n - 2);
    let x = f - k as f32;
    let (a, b) = (v.slices.data[k][t], v.slices.data[k + 1][t]);
    std::array::from_fn(|c| (a[c] as f32 * (1.0 - x) + b[c] as f32 * x).max(0.0) as f64)
}

#[cfg(test)]
mod tests {
    use super::super::testing;
    use super::*;

    #[test]
    fn float32_slices_interpolate_linearly_in_w() {
        let spec = testing::spec(5);
        let nodes = table::Volume::nodes(&spec);
        let v = table::Volume::from_slices(spec.region, testing::slices(&spec, &nodes));
        // At the slices: the samples; between two: their linear blend.
        for (k, &w) in nodes.iter().enumerate() {
            let got = g_f32(&v, 1, w);
            for (g, want) in got.iter().zip(v.slices.data[k][1]) {
                assert!((g - want).abs() < 1e-6);
            }
        }
        let w = 0.25 * nodes[1] + 0.75 * nodes[2];
        let got = g_f32(&v, 0, w);
        let (a, b) = (v.slices.data[1][0], v.slices.data[2][0]);
        for c in 0..3 {
            let want = 0.25 * a[c] + 0.75 * b[c];
            assert!((got[c] - want).abs() < 1e-6, "{got:?} {want}");
        }
    }
}
