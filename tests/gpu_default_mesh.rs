//! The default configuration held to the f64 direct-sum reference on the default scene's
//! mesh, where the diffraction orders are: the default scene rendered exactly as
//! `diffract render` prepares it (its defaults: the default variant, `chebyshev-w`, with
//! the table fitted to the frame, the sun's disc pre-filtered into it, leaving out on,
//! RGBA16F, the grown measured Elaphe field), against the shader's own statement evaluated
//! on the CPU with the reference BRDF: every chosen pixel's ray is cast through the mesh in
//! f64, the vertex stage's frame and `ωr` are interpolated at the hit, the skin texture is
//! sampled bilinearly, and the sun's disc is summed with the reference at 1 nm over 64
//! directions (the continuous disc the pre-filter integrates; MODEL §6.1), then Algorithm
//! 4's blend, the sky's ambient light and the exposure. The worst displayable pixel is
//! summed again over 256 directions: at an order's edge the disc's integral still moves by
//! about 1 % between 64, 128 and 256 directions.
//!
//! The image is 96² at one sample a pixel (the default's 2×2 supersampling averages
//! samples; it does not change what a sample is). The pixels are the 12 where diffraction
//! adds the most light to the skin: four near the specular direction, far brighter than
//! white (Y up to 75 after the exposure, which the tone curve compresses), and eight in the
//! orders. Needs Vulkan; the table is cached under target/test-output so a rerun skips its
//! build (the reference takes about 2.5 minutes on 2 cores).
//!
//! Measured on lavapipe (2026-11-25): in the orders, ΔE2000 (white at Y = 1) 0.04–0.07 at
//! seven pixels and 0.74 at the order's edge (1.08 against 64 directions); near the
//! specular direction the luminance is within 3.4 % of the reference. The goal of ΔE2000
//! p99 ≤ 1 on mesh pixels holds. Before the table's `(u, v)` spacing resolved the unblurred
//! lobe (docs/tables.md), the order's edge was at ΔE2000 3.8 with a third too much blue.

mod gpu_util;

use diffract::brdf::reference;
use diffract::brdf::table::Response;
use diffract::colour::{
    delta_e2000, linear_srgb_to_xyz, xyz_to_lab, xyz_to_linear_srgb, ColourTable,
};
use diffract::light::sky::UniformSky;
use diffract::scene::Scene;
use glam::DVec3;
use gpu_util::golden::srgb8_to_linear;
use gpu_util::*;
use rayon::prelude::*;

const SIZE: u32 = 96;
/// Directions over the sun's disc in the reference (the scene draws with eight).
const REFERENCE_DISC: u32 = 64;
/// Directions over the disc for the worst displayable pixel's second look.
const REFINED_DISC: u32 = 256;
/// Pixels compared: where diffraction adds the most light.
const CHOSEN: usize = 12;
/// Pixels whose reference is displayable (Y ≤ 1 after the exposure): the median and the
/// largest ΔE2000 (white at Y = 1) from the reference (measured 0.064 and 0.74); the
/// largest is the goal itself.
const MAX_MEDIAN_DE: f64 = 0.25;
const MAX_DE: f64 = 1.0;
/// Brighter pixels (near the specular direction): relative luminance error (measured 3.4 %).
const MAX_BRIGHT_REL: f64 = 0.05;

/// The vertex stage's outputs at one vertex (glsl/diffraction.vert, frame.glsl), in f64.
struct VertexOut {
    t: DVec3,
    b: DVec3,
    n: DVec3,
    wr: DVec3,
    uv: [f64; 2],
}

fn vertex_out(v: &diffract::mesh::Vertex, eye: DVec3) -> VertexOut {
    let p = DVec3::from(v.position.map(f64::from));
    let n = DVec3::from(v.normal.map(f64::from)).normalize();
    let any_perp = n
        .cross(if n.x.abs() < 0.9 { DVec3::X } else { DVec3::Y })
        .normalize();
    let t0 = DVec3::new(
        v.tangent[0] as f64,
        v.tangent[1] as f64,
        v.tangent[2] as f64,
    );
    let t = (t0 - n * n.dot(t0)).try_normalize().unwrap_or(any_perp);
    let b = if v.tangent[3] < 0.0 { -1.0 } else { 1.0 } * n.cross(t);
    let d = eye - p;
    VertexOut {
        t,
        b,
        n,
        wr: DVec3::new(d.dot(t), d.dot(b), d.dot(n)),
        uv: [v.uv[0] as f64, 1.0 - v.uv[1] as f64],
    }
}

