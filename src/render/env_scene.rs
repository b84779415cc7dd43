//! Scenes (meshes) lit by an environment map, disc lights and the sun in radiance units
//! (MODEL §10): the mesh is rasterised once on the CPU into a G-buffer (per covered pixel:
//! the orthonormal tangent frame, `ωr` in it and the texture's albedo), then one compute
//! dispatch (glsl/env_scene.comp) integrates every covered pixel with the estimator that
//! the environment-lit BRDF map uses (glsl/env_common.glsl).
//!
//! **Units.** The picture is radiance (linear sRGB). The texture of thesis Algorithm 4 is an
//! albedo on the scale of the diffraction colours (`[texture] gain`, relative to a mirror's
//! specular value); in radiance units its albedo is `gain·S·c_texture`, with `S` the
//! factor that turns the relative reflectance into the absolute BRDF
//! ([`EnvLighting::mirror_scale`]: `A_λ·R0` weighted by D65's luminance), so texture and
//! diffraction keep the balance they have under the sun. Each direction reflects
//! `L·cos θi·[(1 − w_d)·f_r + ((1 − α) + w_d)·t]`, as Algorithm 4 does for the sun; the
//! `ambient` term is left out (the environment is the light that reaches the skin turned
//! away from the sun). The written picture is radiance × `exposure / S`, so a scene's
//! exposure means what it means under the sun.

use std::sync::Arc;

use glam::DVec3;
use rayon::prelude::*;

use super::env::{dispatch, Dispatch, EnvLighting, Lights, PointLight, SampledDisc};
use crate::brdf::Shading;
use crate::colour::{linear_srgb_to_xyz, xyz_to_linear_srgb};
use crate::gpu::Device;
use crate::light::env::EnvMap;
use crate::mesh::Mesh;
use crate::scene::{Camera, Scene};
use crate::Result;

pub(crate) const SPIRV: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/env_scene.comp.spv"));

/// A texture as the G-buffer reads it: linear-sRGB albedo, top row first, repeated.
pub struct Albedo {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<[f32; 3]>,
}

impl Albedo {
    /// `scale` times the linear value of sRGB-encoded `bytes`.
    pub fn from_srgb8(width: u32, height: u32, bytes: &[[u8; 3]], scale: f64) -> Self {
        let lin = |c: u8| {
            let x = f64::from(c) / 255.0;
            let l = if x <= 0.04045 {
                x / 12.92
            } else {
                ((x + 0.055) / 1.055).powf(2.4)
            };
            (l * scale) as f32
        };
        Albedo {
            width,
            height,
            rgb: bytes.iter().map(|p| p.map(lin)).collect(),
        }
    }

