//! The `Params` uniform block as the shaders read it (mirror of glsl/interface.glsl), what
//! the fragment shader writes, and the colour table of binding 2.

use super::variant::PreparedVariant;
use super::Renderer;
use crate::gpu::memory::Pod;
use crate::material::PreparedMaterial;

/// Capacity of the shader's per-term decode table (`MAX_TERMS` in interface.glsl).
pub(crate) const MAX_TERMS: usize = 65;

/// What the fragment shader writes (`OUTPUT_MODE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum OutputMode {
    Mesh = 0,
    MapXyz = 1,
    MapSpectral = 2,
    /// The viewer's map: linear sRGB × exposure for an sRGB target.
    MapDisplay = 3,
}

/// Mirror of `Params` in glsl/interface.glsl (std140: vec4-sized members only).
#[repr(C)]
#[derive(Clone, Copy)]
pub(crate) struct ParamsUbo {
    pub(super) eye_world: [f32; 4],
    pub(super) light_dir_world: [f32; 4],
    pub(super) lighting: [f32; 4],
    pub(super) map_wi: [f32; 4],
    pub(super) map_info: [f32; 4],
    pub spectrum_size: [i32; 4],
    pub band: [i32; 4],
    pub lookup: [f32; 4],
    pub(super) shading: [f32; 4],
    pub(super) light_info: [i32; 4],
    pub(super) sky_tail: [[f32; 4]; crate::light::sky::TAIL_NODES / 4],
    pub decode: [[f32; 4]; MAX_TERMS],
    pub(super) light_disk: [[f32; 4]; crate::light::MAX_DISK_SAMPLES as usize],
}

impl ParamsUbo {
    /// The light's disc: the directions towards it (world space) and their weights, at most
    /// [`crate::light::MAX_DISK_SAMPLES`] (what `Light::disk_samples` gives).
    pub(crate) fn set_light(&mut self, light: &crate::scene::Light) {
        let disk = light.disk_samples();
        let d = light.direction;
        self.light_dir_world = [d[0], d[1], d[2], 0.0];
        self.light_info = [disk.len() as i32, 0, 0, 0];
        for (slot, s) in self.light_disk.iter_mut().zip(&disk) {
            let t = s.towards_light;
            *slot = [t[0], t[1], t[2], s.weight];
        }
    }
}

// SAFETY: repr(C) of 4-byte scalars in 16-byte groups: no padding.
unsafe impl Pod for ParamsUbo {}

impl Renderer {
    /// The shared part of the uniform block plus the variant's; callers fill in the scene
    /// or map part.
    pub(super) fn params(&self, prepared: &PreparedMaterial) -> ParamsUbo {
        let mut params = ParamsUbo::shared(&prepared.shading);
        if let Some((_, v)) = &self.prepared {
            v.fill_params(&mut params);
        }
        params
    }
}

impl ParamsUbo {
    /// The shared part of the uniform block for `shading` (Schlick's `R0`, texture gain 1,
    /// the relative scale, a point light along −Z, no sky), before the variant and the scene or map fill in theirs.
    pub(crate) fn shared(shading: &crate::brdf::Shading) -> ParamsUbo {
        ParamsUbo {
            eye_world: [0.0; 4],
            light_dir_world: [0.0, 0.0, -1.0, 0.0],
            lighting: [1.0, 1.0, 0.0, 0.0],
            map_wi: [0.0, 0.0, 1.0, 0.0],
            map_info: [0.0; 4],
            spectrum_size: [0; 4],
            band: [0; 4],
            lookup: [0.0; 4],
            shading: [crate::brdf::schlick_r0(shading.ior) as f32, 1.0, 1.0, 0.0],
            light_info: [1, 0, 0, 0],
            sky_tail: {
                let t = crate::light::sky::tail_table();
                std::array::from_fn(|i| std::array::from_fn(|j| t[4 * i + j] as f32))
            },
            decode: [[0.0; 4]; MAX_TERMS],
            light_disk: [[0.0, 0.0, 1.0, 1.0]; crate::light::MAX_DISK_SAMPLES as usize],
        }
    }
}

/// The colour table as binding 2 holds it: per spectral sample the CIE weight times the
/// factor of `response` (what the variant's `G` answers) and `λ`, only the samples the
/// variant keeps (all of them when it leaves none out).
pub(super) fn colour_weights(
    prepared: &PreparedMaterial,
    variant: &dyn PreparedVariant,
    response: &crate::brdf::table::Response,
) -> Vec<[f32; 4]> {
    let table = &response.colour(&prepared.colour);
    let sample = |i: usize| {
        let w = table.weights[i];
        [
            w[0] as f32,
            w[1] as f32,
            w[2] as f32,
            table.lambdas_nm[i] as f32,
        ]
    };
    match variant.kept_wavelengths() {
        Some(kept) => kept.iter().map(|&i| sample(i)).collect(),
        None => (0..table.len()).map(sample).collect(),
    }
}
