//! Scenes (meshes) lit by an environment map, disc lights and the sun in radiance units
//! (MODEL §10): the mesh is rasterised once by the raster pipeline into a G-buffer
//! ([`super::gbuffer`]; per covered pixel the orthonormal tangent frame, `ωr` in it and
//! the texture's albedo), then the compute
//! stage (glsl/env_scene.glsl, with the variant's BRDF) integrates the covered pixels in
//! rounds, each round narrowed to the pixels whose noise is still above the target (in
//! groups by the samples their noise predicts they need, [`Plan`]), with the estimator the
//! environment-lit BRDF map uses (glsl/env_common.glsl).
//!
//! **Units.** The picture is radiance (linear sRGB). The texture of thesis Algorithm 4 is an
//! albedo on the scale of the diffraction colours (`[texture] gain`, relative to a mirror's
//! specular value); in radiance units its albedo is `gain·S·c_texture`, with `S` the
//! factor that turns the relative reflectance into the absolute BRDF
//! ([`EnvLighting::mirror_scale`]: `A_λ·R0` weighted by D65's luminance), so texture and
//! diffraction keep the balance they have under the sun. Each direction reflects
//! `L·cos θi·[(1 − w_d)·f_r + ((1 − α) + w_d)·t]`, as Algorithm 4 does for the sun. The
//! scene's `ambient` is a uniform sky ([`scene_sky`]), the environment when no map is
//! given; a map takes its place. The written picture is radiance × `exposure / S`, the
//! units of the sun-lit pass, so the same light gives the same picture either way.

use std::sync::Arc;

use rayon::prelude::*;

use super::env::{dispatch_rounds, Dispatch, EnvLighting, Group};
use crate::brdf::Shading;
use crate::colour::linear_srgb_to_xyz;
use crate::gpu::Device;
use crate::light::env::EnvMap;
use crate::light::set::{Lights, PointLight, SampledDisc};
use crate::mesh::Mesh;
use crate::scene::Scene;
use crate::Result;
use glam::DVec3;

/// A texture as the G-buffer reads it: linear-sRGB albedo, top row first, repeated.
pub struct Albedo {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<[f32; 3]>,
}

impl Albedo {
    /// `scale` times the linear value of sRGB-encoded `bytes`.
    pub fn from_srgb8(width: u32, height: u32, bytes: &[[u8; 3]], scale: f64) -> Self {
        // The 256 codes' values once (a texel takes three lookups, not three powers).
        let lin = crate::colour::srgb8_decode_table().map(|l| (f64::from(l) * scale) as f32);
        Albedo {
            width,
            height,
            rgb: bytes
                .par_iter()
                .map(|p| p.map(|c| lin[usize::from(c)]))
                .collect(),
        }
    }
}

/// The covered pixels of a frame and what the shader reads at each.
pub struct GBuffer {
    pub width: u32,
    pub height: u32,
    /// Row-major index of each covered pixel.
    pub covered: Vec<u32>,
    /// 16 floats per covered pixel: `(T, t_r), (B, t_g), (N, t_b), (ωr, key)`, the frame
    /// orthonormal in world space, `ωr` in it, `t` the albedo; the key's bits are the
    /// output pixel × 16 plus the pixel's place among its output pixel's `ss²`: they share
    /// one low-discrepancy sequence, each taking the next stretch of samples.
    pub data: Vec<f32>,
}

impl GBuffer {
    /// Per covered pixel, the indices of its covered neighbours right, left, down and up
    /// (−1 for none): what a point light's `(u, v)` footprint is taken over, as the raster
    /// pass's `dFdx` and `dFdy` take it (glsl/env_common.glsl, `uvStep`).
    pub fn neighbours(&self) -> Vec<[i32; 4]> {
        let (w, h) = (self.width as usize, self.height as usize);
        let mut at = vec![-1i32; w * h];
        for (k, &p) in self.covered.iter().enumerate() {
            if let Some(slot) = at.get_mut(p as usize) {
                *slot = k as i32;
            }
        }
        let of = |p: Option<usize>| p.and_then(|p| at.get(p)).copied().unwrap_or(-1);
        self.covered
            .iter()
            .map(|&p| {
                let p = p as usize;
                let (x, y) = (p % w.max(1), p / w.max(1));
                [
                    of((x + 1 < w).then_some(p + 1)),
                    of((x > 0).then(|| p - 1)),
                    of((y + 1 < h).then_some(p + w)),
                    of((y > 0).then(|| p - w)),
                ]
            })
            .collect()
    }

    /// What the scene stage reads at binding 6: the sixteen floats of every pixel, then
    /// [`Self::neighbours`], a vec4 a pixel (glsl/env_scene.glsl).
    pub fn device_bytes(&self) -> Vec<u8> {
        let mut bytes: Vec<u8> = self.data.iter().flat_map(|x| x.to_le_bytes()).collect();
        bytes.extend(
            self.neighbours()
                .iter()
                .flatten()
                .flat_map(|k| k.to_le_bytes()),
        );
        bytes
    }
}

