//! What a scene's view needs from a table: the `(u, v, w)` region its pixels can reach and
//! the light's disc as a `(u, v)` footprint, from the mesh's vertices in view.

use crate::brdf::table::{DiscKernel, Region};
use crate::scene::Scene;
use crate::{Error, Result};

/// A scene's mesh in world space (the placement is already applied, so the model matrix is
/// identity); a mesh without triangles is an error.
pub(super) fn load_scene_mesh(scene: &Scene) -> Result<crate::mesh::Mesh> {
    let mesh = scene.mesh.load()?;
    if mesh.indices.is_empty() {
        return Err(Error::invalid(
            "mesh",
            format!("'{}' has no triangles", mesh.name),
        ));
    }
    Ok(mesh)
}

/// The region a table covers when no triangle in view is lit: the diffraction term is zero
/// at every pixel, so the smallest table (around the mirror direction at normal incidence)
/// does. Covering every direction instead would build the largest table there is for a
/// black image (minutes and hundreds of MB for one unlit triangle).
pub(super) fn unlit() -> Region {
    Region::around([[0.0, 0.0, -2.0]], 0.02).unwrap_or(Region::ALL)
}

/// `r` widened by `margin` on every side, within what is physically possible.
pub(super) fn widen(r: &Region, margin: f64) -> Region {
    let all = Region::ALL;
    Region {
        lo: std::array::from_fn(|i| (r.lo[i] - margin).max(all.lo[i])),
        hi: std::array::from_fn(|i| (r.hi[i] + margin).min(all.hi[i])),
    }
}

/// Whether the box `[lo0, lo1, lo2, hi0, hi1, hi2]` contains `need`.
pub(super) fn region_contains(built: &[f64; 6], need: &Region) -> bool {
    (0..3).all(|i| built[i] <= need.lo[i] && need.hi[i] <= built[i + 3])
}

/// Per vertex of `scene`'s mesh: its tangent frame `(T, B, N)` (as the shaders build it)
/// and `ωr` in that frame.
pub(super) fn vertex_frames(
    scene: &Scene,
    mesh: &crate::mesh::Mesh,
) -> Vec<([glam::Vec3; 3], glam::Vec3)> {
    use glam::Vec3;
    let eye = Vec3::from(scene.camera.eye);
    mesh.vertices
        .iter()
        .map(|v| {
            let n = Vec3::from(v.normal).normalize_or(Vec3::Z);
            let t0 = Vec3::new(v.tangent[0], v.tangent[1], v.tangent[2]);
            let t = (t0 - n * n.dot(t0)).normalize_or(n.any_orthonormal_vector());
            let b = if v.tangent[3] < 0.0 { -1.0 } else { 1.0 } * n.cross(t);
            let frame = [t, b, n];
            let d = eye - Vec3::from(v.position);
            let wr = Vec3::new(d.dot(t), d.dot(b), d.dot(n)).normalize_or(Vec3::Z);
            (frame, wr)
        })
        .collect()
}

/// Whether each triangle of `mesh` may show in the frame of `scene`'s camera at `aspect`
/// (not wholly outside one side of the view volume, with 5 % slack); all of them without
/// an aspect.
pub(super) fn triangles_in_view(
    scene: &Scene,
    mesh: &crate::mesh::Mesh,
    aspect: Option<f32>,
) -> Vec<bool> {
    let Some(aspect) = aspect else {
        return vec![true; mesh.indices.len() / 3];
    };
    let m = scene.camera.view_proj(aspect);
    let clip: Vec<glam::Vec4> = mesh
        .vertices
        .iter()
        .map(|v| m * glam::Vec3::from(v.position).extend(1.0))
        .collect();
    mesh.indices
        .chunks_exact(3)
        .map(|tri| {
            let c = [tri[0], tri[1], tri[2]].map(|i| clip[i as usize]);
            let out = |f: &dyn Fn(glam::Vec4) -> bool| c.iter().all(|&p| f(p));
            !(out(&|p| p.w <= 0.0)
                || out(&|p| p.x > 1.05 * p.w)
                || out(&|p| p.x < -1.05 * p.w)
                || out(&|p| p.y > 1.05 * p.w)
                || out(&|p| p.y < -1.05 * p.w))
        })
        .collect()
}

