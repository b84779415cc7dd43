//! Offscreen pictures: BRDF maps and scene frames drawn into an offscreen target, timed,
//! and read back as linear values ([`Picture`]). The last map's pass and target are kept
//! and reused while nothing they were built for changes.

use std::sync::Arc;
use std::time::Instant;

use ash::vk;

use super::params::{colour_weights, OutputMode};
use super::pass::PassOptions;
use super::pass::{MapView, ScenePass};
use super::region::scene_region;
use super::variant::VariantStats;
use super::{Renderer, SceneInputs, MAX_MAP_SIZE};
use crate::brdf;
use crate::brdf::table::Region;
use crate::material::PreparedMaterial;
use crate::scene::Scene;
use crate::{Error, Result};

use crate::gpu::frames::Frames;
use crate::gpu::target::OffscreenTarget;

/// One rendered picture read back from an offscreen target: linear values, row-major from
/// the top row, with the GPU and wall time it took.
#[derive(Debug, Clone)]
pub struct Picture {
    pub width: u32,
    pub height: u32,
    /// Linear sRGB (scenes), XYZ (BRDF maps) or `ρ_λ` in all channels (spectral maps).
    pub rgb: Vec<[f32; 3]>,
    /// GPU time of the draw from timestamps; `None` where the queue has none.
    pub gpu_ms: Option<f64>,
    /// Wall time of the whole call: variant preparation and pipeline creation (unless
    /// reused from the previous frame), draw and readback.
    pub wall_ms: f64,
    /// The variant that drew it.
    pub variant: VariantStats,
    /// A supersampled scene's expected aliasing error: the standard error of each pixel's
    /// mean over its samples, relative to the picture ([`sample_spread`]); `None` with one
    /// sample a pixel.
    pub aliasing: Option<f64>,
}

/// The expected error of a picture box-filtered from `ss × ss` samples a pixel (`rendered`,
/// `width × height` at the supersampled size) against the converged one, from the samples'
/// spread: per pixel and channel the standard error of the mean, `s²/n` with `s²` the
/// samples' variance (`n − 1` in its denominator), summed and taken relative to the
/// picture's own L2 norm. It is exact in expectation for samples independent across a
/// pixel; the regular grid's samples are not, and over the default scene at 128² (2×2) it
/// came within a factor of 1.7 of the error measured against the picture at 16×16 samples
/// a pixel: 0.62 against 0.38 filtered to the footprint, 0.95 against 1.08 at the pixels'
/// centres (docs/results/whole-picture.md). `None` for one sample a pixel.
pub fn sample_spread(rendered: &[[f32; 3]], width: u32, height: u32, ss: u32) -> Option<f64> {
    if ss < 2 || !width.is_multiple_of(ss) || !height.is_multiple_of(ss) {
        return None;
    }
    let (w, ss) = (width as usize, ss as usize);
    let n = (ss * ss) as f64;
    let (mut err2, mut norm2) = (0.0f64, 0.0f64);
    for by in 0..height as usize / ss {
        for bx in 0..w / ss {
            let at = |k: usize| rendered[(by * ss + k / ss) * w + bx * ss + k % ss];
            for c in 0..3 {
                let mean = (0..ss * ss).map(|k| f64::from(at(k)[c])).sum::<f64>() / n;
                let var = (0..ss * ss)
                    .map(|k| (f64::from(at(k)[c]) - mean).powi(2))
                    .sum::<f64>()
                    / (n - 1.0);
                err2 += var / n;
                norm2 += mean * mean;
            }
        }
    }
    (norm2 > 0.0 && err2.is_finite()).then(|| (err2 / norm2).sqrt())
}

/// The median of the times of repeated draws (ms); `None` for no draws.
pub fn median(mut times: Vec<f64>) -> Option<f64> {
    if times.is_empty() {
        return None;
    }
    times.sort_by(f64::total_cmp);
    let n = times.len();
    Some(if n % 2 == 1 {
        times[n / 2]
    } else {
        0.5 * (times[n / 2 - 1] + times[n / 2])
    })
}

impl Picture {
    /// Pixel `(x, y)`, `y` from the top.
    pub fn at(&self, x: u32, y: u32) -> [f32; 3] {
        self.rgb[(y * self.width + x) as usize]
    }
}

