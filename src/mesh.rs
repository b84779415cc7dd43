//! Triangle meshes ready for upload: the GPU vertex layout ([`Vertex`]), OBJ loading through
//! tobj with validation, smooth normals and tangent frames, the procedural shapes the
//! renderer ships with (snake, sphere, plane) and an OBJ writer for them.
//!
//! The tangent frame matters more here than in most renderers: the height field's `x` axis
//! (its columns, MODEL §1) is laid along the vertex tangent `T`, so `T` decides which way the
//! grating ridges run on the surface. Two rules fix it:
//! - **With UVs:** `T` is `∂P/∂u` (per-triangle, area-weighted, Gram–Schmidt against `N`), and
//!   `tangent.w = ±1` is the handedness, so the bitangent is `B = w · (N × T)` and points along
//!   `∂P/∂v`.
//! - **Without UVs** (or where `∂P/∂u` is degenerate): `T` is the *grating direction*, the world
//!   `x` axis projected onto the tangent plane (world `y` where the normal is parallel to `x`),
//!   `w = +1`. It is smooth everywhere except near normals parallel to `x`.
//!
//! Nothing here touches Vulkan or physics; every failure on user input is an [`Error::Parse`]
//! naming the file, never a panic.

use std::collections::HashMap;
use std::io::Write as _;
use std::path::Path;

use glam::{DVec3, Mat3, Mat4, Vec3};

use crate::{Error, Result};

/// One vertex as the GPU reads it (`#[repr(C)]`, 48 bytes, uploaded as-is).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vertex {
    /// Object/world position.
    pub position: [f32; 3],
    /// Unit surface normal.
    pub normal: [f32; 3],
    /// Unit tangent (`xyz`, orthogonal to the normal) and handedness `w = ±1`:
    /// the bitangent is `w · (normal × tangent)`.
    pub tangent: [f32; 4],
    /// Texture coordinates as stored in the file (OBJ convention, `v` up); `[0, 0]` when the
    /// source has none.
    pub uv: [f32; 2],
}

const _: () = assert!(std::mem::size_of::<Vertex>() == 48);

/// An indexed triangle list (counter-clockwise front faces, outward normals).
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    pub vertices: Vec<Vertex>,
    /// Three indices per triangle, each `< vertices.len()`.
    pub indices: Vec<u32>,
    pub name: String,
    /// What loading repaired (zero-area triangles dropped, zero-length normals replaced),
    /// one line each: the command that loaded the mesh reports them as warnings.
    pub repairs: Vec<String>,
}

/// Geometry before normals and tangents are derived: what a file or a generator provides.
struct RawMesh {
    positions: Vec<[f32; 3]>,
    /// `None` where the source gave no normal: a smooth normal is computed there.
    normals: Vec<Option<[f32; 3]>>,
    /// `None` where the source gave no UV: the tangent falls back to the grating direction.
    uvs: Vec<Option<[f32; 2]>>,
    indices: Vec<u32>,
}

fn v3(a: [f32; 3]) -> DVec3 {
    DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64)
}