/// The lights of `scene` besides its environment: the sun over its disc (a point light per
/// direction of `[light]`'s spiral, D65 white) unless `sun` is false, and each
/// `[[disc_light]]`, sampled in its cone (a point light when it has no angular size).
/// `white`: D65's white in the table's units, the colour of the sun.
pub fn scene_lights(scene: &Scene, sun: bool, white: [f64; 3]) -> Lights {
    let mut lights = Lights::default();
    if sun {
        let i = f64::from(scene.light.intensity);
        for s in scene.light.disk_samples() {
            let e = f64::from(s.weight) * i;
            lights.points.push(PointLight {
                towards: s.towards_light.map(f64::from),
                irradiance_xyz: white.map(|c| c * e),
            });
        }
    }
    for d in &scene.disc_lights {
        let xyz = linear_srgb_to_xyz(d.colour.map(f64::from)).map(|c| c * f64::from(d.intensity));
        let omega = d.solid_angle();
        if omega <= 0.0 {
            lights.points.push(PointLight {
                towards: d.towards_light(),
                irradiance_xyz: xyz,
            });
        } else {
            lights.discs.push(SampledDisc {
                towards: d.towards_light(),
                cos_radius: d.angular_radius().cos(),
                solid_angle: omega,
                radiance_xyz: xyz.map(|c| c / omega),
            });
        }
    }
    lights
}

/// The scene's own sky: `[texture] ambient` as the uniform environment it stands for
/// ([`crate::light::sky`], radiance `ambient·I/π` in white), `None` without one. A scene
/// drawn without `--env` is lit by it, as the sun-lit pass lights it in closed form; an
/// `--env` map takes its place.
pub fn scene_sky(scene: &Scene) -> Result<Option<EnvMap>> {
    let Some(t) = scene.texture.as_ref().filter(|t| t.ambient > 0.0) else {
        return Ok(None);
    };
    let sky = crate::light::sky::UniformSky::of_ambient(
        f64::from(t.ambient),
        f64::from(scene.light.intensity),
    );
    let l = sky.radiance as f32;
    EnvMap::from_pixels(2, 1, vec![[l; 3]; 2], "the scene's sky (ambient)").map(Some)
}

/// One environment-lit frame of covered pixels.
pub struct GBufferRequest<'a> {
    pub env: &'a EnvMap,
    pub lights: &'a Lights,
    pub shading: Shading,
    /// The most samples a G-buffer pixel takes.
    pub samples: u32,
    pub seed: u32,
    /// Texture blending's `w_diffuse` (`None`: no texture).
    pub w_diffuse: Option<f64>,
    /// When an output pixel stops taking samples (`None`: every pixel takes `samples`).
    pub noise: Option<NoiseTarget>,
    /// G-buffer pixels per output pixel (supersample²), which interleave one sequence.
    pub stride: u32,
    /// The variant the stages evaluate (`None`: `chebyshev-w` from the lighting's own table;
    /// [`crate::render::Renderer::env_brdf`] binds another).
    pub brdf: Option<&'a std::sync::Arc<crate::render::env_brdf::EnvBrdf>>,
}

/// The most samples an output pixel of a scene takes, unless `--env-samples` says otherwise.
pub const DEFAULT_SAMPLES: u32 = 1024;

/// The noise at which an output pixel stops, unless `--env-noise` says otherwise: CIEDE2000
/// of one estimated standard error ([`NoiseTarget`]).
pub const DEFAULT_NOISE: f64 = 0.3;

/// vec4s a G-buffer pixel of the scene's stage writes: (the samples' linear-sRGB sum, their
/// number), (the sum of the squared batch sums, 0), (the point lights' linear sRGB, 0)
/// (glsl/env_scene.glsl).
pub const SCENE_OUTPUTS: u64 = 3;

/// Samples per noise batch of a G-buffer pixel: the noise of a pixel is estimated from the
/// spread of its batch sums.
pub const NOISE_BATCH: u32 = 4;

/// Samples per output pixel of the first round of an adaptive render; later rounds give the
/// pixels still above the target what their noise predicts they need ([`Plan`]).
pub const FIRST_PASS_SAMPLES: u32 = 64;

/// When an output pixel has taken enough samples: when the CIEDE2000 difference between
/// its picture as written (times `scale`, through the tone curve) and the same plus one
/// estimated standard error in every channel is below `delta_e`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseTarget {
    pub delta_e: f64,
    /// Radiance to the tone curve's input: the exposure over the mirror scale.
    pub scale: f64,
    pub tone: crate::image_io::Tone,
    pub white: f32,
}

impl NoiseTarget {
    /// The estimated CIEDE2000 of a pixel of linear-sRGB mean `m` and standard error `se`.
    pub fn delta_e_of(&self, m: [f64; 3], se: [f64; 3]) -> f64 {
        let lab = |c: [f64; 3]| {
            let t = c.map(|x| {
                f64::from(crate::image_io::tone_map(
                    (x * self.scale) as f32,
                    self.tone,
                    self.white,
                ))
            });
            crate::colour::xyz_to_lab(linear_srgb_to_xyz(t))
        };
        let plus = [0, 1, 2].map(|k| m[k] + se[k]);
        crate::colour::delta_e2000(lab(m), lab(plus))
    }
}

