//! Variant `volume` (glsl/volume.frag): `G(u, v, w)` sampled in f64 on uniform slices of
//! the reachable box, stored as a 3D image, one trilinear fetch per pixel.

use std::sync::Arc;

use super::table::{prepare, Layout};
use super::TableFormat;
use super::{DrawSetup, Family, FetchInputs, PreparedVariant, Preset, Variant};
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

    fn table_w_nodes(&self) -> Option<usize> {
        Some(32)
    }

    fn fetches(&self, _: &FetchInputs<'_>) -> usize {
        1
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
            |r, s| Ok(table::Volume::from_slices(r, s)),
        )
    }
}