fn f3(v: DVec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

/// Hashable key of a position; `+ 0.0` folds `-0.0` into `0.0` so both land in one group.
fn position_key(p: [f32; 3]) -> [u32; 3] {
    p.map(|c| (c + 0.0).to_bits())
}

/// The tangent used where UVs cannot define one: world `x` projected onto the tangent
/// plane, or world `y` when the normal is (nearly) parallel to `x`.
pub fn grating_direction(normal: Vec3) -> Vec3 {
    let n = normal.as_dvec3();
    let project = |a: DVec3| a - n * n.dot(a);
    let t = project(DVec3::X);
    let t = if t.length() > 1e-3 {
        t
    } else {
        project(DVec3::Y)
    };
    t.normalize_or(DVec3::X).as_vec3()
}

impl Mesh {
    /// Axis-aligned bounds `(min, max)` of the vertex positions (`([0;3], [0;3])` if empty).
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        if self.vertices.is_empty() {
            return ([0.0; 3], [0.0; 3]);
        }
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for v in &self.vertices {
            for c in 0..3 {
                lo[c] = lo[c].min(v.position[c]);
                hi[c] = hi[c].max(v.position[c]);
            }
        }
        (lo, hi)
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Loads a Wavefront OBJ (polygons are triangulated, all objects/groups are merged into
    /// one mesh, materials are ignored). Normals and UVs are optional; see the module docs for
    /// how missing ones are filled in. Zero-area triangles are dropped and said in
    /// [`Mesh::repairs`]. Errors name the file and the line, triangle or vertex at fault.
    pub fn load_obj(path: &Path) -> Result<Mesh> {
        let bytes = crate::fsutil::read_bounded(path, "mesh", crate::fsutil::MAX_OBJ_BYTES)?;
        let text = std::str::from_utf8(&bytes).map_err(|e| {
            Error::parse(
                path,
                format!(
                    "not an OBJ text file (invalid UTF-8 at byte {})",
                    e.valid_up_to()
                ),
            )
        })?;
        Self::from_obj_str(text, path)
    }

    /// Parses OBJ text (what [`Mesh::load_obj`] does after reading the file); `path` names
    /// the source in errors and the mesh is named after its file stem.
    pub fn from_obj_str(text: &str, path: &Path) -> Result<Mesh> {
        let triangles = prescan_obj(text, path)?;
        if triangles == 0 {
            return Err(Error::parse(
                path,
                "no triangles (no face has 3 or more vertices)",
            ));
        }
        // `..Default::default()` covers tobj's feature-gated options (`merging`,
        // `reordering`), which another crate in the build may switch on.
        #[allow(clippy::needless_update)]
        let options = tobj::LoadOptions {
            single_index: true,
            triangulate: true,
            ignore_points: true,
            ignore_lines: true,
            ..Default::default()
        };
        // The prescan rejects every index tobj could mishandle; catching a panic anyway keeps
        // the promise that no input file can abort the program.
        let loaded = std::panic::catch_unwind(|| {
            let mut reader = std::io::Cursor::new(text.as_bytes());
            tobj::load_obj_buf(&mut reader, &options, |_| {
                Err(tobj::LoadError::OpenFileFailed)
            })
        })
        .map_err(|_| Error::parse(path, "the OBJ parser failed on this file"))?;
        let (models, _materials) =
            loaded.map_err(|e| Error::parse(path, format!("OBJ parse error: {e}")))?;

        let mut raw = RawMesh {
            positions: Vec::new(),
            normals: Vec::new(),
            uvs: Vec::new(),
            indices: Vec::new(),
        };
        for model in &models {
            let m = &model.mesh;
            let n = m.positions.len() / 3;
            let has_normals = !m.normals.is_empty();
            let has_uvs = !m.texcoords.is_empty();
            if has_normals && m.normals.len() != 3 * n {
                return Err(Error::parse(
                    path,
                    format!(
                        "object `{}`: only some face corners have normals (give all or none)",
                        model.name
                    ),
                ));
            }
            if has_uvs && m.texcoords.len() != 2 * n {
                return Err(Error::parse(
                    path,
                    format!(
                        "object `{}`: only some face corners have texture coordinates (give all or none)",
                        model.name
                    ),
                ));
            }
            let base = raw.positions.len();
            if base + n > u32::MAX as usize {
                return Err(Error::parse(path, "more than 2^32 vertices"));
            }
            for i in 0..n {
                raw.positions.push([
                    m.positions[3 * i],
                    m.positions[3 * i + 1],
                    m.positions[3 * i + 2],
                ]);
                raw.normals.push(
                    has_normals
                        .then(|| [m.normals[3 * i], m.normals[3 * i + 1], m.normals[3 * i + 2]]),
                );
                raw.uvs
                    .push(has_uvs.then(|| [m.texcoords[2 * i], m.texcoords[2 * i + 1]]));
            }
            for &idx in &m.indices {
                if idx as usize >= n {
                    return Err(Error::parse(
                        path,
                        format!(
                            "object `{}`: vertex index {idx} out of range ({n} vertices)",
                            model.name
                        ),
                    ));
                }
                raw.indices.push((base + idx as usize) as u32);
            }
        }
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "mesh".into());
        let rescaled = fit_to_scene_units(&mut raw, path);
        let mut mesh = finish(name, raw, path)?;
        mesh.repairs.extend(rescaled);
        Ok(mesh)
    }

    /// Writes the mesh as OBJ (positions, UVs, normals and `v/vt/vn` faces; tangents are
    /// re-derived on load). Shortest round-trip float formatting makes a reload bit-exact.
    /// Written to a temporary file beside `path` and renamed into place.
    pub fn write_obj(&self, path: &Path) -> Result<()> {
        use std::fmt::Write as _;
        let mut s = String::with_capacity(self.vertices.len() * 96 + self.indices.len() * 12);
        // Writing into a String cannot fail; the results are ignored for that reason.
        let _ = writeln!(
            s,
            "# diffract mesh `{}`: {} vertices, {} triangles",
            self.name,
            self.vertices.len(),
            self.triangle_count()
        );
        let _ = writeln!(s, "o {}", self.name);
        for v in &self.vertices {
            let p = v.position;
            let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
        }
        for v in &self.vertices {
            let _ = writeln!(s, "vt {} {}", v.uv[0], v.uv[1]);
        }
        for v in &self.vertices {
            let n = v.normal;
            let _ = writeln!(s, "vn {} {} {}", n[0], n[1], n[2]);
        }
        for t in self.indices.chunks_exact(3) {
            let (a, b, c) = (t[0] + 1, t[1] + 1, t[2] + 1);
            let _ = writeln!(s, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}");
        }
        crate::fsutil::write_atomically(path, |w| {
            w.write_all(s.as_bytes()).map_err(|e| Error::io(path, e))
        })
    }

    /// A built-in shape by name: `snake`, `scaly-snake`, `sphere` or `plane` (all but
    /// `scaly-snake` are shipped as `assets/<name>.obj`).
    pub fn builtin(name: &str) -> Option<Mesh> {
        match name {
            "snake" => Some(Mesh::snake(2.0, 0.08, 160, 48)),
            "scaly-snake" => Some(Mesh::scaly_snake(2.0, 0.08, 64, 18)),
            "sphere" => Some(Mesh::sphere(1.0, 64, 32)),
            "plane" => Some(Mesh::plane(2.0, 16)),
            _ => None,
        }
    }

    /// Names accepted by [`Mesh::builtin`].
    pub const BUILTIN_NAMES: [&'static str; 4] = ["snake", "scaly-snake", "sphere", "plane"];

    /// A UV sphere centred at the origin, `y` up. `u = φ/2π` runs around the `y` axis (so the
    /// tangent is the east direction), `v = θ/π` from the north pole (`+y`) to the south pole.
    /// Counts are clamped to `segments ∈ [3, 4096]`, `rings ∈ [2, 4096]`; a radius that is not
    /// positive and finite is replaced by 1.
    pub fn sphere(radius: f32, segments: u32, rings: u32) -> Mesh {
        let r = if radius.is_finite() && radius > 0.0 {
            radius
        } else {
            1.0
        } as f64;
        let (ns, nr) = (segments.clamp(3, 4096), rings.clamp(2, 4096));
        let raw = grid(ns, nr, |u, v| {
            // The poles are single points: exact, so the pole triangles become clean fans.
            if v == 0.0 || v == 1.0 {
                let y = if v == 0.0 { 1.0 } else { -1.0 };
                return (DVec3::new(0.0, y * r, 0.0), Some(DVec3::new(0.0, y, 0.0)));
            }
            let (phi, theta) = (u * std::f64::consts::TAU, v * std::f64::consts::PI);
            let n = DVec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            (n * r, Some(n))
        });
        build_generated("sphere", raw)
    }

    /// A square of side `size` in the `xy` plane centred at the origin, facing `+z`:
    /// `u` runs along `x`, `v` along `y`, tangent `+x`. `subdivisions ∈ [1, 4096]` quads per
    /// side; a size that is not positive and finite is replaced by 1.
    pub fn plane(size: f32, subdivisions: u32) -> Mesh {
        let s = if size.is_finite() && size > 0.0 {
            size
        } else {
            1.0
        } as f64;
        let n = subdivisions.clamp(1, 4096);
        let raw = grid(n, n, |u, v| {
            (
                DVec3::new((u - 0.5) * s, (v - 0.5) * s, 0.0),
                Some(DVec3::Z),
            )
        });
        build_generated("plane", raw)
    }

    /// A snake lying on the ground (`y = 0`, `y` up): a tube whose centre line is an S curve
    /// in the `xz` plane, from the tail (`x = −length/2`) to the head (`x ≈ +length/2`), with
    /// a long tapering tail, a slight neck and a rounded snout. Cross sections are ellipses
    /// (`radius` wide, `0.8·radius` high) resting on the ground.
    ///
    /// `u ∈ [0,1]` runs **around** the body and `v ∈ [0,1]` **along** it (by arc length, so a
    /// texture is not stretched), so the tangent `∂P/∂u` circles the body and the height
    /// field's ridges (lines of constant `x`) run along the body axis, as on real snake
    /// scales. Normals are area-weighted smooth normals.
    /// Counts are clamped to `segments_along ∈ [4, 4096]`, `segments_around ∈ [3, 4096]`;
    /// sizes that are not positive and finite are replaced by 2 and 0.08.
    pub fn snake(length: f32, radius: f32, segments_along: u32, segments_around: u32) -> Mesh {
        let len = if length.is_finite() && length > 0.0 {
            length
        } else {
            2.0
        } as f64;
        let rad = if radius.is_finite() && radius > 0.0 {
            radius
        } else {
            0.08
        } as f64;
        let (na, nr) = (
            segments_along.clamp(4, 4096),
            segments_around.clamp(3, 4096),
        );
        let curve = SnakeCurve::new(len);
        let raw = grid(nr, na, |u, v| {
            let (c, tp) = curve.at_arc_fraction(v);
            let r = rad * snake_profile(v);
            // Side vector U × T: with θ = 2πu this makes ∂P/∂u × ∂P/∂v point outwards and
            // the tangent frame right-handed (w = +1).
            let side = DVec3::Y.cross(tp);
            let (s, co) = (u * std::f64::consts::TAU).sin_cos();
            let height = 0.8 * r;
            let centre = DVec3::new(c.x, height, c.z);
            let p = centre + side * (r * co) + DVec3::Y * (height * s);
            (p, None)
        });
        build_generated("snake", raw)
    }

    /// The snake of [`Mesh::snake`] covered in curved, overlapping scales, as on a real
    /// snake's skin: `scales_along × scales_around` scales in staggered rows (alternate rings
    /// shifted by half a scale), each a smooth dome over the body (rising 5 % of the body
    /// radius, so its normal tilts by up to about ±20° across it), lifted at its tail end by
    /// 3 % of the radius so it lies over the next scale like a shingle, and tapered towards
    /// that free edge. Scales are 35 % longer and 25 % wider than their cells, so they
    /// overlap and no body shows between them; a plain body tube slightly inside them
    /// covers the tail tip and the head, where there are no scales.
    ///
    /// **Frame:** here `u` runs **along** the body (tail → head, by arc length) and `v`
    /// **around** it (`v = 0.25` the belly, `0.75` the spine), the reverse of
    /// [`Mesh::snake`]: the tangent `T = ∂P/∂u` follows each scale's dome along the body, so
    /// the height field's rows (the measured Elaphe ridges, which run along `x`) run along
    /// the body as on the animal, and the grating diffracts around it. Normals are analytic
    /// per scale (smooth within a scale, a crease where one scale overlaps the next), so the
    /// diffraction colour sweeps smoothly across each scale.
    ///
    /// Counts are clamped to `scales_along ∈ [4, 1024]`, `scales_around ∈ [3, 256]`; sizes
    /// that are not positive and finite are replaced by 2 and 0.08.
    pub fn scaly_snake(length: f32, radius: f32, scales_along: u32, scales_around: u32) -> Mesh {
        Self::scaly_snake_with(length, radius, scales_along, scales_around, 6)
    }

    /// [`Mesh::scaly_snake`] with `quads` (clamped to 1..=32) quads along each side of a
    /// scale instead of 6: the resolution per-vertex evaluation depends on.
    pub fn scaly_snake_with(
        length: f32,
        radius: f32,
        scales_along: u32,
        scales_around: u32,
        quads: u32,
    ) -> Mesh {
        let len = if length.is_finite() && length > 0.0 {
            length
        } else {
            2.0
        } as f64;
        let rad = if radius.is_finite() && radius > 0.0 {
            radius
        } else {
            0.08
        } as f64;
        let (na, nr) = (
            scales_along.clamp(4, 1024) as usize,
            scales_around.clamp(3, 256) as usize,
        );
        let body = ScalyBody::new(len, rad);
        // The body under the scales, a little inside them.
        let mut raw = grid(4 * na as u32, 3 * nr as u32, |u, v| {
            (body.point(u, v, 0.985), None)
        });
        let q_side = quads.clamp(1, 32) as usize; // quads per scale side
        let (ds, da) = (1.0 / na as f64, 1.0 / nr as f64);
        let (over_s, over_a) = (1.35, 1.25);
        let (dome, lift) = (0.05, 0.03);
        for i in 0..na {
            let sc = (i as f64 + 0.5) * ds;
            // No scales where the body narrows to its tips (the tail point, the snout).
            let reach = 0.5 * ds * over_s;
            if snake_profile(sc - reach) < 0.3 || snake_profile(sc + reach) < 0.3 || sc > 0.93 {
                continue;
            }
            for j in 0..nr {
                let ac = (j as f64 + 0.5 + 0.5 * (i % 2) as f64) * da;
                // (p, q) ∈ [−1, 1]²: p around, q along (q = −1 the tail end, the free edge).
                let at = |p: f64, q: f64| {
                    let taper = 1.0 - 0.4 * (-q).max(0.0).powi(2);
                    let s = sc + q * 0.5 * ds * over_s;
                    let a = ac + p * taper * 0.5 * da * over_a;
                    let h = dome * (1.0 - p * p) * (1.0 - q * q) + lift * 0.5 * (1.0 - q);
                    (body.point(s, a, 1.0 + h), [s as f32, a as f32])
                };
                let base = raw.positions.len() as u32;
                for qi in 0..=q_side {
                    for pi in 0..=q_side {
                        let (p, q) = (
                            2.0 * pi as f64 / q_side as f64 - 1.0,
                            2.0 * qi as f64 / q_side as f64 - 1.0,
                        );
                        let (pos, uv) = at(p, q);
                        // Analytic (central-difference) normal of the dome: smooth in a scale.
                        let e = 1e-4;
                        let dq = at(p, q + e).0 - at(p, q - e).0;
                        let dp = at(p + e, q).0 - at(p - e, q).0;
                        let n = dq.cross(dp).normalize_or(DVec3::Y);
                        raw.positions.push(f3(pos));
                        raw.normals.push(Some(f3(n)));
                        raw.uvs.push(Some(uv));
                    }
                }
                let k = |pi: usize, qi: usize| base + (qi * (q_side + 1) + pi) as u32;
                for qi in 0..q_side {
                    for pi in 0..q_side {
                        // Counter-clockwise seen from outside: ∂P/∂q × ∂P/∂p points out.
                        let (a, b, c, d) =
                            (k(pi, qi), k(pi, qi + 1), k(pi + 1, qi + 1), k(pi + 1, qi));
                        raw.indices.extend_from_slice(&[a, b, c, a, c, d]);
                    }
                }
            }
        }
        build_generated("scaly-snake", raw)
    }

    /// Facets the mesh into flat "scales", as on a snake's skin: every pair of consecutive
    /// triangles (a quad of the built-in grids; a lone last triangle stands alone) becomes
    /// one flat facet with the averaged face normal, and its frame is rolled about the
    /// facet's bitangent by a seeded random angle in `±roll_deg` and pitched about its
    /// tangent by one in `±pitch_deg`.
    ///
    /// A 1D grating across `T` diffracts only where `v = −(ωi+ωr)·B ≈ 0` and `u` meets an
    /// order, both within the coherence lobe (~0.005): on a smooth surface that is a
    /// hairline. Rolling spreads `u` and pitching spreads `v` from scale to scale, so whole
    /// scales light up in the colours of their orders, as on real iridescent skin.
    pub fn scales(&self, roll_deg: f32, pitch_deg: f32, seed: u64) -> Mesh {
        let mut state = seed ^ 0x05CA_1E5E_DD1F_FAC7_u64;
        let mut next_unit = move || {
            // splitmix64 → uniform in [−1, 1)
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        };
        let roll = f64::from(roll_deg).to_radians();
        let pitch = f64::from(pitch_deg).to_radians();
        let mut out = Mesh {
            vertices: Vec::with_capacity(self.indices.len()),
            indices: Vec::with_capacity(self.indices.len()),
            name: format!(
                "{} (scales, roll ±{roll_deg}°, pitch ±{pitch_deg}°)",
                self.name
            ),
            repairs: self.repairs.clone(),
        };
        for facet in self.indices.chunks(6) {
            let corner = |i: &u32| self.vertices[*i as usize];
            let p = |i: &u32| v3(corner(i).position);
            let mut n = DVec3::ZERO;
            let mut t = DVec3::ZERO;
            for tri in facet.chunks_exact(3) {
                n += (p(&tri[1]) - p(&tri[0])).cross(p(&tri[2]) - p(&tri[0]));
            }
            for i in facet {
                let tg = corner(i).tangent;
                t += v3([tg[0], tg[1], tg[2]]);
            }
            let n = n.normalize_or(v3(corner(&facet[0]).normal));
            let t = (t - n * n.dot(t))
                .try_normalize()
                .unwrap_or_else(|| grating_direction(n.as_vec3()).as_dvec3());
            let (s, c) = (roll * next_unit()).sin_cos();
            let (n, t) = (n * c + t * s, t * c - n * s);
            // Pitch: rotate the normal towards the bitangent (about the tangent).
            let b = n.cross(t);
            let (s, c) = (pitch * next_unit()).sin_cos();
            let n = n * c + b * s;
            for i in facet {
                let mut v = corner(i);
                v.normal = f3(n);
                v.tangent = [t.x as f32, t.y as f32, t.z as f32, v.tangent[3]];
                out.indices.push(out.vertices.len() as u32);
                out.vertices.push(v);
            }
        }
        out
    }

    /// Applies an affine transform: positions by `m`, normals by its inverse transpose,
    /// tangents by its linear part. A mirroring transform (negative determinant) reverses
    /// the winding and flips the handedness so faces stay front-facing and frames stay valid.
    pub fn transform(&mut self, m: Mat4) {
        let lin = Mat3::from_mat4(m).as_dmat3();
        let det = lin.determinant();
        let normal_m = if det.abs() > 0.0 {
            lin.inverse().transpose()
        } else {
            lin
        };
        let m = m.as_dmat4();
        for v in &mut self.vertices {
            v.position = f3(m.transform_point3(v3(v.position)));
            let n = (normal_m * v3(v.normal)).normalize_or(DVec3::Z);
            let t = lin * v3([v.tangent[0], v.tangent[1], v.tangent[2]]);
            let t = (t - n * n.dot(t)).try_normalize();
            let t = match t {
                Some(t) => t,
                None => grating_direction(n.as_vec3()).as_dvec3(),
            };
            v.normal = f3(n);
            let w = if det < 0.0 {
                -v.tangent[3]
            } else {
                v.tangent[3]
            };
            v.tangent = [t.x as f32, t.y as f32, t.z as f32, w];
        }
        if det < 0.0 {
            for tri in self.indices.chunks_exact_mut(3) {
                tri.swap(1, 2);
            }
        }
    }
}

/// Checks an OBJ text line by line before tobj sees it, so that errors carry line numbers
/// and no index can reach tobj's unchecked arithmetic. Returns the number of triangles the
/// faces will make.
fn prescan_obj(text: &str, path: &Path) -> Result<usize> {
    let (mut nv, mut nvt, mut nvn) = (0usize, 0usize, 0usize);
    let mut triangles = 0usize;
    for (i, line) in text.lines().enumerate() {
        let ln = i + 1;
        let mut words = line.split_whitespace();
        let err = |msg: String| Error::parse(path, format!("line {ln}: {msg}"));
        let numbers = |what: &str, n: usize, words: std::str::SplitWhitespace| {
            let got: Vec<&str> = words.take(n).collect();
            if got.len() < n {
                return Err(err(format!(
                    "{what} needs {n} numbers, found {}",
                    got.len()
                )));
            }
            for w in got {
                match w.parse::<f32>() {
                    Ok(x) if x.is_finite() => {}
                    Ok(_) => return Err(err(format!("{what} is not finite (`{w}`)"))),
                    Err(_) => return Err(err(format!("{what}: `{w}` is not a number"))),
                }
            }
            Ok(())
        };
        match words.next() {
            Some("v") => {
                numbers("vertex position", 3, words)?;
                nv += 1;
            }
            Some("vt") => {
                numbers("texture coordinate", 2, words)?;
                nvt += 1;
            }
            Some("vn") => {
                numbers("normal", 3, words)?;
                nvn += 1;
            }
            Some("f") => {
                let mut corners = 0usize;
                for word in words {
                    corners += 1;
                    let parts: Vec<&str> = word.split('/').collect();
                    if parts.len() > 3 {
                        return Err(err(format!("face corner `{word}` has more than v/vt/vn")));
                    }
                    for (k, part) in parts.iter().enumerate() {
                        let (what, plural, count) = match k {
                            0 => ("vertex", "vertices", nv),
                            1 => ("texture coordinate", "texture coordinates", nvt),
                            _ => ("normal", "normals", nvn),
                        };
                        if part.is_empty() {
                            if k == 0 {
                                return Err(err(format!(
                                    "face corner `{word}` has no vertex index"
                                )));
                            }
                            continue;
                        }
                        let idx: i64 = part.parse().map_err(|_| {
                            err(format!("face corner `{word}`: `{part}` is not an index"))
                        })?;
                        let ok = if idx > 0 {
                            idx as u64 <= count as u64
                        } else {
                            idx != 0 && idx.unsigned_abs() <= count as u64
                        };
                        if !ok {
                            return Err(err(format!(
                                "face references {what} {idx}, but {count} {plural} are defined so far{}",
                                if idx == 0 { " (OBJ indices start at 1)" } else { "" }
                            )));
                        }
                    }
                }
                if corners >= 3 {
                    triangles += corners - 2;
                }
            }
            _ => {}
        }
    }
    Ok(triangles)
}

/// Largest extent (bounding-box diagonal) and distance from the origin of a mesh used as it
/// is, in scene units. The camera, the depth range and the shaders work in float32: a mesh
/// far beyond the scene's few units (coordinates of 1e30, a model in nanometres) loses its
/// shape in the view transform or overflows it.
pub const MAX_SCENE_EXTENT: f64 = 1e4;
/// Smallest extent of a mesh used as it is, in scene units (below it, float32 positions
/// carry too few digits for smooth normals and a stable depth test).
pub const MIN_SCENE_EXTENT: f64 = 1e-4;
/// Extent a mesh outside the range above is scaled to: the size of the built-in meshes,
/// which the default camera frames.
const FITTED_EXTENT: f64 = 2.0;

/// Recentres at the origin and rescales to [`FITTED_EXTENT`] a mesh whose extent or
/// distance from the origin lies outside what float32 scene units hold
/// ([`MAX_SCENE_EXTENT`], [`MIN_SCENE_EXTENT`]); returns the note for [`Mesh::repairs`].
/// Uniform scaling and translation keep the normals a file gives.
fn fit_to_scene_units(raw: &mut RawMesh, path: &Path) -> Option<String> {
    let used = raw.indices.iter().map(|&i| raw.positions[i as usize]);
    let (lo, hi) = used.fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(v3(p)), hi.max(v3(p))),
    );
    let extent = (hi - lo).length();
    let centre = 0.5 * (lo + hi);
    let inside = extent <= MAX_SCENE_EXTENT && centre.length() <= MAX_SCENE_EXTENT;
    if !extent.is_finite() || extent == 0.0 || (inside && extent >= MIN_SCENE_EXTENT) {
        return None;
    }
    let scale = FITTED_EXTENT / extent;
    for p in raw.positions.iter_mut() {
        *p = f3((v3(*p) - centre) * scale);
    }
    Some(format!(
        "{}: spans {extent:.3e} units around ({:.3e}, {:.3e}, {:.3e}), outside the scene's {MIN_SCENE_EXTENT:e} to {MAX_SCENE_EXTENT:e}; recentred at the origin and scaled by {scale:.3e} to {FITTED_EXTENT} units",
        path.display(),
        centre.x,
        centre.y,
        centre.z
    ))
}