/// The `(u, v, w)` a scene's mesh can reach: the tangent-frame `−ωi − ωr` of every vertex of
/// a triangle that has a lit, visible vertex (as the shaders compute them), for every
/// direction over the light's disc (only its centre when the table holds the disc,
/// `centre_only`), with a margin for the renormalised interpolation between vertices.
/// With an `aspect`, only triangles inside the camera's frame count. `None` when nothing
/// is lit.
pub(super) fn scene_region(
    scene: &Scene,
    mesh: &crate::mesh::Mesh,
    aspect: Option<f32>,
    centre_only: bool,
) -> Option<Region> {
    use glam::Vec3;
    let lights: Vec<Vec3> = if centre_only {
        vec![scene.light.towards_light()]
    } else {
        scene
            .light
            .disk_samples()
            .iter()
            .map(|s| Vec3::from(s.towards_light))
            .collect()
    };
    // Per vertex: whether any direction lights it (and the eye sees it), and its points.
    let uvw: Vec<(bool, Vec<[f64; 3]>)> = vertex_frames(scene, mesh)
        .iter()
        .map(|&([t, b, n], wr)| {
            let frame = |d: Vec3| Vec3::new(d.dot(t), d.dot(b), d.dot(n));
            let mut lit = false;
            let points = lights
                .iter()
                .map(|&l| {
                    let wi = frame(l).normalize_or(Vec3::Z);
                    lit |= wi.z > 0.0 && wr.z > 0.0;
                    [
                        -(wi.x + wr.x) as f64,
                        -(wi.y + wr.y) as f64,
                        -(wi.z + wr.z) as f64,
                    ]
                })
                .collect();
            (lit, points)
        })
        .collect();
    let shown = triangles_in_view(scene, mesh, aspect);
    let points = mesh
        .indices
        .chunks_exact(3)
        .zip(shown)
        .flat_map(|(tri, shown)| {
            let any_lit = shown && tri.iter().any(|&i| uvw[i as usize].0);
            tri.iter()
                .filter(move |_| any_lit)
                .flat_map(|&i| uvw[i as usize].1.iter().copied())
                .collect::<Vec<_>>()
        });
    Region::around(points, 0.02)
}

/// The footprint in `(u, v)` of the light's disc for a table to pre-filter: the
/// covariance-mean of the exact footprints ([`DiscKernel::footprint`]) at the lit vertices
/// of the triangles in the camera's frame at `aspect`. `None` for a point light.
pub(super) fn scene_disc(
    scene: &Scene,
    mesh: &crate::mesh::Mesh,
    aspect: f32,
) -> Option<DiscKernel> {
    use glam::Vec3;
    let light = &scene.light;
    let radius = f64::from(light.angular_diameter_deg).to_radians() / 2.0;
    if light.disk_samples().len() < 2 || radius.is_nan() || radius <= 0.0 {
        return None;
    }
    let l = light.towards_light();
    let frames = vertex_frames(scene, mesh);
    let shown = triangles_in_view(scene, mesh, Some(aspect));
    let mut seen = vec![false; frames.len()];
    for (tri, shown) in mesh.indices.chunks_exact(3).zip(shown) {
        if shown {
            for &i in tri {
                seen[i as usize] = true;
            }
        }
    }
    let kernels: Vec<DiscKernel> = frames
        .iter()
        .zip(seen)
        .filter_map(|(&([t, b, n], wr), seen)| {
            let wi = Vec3::new(l.dot(t), l.dot(b), l.dot(n)).normalize_or(Vec3::Z);
            (seen && wi.z > 0.0 && wr.z > 0.0)
                .then(|| DiscKernel::footprint([wi.x, wi.y, wi.z].map(f64::from), radius))
        })
        .collect();
    DiscKernel::mean(&kernels)
}