/// What [`shade_gbuffer`] drew.
pub struct Shaded {
    /// Linear-sRGB radiance of every covered pixel, in the G-buffer's order.
    pub rgb: Vec<[f32; 3]>,
    /// Samples each output pixel took (its G-buffer pixels' together), one entry per
    /// output pixel with a covered G-buffer pixel.
    pub samples: Vec<u32>,
    pub gpu_ms: f64,
    /// Batches of samples left out for a NaN or an infinity.
    pub dropped: u64,
}

/// The covered pixels of `g` grouped by their output pixel (indices into `g.covered`).
fn output_groups(g: &GBuffer) -> Vec<Vec<u32>> {
    let key = |i: usize| g.data[16 * i + 15].to_bits() >> 4;
    let mut order: Vec<u32> = (0..g.covered.len() as u32).collect();
    order.sort_by_key(|&i| key(i as usize));
    let mut groups: Vec<Vec<u32>> = Vec::new();
    for i in order {
        match groups.last_mut() {
            Some(last) if key(last[0] as usize) == key(i as usize) => last.push(i),
            _ => groups.push(vec![i]),
        }
    }
    groups
}

/// The estimated standard error and mean (linear sRGB) of an output pixel from the raw
/// sums of its covered G-buffer pixels (three vec4 each, glsl/env_scene.glsl).
fn pixel_noise(sums: &[[f32; 4]], members: &[u32]) -> ([f64; 3], [f64; 3]) {
    let c = members.len() as f64;
    let (mut mean, mut var) = ([0.0; 3], [0.0; 3]);
    for &i in members {
        let i = 3 * i as usize;
        let (sum, sq, point) = (sums[i], sums[i + 1], sums[i + 2]);
        let n = f64::from(sum[3]).max(1.0);
        let batches = (n / f64::from(NOISE_BATCH)).max(1.0);
        for k in 0..3 {
            let s1 = f64::from(sum[k]);
            mean[k] += (f64::from(point[k]) + s1 / n) / c;
            // The spread of the batch sums, then the variance of the pixel's mean.
            let vb = if batches > 1.0 {
                ((f64::from(sq[k]) - s1 * s1 / batches) / (batches - 1.0)).max(0.0)
            } else {
                f64::INFINITY
            };
            var[k] += vb / (f64::from(NOISE_BATCH) * n) / (c * c);
        }
    }
    (var.map(f64::sqrt), mean)
}

/// The most a round multiplies an output pixel's samples by ([`Plan`]).
const MOST_GROWTH: f64 = 4.0;
/// The least a round multiplies an output pixel's samples by.
const LEAST_GROWTH: f64 = 1.25;
/// The margin on an output pixel's predicted need.
const NEED_MARGIN: f64 = 1.1;
/// Fewest G-buffer pixels a group of a round is dispatched with: a smaller group joins the
/// one that starts where it does and goes further (two cores of lavapipe share a dispatch
/// by its workgroups of 64).
const LEAST_GROUP: usize = 512;

/// The sample counts (per G-buffer pixel) at which an adaptive render's groups end: `first`,
/// then a quarter octave apart, each a multiple of 8 (so that a light sample every m-th,
/// m ≤ 8 dividing `first` and `most`, stays exactly 1/m of them,
/// [`crate::light::set::light_every`]), up to `most`.
fn ladder(first: u32, most: u32) -> Vec<u32> {
    let mut rungs = vec![first.min(most)];
    let mut exact = f64::from(first.max(1));
    while let Some(&last) = rungs.last().filter(|&&r| r < most) {
        exact *= 2f64.powf(0.25);
        let rung = ((exact / 8.0).ceil() as u32 * 8).max((last / 8 + 1) * 8);
        rungs.push(rung.min(most));
    }
    rungs
}

/// The rounds of an adaptive render: what each output pixel has taken (per G-buffer pixel)
/// and whether it goes on. After each round, an output pixel whose estimated noise is `r`
/// times the target takes what `r²` predicts it needs (the noise falls as the square root
/// of the samples), times [`NEED_MARGIN`], at least [`LEAST_GROWTH`] and at most
/// [`MOST_GROWTH`] times what it has, up on the [`ladder`]: it stops close to its need
/// instead of up to twice past it, and a pixel far from its target gets there in fewer
/// rounds.
struct Plan {
    reached: Vec<u32>,
    live: Vec<bool>,
    ladder: Vec<u32>,
}

impl Plan {
    fn new(outputs: usize, first: u32, most: u32) -> Self {
        Plan {
            reached: vec![first.min(most); outputs],
            live: vec![true; outputs],
            ladder: ladder(first, most),
        }
    }

