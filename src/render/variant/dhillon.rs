//! Variant `dhillon` (glsl/dhillon.frag): Dhillon et al. 2014's representation
//! `G = Σ_p I_p(u, v)·ŵ^p`, the planes of the powers of `ŵ` (the reachable `w` interval
//! mapped onto `[−1, 1]`), Horner per pixel. The planes are fitted from the same exact f64
//! samples as `chebyshev-w` (not built from products of Taylor terms as in the paper), and
//! the build refuses a table whose float32 sum would miss the material's tolerance.

use std::sync::Arc;

use super::table::{prepare, Layout};
use super::{DrawSetup, Family, FetchInputs, PreparedVariant, Preset, Variant};
use crate::brdf::table;
use crate::gpu::Device;
use crate::Result;

pub(crate) struct Dhillon;

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

    fn table_w_nodes(&self) -> Option<usize> {
        Some(12)
    }

    fn fetches(&self, f: &FetchInputs<'_>) -> usize {
        f.table.w_nodes_for(Self::KIND)
    }

    fn profile_presets(&self) -> &'static [Preset] {
        const ROWS: &[Preset] = &[Preset::named("dhillon")];
        ROWS
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
            Layout::Planes,
            table::ChebyshevW::nodes,
            |r, s| {
                // A tenth of the tolerance for the dropped tail of the series in w.
                let d = table::Dhillon::from_chebyshev(
                    &table::ChebyshevW::from_nodes(r, &s),
                    0.1 * tolerance,
                );
                d.check(tolerance)?;
                Ok(d)
            },
        )
    }
}
