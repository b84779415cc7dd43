//! Variant `dhillon` (glsl/dhillon.frag): Dhillon et al. 2014's representation
//! `G = Σ_p I_p(u, v)·ŵ^p`, the planes of the powers of `ŵ` (the reachable `w` interval
//! mapped onto `[−1, 1]`), Horner per pixel. The planes are fitted from the same exact f64
//! samples as `chebyshev-w` (not built from products of Taylor terms as in the paper), and
//! the build refuses a table whose float32 sum would miss the material's tolerance.

use std::sync::Arc;

use super::table::{prepare, Layout, TableLayout, TableTraits};
use super::{
    DrawSetup, Family, FetchInputs, Mirrored, PreparedVariant, Preset, Stability, Variant,
};
use crate::brdf::table;
use crate::gpu::Device;
use crate::Result;

pub(crate) struct Dhillon;

/// One bilinear plane per power of `ŵ` kept by the fit.
const LAYOUT: TableLayout = TableLayout {
    layout: Layout::Planes,
    ghosts: 0,
    fitted: true,
};

impl Variant for Dhillon {
    fn name(&self) -> &'static str {
        "dhillon"
    }

    fn summary(&self) -> &'static str {
        "Dhillon et al. 2014's form G = Σ_p I_p(u,v)·ŵ^p, ŵ = w mapped onto its reachable interval; I_p fitted from the f64 table (not built from products of Taylor terms as in the paper); Horner; refused, with its expected error, where float32 cannot hold the sum"
    }

    fn family(&self) -> Family {
        Family::Table
    }

    fn fragment(&self) -> &'static str {
        "dhillon.frag"
    }

    fn table_traits(&self) -> Option<TableTraits> {
        Some(TableTraits {
            w_nodes: 12,
            follows_field: false,
            layout: LAYOUT,
        })
    }

    fn fetches(&self, f: &FetchInputs<'_>) -> usize {
        super::table::fetches(Self::KIND, f)
    }

    fn fetch_formula(&self) -> &'static str {
        "P ≤ K (the powers the fit keeps)"
    }

    fn profile_presets(&self) -> &'static [Preset] {
        const ROWS: &[Preset] = &[Preset::named("dhillon")];
        ROWS
    }

    fn stability(&self) -> Stability {
        Stability::Table(|hf, coherence_um, spec, tolerance| {
            let cheb = table::ChebyshevW::build(hf, coherence_um, spec, &|| ())?;
            let d = table::Dhillon::from_chebyshev(&cheb, 0.1 * tolerance);
            Ok(match d.check(tolerance) {
                Err(e) => Mirrored::Refused {
                    expected: d.expected_error(),
                    message: e.to_string(),
                },
                Ok(()) => Mirrored::Eval(Box::new(move |t, w| g_f32(&d, t, w))),
            })
        })
    }

    fn prepare(
        &self,
        dev: &Arc<Device>,
        setup: &DrawSetup<'_>,
    ) -> Result<Box<dyn PreparedVariant>> {
        let tolerance = setup.prepared.material.tolerance;
        prepare(
            Self::KIND,
            dev,
            setup,
            LAYOUT.layout,
            table::ChebyshevW::nodes,
            |r, s| {
                // A tenth of the tolerance for the dropped tail of the series in w.
                let d = table::Dhillon::from_chebyshev(
                    &table::ChebyshevW::from_nodes(r, &s),
                    0.1 * tolerance,
                );
                d.check(tolerance)?;
                Ok((d, None))
            },
        )
    }
}

/// `G` at `(u, v)` node `t` and `w` as glsl/dhillon.frag evaluates it: Horner over the
/// powers of `ŵ` in float32, clamped to `G ≥ 0`.
pub(crate) fn g_f32(d: &table::Dhillon, t: usize, w: f64) -> [f64; 3] {
    let x = d.w_hat(w) as f32;
    let mut g = [0.0f32; 3];
    for p in d.powers.iter().rev() {
        g = std::array::from_fn(|c| g[c] * x + p[t][c] as f32);
    }
    g.map(|v| v.max(0.0) as f64)
}

#[cfg(test)]
mod tests {
    use super::super::testing;
    use super::*;

    #[test]
    fn float32_horner_reproduces_the_polynomial() {
        let spec = testing::spec(8);
        let cheb = table::ChebyshevW::from_nodes(
            spec.region,
            &testing::slices(&spec, &table::ChebyshevW::nodes(&spec)),
        );
        // A cubic: the tail beyond ŵ³ is f64 noise and is dropped.
        let d = table::Dhillon::from_chebyshev(&cheb, 1e-9);
        assert_eq!(d.powers.len(), 4);
        for w_hat in [-1.0, -0.5, 0.0, 0.3, 1.0] {
            let w = -1.35 + 0.25 * w_hat;
            for t in 0..2 {
                let (got, want) = (g_f32(&d, t, w), testing::g(t, w_hat));
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