/// A `(nu+1) × (nv+1)` vertex grid over `u, v ∈ [0,1]` (rows of constant `v`) with two
/// triangles per cell ordered so that `∂P/∂u × ∂P/∂v` is the front face; triangles whose
/// corners coincide (poles, pointed tips) are left out.
fn grid(nu: u32, nv: u32, f: impl Fn(f64, f64) -> (DVec3, Option<DVec3>)) -> RawMesh {
    let (nu, nv) = (nu as usize, nv as usize);
    let mut raw = RawMesh {
        positions: Vec::with_capacity((nu + 1) * (nv + 1)),
        normals: Vec::with_capacity((nu + 1) * (nv + 1)),
        uvs: Vec::with_capacity((nu + 1) * (nv + 1)),
        indices: Vec::with_capacity(nu * nv * 6),
    };
    for j in 0..=nv {
        for i in 0..=nu {
            let (u, v) = (i as f64 / nu as f64, j as f64 / nv as f64);
            let (p, n) = f(u, v);
            raw.positions.push(f3(p));
            raw.normals.push(n.map(f3));
            raw.uvs.push(Some([u as f32, v as f32]));
        }
    }
    let at = |i: usize, j: usize| (j * (nu + 1) + i) as u32;
    let push = |raw: &mut RawMesh, t: [u32; 3]| {
        let p = t.map(|k| raw.positions[k as usize]);
        if p[0] != p[1] && p[1] != p[2] && p[0] != p[2] {
            raw.indices.extend_from_slice(&t);
        }
    };
    for j in 0..nv {
        for i in 0..nu {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            push(&mut raw, [a, b, c]);
            push(&mut raw, [a, c, d]);
        }
    }
    raw
}