    /// Bilinear lookup with repeat at texture coordinates `(s, t)` (`t` down).
    fn at(&self, s: f64, t: f64) -> [f32; 3] {
        let (w, h) = (self.width as i64, self.height as i64);
        let x = s * w as f64 - 0.5;
        let y = t * h as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let texel = |i: i64, j: i64| self.rgb[(j.rem_euclid(h) * w + i.rem_euclid(w)) as usize];
        let (i, j) = (x0 as i64, y0 as i64);
        let (a, b, c, d) = (
            texel(i, j),
            texel(i + 1, j),
            texel(i, j + 1),
            texel(i + 1, j + 1),
        );
        [0, 1, 2].map(|k| {
            (1.0 - fy) * ((1.0 - fx) * a[k] + fx * b[k]) + fy * ((1.0 - fx) * c[k] + fx * d[k])
        })
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

/// A vertex after the vertex stage: clip position, frame, world position, texture coordinate.
#[derive(Clone, Copy)]
struct Projected {
    clip: [f64; 4],
    t: DVec3,
    b: DVec3,
    n: DVec3,
    p: DVec3,
    uv: [f64; 2],
}

fn project(mesh: &Mesh, camera: &Camera, aspect: f32) -> Vec<Projected> {
    let vp = camera.view_proj(aspect).as_dmat4();
    mesh.vertices
        .iter()
        .map(|v| {
            let p = DVec3::from(v.position.map(f64::from));
            let c = vp * p.extend(1.0);
            // frame.glsl's tangentFrame with an identity model matrix (the mesh is in world
            // space).
            let n = DVec3::from(v.normal.map(f64::from)).normalize_or(DVec3::Z);
            let any = n
                .cross(if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y })
                .normalize();
            let t0 = DVec3::new(
                f64::from(v.tangent[0]),
                f64::from(v.tangent[1]),
                f64::from(v.tangent[2]),
            );
            let t = (t0 - n * n.dot(t0)).try_normalize().unwrap_or(any);
            let sign = if v.tangent[3] < 0.0 { -1.0 } else { 1.0 };
            Projected {
                clip: c.to_array(),
                t,
                b: sign * n.cross(t),
                n,
                p,
                uv: [f64::from(v.uv[0]), 1.0 - f64::from(v.uv[1])],
            }
        })
        .collect()
}

/// The nearest triangle at each pixel centre and its perspective-correct barycentrics.
/// Triangles with a vertex at or behind the eye plane are left out (no clipping); both
/// windings are drawn, as the graphics pipeline draws them (no culling).
fn nearest_triangles(
    verts: &[Projected],
    indices: &[u32],
    width: u32,
    height: u32,
) -> Vec<Option<(u32, [f64; 3])>> {
    let (w, h) = (width as usize, height as usize);
    let screen: Vec<Option<[f64; 3]>> = verts
        .iter()
        .map(|v| {
            let [x, y, z, cw] = v.clip;
            (cw > 1e-9).then(|| {
                [
                    (x / cw * 0.5 + 0.5) * w as f64,
                    (y / cw * 0.5 + 0.5) * h as f64,
                    z / cw,
                ]
            })
        })
        .collect();
    let edge = |a: [f64; 3], b: [f64; 3], p: [f64; 2]| {
        (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
    };
    const BAND: usize = 8;
    let mut out = vec![None; w * h];
    out.par_chunks_mut(w * BAND)
        .enumerate()
        .for_each(|(band, rows)| {
            let (y0, y1) = (band * BAND, (band * BAND + rows.len() / w).min(h));
            let mut depth = vec![f64::INFINITY; rows.len()];
            for (k, tri) in indices.chunks_exact(3).enumerate() {
                let ids = [tri[0], tri[1], tri[2]].map(|i| i as usize);
                let (Some(a), Some(b), Some(c)) = (screen[ids[0]], screen[ids[1]], screen[ids[2]])
                else {
                    continue;
                };
                let area = edge(a, b, [c[0], c[1]]);
                if area.abs() < 1e-12 {
                    continue;
                }
                let ymin = a[1].min(b[1]).min(c[1]);
                let ymax = a[1].max(b[1]).max(c[1]);
                let py0 = ((ymin - 0.5).ceil().max(y0 as f64)) as usize;
                let py1 = ((ymax - 0.5).floor().min(y1 as f64 - 1.0)).max(-1.0);
                if py1 < py0 as f64 {
                    continue;
                }
                let xmin = a[0].min(b[0]).min(c[0]);
                let xmax = a[0].max(b[0]).max(c[0]);
                let px0 = (xmin - 0.5).ceil().max(0.0) as usize;
                let px1 = (xmax - 0.5).floor().min(w as f64 - 1.0);
                if px1 < px0 as f64 {
                    continue;
                }
                for py in py0..=py1 as usize {
                    for px in px0..=px1 as usize {
                        let p = [px as f64 + 0.5, py as f64 + 0.5];
                        let l0 = edge(b, c, p) / area;
                        let l1 = edge(c, a, p) / area;
                        let l2 = 1.0 - l0 - l1;
                        if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                            continue;
                        }
                        let z = l0 * a[2] + l1 * b[2] + l2 * c[2];
                        let slot = (py - y0) * w + px;
                        if !(0.0..=1.0).contains(&z) || z >= depth[slot] {
                            continue;
                        }
                        depth[slot] = z;
                        let q = [l0, l1, l2];
                        let pw = [0, 1, 2].map(|i| q[i] / verts[ids[i]].clip[3]);
                        let s = pw[0] + pw[1] + pw[2];
                        rows[slot] = Some((k as u32, pw.map(|x| x / s)));
                    }
                }
            }
        });
    out
}

/// Rasterises `mesh` (world space) as `camera` sees it at `width`×`height`, `ss`×`ss`
/// pixels to an output pixel (the key of each pixel's sequence, [`GBuffer::data`]).
pub fn rasterise(
    mesh: &Mesh,
    camera: &Camera,
    (width, height, ss): (u32, u32, u32),
    albedo: Option<&Albedo>,
) -> GBuffer {
    let verts = project(mesh, camera, width as f32 / height as f32);
    let hits = nearest_triangles(&verts, &mesh.indices, width, height);
    let eye = DVec3::from(camera.eye.map(f64::from));
    let covered: Vec<u32> = (0..hits.len() as u32)
        .filter(|&i| hits[i as usize].is_some())
        .collect();
    let data: Vec<f32> = covered
        .par_iter()
        .flat_map_iter(|&i| {
            let (k, bary) = hits[i as usize].unwrap_or_default();
            let ids = &mesh.indices[3 * k as usize..3 * k as usize + 3];
            let lerp = |f: &dyn Fn(&Projected) -> DVec3| {
                ids.iter()
                    .zip(bary)
                    .fold(DVec3::ZERO, |a, (&v, w)| a + w * f(&verts[v as usize]))
            };
            let n = lerp(&|v| v.n).normalize_or(DVec3::Z);
            let t0 = lerp(&|v| v.t);
            let t = (t0 - n * n.dot(t0))
                .try_normalize()
                .unwrap_or_else(|| n.any_orthonormal_vector());
            let b0 = lerp(&|v| v.b);
            let b = if b0.dot(n.cross(t)) < 0.0 {
                -n.cross(t)
            } else {
                n.cross(t)
            };
            let to_eye = (eye - lerp(&|v| v.p)).normalize_or(n);
            let wr = [to_eye.dot(t), to_eye.dot(b), to_eye.dot(n)];
            let uv = lerp(&|v| DVec3::new(v.uv[0], v.uv[1], 0.0));
            let tex = albedo.map_or([0.0; 3], |a| a.at(uv.x, uv.y));
            let f = |v: DVec3| v.to_array().map(|x| x as f32);
            let (t, b, n) = (f(t), f(b), f(n));
            let ss = ss.max(1);
            let (x, y) = (i % width, i / width);
            let out = (y / ss) * (width / ss) + x / ss;
            let key = f32::from_bits((out << 4) | ((y % ss) * ss + x % ss));
            #[rustfmt::skip]
            let px = [
                t[0], t[1], t[2], tex[0], b[0], b[1], b[2], tex[1], n[0], n[1], n[2], tex[2],
                wr[0] as f32, wr[1] as f32, wr[2] as f32, key,
            ];
            px
        })
        .collect();
    GBuffer {
        width,
        height,
        covered,
        data,
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

/// One environment-lit frame of covered pixels.
pub struct GBufferRequest<'a> {
    pub env: &'a EnvMap,
    pub lights: &'a Lights,
    pub shading: Shading,
    pub samples: u32,
    pub seed: u32,
    /// Texture blending's `w_diffuse` (`None`: no texture).
    pub w_diffuse: Option<f64>,
}

/// Linear-sRGB radiance of every covered pixel of `g` (in `g.covered`'s order) and the
/// dispatches' time.
pub fn shade_gbuffer(
    dev: &Arc<Device>,
    lighting: &EnvLighting,
    g: &GBuffer,
    req: &GBufferRequest<'_>,
) -> Result<(Vec<[f32; 3]>, f64)> {
    let bytes: Vec<u8> = g.data.iter().flat_map(|x| x.to_le_bytes()).collect();
    let (sums, gpu_ms) = dispatch(
        dev,
        lighting,
        &Dispatch {
            env: req.env,
            lights: req.lights,
            shading: req.shading,
            samples: req.samples,
            seed: req.seed,
            w_diffuse: req.w_diffuse,
            pixels: g.covered.len() as u64,
            map_side: 0,
            outputs: 2,
            extra: Some(if bytes.is_empty() { &[0; 64] } else { &bytes }),
            spirv: SPIRV,
            name: "env scene",
        },
    )?;
    let rgb = sums
        .chunks_exact(2)
        .map(|p| {
            let d = xyz_to_linear_srgb([p[0][0], p[0][1], p[0][2]].map(f64::from));
            [0, 1, 2].map(|c| (d[c] + f64::from(p[1][c])) as f32)
        })
        .collect();
    Ok((rgb, gpu_ms))
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
    /// Samples per output pixel, shared among its `supersample²` G-buffer pixels.
    pub samples: u32,
    pub seed: u32,
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
    /// Samples each G-buffer pixel took.
    pub samples_per_pixel: u32,
    pub gpu_ms: f64,
    pub raster_ms: f64,
}

/// Most G-buffer pixels (`width × height × supersample²`) of an environment-lit scene: the
/// host holds about 100 bytes a pixel while it rasterises (2 GB here).
pub const MAX_GBUFFER_PIXELS: u64 = 4096 * 4096;

/// Refuses a scene whose G-buffer would pass [`MAX_GBUFFER_PIXELS`] or, given `dev`, the
/// largest storage buffer it binds (64 bytes a pixel), before any work.
pub fn check_size(dev: Option<&Device>, scene: &Scene) -> Result<()> {
    let (w, h) = scene.output.render_size();
    let pixels = u64::from(w) * u64::from(h);
    let device = dev.map_or(u64::MAX, |d| crate::gpu::compute::max_storage_range(d) / 64);
    let limit = MAX_GBUFFER_PIXELS.min(device);
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
    let g = rasterise(req.mesh, &scene.camera, (w, h, ss), albedo.as_ref());
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
    let (shaded, gpu_ms) = shade_gbuffer(
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
        },
    )?;
    let s = lighting.mirror_scale;
    let mut rgb = background(scene, req.env, w, h, s);
    for (&i, c) in g.covered.iter().zip(&shaded) {
        rgb[i as usize] = c.map(|x| (f64::from(x) / s) as f32);
    }
    Ok(EnvSceneFrame {
        width: w,
        height: h,
        rgb,
        covered: g.covered.len(),
        samples_per_pixel: per_pixel,
        gpu_ms,
        raster_ms,
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