/// The nearest triangle the ray `o + s·d` hits: its index and barycentrics `(1 − β − γ, β, γ)`.
fn cast(mesh: &diffract::mesh::Mesh, o: DVec3, d: DVec3) -> Option<(usize, [f64; 3])> {
    let pos = |i: u32| DVec3::from(mesh.vertices[i as usize].position.map(f64::from));
    let mut best: Option<(f64, usize, [f64; 3])> = None;
    for (k, tri) in mesh.indices.chunks_exact(3).enumerate() {
        let (a, b, c) = (pos(tri[0]), pos(tri[1]), pos(tri[2]));
        let (e1, e2) = (b - a, c - a);
        let p = d.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-18 {
            continue;
        }
        let s = o - a;
        let beta = s.dot(p) / det;
        let q = s.cross(e1);
        let gamma = d.dot(q) / det;
        let dist = e2.dot(q) / det;
        if beta < 0.0 || gamma < 0.0 || beta + gamma > 1.0 || dist <= 0.0 {
            continue;
        }
        if best.is_none_or(|(bd, _, _)| dist < bd) {
            best = Some((dist, k, [1.0 - beta - gamma, beta, gamma]));
        }
    }
    best.map(|(_, k, w)| (k, w))
}

/// Bilinear lookup of linear texels (sRGB decoded per texel, as an `_SRGB` image is),
/// repeating, at texture coordinates `uv` (texel centres at `(i + ½)/w`).
fn bilinear(tex: &(u32, u32, Vec<[f32; 3]>), uv: [f64; 2]) -> [f64; 3] {
    let (w, h, px) = tex;
    let (w, h) = (*w as i64, *h as i64);
    let x = uv[0] * w as f64 - 0.5;
    let y = uv[1] * h as f64 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at = |i: i64, j: i64| {
        let (i, j) = (i.rem_euclid(w), j.rem_euclid(h));
        px[(j * w + i) as usize].map(f64::from)
    };
    let (x0, y0) = (x0 as i64, y0 as i64);
    let mut out = [0.0; 3];
    for (dx, dy, wgt) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (1, 0, fx * (1.0 - fy)),
        (0, 1, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        let t = at(x0 + dx, y0 + dy);
        for c in 0..3 {
            out[c] += wgt * t[c];
        }
    }
    out
}