    /// The count a pixel that has `n` samples and an estimated noise `ratio` times the
    /// target goes on to (`n` itself: it stops).
    fn next_count(&self, n: u32, ratio: f64) -> u32 {
        let most = *self.ladder.last().unwrap_or(&n);
        if ratio < 1.0 || n >= most {
            return n;
        }
        let n = f64::from(n);
        let want = (n * ratio * ratio * NEED_MARGIN).clamp(n * LEAST_GROWTH, n * MOST_GROWTH);
        // A NaN or infinite estimate (a single batch) goes the furthest.
        let want = if want.is_nan() { n * MOST_GROWTH } else { want };
        self.ladder
            .iter()
            .copied()
            .find(|&c| f64::from(c) >= want)
            .unwrap_or(most)
    }

    /// The groups of the next round from the sums so far (`groups`: each output pixel's
    /// G-buffer pixels).
    fn next_round(
        &mut self,
        groups: &[Vec<u32>],
        sums: &[[f32; 4]],
        target: &NoiseTarget,
    ) -> Vec<Group> {
        let next: Vec<u32> = groups
            .par_iter()
            .enumerate()
            .map(|(o, m)| {
                let n = self.reached[o];
                if !self.live[o] {
                    return n;
                }
                let (se, mean) = pixel_noise(sums, m);
                self.next_count(n, target.delta_e_of(mean, se) / target.delta_e)
            })
            .collect();
        let mut by_span = std::collections::BTreeMap::<(u32, u32), Vec<usize>>::new();
        for (o, to) in next.into_iter().enumerate() {
            self.live[o] = self.live[o] && to > self.reached[o];
            if self.live[o] {
                by_span.entry((self.reached[o], to)).or_default().push(o);
            }
        }
        // A small group goes on with the next one from the same start (further: more
        // samples never hurt).
        let mut round: Vec<Group> = Vec::new();
        let mut carried: Vec<usize> = Vec::new();
        let spans: Vec<(u32, u32)> = by_span.keys().copied().collect();
        for (i, &(from, to)) in spans.iter().enumerate() {
            let mut outputs = std::mem::take(&mut carried);
            outputs.extend(by_span.remove(&(from, to)).unwrap_or_default());
            let size: usize = outputs.iter().map(|&o| groups[o].len()).sum();
            if size < LEAST_GROUP && spans.get(i + 1).is_some_and(|s| s.0 == from) {
                carried = outputs;
                continue;
            }
            outputs.iter().for_each(|&o| self.reached[o] = to);
            round.push(Group {
                pixels: outputs
                    .iter()
                    .flat_map(|&o| groups[o].iter().copied())
                    .collect(),
                from,
                to,
            });
        }
        round
    }
}

/// Linear-sRGB radiance of every covered pixel of `g` (in `g.covered`'s order), the
/// samples each took and the dispatches' time. With a noise target, every pixel takes
/// [`FIRST_PASS_SAMPLES`] per output pixel (at most `req.samples`), then the output pixels
/// still above the target take, round by round, what their noise predicts they need
/// ([`Plan`]), up to `req.samples`.
pub fn shade_gbuffer(
    dev: &Arc<Device>,
    lighting: &EnvLighting,
    g: &GBuffer,
    req: &GBufferRequest<'_>,
) -> Result<Shaded> {
    let bytes = g.device_bytes();
    let stride = req.stride.max(1);
    let first = match req.noise {
        Some(_) => FIRST_PASS_SAMPLES
            .div_ceil(stride)
            .next_multiple_of(NOISE_BATCH)
            .min(req.samples),
        None => req.samples,
    };
    let groups = output_groups(g);
    let mut plan = Plan::new(groups.len(), first, req.samples);
    let mut next = |sums: &[[f32; 4]]| match req.noise {
        Some(target) => plan.next_round(&groups, sums, &target),
        None => Vec::new(),
    };
    let run = dispatch_rounds(
        dev,
        lighting,
        &Dispatch {
            env: req.env,
            lights: req.lights,
            shading: req.shading,
            samples: req.samples,
            first,
            seed: req.seed,
            w_diffuse: req.w_diffuse,
            pixels: g.covered.len() as u64,
            map_side: 0,
            outputs: SCENE_OUTPUTS,
            extra: Some(if bytes.is_empty() { &[0; 64] } else { &bytes }),
            stride,
            batch: NOISE_BATCH,
            stage: super::env_brdf::EnvStage::Scene,
            brdf: req.brdf,
            name: "env scene",
            per_dispatch: None,
        },
        vec![Group {
            pixels: (0..g.covered.len() as u32).collect(),
            from: 0,
            to: first,
        }],
        &mut next,
    )?;
    let rgb = run
        .sums
        .chunks_exact(3)
        .map(|p| super::env::mean_of(p[0], p[2]))
        .collect();
    let samples = groups
        .iter()
        .map(|m| m.iter().map(|&i| run.sums[3 * i as usize][3] as u32).sum())
        .collect();
    Ok(Shaded {
        rgb,
        samples,
        gpu_ms: run.gpu_ms,
        dropped: run.dropped,
    })
}

