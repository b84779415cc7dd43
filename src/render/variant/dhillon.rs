//! Variant `dhillon` (glsl/dhillon.frag, Dhillon et al. 2014): `G = Σ_p I_p(u, v)·w^p`,
//! the planes of the powers of `w`, Horner per pixel. Built from the same exact f64
//! samples as `chebyshev-w` and rewritten in the monomial basis, whose float32
//! conditioning is what this variant exposes.

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
        "Dhillon et al. 2014: G = Σ_p I_p(u,v)·w^p from f64 tables, Horner (monomials: ill-conditioned in f32)"
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
        prepare(
            Self::KIND,
            dev,
            setup,
            Layout::Planes,
            table::ChebyshevW::nodes,
            |r, s| table::Dhillon::from_chebyshev(&table::ChebyshevW::from_nodes(r, &s)),
        )
    }
}
