//! Variant `volume` (glsl/volume.frag): `G(u, v, w)` sampled in f64 on uniform slices of
//! the reachable box, stored as a 3D image, one trilinear fetch per pixel.

use std::sync::Arc;

use super::table::{prepare, Layout};
use super::{DrawSetup, PreparedVariant, Variant, VariantKind};
use crate::brdf::{table, table_cache};
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
        let p = setup.prepared;
        prepare(self.kind(), dev, setup, Layout::Volume, |spec, tick| {
            let s = table_cache::sample_g_cached(
                &p.heightfield,
                p.material.coherence_um,
                spec,
                &table::Volume::nodes(spec),
                setup.cache_dir,
                tick,
            )?;
            Ok(table::Volume::from_slices(spec.region, s))
        })
    }
}