/// Finishes a generated shape. Generators produce valid geometry by construction, so a
/// failure here is a bug in this file, not a user error; it degrades to an empty mesh
/// rather than a panic and is caught by the unit tests.
fn build_generated(name: &str, raw: RawMesh) -> Mesh {
    let origin = format!("builtin:{name}");
    finish(name.to_string(), raw, Path::new(&origin)).unwrap_or_else(|e| {
        debug_assert!(false, "generator {name} is broken: {e}");
        Mesh {
            vertices: Vec::new(),
            indices: Vec::new(),
            name: name.to_string(),
            repairs: Vec::new(),
        }
    })
}

/// Validates raw geometry, drops zero-area triangles and unreferenced vertices, and fills in
/// normals and tangents (module docs). `origin` names the source in errors.
fn finish(name: String, raw: RawMesh, origin: &Path) -> Result<Mesh> {
    let err = |msg: String| Error::parse(origin, msg);
    let n = raw.positions.len();
    if raw.indices.len() < 3 {
        return Err(err("no triangles".into()));
    }
    if !raw.indices.len().is_multiple_of(3) {
        return Err(err(format!(
            "{} indices is not a whole number of triangles",
            raw.indices.len()
        )));
    }
    for (t, tri) in raw.indices.chunks_exact(3).enumerate() {
        for &i in tri {
            if i as usize >= n {
                return Err(err(format!(
                    "triangle {}: vertex index {i} out of range ({n} vertices)",
                    t + 1
                )));
            }
        }
    }
    for i in 0..n {
        let bad = |what: &str, vals: &[f32]| {
            Err(err(format!("vertex {}: non-finite {what} {vals:?}", i + 1)))
        };
        if !raw.positions[i].iter().all(|c| c.is_finite()) {
            return bad("position", &raw.positions[i]);
        }
        if let Some(nn) = raw.normals[i] {
            if !nn.iter().all(|c| c.is_finite()) {
                return bad("normal", &nn);
            }
        }
        if let Some(uv) = raw.uvs[i] {
            if !uv.iter().all(|c| c.is_finite()) {
                return bad("texture coordinate", &uv);
            }
        }
    }

    // Zero-area triangles carry no surface and would poison normals and tangents.
    let (lo, hi) = raw.positions.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(v3(*p)), hi.max(v3(*p))),
    );
    let diag2 = (hi - lo).length_squared();
    let total = raw.indices.len() / 3;
    let mut kept = Vec::with_capacity(raw.indices.len());
    for tri in raw.indices.chunks_exact(3) {
        let [a, b, c] = [0, 1, 2].map(|k| v3(raw.positions[tri[k] as usize]));
        let twice_area = (b - a).cross(c - a).length();
        if twice_area > 1e-12 * diag2 {
            kept.extend_from_slice(tri);
        }
    }
    if kept.is_empty() {
        return Err(err(format!(
            "all {total} triangles have zero area (degenerate mesh)"
        )));
    }
    let dropped = total - kept.len() / 3;
    let mut repairs = Vec::new();
    if dropped > 0 {
        repairs.push(format!(
            "{}: dropped {dropped} of {total} triangles with zero area",
            origin.display()
        ));
    }

    // Keep only referenced vertices, in their original order.
    let mut remap = vec![u32::MAX; n];
    for &i in &kept {
        remap[i as usize] = 0;
    }
    let mut order = Vec::new();
    for (i, r) in remap.iter_mut().enumerate() {
        if *r == 0 {
            *r = order.len() as u32;
            order.push(i);
        }
    }
    let indices: Vec<u32> = kept.iter().map(|&i| remap[i as usize]).collect();
    let positions: Vec<DVec3> = order.iter().map(|&i| v3(raw.positions[i])).collect();
    let given_normals: Vec<Option<[f32; 3]>> = order.iter().map(|&i| raw.normals[i]).collect();
    let uvs: Vec<Option<[f32; 2]>> = order.iter().map(|&i| raw.uvs[i]).collect();
    let nverts = positions.len();

    // Rounded to f32 before deriving tangents, so a mesh and its OBJ round trip (which
    // stores f32 normals) get bit-identical tangents.
    let (normals, replaced) = vertex_normals(&positions, &given_normals, &indices);
    if replaced > 0 {
        repairs.push(format!(
            "{}: {replaced} zero-length normal(s) replaced by smooth normals",
            origin.display()
        ));
    }
    let normals: Vec<DVec3> = normals.into_iter().map(|n| v3(f3(n))).collect();
    let tangents = vertex_tangents(&positions, &normals, &uvs, &indices);

    let vertices = (0..nverts)
        .map(|i| Vertex {
            position: f3(positions[i]),
            normal: f3(normals[i]),
            tangent: tangents[i],
            uv: uvs[i].unwrap_or([0.0, 0.0]),
        })
        .collect();
    Ok(Mesh {
        vertices,
        indices,
        name,
        repairs,
    })
}