/// What a BRDF map pass is built for: the objects of a [`MapPass`] are reused while
/// none of these change (a new `θi`, `φi` or `λ` only rewrites the uniform block).
#[derive(Debug, Clone, PartialEq)]
struct MapKey {
    /// Address of the prepared variant the descriptor set points at (the pass holds an
    /// `Arc` of it, so the address cannot be reused while the key lives).
    variant: usize,
    output: OutputMode,
    options: PassOptions,
    size: u32,
    /// The colour table as uploaded (`λ` and weights).
    colour: Vec<[f32; 4]>,
}

/// The last BRDF map's objects: pass (pipeline, descriptor set, buffers), offscreen target
/// and its frame (command buffer, fence, timestamps). Creating and destroying them for every
/// map cost time (most of lavapipe's 135 ms a 16² frame went to the pipeline) and, with the
/// validation layer on, ~11 KB of its bookkeeping a frame (README: soak).
pub(super) struct MapPass {
    key: MapKey,
    frames: Frames,
    pass: ScenePass,
    target: OffscreenTarget,
}

impl Renderer {
    /// A BRDF map (thesis §5): an S×S image of the hemisphere of view directions, pixel
    /// `(i, j)` (row `j` from the top) at `x = 2(i+½)/S − 1`, `y = 1 − 2(j+½)/S`,
    /// `ωr = (x, y, √(1−x²−y²))`, black outside the unit disk; light from `(θi, φi)`.
    /// Channels: linear XYZ, or `ρ_λ` in all three with `lambda_nm` (flss only).
    pub fn render_brdf_map(
        &mut self,
        prepared: &PreparedMaterial,
        theta_i_deg: f64,
        phi_i_deg: f64,
        size: u32,
        lambda_nm: Option<f64>,
    ) -> Result<Picture> {
        let start = Instant::now();
        check_map_args(theta_i_deg, phi_i_deg, size, lambda_nm)?;
        let wi = brdf::direction(theta_i_deg, phi_i_deg);
        let output = if lambda_nm.is_some() {
            OutputMode::MapSpectral
        } else {
            OutputMode::MapXyz
        };
        // The shader sees ωi in float32: the table must cover what it computes from it.
        let wi32 = wi.map(|c| c as f32 as f64);
        let region = Region::brdf_map(wi32).widened(1e-5);
        self.prepare_variant(prepared, region, output, None)?;
        let mut params = self.params(prepared);
        params.map_wi = [
            wi32[0] as f32,
            wi32[1] as f32,
            wi32[2] as f32,
            lambda_nm.map_or(0.0, |l| (l * 1e-3) as f32),
        ];
        params.map_info = [size as f32, 0.0, 0.0, 0.0];
        let options = PassOptions {
            fresnel: prepared.shading.fresnel,
            shadowing: prepared.shading.shadowing,
            texture_blending: false,
        };
        let Some((built, variant)) = &self.prepared else {
            return Err(Error::invalid("variant", "no variant prepared"));
        };
        let key = MapKey {
            variant: Arc::as_ptr(variant) as *const () as usize,
            output,
            options,
            size,
            colour: colour_weights(prepared, variant.as_ref(), &built.table.response),
        };
        // Taken out while it draws: a failed frame drops it rather than leave a pass in an
        // unknown state for the next one.
        let mut map = match self.map.take() {
            Some(m) if m.key == key => m,
            old => {
                // The old objects go before the new ones are made.
                drop(old);
                let target = OffscreenTarget::new(&self.dev, size, size)?;
                let pass = self.build_pass(
                    prepared,
                    params,
                    output,
                    options,
                    None,
                    [0.0; 4],
                    None,
                    target.render_pass(),
                )?;
                MapPass {
                    key,
                    frames: Frames::single(&self.dev, "brdf map frame")?,
                    pass,
                    target,
                }
            }
        };
        map.pass.params = params;
        let mut frame = self.draw(&map.pass, &map.target, &mut map.frames)?;
        self.map = Some(map);
        frame.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(frame)
    }

