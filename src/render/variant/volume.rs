//! Variant `volume` (glsl/volume.frag): `G(u, v, w)` sampled in f64 on uniform slices of
//! the reachable box, stored as a 3D image, one trilinear fetch per pixel.

use std::sync::Arc;

use super::table::{prepare, Layout};
use super::{DrawSetup, PreparedVariant, Variant, VariantKind};
use crate::brdf::table;
use crate::gpu::{shaders, Device};
use crate::Result;

pub(crate) struct Volume;

impl Variant for Volume {
    fn kind(&self) -> VariantKind {
        VariantKind::Volume
    }

    fn fragment_spirv(&self) -> &'static [u8] {
        shaders::VOLUME_FRAG
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
            Layout::Volume,
            table::Volume::nodes,
            |r, s| Ok(table::Volume::from_slices(r, s)),
        )
    }
}