/// Unit normals: the given ones where they are non-zero, else area-weighted smooth normals
/// averaged over every vertex at the same position (so UV seams do not show as creases).
/// Also returns how many given normals had zero length and were replaced.
fn vertex_normals(
    positions: &[DVec3],
    given: &[Option<[f32; 3]>],
    indices: &[u32],
) -> (Vec<DVec3>, usize) {
    let n = positions.len();
    let mut group_of = vec![0usize; n];
    let mut groups: HashMap<[u32; 3], usize> = HashMap::new();
    for (i, g) in group_of.iter_mut().enumerate() {
        let next = groups.len();
        *g = *groups.entry(position_key(f3(positions[i]))).or_insert(next);
    }
    let mut group_sum = vec![DVec3::ZERO; groups.len()];
    let mut vertex_sum = vec![DVec3::ZERO; n];
    let mut first_face = vec![DVec3::ZERO; n];
    for tri in indices.chunks_exact(3) {
        let [a, b, c] = [0, 1, 2].map(|k| positions[tri[k] as usize]);
        // |cross| = 2·area: the sum is area-weighted.
        let face = (b - a).cross(c - a);
        for &k in tri {
            let k = k as usize;
            group_sum[group_of[k]] += face;
            vertex_sum[k] += face;
            if first_face[k] == DVec3::ZERO {
                first_face[k] = face;
            }
        }
    }
    let mut replaced = 0usize;
    let normals = (0..n)
        .map(|i| {
            if let Some(g) = given[i] {
                if let Some(u) = v3(g).try_normalize() {
                    return u;
                }
                replaced += 1;
            }
            // Opposite faces at one position (a two-sided sheet) cancel: fall back to this
            // vertex's own faces, then to the first face it belongs to (never zero: every
            // remaining vertex is used by a triangle of non-zero area).
            group_sum[group_of[i]]
                .try_normalize()
                .or_else(|| vertex_sum[i].try_normalize())
                .or_else(|| first_face[i].try_normalize())
                .unwrap_or(DVec3::Z)
        })
        .collect();
    (normals, replaced)
}

