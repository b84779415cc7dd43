//! Variant `chebyshev-w` (glsl/chebyshev_w.frag): `G` sampled in f64 at K Chebyshev nodes
//! of the reachable `w` range and stored as K coefficient planes of a series in `ŵ`; K
//! bilinear fetches and Clenshaw's recurrence per pixel.

use std::sync::Arc;

use super::table::{prepare, Layout, TableLayout, TableTraits};
use super::{
    DrawSetup, Family, FetchInputs, Mirrored, PreparedVariant, Preset, Stability, Variant,
};
use crate::brdf::table;
use crate::gpu::Device;
use crate::Result;

pub(crate) struct ChebyshevW;

/// Its coefficient planes packed four values a texel, each a cubic B-spline in `(u, v)`
/// with one ghost texel a side.
const LAYOUT: TableLayout = TableLayout {
    layout: Layout::PackedPlanes,
    ghosts: 1,
    fitted: false,
};

impl Variant for ChebyshevW {
    fn name(&self) -> &'static str {
        "chebyshev-w"
    }

    fn summary(&self) -> &'static str {
        "G = Σ_j c_j(u,v)·T_j(ŵ) from f64 tables, Clenshaw in w, cubic B-spline in (u,v): 4⌈3K/4⌉ bilinear fetches"
    }

    fn family(&self) -> Family {
        Family::Table
    }

    fn fragment(&self) -> &'static str {
        "chebyshev_w.frag"
    }

    fn table_traits(&self) -> Option<TableTraits> {
        Some(TableTraits {
            w_nodes: 16,
            follows_field: true,
            layout: LAYOUT,
        })
    }

    fn fetches(&self, f: &FetchInputs<'_>) -> usize {
        super::table::fetches(Self::KIND, f)
    }

    fn fetch_formula(&self) -> &'static str {
        "4⌈3K/4⌉ (K coefficients, at most the w nodes: those the tolerance keeps; four values a texel, four bilinear fetches a spline)"
    }

    fn profile_presets(&self) -> &'static [Preset] {
        const ROWS: &[Preset] = &[
            Preset::named("chebyshev-w"),
            Preset {
                table_step_nm: Some(5),
                ..Preset::named("chebyshev-w 5nm")
            },
        ];
        ROWS
    }

    fn stability(&self) -> Stability {
        Stability::Table(|hf, coherence_um, spec, _| {
            let c = table::ChebyshevW::build(hf, coherence_um, spec, &|| ())?;
            Ok(Mirrored::Eval(Box::new(move |t, w| g_f32(&c, t, w))))
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
            LAYOUT.layout,
            table::ChebyshevW::nodes,
            |r, s| -> Result<(Box<dyn table::GTable>, _)> {
                // The terms whose sum stays within the material's tolerance of the peak
                // are left out (and their planes with them), as wavelengths are.
                let (base, terms) =
                    table::ChebyshevW::from_nodes_within(r, &s, setup.leave_out_tolerance());
                let table: Box<dyn table::GTable> = if super::table::reads_boxes(dev, setup) {
                    Box::new(table::Summed::new(base))
                } else {
                    Box::new(table::Levelled::new(base, setup.table.levels))
                };
                Ok((table, Some(terms)))
            },
        )
    }
}

/// `G` at `(u, v)` node `t` and `w` as glsl/chebyshev_w.frag evaluates it: Clenshaw's
/// recurrence over the coefficients in float32, clamped to `G ≥ 0`.
pub(crate) fn g_f32(c: &table::ChebyshevW, t: usize, w: f64) -> [f64; 3] {
    let x = c.w_hat(w) as f32;
    let (mut b1, mut b2) = ([0.0f32; 3], [0.0f32; 3]);
    for cj in c.coeffs.iter().skip(1).rev() {
        let b0: [f32; 3] = std::array::from_fn(|ch| cj[t][ch] as f32 + 2.0 * x * b1[ch] - b2[ch]);
        b2 = b1;
        b1 = b0;
    }
    std::array::from_fn(|ch| (c.coeffs[0][t][ch] as f32 + x * b1[ch] - b2[ch]).max(0.0) as f64)
}

#[cfg(test)]
mod tests {
    use super::super::testing;
    use super::*;

    #[test]
    fn float32_clenshaw_reproduces_the_series() {
        let spec = testing::spec(8);
        let c = table::ChebyshevW::from_nodes(
            spec.region,
            &testing::slices(&spec, &table::ChebyshevW::nodes(&spec)),
        );
        // Eight coefficients hold a cubic exactly: the series is the function itself, and
        // Clenshaw in float32 adds only float32's rounding.
        for w_hat in [-1.0, -0.73, -0.1, 0.0, 0.42, 0.999] {
            let w = -1.35 + 0.25 * w_hat;
            for t in 0..2 {
                let (got, want) = (g_f32(&c, t, w), testing::g(t, w_hat));
                for ch in 0..3 {
                    assert!(
                        (got[ch] - want[ch]).abs() < 2e-6,
                        "{t} {w_hat}: {got:?} {want:?}"
                    );
                }
            }
        }
    }
}