/// A scene drawn in radiance units ([module notes](self)).
pub struct EnvScene<'a> {
    pub scene: &'a Scene,
    pub mesh: &'a Mesh,
    /// The scene's texture (`(width, height, sRGB bytes)`), when it is blended in.
    pub texture: Option<&'a (u32, u32, Vec<[u8; 3]>)>,
    /// `None`: no environment (black).
    pub env: Option<&'a EnvMap>,
    pub lights: &'a Lights,
    pub shading: Shading,
    /// The most samples an output pixel takes, shared among its `supersample²` G-buffer
    /// pixels.
    pub samples: u32,
    pub seed: u32,
    /// An output pixel stops once its estimated CIEDE2000 noise (as written) is below
    /// this ([`NoiseTarget`]); `None`: every pixel takes `samples`.
    pub noise: Option<f64>,
    /// The variant the stages evaluate (`None`: `chebyshev-w` from the lighting's own table;
    /// [`crate::render::Renderer::env_brdf`] binds another).
    pub brdf: Option<&'a std::sync::Arc<crate::render::env_brdf::EnvBrdf>>,
}

/// A frame at the scene's render size ([`crate::scene::Output::render_size`]), ready for
/// the exposure: radiance over [`EnvLighting::mirror_scale`]; uncovered pixels hold the
/// environment seen along the camera ray (also over the scale), or without an environment
/// the background divided by the exposure (so it comes out as given).
pub struct EnvSceneFrame {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<[f32; 3]>,
    pub covered: usize,
    /// The samples its output pixels took: the mean and the most.
    pub samples_mean: f64,
    pub samples_most: u32,
    pub gpu_ms: f64,
    pub raster_ms: f64,
    /// Batches of samples left out for a NaN or an infinity.
    pub dropped: u64,
}

/// Most G-buffer pixels (`width × height × supersample²`) of an environment-lit scene: the
/// host holds about 100 bytes a pixel while it rasterises (2 GB here).
pub const MAX_GBUFFER_PIXELS: u64 = 4096 * 4096;

/// The most G-buffer pixels an environment-lit scene may draw: [`MAX_GBUFFER_PIXELS`] and,
/// given `dev`, the largest storage buffer it binds (64 bytes a pixel).
pub fn gbuffer_pixels_most(dev: Option<&Device>) -> u64 {
    let device = dev.map_or(u64::MAX, |d| crate::gpu::compute::max_storage_range(d) / 64);
    MAX_GBUFFER_PIXELS.min(device)
}

/// `scene` with `[output] supersample` lowered, where its G-buffer would pass the limit
/// ([`check_size`]), to the most samples a pixel whose G-buffer fits, and the supersampling
/// it asked for; `None` when it fits as asked (or not even at one sample a pixel, which
/// [`check_size`] refuses). The G-buffer's samples only anti-alias the surface and the point
/// lights: an output pixel's environment samples are shared among them whatever their count.
pub fn fit_supersample(dev: Option<&Device>, scene: &Scene) -> (Scene, Option<u32>) {
    let out = &scene.output;
    let limit = gbuffer_pixels_most(dev);
    let fits = |s: u32| u64::from(out.width * s) * u64::from(out.height * s) <= limit;
    let asked = out.supersample.max(1);
    match (1..asked).rev().find(|&s| fits(s)) {
        Some(s) if !fits(asked) => {
            let mut fitted = scene.clone();
            fitted.output.supersample = s;
            (fitted, Some(asked))
        }
        _ => (scene.clone(), None),
    }
}

/// [`fit_supersample`], then [`check_size`] on what it gives: the scene to draw, and where
/// its supersampling was lowered, the line that says so.
pub fn fit_size(dev: Option<&Device>, scene: &Scene) -> Result<(Scene, Option<String>)> {
    let (fitted, asked) = fit_supersample(dev, scene);
    check_size(dev, &fitted)?;
    let note = asked.map(|asked| {
        let (w, h) = fitted.output.render_size();
        format!(
            "G-buffer: {s}×{s} samples a pixel ({w}×{h}), not [output] supersample = {asked}, whose G-buffer would pass the {} pixels this device can hold; the environment's samples are shared among an output pixel's G-buffer pixels whatever their count",
            gbuffer_pixels_most(dev),
            s = fitted.output.supersample,
        )
    });
    Ok((fitted, note))
}

/// Refuses a scene whose G-buffer would pass [`MAX_GBUFFER_PIXELS`] or, given `dev`, the
/// largest storage buffer it binds (64 bytes a pixel), before any work.
pub fn check_size(dev: Option<&Device>, scene: &Scene) -> Result<()> {
    let (w, h) = scene.output.render_size();
    let pixels = u64::from(w) * u64::from(h);
    let limit = gbuffer_pixels_most(dev);
    if pixels > limit {
        return Err(crate::Error::invalid(
            "image size",
            format!(
                "{w}×{h} G-buffer pixels (width × height × supersample²); an environment-lit scene draws at most {limit}"
            ),
        ));
    }
    Ok(())
}

