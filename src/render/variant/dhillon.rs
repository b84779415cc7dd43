//! Variant `dhillon` (glsl/dhillon.frag, Dhillon et al. 2014): `G = Σ_p I_p(u, v)·w^p`,
//! the planes of the powers of `w`, Horner per pixel. Built from the same exact f64
//! samples as `chebyshev-w` and rewritten in the monomial basis, whose float32
//! conditioning is what this variant exposes.

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
        prepare(
            self.kind(),
            dev,
            setup,
            Layout::Planes,
            table::ChebyshevW::nodes,
            |r, s| table::Dhillon::from_chebyshev(&table::ChebyshevW::from_nodes(r, &s)),
        )
    }
}