/// Tangents `[x, y, z, w]` per vertex (module docs): area-weighted unit `∂P/∂u` and `∂P/∂v`
/// of the triangles around each vertex, Gram–Schmidt against the normal, handedness from the
/// accumulated `∂P/∂v`; the grating direction where UVs are missing or degenerate.
fn vertex_tangents(
    positions: &[DVec3],
    normals: &[DVec3],
    uvs: &[Option<[f32; 2]>],
    indices: &[u32],
) -> Vec<[f32; 4]> {
    let n = positions.len();
    let mut t_acc = vec![DVec3::ZERO; n];
    let mut b_acc = vec![DVec3::ZERO; n];
    for tri in indices.chunks_exact(3) {
        let k = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
        let (Some(uv0), Some(uv1), Some(uv2)) = (uvs[k[0]], uvs[k[1]], uvs[k[2]]) else {
            continue;
        };
        let e1 = positions[k[1]] - positions[k[0]];
        let e2 = positions[k[2]] - positions[k[0]];
        let (du1, dv1) = ((uv1[0] - uv0[0]) as f64, (uv1[1] - uv0[1]) as f64);
        let (du2, dv2) = ((uv2[0] - uv0[0]) as f64, (uv2[1] - uv0[1]) as f64);
        let det = du1 * dv2 - du2 * dv1;
        if det.abs() < 1e-20 {
            continue;
        }
        // Solving [e1 e2] = [∂P/∂u ∂P/∂v]·[[du1 du2],[dv1 dv2]] for the two derivatives.
        let dpdu = (e1 * dv2 - e2 * dv1) / det;
        let dpdv = (e2 * du1 - e1 * du2) / det;
        let area = 0.5 * e1.cross(e2).length();
        let (Some(tu), Some(tv)) = (dpdu.try_normalize(), dpdv.try_normalize()) else {
            continue;
        };
        for &i in &k {
            t_acc[i] += tu * area;
            b_acc[i] += tv * area;
        }
    }
    (0..n)
        .map(|i| {
            let nrm = normals[i];
            let t = t_acc[i] - nrm * nrm.dot(t_acc[i]);
            // Relative threshold: a tangent almost parallel to the normal is noise.
            if t.length() > 1e-6 * t_acc[i].length() && t.length() > 0.0 {
                let t = t.normalize();
                let w = if nrm.cross(t).dot(b_acc[i]) < 0.0 {
                    -1.0
                } else {
                    1.0
                };
                [t.x as f32, t.y as f32, t.z as f32, w]
            } else {
                let g = grating_direction(nrm.as_vec3());
                [g.x, g.y, g.z, 1.0]
            }
        })
        .collect()
}

/// Relative body radius along the snake (`s` = arc fraction, 0 at the tail tip, 1 at the
/// snout): zero at both tips.
fn snake_profile(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    // The tail tapers over the last 30% of the body: a level trunk keeps the skin's
    // bitangent horizontal, so a horizontal grating condition holds along it.
    let tail = (s / 0.3).min(1.0).powf(0.65);
    let neck = 1.0 - 0.12 * (-((s - 0.86) / 0.03).powi(2)).exp();
    // Circular snout: with d = (1 − s)/0.07, 1 − (1 − d)² = d(2 − d), exactly 0 at s = 1 so
    // the tip ring collapses to one point (a clean triangle fan).
    let d = ((1.0 - s) / 0.07).clamp(0.0, 1.0);
    let snout = (d * (2.0 - d)).sqrt();
    tail * neck * snout
}

/// The body of [`Mesh::scaly_snake`]: `point(s, a, k)` is the tube point at arc fraction `s`
/// (tail → head) and around-fraction `a`, `k` times the local radius from the centre line
/// (`k > 1` lies above the skin). `θ = −2πa`, so `∂P/∂s × ∂P/∂a` points outwards.
struct ScalyBody {
    curve: SnakeCurve,
    radius: f64,
}

impl ScalyBody {
    fn new(length: f64, radius: f64) -> Self {
        Self {
            curve: SnakeCurve::new(length),
            radius,
        }
    }

