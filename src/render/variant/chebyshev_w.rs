//! Variant `chebyshev-w` (glsl/chebyshev_w.frag): `G` sampled in f64 at K Chebyshev nodes
//! of the reachable `w` range and stored as K coefficient planes of a series in `ŵ`; K
//! bilinear fetches and Clenshaw's recurrence per pixel.

use std::sync::Arc;

use super::table::{packed_layers, prepare, Layout};
use super::{DrawSetup, Family, FetchInputs, PreparedVariant, Preset, Variant};
use crate::brdf::table;
use crate::gpu::Device;
use crate::Result;

pub(crate) struct ChebyshevW;

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

    fn table_w_nodes(&self) -> Option<usize> {
        Some(16)
    }

    fn w_nodes_follow_the_field(&self) -> bool {
        true
    }

    fn fetches(&self, f: &FetchInputs<'_>) -> usize {
        4 * packed_layers(f.table.w_nodes_for(Self::KIND))
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

    fn prepare(
        &self,
        dev: &Arc<Device>,
        setup: &DrawSetup<'_>,
    ) -> Result<Box<dyn PreparedVariant>> {
        prepare(
            Self::KIND,
            dev,
            setup,
            Layout::PackedPlanes,
            table::ChebyshevW::nodes,
            |r, s| Ok(table::ChebyshevW::from_nodes(r, &s)),
        )
    }
}