#[test]
fn the_default_configuration_matches_the_reference_on_the_default_scene() {
    let Some(mut r) = renderer() else { return };
    let mut scene = Scene::default_scene();
    scene.output.width = SIZE;
    scene.output.height = SIZE;
    scene.output.supersample = 1;
    let prepared = as_render_defaults(&mut r, &scene.material, "default-mesh-cache");
    let frame = r.render_scene(&scene, &prepared).expect("default scene");
    assert_no_validation(&r);
    let name = &frame.variant.name;
    assert!(
        name.starts_with("chebyshev-w") && name.contains("disc pre-filtered"),
        "the default draws the table with the disc: {name}"
    );

    // The geometry, as the vertex stage and the rasteriser see it.
    let mesh = scene.mesh.load().expect("mesh");
    let eye = DVec3::from(scene.camera.eye.map(f64::from));
    let outs: Vec<VertexOut> = mesh.vertices.iter().map(|v| vertex_out(v, eye)).collect();
    let inv = scene
        .camera
        .view_proj(scene.output.aspect())
        .as_dmat4()
        .inverse();
    let spec = scene
        .texture
        .as_ref()
        .expect("the default scene has a skin");
    let (tw, th, bytes) = spec.load().expect("skin");
    let texels = (
        tw,
        th,
        bytes
            .iter()
            .map(|p| p.map(srgb8_to_linear))
            .collect::<Vec<_>>(),
    );
    // The reference integrates the disc the table's pre-filter integrates (the continuous
    // disc) with REFERENCE_DISC directions, not the scene's eight: at an order's edge eight
    // directions miss the disc's integral by 15 %.
    let mut light = scene.light.clone();
    light.disk_samples = REFERENCE_DISC;
    let disk: Vec<(DVec3, f64)> = light
        .disk_samples()
        .iter()
        .map(|s| (DVec3::from(s.towards_light.map(f64::from)), s.weight as f64))
        .collect();
    let light = &light;
    let fine: Vec<(DVec3, f64)> = {
        let mut l = light.clone();
        l.disk_samples = REFINED_DISC;
        l.disk_samples()
            .iter()
            .map(|s| (DVec3::from(s.towards_light.map(f64::from)), s.weight as f64))
            .collect()
    };
    let ior = prepared.material.ior;
    let r0 = ((ior - 1.0) / (ior + 1.0)).powi(2);
    let (intensity, exposure) = (light.intensity as f64, scene.output.exposure as f64);
    let (w_d, ambient, gain) = (spec.w_diffuse as f64, spec.ambient as f64, spec.gain as f64);

    // Per pixel: the interpolated frame, ωr, the texture and each disc direction's ωi.
    struct Pixel {
        ij: (u32, u32),
        frame: [DVec3; 3],
        wr: DVec3,
        tex: [f64; 3],
        /// (ωi, weight · irradiance, Schlick F at the half vector).
        lights: Vec<(DVec3, f64, f64)>,
    }
    let lights_of = |[t, b, n]: [DVec3; 3], wr: DVec3, disk: &[(DVec3, f64)]| {
        disk.iter()
            .map(|&(l, weight)| {
                let wi = DVec3::new(l.dot(t), l.dot(b), l.dot(n)).normalize();
                let h = (wi + wr).normalize();
                let m = 1.0 - wr.dot(h).clamp(0.0, 1.0);
                let f = r0 + (1.0 - r0) * m.powi(5);
                (wi, weight * wi.z.max(0.0) * intensity, f)
            })
            .collect::<Vec<_>>()
    };
    let pixels: Vec<Pixel> = (0..SIZE * SIZE)
        .into_par_iter()
        .filter_map(|k| {
            let (i, j) = (k % SIZE, k / SIZE);
            let (near, far) = pixel_ray(&inv, i, j, SIZE, SIZE);
            let (tri, bary) = cast(&mesh, near, (far - near).normalize())?;
            // Away from triangle edges, where the rasteriser and the ray may disagree.
            if bary.iter().any(|&b| b < 0.02) {
                return None;
            }
            let idx = &mesh.indices[3 * tri..3 * tri + 3];
            let lerp = |f: &dyn Fn(&VertexOut) -> DVec3| {
                idx.iter()
                    .zip(bary)
                    .fold(DVec3::ZERO, |acc, (&v, w)| acc + w * f(&outs[v as usize]))
            };
            let (t, b, n) = (lerp(&|o| o.t), lerp(&|o| o.b), lerp(&|o| o.n));
            let wr = lerp(&|o| o.wr).normalize();
            let uv = lerp(&|o| DVec3::new(o.uv[0], o.uv[1], 0.0));
            let tex = bilinear(&texels, [uv.x, uv.y]).map(|c| gain * c);
            Some(Pixel {
                ij: (i, j),
                frame: [t, b, n],
                lights: lights_of([t, b, n], wr, &disk),
                wr,
                tex,
            })
        })
        .collect();
    // Algorithm 4 with the diffraction colour `diff[k]` of each disc direction, plus the
    // ambient sky in closed form (light::sky), times the exposure; in radiance over the
    // picture's scale (MODEL §10).
    let response = Response::radiance(prepared.material.coherence_um, &prepared.shading);
    let sky = UniformSky::of_ambient(ambient, intensity);
    let fresnel = (r0, prepared.shading.fresnel);
    let shade = |p: &Pixel, diff: &[[f64; 3]]| -> [f64; 3] {
        let mut c = [0.0; 3];
        for (k, &(_, lit, f)) in p.lights.iter().enumerate() {
            let alpha = f.abs().min(1.0);
            for ch in 0..3 {
                let blend = (1.0 - w_d) * diff[k][ch] + (1.0 - alpha) * p.tex[ch] + w_d * p.tex[ch];
                c[ch] += lit * blend;
            }
        }
        let sky = sky.reflected(p.wr.z, p.tex, w_d, fresnel, response.scale());
        [0, 1, 2].map(|ch| (c[ch] + sky[ch]) * exposure)
    };
    assert!(pixels.len() > 1000, "{} mesh pixels hit", pixels.len());

    // Where diffraction adds the most: the GPU's pixel less the skin alone.
    let no_diffraction = vec![[0.0; 3]; disk.len()];
    let mut added: Vec<(usize, f64)> = pixels
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let gpu = frame.at(p.ij.0, p.ij.1).map(f64::from);
            let skin = shade(p, &no_diffraction);
            let lum = |c: [f64; 3]| linear_srgb_to_xyz(c)[1];
            (k, lum(gpu) - lum(skin))
        })
        .collect();
    added.sort_by(|a, b| b.1.total_cmp(&a.1));
    let chosen: Vec<&Pixel> = added
        .iter()
        .take(CHOSEN)
        .map(|&(k, _)| &pixels[k])
        .collect();

    // The BRDF is reciprocal (C and G depend on ωi and ωr symmetrically), so each pixel's
    // disc directions are the "view" directions of one xyz_many call lit from its ωr: the
    // same numbers as reference::xyz per direction (to rounding), several times faster.
    let table = response.colour(&ColourTable::new(1).unwrap());
    let diffraction = |wr: DVec3, lights: &[(DVec3, f64, f64)]| -> Vec<[f64; 3]> {
        let dirs: Vec<[f64; 3]> = lights.iter().map(|l| l.0.to_array()).collect();
        reference::xyz_many(
            &prepared.heightfield,
            prepared.material.coherence_um,
            &prepared.shading,
            &table,
            wr.to_array(),
            &dirs,
            &|| {},
        )
        .into_iter()
        .map(xyz_to_linear_srgb)
        .collect()
    };
    let refs: Vec<[f64; 3]> = chosen
        .iter()
        .flat_map(|px| diffraction(px.wr, &px.lights))
        .collect();
    let de_of = |gpu: [f64; 3], expected: [f64; 3]| {
        // Against white at Y = 1 after the exposure (where the tone curve starts).
        delta_e2000(
            xyz_to_lab(linear_srgb_to_xyz(gpu)),
            xyz_to_lab(linear_srgb_to_xyz(expected)),
        )
    };
    let mut des = Vec::new();
    let mut worst_bright: f64 = 0.0;
    let mut coloured = 0;
    let mut worst_pixel: Option<(f64, usize)> = None;
    for (p, px) in chosen.iter().enumerate() {
        let diff = &refs[p * disk.len()..(p + 1) * disk.len()];
        let expected = shade(px, diff);
        let gpu = frame.at(px.ij.0, px.ij.1).map(f64::from);
        let skin = shade(px, &no_diffraction);
        let (yg, yr) = (linear_srgb_to_xyz(gpu)[1], linear_srgb_to_xyz(expected)[1]);
        let what = if yr <= 1.0 {
            let de = de_of(gpu, expected);
            des.push(de);
            if worst_pixel.is_none_or(|(w, _)| de > w) {
                worst_pixel = Some((de, p));
            }
            format!("ΔE2000 {de:.3}")
        } else {
            let rel = (yg - yr).abs() / yr;
            worst_bright = worst_bright.max(rel);
            format!("luminance {:+.2} %", 100.0 * (yg - yr) / yr)
        };
        eprintln!(
            "pixel {:?}: GPU {gpu:.4?} reference {expected:.4?} (skin alone {skin:.4?}): {what}",
            px.ij
        );
        // Diffraction adds a fifth or more to the skin's light here.
        if yr >= 1.2 * linear_srgb_to_xyz(skin)[1] {
            coloured += 1;
        }
    }
    // The worst displayable pixel again, its disc summed over REFINED_DISC directions: at
    // an order's edge the disc's integral still moves by about 1 % between 64, 128 and
    // 256 directions (measured: ΔE2000 1.08, 0.47 and 0.74 for the same GPU pixel).
    if let Some((de, p)) = worst_pixel {
        let px = chosen[p];
        let lights = lights_of(px.frame, px.wr, &fine);
        let refined = Pixel {
            lights: lights.clone(),
            ..*px
        };
        let expected = shade(&refined, &diffraction(px.wr, &lights));
        let gpu = frame.at(px.ij.0, px.ij.1).map(f64::from);
        let fine_de = de_of(gpu, expected);
        eprintln!(
            "pixel {:?} against {REFINED_DISC} directions: reference {expected:.4?}: ΔE2000 {fine_de:.3} ({de:.3} against {REFERENCE_DISC})",
            px.ij
        );
        let at = des.iter().position(|&d| d == de).unwrap();
        des[at] = fine_de;
    }
    des.sort_by(f64::total_cmp);
    let (median, worst) = (des[des.len() / 2], des[des.len() - 1]);
    eprintln!(
        "{} displayable pixels: ΔE2000 median {median:.3}, largest {worst:.3}; brighter: luminance within {:.2} %",
        des.len(),
        100.0 * worst_bright
    );
    assert!(
        coloured >= CHOSEN / 2,
        "the chosen pixels are where the orders are: diffraction brightens only {coloured}"
    );
    assert!(des.len() >= CHOSEN / 2, "{} displayable pixels", des.len());
    assert!(
        median <= MAX_MEDIAN_DE && worst <= MAX_DE,
        "ΔE2000 from the reference: median {median:.3} (limit {MAX_MEDIAN_DE}), largest {worst:.3} (limit {MAX_DE})"
    );
    assert!(
        worst_bright <= MAX_BRIGHT_REL,
        "near the specular direction the luminance is {:.2} % off (limit {:.0} %)",
        100.0 * worst_bright,
        100.0 * MAX_BRIGHT_REL
    );
}