    /// Renders `scene`'s mesh with the diffraction shader (thesis Algorithms 2–4) using
    /// `prepared` as the material (callers prepare `scene.material`, possibly overridden).
    /// Pixels are linear sRGB already multiplied by the light intensity, `cosθi` and the
    /// scene's exposure; uncovered pixels hold the background colour as given.
    pub fn render_scene(&mut self, scene: &Scene, prepared: &PreparedMaterial) -> Result<Picture> {
        let inputs = SceneInputs::load(scene, true)?;
        self.render_scene_with(scene, &inputs, prepared)
    }

    /// [`render_scene`](Self::render_scene) with the scene's files already loaded.
    pub fn render_scene_with(
        &mut self,
        scene: &Scene,
        inputs: &SceneInputs,
        prepared: &PreparedMaterial,
    ) -> Result<Picture> {
        let start = Instant::now();
        let out = &scene.output;
        let options = PassOptions {
            fresnel: prepared.shading.fresnel,
            shadowing: prepared.shading.shadowing,
            texture_blending: true,
        };
        let target = OffscreenTarget::new(&self.dev, out.width, out.height)?;
        let uploads = self.upload_scene(scene, inputs, options)?;
        let pass = self.scene_pass_of(
            scene,
            &inputs.mesh,
            uploads,
            prepared,
            options,
            target.render_pass(),
            out.aspect(),
        )?;
        let mut frames = Frames::single(&self.dev, "diffraction frame")?;
        let mut frame = self.draw(&pass, &target, &mut frames)?;
        frame.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(frame)
    }

    /// `scene` as `diffract render` writes it, at the output size: drawn at the supersampled
    /// size ([`crate::scene::Output::render_size`]) with unit exposure, box-filtered in linear
    /// light, then exposed and, with `tone`, tone-mapped ([`crate::scene::Output::resolve`]);
    /// without `tone` (EXR) it stays linear after the exposure. The background is drawn
    /// divided by the exposure, so it comes out as given (before the tone curve).
    /// `inputs`: the scene's files already loaded ([`SceneInputs`]), else they are loaded here.
    pub fn render_output(
        &mut self,
        scene: &Scene,
        inputs: Option<&SceneInputs>,
        prepared: &PreparedMaterial,
        tone: bool,
    ) -> Result<Picture> {
        let out = &scene.output;
        let (rw, rh) = out.render_size();
        let mut big = scene.clone();
        big.output.width = rw;
        big.output.height = rh;
        big.output.exposure = 1.0;
        big.output.background = out.background.map(|c| c / out.exposure);
        let mut frame = match inputs {
            Some(inputs) => self.render_scene_with(&big, inputs, prepared)?,
            None => self.render_scene(&big, prepared)?,
        };
        frame.aliasing = sample_spread(&frame.rgb, rw, rh, out.supersample.max(1));
        frame.rgb = if tone {
            out.resolve(&frame.rgb)?
        } else {
            let (_, _, px) =
                crate::image_io::box_downsample(rw, rh, &frame.rgb, out.supersample.max(1))?;
            px.into_iter()
                .map(|p| p.map(|c| c * out.exposure))
                .collect()
        };
        frame.width = out.width;
        frame.height = out.height;
        Ok(frame)
    }

    /// The viewer's BRDF map (thesis §5, as [`Renderer::render_brdf_map`] draws it) as a pass
    /// for `render_pass`: light from `map.wi` (tangent frame, `z ≥ 0`), drawn into the
    /// top-left `map.size`² pixels of whatever target it is recorded into, as displayable
    /// colour: the shader turns the map's XYZ into linear sRGB and multiplies it by
    /// `map.exposure`
    /// (`OUTPUT_MODE` = MODE_MAP_DISPLAY) and the sRGB target applies the transfer curve, as
    /// `render --brdf-map --png --exposure E` does on the CPU. Move the light and resize with
    /// [`ScenePass::set_map`]. Table variants are prepared for the map's region joined with
    /// the view of `beside` (the mesh drawn next to the map), so that the two passes share
    /// one table and neither makes the other rebuild it.
    pub fn brdf_map_pass(
        &mut self,
        prepared: &PreparedMaterial,
        map: MapView,
        options: PassOptions,
        beside: Option<&Scene>,
        render_pass: vk::RenderPass,
    ) -> Result<ScenePass> {
        let MapView { wi, size, exposure } = map;
        if size == 0 || size > MAX_MAP_SIZE {
            return Err(Error::invalid(
                "BRDF map size",
                format!("{size}; expected 1..={MAX_MAP_SIZE} pixels"),
            ));
        }
        if !(wi.iter().all(|c| c.is_finite()) && wi[2] >= 0.0) {
            return Err(Error::invalid(
                "BRDF map light",
                format!("{wi:?}; expected a finite direction with z ≥ 0"),
            ));
        }
        let wi32 = wi.map(|c| c as f32 as f64);
        let mut region = Region::brdf_map(wi32).widened(1e-5);
        if let Some(scene) = beside {
            if let Some(r) = scene_region(scene, &*self.scene_mesh(scene)?, None, false) {
                region = region.union(&r);
            }
        }
        self.prepare_variant(prepared, region, OutputMode::MapDisplay, None)?;
        let mut params = self.params(prepared);
        params.map_wi = [wi32[0] as f32, wi32[1] as f32, wi32[2] as f32, 0.0];
        params.map_info = [size as f32, 0.0, 0.0, 0.0];
        params.lighting[1] = exposure;
        let options = PassOptions {
            texture_blending: false,
            ..options
        };
        self.build_pass(
            prepared,
            params,
            OutputMode::MapDisplay,
            options,
            None,
            [0.0; 4],
            None,
            render_pass,
        )
    }