/// Draws `req` with `lighting` on `dev`.
pub fn render_env_scene(
    dev: &Arc<Device>,
    lighting: &EnvLighting,
    req: &EnvScene<'_>,
) -> Result<EnvSceneFrame> {
    let start = std::time::Instant::now();
    let scene = req.scene;
    check_size(Some(dev), scene)?;
    let out = &scene.output;
    let (w, h) = out.render_size();
    let ss = out.supersample.max(1);
    let blend = scene.texture.as_ref().zip(req.texture);
    let albedo = blend.map(|(spec, (tw, th, bytes))| {
        Albedo::from_srgb8(
            *tw,
            *th,
            bytes,
            f64::from(spec.gain) * lighting.mirror_scale,
        )
    });
    let g = super::gbuffer::rasterise(dev, req.mesh, &scene.camera, (w, h, ss), albedo.as_ref())?;
    let raster_ms = start.elapsed().as_secs_f64() * 1e3;
    let black;
    let env = match req.env {
        Some(e) => e,
        None => {
            black = EnvMap::from_pixels(2, 1, vec![[0.0; 3]; 2], "no environment")?;
            &black
        }
    };
    let per_pixel = req.samples.div_ceil(ss * ss).max(1);
    let noise = req.noise.map(|delta_e| NoiseTarget {
        delta_e,
        scale: f64::from(out.exposure) / lighting.mirror_scale,
        tone: out.tone,
        white: out.white,
    });
    let shaded = shade_gbuffer(
        dev,
        lighting,
        &g,
        &GBufferRequest {
            env,
            lights: req.lights,
            shading: req.shading,
            samples: per_pixel,
            seed: req.seed,
            w_diffuse: blend.map(|(spec, _)| f64::from(spec.w_diffuse)),
            noise,
            stride: ss * ss,
            brdf: req.brdf,
        },
    )?;
    let samples_mean = shaded.samples.iter().map(|&n| f64::from(n)).sum::<f64>()
        / shaded.samples.len().max(1) as f64;
    let samples_most = shaded.samples.iter().copied().max().unwrap_or(0);
    let s = lighting.mirror_scale;
    let mut rgb = background(scene, req.env, w, h, s);
    for (&i, c) in g.covered.iter().zip(&shaded.rgb) {
        rgb[i as usize] = c.map(|x| (f64::from(x) / s) as f32);
    }
    Ok(EnvSceneFrame {
        width: w,
        height: h,
        rgb,
        covered: g.covered.len(),
        samples_mean,
        samples_most,
        gpu_ms: shaded.gpu_ms,
        raster_ms,
        dropped: shaded.dropped,
    })
}

