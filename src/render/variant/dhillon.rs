//! Variant `dhillon` (glsl/dhillon.frag): Dhillon et al. 2014's representation
//! `G = Σ_p I_p(u, v)·ŵ^p`, the planes of the powers of `ŵ` (the reachable `w` interval
//! mapped onto `[−1, 1]`), Horner per pixel. The planes are fitted from the same exact f64
//! samples as `chebyshev-w` (not built from products of Taylor terms as in the paper), and
//! the build refuses a table whose float32 sum would miss the material's tolerance.

use std::sync::Arc;

use super::table::{prepare, Layout};
use super::{DrawSetup, PreparedVariant, Variant, VariantKind};
use crate::brdf::table;
use crate::gpu::{shaders, Device};
use crate::Result;

pub(crate) struct Dhillon;

impl Variant for Dhillon {
    fn kind(&self) -> VariantKind {
        VariantKind::Dhillon
    }

    fn fragment_spirv(&self) -> &'static [u8] {
        shaders::DHILLON_FRAG
    }

    fn prepare(
        &self,
        dev: &Arc<Device>,
        setup: &DrawSetup<'_>,
    ) -> Result<Box<dyn PreparedVariant>> {
        let tolerance = setup.prepared.material.tolerance;
        prepare(
            self.kind(),
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