    /// Records `pass` into the offscreen `target` as a frame of `frames` (timed when the
    /// queue has timestamps), submits, waits and reads the linear result back.
    pub(super) fn draw(
        &self,
        pass: &ScenePass,
        target: &OffscreenTarget,
        frames: &mut Frames,
    ) -> Result<Picture> {
        let cb = frames.begin()?.cb;
        pass.record(cb, &target.target());
        frames.end_timing();
        target.record_readback(cb);
        frames.submit(&[], &[])?;
        let gpu_ms = frames.wait()?;
        let rgb = target
            .read_rgba()?
            .into_iter()
            .map(|p| [p[0], p[1], p[2]])
            .collect();
        Ok(Picture {
            width: target.extent.width,
            height: target.extent.height,
            rgb,
            gpu_ms,
            wall_ms: 0.0,
            variant: pass.stats.clone(),
            aliasing: None,
        })
    }
}

/// Range checks of a BRDF map's arguments.
fn check_map_args(
    theta_i_deg: f64,
    phi_i_deg: f64,
    size: u32,
    lambda_nm: Option<f64>,
) -> Result<()> {
    if size == 0 || size > MAX_MAP_SIZE {
        return Err(Error::invalid(
            "BRDF map size",
            format!("{size}; expected 1..={MAX_MAP_SIZE} pixels"),
        ));
    }
    if !(theta_i_deg.is_finite() && (0.0..=90.0).contains(&theta_i_deg)) {
        return Err(Error::invalid(
            "theta-i",
            format!("{theta_i_deg}°; expected 0..=90° from the normal"),
        ));
    }
    if !phi_i_deg.is_finite() {
        return Err(Error::invalid("phi-i", format!("{phi_i_deg}°")));
    }
    let lo = crate::colour::LAMBDA_MIN_NM as f64;
    let hi = crate::colour::LAMBDA_MAX_NM as f64;
    if let Some(l) = lambda_nm {
        if !(l.is_finite() && (lo..=hi).contains(&l)) {
            return Err(Error::invalid(
                "wavelength",
                format!("{l} nm; expected {lo}..={hi} nm"),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::sample_spread;

    /// Equal samples spread nothing; samples a and b in equal numbers give each pixel's
    /// mean a standard error of |a − b|/2·√(n/(n − 1))/√n.
    #[test]
    fn the_spread_is_the_standard_error_of_each_pixels_mean() {
        let flat = vec![[0.5f32, 0.25, 1.0]; 16];
        assert_eq!(sample_spread(&flat, 4, 4, 2), Some(0.0));
        assert_eq!(sample_spread(&flat, 4, 4, 1), None);
        // One 2×2 pixel: samples 1, 3, 1, 3 in every channel; mean 2, variance 4/3.
        let px = vec![[1.0f32; 3], [3.0; 3], [1.0; 3], [3.0; 3]];
        let e = sample_spread(&px, 2, 2, 2).unwrap();
        let want = ((4.0 / 3.0) / 4.0f64).sqrt() / 2.0;
        assert!((e - want).abs() < 1e-12, "{e} vs {want}");
    }
}