    fn point(&self, s: f64, a: f64, k: f64) -> DVec3 {
        let s = s.clamp(0.0, 1.0);
        let (c, tp) = self.curve.at_arc_fraction(s);
        let r = self.radius * snake_profile(s);
        let side = DVec3::Y.cross(tp);
        let (sn, co) = (-a * std::f64::consts::TAU).sin_cos();
        let height = 0.8 * r;
        // The belly rests on the ground at k = 1; scales above it grow outwards from the
        // centre of the cross-section.
        let centre = DVec3::new(c.x, height, c.z);
        centre + (side * (r * co) + DVec3::Y * (height * sn)) * k
    }
}

/// The snake's centre line in the `xz` plane, re-parametrised by arc length.
struct SnakeCurve {
    length: f64,
    /// Cumulative arc length at `TABLE` equal steps of the curve parameter.
    arc: Vec<f64>,
}

impl SnakeCurve {
    const TABLE: usize = 4096;

    fn new(length: f64) -> Self {
        let mut arc = Vec::with_capacity(Self::TABLE + 1);
        let mut total = 0.0;
        let mut prev = Self::point(length, 0.0);
        arc.push(0.0);
        for k in 1..=Self::TABLE {
            let p = Self::point(length, k as f64 / Self::TABLE as f64);
            total += (p - prev).length();
            arc.push(total);
            prev = p;
        }
        Self { length, arc }
    }

    /// The S curve at parameter `t ∈ [0,1]`: one sine period across `x`, amplitude 12 % of
    /// the length.
    fn point(length: f64, t: f64) -> DVec3 {
        let x = length * (t - 0.5);
        let z = 0.12 * length * (std::f64::consts::TAU * t).sin();
        DVec3::new(x, 0.0, z)
    }

    /// Centre point and unit horizontal direction at arc fraction `s ∈ [0,1]`.
    fn at_arc_fraction(&self, s: f64) -> (DVec3, DVec3) {
        let total = self.arc[Self::TABLE];
        let target = s.clamp(0.0, 1.0) * total;
        let k = self
            .arc
            .partition_point(|&a| a < target)
            .clamp(1, Self::TABLE);
        let (a0, a1) = (self.arc[k - 1], self.arc[k]);
        let frac = if a1 > a0 {
            (target - a0) / (a1 - a0)
        } else {
            0.0
        };
        let t = ((k - 1) as f64 + frac) / Self::TABLE as f64;
        let h = 1e-5;
        let d =
            Self::point(self.length, (t + h).min(1.0)) - Self::point(self.length, (t - h).max(0.0));
        (Self::point(self.length, t), d.normalize_or(DVec3::X))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp_dir(tag: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("diffract-mesh-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn repairs_are_listed_for_the_command_to_report() {
        // A zero-area triangle (1, 2, 4 are collinear) and a zero-length given normal.
        let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nvn 0 0 1\nvn 0 0 0\n\
                   f 1//1 2//2 3//1\nf 1//1 2//1 4//1\n";
        let m = Mesh::from_obj_str(obj, Path::new("bad.obj")).unwrap();
        assert_eq!(m.triangle_count(), 1);
        assert_eq!(m.repairs.len(), 2, "{:?}", m.repairs);
        assert!(m.repairs[0].contains("dropped 1 of 2 triangles with zero area"));
        assert!(m.repairs[1].contains("1 zero-length normal(s) replaced"));
        assert!(Mesh::builtin("snake").unwrap().repairs.is_empty());
    }

    fn check_frames(m: &Mesh) {
        assert!(!m.indices.is_empty());
        for v in &m.vertices {
            let n = Vec3::from(v.normal);
            let t = Vec3::new(v.tangent[0], v.tangent[1], v.tangent[2]);
            assert!((n.length() - 1.0).abs() < 1e-5, "{v:?}");
            assert!((t.length() - 1.0).abs() < 1e-5, "{v:?}");
            assert!(n.dot(t).abs() < 1e-5, "{v:?}");
            assert!(v.tangent[3] == 1.0 || v.tangent[3] == -1.0);
        }
        for tri in m.indices.chunks_exact(3) {
            let p = [0, 1, 2].map(|k| Vec3::from(m.vertices[tri[k] as usize].position));
            let face = (p[1] - p[0]).cross(p[2] - p[0]);
            let avg: Vec3 = tri
                .iter()
                .map(|&i| Vec3::from(m.vertices[i as usize].normal))
                .sum();
            assert!(
                face.dot(avg) > 0.0,
                "triangle {tri:?} winds against its normals"
            );
        }
    }

    #[test]
    fn vertex_layout_is_48_bytes() {
        assert_eq!(std::mem::size_of::<Vertex>(), 48);
        assert_eq!(std::mem::offset_of!(Vertex, normal), 12);
        assert_eq!(std::mem::offset_of!(Vertex, tangent), 24);
        assert_eq!(std::mem::offset_of!(Vertex, uv), 40);
    }

    #[test]
    fn plane_faces_z_with_tangent_x() {
        let m = Mesh::plane(2.0, 4);
        check_frames(&m);
        assert_eq!(m.vertices.len(), 25);
        assert_eq!(m.triangle_count(), 32);
        for v in &m.vertices {
            assert_eq!(v.normal, [0.0, 0.0, 1.0]);
            assert!(
                (Vec3::new(v.tangent[0], v.tangent[1], v.tangent[2]) - Vec3::X).length() < 1e-6
            );
            assert_eq!(v.tangent[3], 1.0);
            assert!((v.uv[0] - (v.position[0] / 2.0 + 0.5)).abs() < 1e-6);
            assert!((v.uv[1] - (v.position[1] / 2.0 + 0.5)).abs() < 1e-6);
        }
        assert_eq!(m.bounds(), ([-1.0, -1.0, 0.0], [1.0, 1.0, 0.0]));
    }

    #[test]
    fn sphere_normals_are_radial_and_tangents_point_east() {
        let m = Mesh::sphere(2.0, 32, 16);
        check_frames(&m);
        for v in &m.vertices {
            let p = Vec3::from(v.position);
            assert!((p.length() - 2.0).abs() < 1e-5);
            assert!((p / 2.0 - Vec3::from(v.normal)).length() < 1e-5);
            let t = Vec3::new(v.tangent[0], v.tangent[1], v.tangent[2]);
            let horizontal = (p.x * p.x + p.z * p.z).sqrt();
            if horizontal > 0.5 {
                // East = ∂P/∂φ ∝ (−sin φ, 0, cos φ).
                let east = Vec3::new(-p.z, 0.0, p.x).normalize();
                assert!(t.dot(east) > 0.98, "{v:?}");
                assert_eq!(v.tangent[3], 1.0);
            }
        }
    }

    #[test]
    fn snake_lies_on_the_ground_with_tangent_around_the_body() {
        let m = Mesh::snake(2.0, 0.08, 100, 24);
        check_frames(&m);
        let (lo, hi) = m.bounds();
        assert!(lo[1].abs() < 1e-6, "belly must touch y = 0: {lo:?}");
        assert!(hi[1] > 0.1 && hi[1] < 0.14, "{hi:?}");
        assert!(hi[0] - lo[0] > 1.8 && hi[0] - lo[0] < 2.2);
        assert!(hi[2] - lo[2] > 0.4, "S curve spans z: {lo:?} {hi:?}");
        // The tangent circles the body: it is (nearly) perpendicular to the body axis, which
        // for the mid-body vertices is ∂P/∂v. Check against the neighbour one ring ahead.
        let row = 25;
        let mut checked = 0;
        for j in 20..80 {
            for i in 0..24 {
                let a = &m.vertices[j * row + i];
                let b = &m.vertices[(j + 1) * row + i];
                let axis = (Vec3::from(b.position) - Vec3::from(a.position)).normalize();
                let t = Vec3::new(a.tangent[0], a.tangent[1], a.tangent[2]);
                assert!(t.dot(axis).abs() < 0.2, "ring {j}, {i}: {t} vs axis {axis}");
                assert_eq!(a.tangent[3], 1.0);
                checked += 1;
            }
        }
        assert!(checked > 1000);
    }

    #[test]
    fn scaly_snake_resolution_follows_the_quads_per_scale() {
        let counts: Vec<(usize, usize)> = [1, 2, 6, 12]
            .iter()
            .map(|&q| {
                let m = Mesh::scaly_snake_with(2.0, 0.08, 64, 18, q);
                (m.vertices.len(), m.indices.len() / 3)
            })
            .collect();
        println!("scaly-snake vertices, triangles at 1, 2, 6, 12 quads a scale side: {counts:?}");
        assert_eq!(
            Mesh::scaly_snake_with(2.0, 0.08, 64, 18, 6).vertices.len(),
            Mesh::builtin("scaly-snake").unwrap().vertices.len()
        );
        assert!(counts
            .windows(2)
            .all(|w| w[0].0 < w[1].0 && w[0].1 < w[1].1));
    }

    #[test]
    fn scaly_snake_has_domed_scales_with_tangents_along_the_body() {
        let m = Mesh::builtin("scaly-snake").unwrap();
        check_frames(&m);
        let curve = SnakeCurve::new(2.0);
        let mid = |v: &Vertex| (0.08..=0.9).contains(&v.uv[0]);
        let (mut along, mut tilt, mut n_mid) = (0.0f64, Vec::new(), 0usize);
        for v in m.vertices.iter().filter(|v| mid(v)) {
            let s = f64::from(v.uv[0]);
            let (c, axis) = curve.at_arc_fraction(s);
            let centre = DVec3::new(c.x, 0.8 * 0.08 * snake_profile(s), c.z);
            let n = v3(v.normal);
            let radial = (v3(v.position) - centre).normalize();
            assert!(n.dot(radial) > 0.5, "normal points into the body: {v:?}");
            let t = v3([v.tangent[0], v.tangent[1], v.tangent[2]]);
            assert!(t.dot(axis) > 0.6, "tangent not along the body: {v:?}");
            along += t.dot(axis);
            tilt.push(n.dot(radial).clamp(-1.0, 1.0).acos().to_degrees());
            n_mid += 1;
        }
        assert!(n_mid > 10_000, "{n_mid}");
        // Mean |cos| between T and the body axis: the domes tilt T by up to ~20°.
        assert!(along / n_mid as f64 > 0.95, "{}", along / n_mid as f64);
        // Domed, not flat: a tube's normal leaves the radial direction by at most ~7° (its
        // 1 : 0.8 ellipse); the scales' domes tilt a good share of normals beyond 12°.
        tilt.sort_by(f64::total_cmp);
        let p90 = tilt[tilt.len() * 9 / 10];
        assert!(p90 > 12.0 && tilt[tilt.len() - 1] < 45.0, "p90 {p90}");
        // Smooth within a scale: on the trunk, corners of one triangle typically differ by a
        // few degrees (6×6 quads a scale tilting ±25°: ~8° a quad); the
        // largest changes are at a scale's free tail edge, where dome, lift and taper meet.
        let mut worst = 0.0f64;
        let mut changes = Vec::new();
        for tri in m.indices.chunks_exact(3) {
            let vs = [0, 1, 2].map(|k| m.vertices[tri[k] as usize]);
            if vs.iter().all(|v| (0.3..=0.85).contains(&v.uv[0])) {
                for (a, b) in [(0, 1), (1, 2), (0, 2)] {
                    let d = v3(vs[a].normal).dot(v3(vs[b].normal)).clamp(-1.0, 1.0);
                    worst = worst.max(d.acos().to_degrees());
                    changes.push(d.acos().to_degrees());
                }
            }
        }
        changes.sort_by(f64::total_cmp);
        let median = changes[changes.len() / 2];
        println!(
            "normal change across a triangle: median {median:.1}°, max {worst:.1}°; p90 tilt {p90:.1}°"
        );
        assert!(median < 10.0 && worst < 35.0, "{median} {worst}");
    }

    #[test]
    fn missing_uvs_give_the_grating_direction() {
        assert!((grating_direction(Vec3::Y) - Vec3::X).length() < 1e-6);
        assert!((grating_direction(Vec3::X) - Vec3::Y).length() < 1e-6);
        let n = Vec3::new(1.0, 1.0, 0.0).normalize();
        let t = grating_direction(n);
        assert!(t.dot(n).abs() < 1e-6 && t.x > 0.0);
    }

    #[test]
    fn transform_keeps_frames_and_winding() {
        let mut m = Mesh::sphere(1.0, 12, 6);
        let mirror = Mat4::from_scale(Vec3::new(-2.0, 1.0, 1.0))
            * Mat4::from_rotation_y(0.3)
            * Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0));
        m.transform(mirror);
        check_frames(&m);
    }