/// What the camera sees where no triangle is ([`EnvSceneFrame`]).
pub fn background(
    scene: &Scene,
    env: Option<&EnvMap>,
    w: u32,
    h: u32,
    scale: f64,
) -> Vec<[f32; 3]> {
    let out = &scene.output;
    let Some(env) = env else {
        let c = out.background.map(|c| c / out.exposure);
        return vec![c; (w * h) as usize];
    };
    let inv = scene
        .camera
        .view_proj(w as f32 / h as f32)
        .as_dmat4()
        .inverse();
    (0..w * h)
        .into_par_iter()
        .map(|k| {
            let x = 2.0 * (f64::from(k % w) + 0.5) / f64::from(w) - 1.0;
            let y = 2.0 * (f64::from(k / w) + 0.5) / f64::from(h) - 1.0;
            let near = inv.project_point3(DVec3::new(x, y, 0.0));
            let far = inv.project_point3(DVec3::new(x, y, 1.0));
            let d = (far - near).normalize_or(DVec3::NEG_Z);
            env.radiance(d.to_array()).map(|c| (c / scale) as f32)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The raw sums a G-buffer pixel holds after `batches` batches of [`NOISE_BATCH`]
    /// samples whose batch means are `means` (one value for every channel) and point part
    /// `point`.
    fn sums(means: &[f64], point: f64) -> [[f32; 4]; 3] {
        let b = f64::from(NOISE_BATCH);
        let s1: f64 = means.iter().map(|m| m * b).sum();
        let sq: f64 = means.iter().map(|m| (m * b).powi(2)).sum();
        let n = (means.len() as u32 * NOISE_BATCH) as f32;
        [
            [s1 as f32, s1 as f32, s1 as f32, n],
            [sq as f32, sq as f32, sq as f32, 0.0],
            [point as f32, point as f32, point as f32, 0.0],
        ]
    }

    #[test]
    fn a_g_buffer_over_the_limit_takes_the_most_samples_that_fit() {
        let sized = |side: u32, ss: u32| {
            let mut s = Scene::default_scene();
            s.output.width = side;
            s.output.height = side;
            s.output.supersample = ss;
            s
        };
        // 1024² at 3×3 is 3072², within 4096².
        let (fitted, asked) = fit_supersample(None, &sized(1024, 3));
        assert_eq!((fitted.output.supersample, asked), (3, None));
        assert!(check_size(None, &fitted).is_ok());
        // 2048² at 3×3 would be 6144²; at 2×2 it is 4096², the limit.
        let (fitted, asked) = fit_supersample(None, &sized(2048, 3));
        assert_eq!((fitted.output.supersample, asked), (2, Some(3)));
        assert!(check_size(None, &fitted).is_ok());
        // 3000² at 4×4 fits only at one sample a pixel.
        let (fitted, asked) = fit_supersample(None, &sized(3000, 4));
        assert_eq!((fitted.output.supersample, asked), (1, Some(4)));
        // 8192² does not fit at all: left as asked, and refused.
        let (fitted, asked) = fit_supersample(None, &sized(8192, 2));
        assert_eq!((fitted.output.supersample, asked), (2, None));
        assert!(check_size(None, &fitted).is_err());
        // fit_size: the line only where the supersampling was lowered; the refusal as is.
        let (fitted, note) = fit_size(None, &sized(2048, 3)).unwrap();
        assert_eq!(fitted.output.supersample, 2);
        assert!(note.is_some_and(|n| n.contains("2×2 samples a pixel (4096×4096)")));
        assert!(fit_size(None, &sized(1024, 3)).unwrap().1.is_none());
        assert!(fit_size(None, &sized(8192, 2)).is_err());
    }

    #[test]
    fn the_noise_of_a_pixel_is_the_standard_error_of_its_batches() {
        // Batch means 1, 3, 1, 3: mean 2, their variance 4/3, the mean's 4/3/4 = 1/3.
        let one = sums(&[1.0, 3.0, 1.0, 3.0], 0.5);
        let (se, mean) = pixel_noise(&one, &[0]);
        assert!((mean[0] - 2.5).abs() < 1e-6, "{mean:?}");
        assert!((se[0] - (1.0f64 / 3.0).sqrt()).abs() < 1e-6, "{se:?}");
        // Two G-buffer pixels of one output pixel: the mean of their means, and the
        // standard error of that mean (independent: variances add, over 2²).
        let mut two = one.to_vec();
        two.extend(sums(&[2.0, 2.0, 2.0, 2.0], 0.0));
        let (se, mean) = pixel_noise(&two, &[0, 1]);
        assert!((mean[1] - 2.25).abs() < 1e-6, "{mean:?}");
        assert!((se[1] - (1.0f64 / 3.0 / 4.0).sqrt()).abs() < 1e-6, "{se:?}");
        // One batch tells nothing about the spread: infinite, so the pixel goes on.
        let (se, _) = pixel_noise(&sums(&[1.0], 0.0), &[0]);
        assert!(se[0].is_infinite());
    }

    #[test]
    fn the_ladder_climbs_a_quarter_octave_a_rung_in_multiples_of_eight() {
        for (first, most) in [(16, 256), (8, 114), (4, 64), (64, 1024), (16, 16), (24, 20)] {
            let l = ladder(first, most);
            assert_eq!(l[0], first.min(most), "{l:?}");
            assert_eq!(*l.last().unwrap(), most, "{l:?}");
            for w in l.windows(2) {
                assert!(w[1] > w[0], "{l:?}");
                assert!(w[1] % 8 == 0 || w[1] == most, "{l:?}");
                // A quarter octave, or the least step of 8 where that is more.
                assert!(
                    f64::from(w[1]) <= f64::from(w[0]) * 2f64.powf(0.25) + 8.0,
                    "{l:?}"
                );
            }
        }
        assert_eq!(ladder(16, 64), vec![16, 24, 32, 40, 48, 56, 64]);
    }

    #[test]
    fn a_pixel_goes_on_to_what_its_noise_predicts_within_bounds() {
        let plan = Plan::new(1, 16, 256);
        // Below the target: it stops where it is.
        assert_eq!(plan.next_count(16, 0.9), 16);
        // Just above: at least a quarter more.
        assert_eq!(plan.next_count(16, 1.01), 24);
        // 1.5 times the target: 1.5²·1.1 = 2.475 times the samples, the next rung up.
        let c = plan.next_count(64, 1.5);
        assert!(
            c as f64 >= 64.0 * 2.475 && (c as f64) < 64.0 * 2.475 * 1.2,
            "{c}"
        );
        // Far above, or unknown (one batch): at most four times, up on the ladder.
        for r in [10.0, f64::INFINITY, f64::NAN] {
            let c = plan.next_count(32, r);
            assert!((128..=136).contains(&c), "{r}: {c}");
        }
        // Never past the most; at the most it stops.
        assert_eq!(plan.next_count(200, 3.0), 256);
        assert_eq!(plan.next_count(256, 3.0), 256);
    }

    #[test]
    fn a_round_groups_the_pixels_by_their_counts_and_merges_small_groups() {
        let target = NoiseTarget {
            delta_e: 0.3,
            scale: 1.0,
            tone: crate::image_io::Tone::Linear,
            white: 8.0,
        };
        // Four batches a G-buffer pixel (16 samples). Output pixel 0: no spread (stops);
        // 1: a little over the target; 2: far over it; each holds one G-buffer pixel.
        let noisy = |d: f64| sums(&[0.2 - d, 0.2 + d, 0.2 - d, 0.2 + d], 0.0);
        let mut raw = Vec::new();
        for d in [0.0, 0.006, 0.05] {
            raw.extend(noisy(d));
        }
        let ratio = |o: usize| {
            let (se, mean) = pixel_noise(&raw, &[o as u32]);
            target.delta_e_of(mean, se) / target.delta_e
        };
        let r = [0, 1, 2].map(ratio);
        assert!(
            r[0] < 1.0 && r[1] > 1.0 && r[1] < 2.0 && r[2] > 2.0,
            "{r:?}"
        );
        let groups = vec![vec![0u32], vec![1], vec![2]];
        let mut plan = Plan::new(3, 16, 256);
        let (to1, to2) = (plan.next_count(16, ratio(1)), plan.next_count(16, ratio(2)));
        assert!(to1 < to2);
        let round = plan.next_round(&groups, &raw, &target);
        // Both go on from 16; the smaller group (one pixel) joins the one that goes further.
        assert_eq!(round.len(), 1);
        assert_eq!((round[0].from, round[0].to), (16, to2));
        assert_eq!(round[0].pixels, vec![1, 2]);
        assert_eq!(plan.reached, vec![16, to2, to2]);
        assert_eq!(plan.live, vec![false, true, true]);
        // A stopped pixel stays stopped; with the same sums the others go on again.
        let again = plan.next_round(&groups, &raw, &target);
        assert!(again
            .iter()
            .all(|g| !g.pixels.contains(&0) && g.from == to2));
        // Without spread anywhere the round is empty: the integration ends.
        let calm: Vec<[f32; 4]> = (0..3).flat_map(|_| noisy(0.0)).collect();
        assert!(Plan::new(3, 16, 256)
            .next_round(&groups, &calm, &target)
            .is_empty());
    }

    #[test]
    fn the_noise_target_measures_the_error_as_written() {
        let target = NoiseTarget {
            delta_e: 0.3,
            scale: 1.0,
            tone: crate::image_io::Tone::Linear,
            white: 8.0,
        };
        let grey = [0.2; 3];
        assert_eq!(target.delta_e_of(grey, [0.0; 3]), 0.0);
        let small = target.delta_e_of(grey, [1e-4; 3]);
        let large = target.delta_e_of(grey, [1e-2; 3]);
        assert!(
            small < 0.1 && large > 1.0 && large > small,
            "{small} {large}"
        );
        // The same noise is worth more on a darker pixel, and less once exposed down.
        assert!(target.delta_e_of([0.02; 3], [1e-3; 3]) > target.delta_e_of(grey, [1e-3; 3]));
        let dim = NoiseTarget {
            scale: 0.01,
            ..target
        };
        assert!(dim.delta_e_of(grey, [1e-2; 3]) < large);
    }

    #[test]
    fn neighbours_are_the_covered_pixels_right_left_down_and_up() {
        // A 3×3 frame covering all but its centre and its top-right corner:
        //   0 1 .
        //   3 . 5
        //   6 7 8
        let covered = vec![0u32, 1, 3, 5, 6, 7, 8];
        let g = GBuffer {
            width: 3,
            height: 3,
            data: vec![0.0; 16 * covered.len()],
            covered,
        };
        let n = g.neighbours();
        // Indices into `covered`: pixel 0 is 0, 1 is 1, 3 is 2, 5 is 3, 6 is 4, 7 is 5, 8 is 6.
        assert_eq!(n[0], [1, -1, 2, -1]); // pixel 0: right 1, down 3
        assert_eq!(n[1], [-1, 0, -1, -1]); // pixel 1: left 0 (2 and 4 not covered)
        assert_eq!(n[2], [-1, -1, 4, 0]); // pixel 3: down 6, up 0 (4 not covered)
        assert_eq!(n[3], [-1, -1, 6, -1]); // pixel 5: down 8 (2 not covered, 3 is another row)
        assert_eq!(n[5], [6, 4, -1, -1]); // pixel 7: right 8, left 6
        let bytes = g.device_bytes();
        assert_eq!(bytes.len(), (16 + 4) * 4 * g.covered.len());
        let at = 16 * 4 * g.covered.len();
        assert_eq!(bytes[at..at + 4], 1i32.to_le_bytes());
    }

    #[test]
    fn output_groups_gather_the_pixels_that_share_a_sequence() {
        // Keys (output pixel << 4 | place) of five covered pixels, out of order.
        let keys = [(7u32, 0u32), (3, 1), (7, 3), (3, 0), (9, 2)];
        let mut data = vec![0.0f32; 16 * keys.len()];
        for (i, (out, place)) in keys.iter().enumerate() {
            data[16 * i + 15] = f32::from_bits((out << 4) | place);
        }
        let g = GBuffer {
            width: 4,
            height: 4,
            covered: (0..keys.len() as u32).collect(),
            data,
        };
        let mut groups = output_groups(&g);
        groups.iter_mut().for_each(|m| m.sort_unstable());
        assert_eq!(groups, vec![vec![1, 3], vec![0, 2], vec![4]]);
    }
}
