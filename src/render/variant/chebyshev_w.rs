//! Variant `chebyshev-w` (glsl/chebyshev_w.frag): `G` sampled in f64 at K Chebyshev nodes
//! of the reachable `w` range and stored as K coefficient planes of a series in `ŵ`; K
//! bilinear fetches and Clenshaw's recurrence per pixel.

use std::sync::Arc;

use super::table::{prepare, Layout};
use super::{DrawSetup, PreparedVariant, Variant, VariantKind};
use crate::brdf::table;
use crate::gpu::{shaders, Device};
use crate::Result;

pub(crate) struct ChebyshevW;

impl Variant for ChebyshevW {
    fn kind(&self) -> VariantKind {
        VariantKind::ChebyshevW
    }

    fn fragment_spirv(&self) -> &'static [u8] {
        shaders::CHEBYSHEV_W_FRAG
    }

    fn prepare(
        &self,
        dev: &Arc<Device>,
        setup: &DrawSetup<'_>,
    ) -> Result<Box<dyn PreparedVariant>> {
        prepare(
            self.kind(),
            dev,
            setup,
            Layout::Planes,
            table::ChebyshevW::nodes,
            |r, s| Ok(table::ChebyshevW::from_nodes(r, &s)),
        )
    }
}