    #[test]
    fn obj_round_trip_keeps_every_vertex() {
        let d = tmp_dir("roundtrip");
        for m in [
            Mesh::plane(1.5, 3),
            Mesh::sphere(0.7, 10, 5),
            Mesh::snake(1.0, 0.05, 20, 8),
        ] {
            let p = d.join(format!("{}.obj", m.name));
            m.write_obj(&p).unwrap();
            let back = Mesh::load_obj(&p).unwrap();
            assert_eq!(back.triangle_count(), m.triangle_count());
            for (ta, tb) in m.indices.chunks_exact(3).zip(back.indices.chunks_exact(3)) {
                for k in 0..3 {
                    let (a, b) = (m.vertices[ta[k] as usize], back.vertices[tb[k] as usize]);
                    // Positions and UVs are exact; the loader re-normalises directions,
                    // which may move them by an ulp.
                    assert_eq!(
                        (a.position, a.uv, a.tangent[3]),
                        (b.position, b.uv, b.tangent[3])
                    );
                    let close =
                        |x: [f32; 3], y: [f32; 3]| (0..3).all(|i| (x[i] - y[i]).abs() <= 1e-6);
                    assert!(close(a.normal, b.normal), "{a:?} vs {b:?}");
                    assert!(
                        close(
                            [a.tangent[0], a.tangent[1], a.tangent[2]],
                            [b.tangent[0], b.tangent[1], b.tangent[2]]
                        ),
                        "{a:?} vs {b:?}"
                    );
                }
            }
        }
        let _ = std::fs::remove_dir_all(d);
    }
}
