//! Meshes, scene files and image output: no GPU needed, all fast.
//!
//! `DIFFRACT_UPDATE_ASSETS=1 cargo test --release --test mesh_scene shipped_meshes` rewrites
//! the shipped `assets/{snake,sphere,plane}.obj` from the generators before comparing.

use std::path::{Path, PathBuf};

use diffract::image_io;
use diffract::mesh::{Mesh, Vertex};
use diffract::scene::{Scene, DEFAULT_SCENE_TOML};
use diffract::Error;
use glam::{Vec3, Vec4Swizzles};

fn asset(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("assets")
        .join(name)
}

fn tmp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-ms-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn obj(text: &str) -> diffract::Result<Mesh> {
    Mesh::from_obj_str(text, Path::new("test.obj"))
}

fn err_text(r: diffract::Result<impl std::fmt::Debug>) -> String {
    match r {
        Ok(v) => panic!("expected an error, got {v:?}"),
        Err(e) => e.to_string(),
    }
}

fn close(a: &Vertex, b: &Vertex, tol: f32) -> bool {
    let pairs = a
        .position
        .iter()
        .zip(&b.position)
        .chain(a.normal.iter().zip(&b.normal))
        .chain(a.tangent.iter().zip(&b.tangent))
        .chain(a.uv.iter().zip(&b.uv));
    pairs.into_iter().all(|(x, y)| (x - y).abs() <= tol)
}

/// Built-in meshes shipped as `assets/<name>.obj`; `scaly-snake` (83k triangles, ~6 MB of
/// OBJ) is only generated.
const SHIPPED: [&str; 3] = ["snake", "sphere", "plane"];

#[test]
fn shipped_meshes_match_the_generators() {
    if std::env::var("DIFFRACT_UPDATE_ASSETS").is_ok_and(|v| v == "1") {
        for name in SHIPPED {
            let m = Mesh::builtin(name).unwrap();
            m.write_obj(&asset(&format!("{name}.obj"))).unwrap();
        }
    }
    for name in SHIPPED {
        let generated = Mesh::builtin(name).unwrap();
        let loaded = Mesh::load_obj(&asset(&format!("{name}.obj")))
            .unwrap_or_else(|e| panic!("{name}: {e} (regenerate: see the file docs)"));
        assert_eq!(
            loaded.triangle_count(),
            generated.triangle_count(),
            "{name}"
        );
        // tobj renumbers vertices by first use, so compare triangle corners.
        for (ta, tb) in generated
            .indices
            .chunks_exact(3)
            .zip(loaded.indices.chunks_exact(3))
        {
            for k in 0..3 {
                let (a, b) = (
                    &generated.vertices[ta[k] as usize],
                    &loaded.vertices[tb[k] as usize],
                );
                assert!(close(a, b, 1e-5), "{name} is stale: {a:?} vs {b:?}");
            }
        }
    }
    assert!(Mesh::builtin("teapot").is_none());
}

#[test]
fn smooth_normals_and_grating_tangents_without_normals_or_uvs() {
    // An octahedron (no vn/vt): every corner sits in four equal faces, so its area-weighted
    // normal is radial; tangents follow the grating direction (world x projected, world y at
    // the ±x corners).
    let text = "\
v 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1
f 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n";
    let m = obj(text).unwrap();
    assert_eq!(m.vertices.len(), 6);
    assert_eq!(m.triangle_count(), 8);
    for v in &m.vertices {
        let p = Vec3::from(v.position);
        let n = Vec3::from(v.normal);
        assert!((p - n).length() < 1e-6, "corner normal {n} at {p}");
        let t = Vec3::new(v.tangent[0], v.tangent[1], v.tangent[2]);
        let want = if n.x.abs() > 0.5 {
            Vec3::Y
        } else {
            (Vec3::X - n * n.x).normalize()
        };
        assert!((t - want).length() < 1e-6, "{t} vs {want}");
        assert_eq!(v.tangent[3], 1.0);
        assert_eq!(v.uv, [0.0, 0.0]);
    }
    // A cube of quads: triangulated, normals point outwards, faces wind outwards.
    let text = "\
v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1
f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 4 8 7 3\nf 1 5 8 4\nf 2 3 7 6\n";
    let m = obj(text).unwrap();
    assert_eq!(m.vertices.len(), 8);
    assert_eq!(m.triangle_count(), 12);
    for v in &m.vertices {
        assert!(Vec3::from(v.normal).dot(Vec3::from(v.position)) > 1.0);
    }
    for tri in m.indices.chunks_exact(3) {
        let p = [0, 1, 2].map(|k| Vec3::from(m.vertices[tri[k] as usize].position));
        let c = (p[0] + p[1] + p[2]) / 3.0;
        assert!((p[1] - p[0]).cross(p[2] - p[0]).dot(c) > 0.0);
    }
}

#[test]
fn uv_tangents_follow_du_and_handedness_follows_dv() {
    // Same square twice: v up (right-handed) and v mirrored (left-handed).
    let text = "\
v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 1 -1\nvt 0 -1
vn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\no mirrored\nf 1/1/1 2/2/1 3/5/1 4/6/1\n";
    let m = obj(text).unwrap();
    assert_eq!(m.triangle_count(), 4);
    assert_eq!(m.vertices.len(), 8);
    for (i, v) in m.vertices.iter().enumerate() {
        assert_eq!(v.normal, [0.0, 0.0, 1.0]);
        let t = Vec3::new(v.tangent[0], v.tangent[1], v.tangent[2]);
        assert!((t - Vec3::X).length() < 1e-6, "{v:?}");
        // Objects are merged in file order: the last four vertices are the mirrored square.
        let mirrored = i >= 4;
        assert_eq!(v.tangent[3], if mirrored { -1.0 } else { 1.0 }, "{v:?}");
    }
}

#[test]
fn several_objects_are_merged_and_negative_indices_work() {
    let text =
        "o a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\no b\nv 0 0 1\nv 1 0 1\nv 0 1 1\nf 4 5 6\n";
    let m = obj(text).unwrap();
    assert_eq!(m.triangle_count(), 2);
    assert_eq!(m.vertices.len(), 6);
    let (lo, hi) = m.bounds();
    assert_eq!((lo, hi), ([0.0; 3], [1.0; 3]));
}

#[test]
fn zero_area_triangles_are_dropped_if_others_remain() {
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\nf 1 1 3\n";
    let m = obj(text).unwrap();
    assert_eq!(m.triangle_count(), 1);
    // The vertex used only by dropped triangles is gone.
    assert_eq!(m.vertices.len(), 3);
    let e = err_text(obj("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 3 2 1\n"));
    assert!(e.contains("test.obj") && e.contains("zero area"), "{e}");
}

#[test]
fn bad_obj_files_are_clear_errors_not_panics() {
    let cases: &[(&str, &str)] = &[
        ("", "no triangles"),
        ("# only a comment\nv 0 0 0\n", "no triangles"),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n",
            "line 4: face references vertex 99, but 3 vertices",
        ),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "start at 1"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n", "line 4"),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/-99999999999999999 2/1 3/1\n",
            "texture coordinate",
        ),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//7 2//7 3//7\n", "normal 7"),
        (
            "v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            "line 1: vertex position is not finite",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 inf\nf 1//1 2//1 3//1\n",
            "normal is not finite",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 1e39\nf 1/1 2/1 3/1\n",
            "texture coordinate is not finite",
        ),
        (
            "v 0 zero 0\n",
            "line 1: vertex position: `zero` is not a number",
        ),
        ("v 0 0\n", "needs 3 numbers"),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n",
            "more than v/vt/vn",
        ),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf a b c\n", "not an index"),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2 3\n",
            "only some face corners have normals",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2 3\n",
            "only some face corners have texture",
        ),
        (
            "v 1 0 0 1e-45\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            "non-finite position",
        ),
    ];
    for (text, want) in cases {
        let e = err_text(obj(text));
        assert!(e.starts_with("test.obj: "), "{e}");
        assert!(e.contains(want), "for {text:?}: got `{e}`, wanted `{want}`");
        assert!(!e.contains('\n'), "one line: {e}");
    }
}

#[test]
fn unreadable_and_binary_files_are_errors() {
    let d = tmp_dir("objfiles");
    let missing = d.join("missing.obj");
    assert!(matches!(Mesh::load_obj(&missing), Err(Error::Io { .. })));
    assert!(Mesh::load_obj(&d).is_err(), "a directory");
    let garbage = d.join("garbage.obj");
    std::fs::write(&garbage, [0xff, 0xfe, 0x00, 0x13, 0x37, 0x80, 0x81]).unwrap();
    let e = err_text(Mesh::load_obj(&garbage));
    assert!(e.contains("garbage.obj") && e.contains("UTF-8"), "{e}");
    let empty = d.join("empty.obj");
    std::fs::write(&empty, b"").unwrap();
    assert!(err_text(Mesh::load_obj(&empty)).contains("no triangles"));
    let _ = std::fs::remove_dir_all(d);
}

/// Seeded token soup of OBJ-like lines: nothing may panic, whatever comes back.
#[test]
fn fuzzed_obj_text_never_panics() {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let numbers = [
        "0", "1", "-1", "0.5", "2", "1e38", "-1e38", "nan", "inf", "x", "",
    ];
    let corners = [
        "1",
        "2",
        "3",
        "4",
        "-1",
        "-2",
        "1/1",
        "2/2",
        "3/3",
        "1//1",
        "2//1",
        "3//1",
        "1/1/1",
        "0",
        "99",
        "1/",
        "/1",
        "//",
        "9999999999999999999",
        "-9223372036854775808",
        "1/2/3/4",
    ];
    let other = [
        "o a",
        "g",
        "usemtl m",
        "mtllib none.mtl",
        "s 1",
        "# c",
        "l 1 2",
        "p 1",
        "x y",
    ];
    let mut ok = 0;
    for _ in 0..20000 {
        let mut text = String::new();
        for _ in 0..(next() % 14) {
            let (head, count, pool): (&str, u64, &[&str]) = match next() % 8 {
                0..=2 => ("v", 3, &numbers[..if next() % 4 == 0 { 11 } else { 5 }]),
                3 => ("vt", 2, &numbers[..if next() % 4 == 0 { 11 } else { 5 }]),
                4 => ("vn", 3, &numbers[..if next() % 4 == 0 { 11 } else { 5 }]),
                5 | 6 => (
                    "f",
                    3 + next() % 3,
                    &corners[..if next() % 4 == 0 { 21 } else { 6 }],
                ),
                _ => (other[(next() % other.len() as u64) as usize], 0, &[]),
            };
            text.push_str(head);
            // Now and then a line has the wrong number of words.
            let count = if next() % 10 == 0 { next() % 6 } else { count };
            for _ in 0..count.min(if pool.is_empty() { 0 } else { 6 }) {
                text.push(' ');
                text.push_str(pool[(next() % pool.len() as u64) as usize]);
            }
            text.push('\n');
        }
        if let Ok(m) = obj(&text) {
            ok += 1;
            assert!(m.indices.iter().all(|&i| (i as usize) < m.vertices.len()));
            assert!(m.vertices.iter().all(|v| v
                .normal
                .iter()
                .chain(&v.tangent)
                .all(|c| c.is_finite())));
        }
    }
    // The soup must sometimes be valid, or the test exercises nothing past the prescan.
    assert!(ok > 0);
}

// ---------------------------------------------------------------------------------------
// Scenes

fn scene(text: &str) -> diffract::Result<Scene> {
    Scene::from_toml_str(text, Path::new("/scenes/s.toml"))
}

/// The first default scene, kept as a named example (and the goldens' scene).
fn flat_scales() -> Scene {
    Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/examples/flat_scales.toml"))
        .expect("assets/examples/flat_scales.toml")
}

#[test]
fn default_scene_file_is_valid_and_complete() {
    let s = Scene::default_scene();
    assert_eq!(s.mesh.builtin.as_deref(), Some("scaly-snake"));
    assert_eq!(s.material.heightfield, "builtin:elaphe-grown");
    assert_eq!((s.output.width, s.output.height), (512, 512));
    assert_eq!(Scene::default(), s);
    // Every section is spelt out in the file (it documents the format).
    for section in [
        "[camera]",
        "[light]",
        "[mesh]",
        "[material]",
        "[output]",
        "[texture]",
    ] {
        assert!(DEFAULT_SCENE_TOML.contains(section), "{section}");
    }
}

#[test]
fn flat_scales_camera_frames_the_trunk() {
    let s = flat_scales();
    let mesh = s.mesh.load().unwrap();
    let vp = s.camera.view_proj(s.output.aspect());
    let ndc = |p: [f32; 3]| {
        let c = vp * Vec3::from(p).extend(1.0);
        assert!(c.w > 0.0);
        c.xyz() / c.w
    };
    // The level trunk (middle of the body) is fully in view, inside the depth range.
    let mut trunk = 0;
    for v in &mesh.vertices {
        if (v.position[0] - 0.15).abs() < 0.6 {
            let p = ndc(v.position);
            assert!(p.x.abs() < 1.0 && p.y.abs() < 0.95, "{p} outside the frame");
            assert!(p.z > 0.0 && p.z < 1.0);
            trunk += 1;
        }
    }
    assert!(trunk > 1000, "{trunk}");
    // ... and the body spans the width of the frame.
    let (lo, hi) = mesh.bounds();
    assert!(ndc([lo[0], 0.0, 0.0]).x < -0.9 && ndc([hi[0], 0.0, 0.0]).x > 0.9);
}

/// The flat-scales example's light, camera and scales must put a good share of the visible, lit skin
/// scales into first-order diffraction of the Elaphe grating (period ≈ 1.14 µm): |v| inside
/// the coherence lobe and |u| between λ/d for 380 and 780 nm (u, v = −(ωi + ωr)·(T, B) in
/// the tangent frame, MODEL §1).
#[test]
fn flat_scales_scene_shows_first_order_colours() {
    let s = flat_scales();
    let mesh = s.mesh.load().unwrap();
    let wi = s.light.towards_light();
    let (period, mut visible, mut coloured) = (1.144f32, 0, 0);
    for v in &mesh.vertices {
        let n = Vec3::from(v.normal);
        let wr = (s.camera.eye() - Vec3::from(v.position)).normalize();
        if n.dot(wi) <= 0.05 || n.dot(wr) <= 0.05 {
            continue;
        }
        visible += 1;
        let t = Vec3::new(v.tangent[0], v.tangent[1], v.tangent[2]);
        let b = n.cross(t) * v.tangent[3];
        let (u, vv) = (-(wi + wr).dot(t), -(wi + wr).dot(b));
        if vv.abs() < 0.01 && u.abs() > 0.38 / period && u.abs() < 0.78 / period {
            coloured += 1;
        }
    }
    println!("{coloured} of {visible} lit scale corners diffract");
    assert!(visible > 3000, "{visible}");
    assert!(
        coloured * 20 > visible,
        "{coloured} of {visible} lit scale corners diffract"
    );
}

#[test]
fn full_scene_with_relative_paths() {
    let text = r#"
[camera]
eye = [0, 0, 4]
target = [0, 0, 0]
fov_y_deg = 50

[light]
direction = [0, 0, -1]
intensity = 2.5

[mesh]
path = "models/thing.obj"
translate = [1, 2, 3]
rotate_deg = [0, 90, 0]
scale = 2

[material]
heightfield = "hf/elaphe.png"
dh_um = 0.05
terms = 12
expansion = "chebyshev"

[output]
width = 64
height = 32
exposure = 0.5

[texture]
path = "skin.png"
"#;
    let s = scene(text).unwrap();
    assert_eq!(
        s.mesh.path.as_deref(),
        Some(Path::new("/scenes/models/thing.obj"))
    );
    assert_eq!(s.material.heightfield, "/scenes/hf/elaphe.png");
    let t = s.texture.as_ref().unwrap();
    assert_eq!(t.path, Path::new("/scenes/skin.png"));
    assert_eq!(t.w_diffuse, 0.3);
    assert_eq!(s.output.aspect(), 2.0);
    assert_eq!(s.light.towards_light(), Vec3::Z);
    assert_eq!(
        s.camera.near,
        diffract::scene::Camera::default().near,
        "unspecified keys keep their defaults"
    );
    // Model matrix: scale 2, then 90° about y (x → −z), then translate.
    let p = s.model_matrix().transform_point3(Vec3::X);
    assert!((p - Vec3::new(1.0, 2.0, 1.0)).length() < 1e-5, "{p}");
    // Absolute paths stay as they are.
    let s = scene("[mesh]\npath = \"/abs/m.obj\"\n[material]\nheightfield = \"builtin:blazed\"")
        .unwrap();
    assert_eq!(s.mesh.path.as_deref(), Some(Path::new("/abs/m.obj")));
    assert_eq!(s.material.heightfield, "builtin:blazed");
}

#[test]
fn mesh_spec_load_applies_the_transform() {
    let s = scene("[mesh]\nbuiltin = \"sphere\"\ntranslate = [0, 5, 0]\nscale = 0.5\nrotate_deg = [30, 40, 50]").unwrap();
    let m = s.mesh.load().unwrap();
    let (lo, hi) = m.bounds();
    assert!(
        (lo[1] - 4.5).abs() < 2e-3 && (hi[1] - 5.5).abs() < 2e-3,
        "{lo:?} {hi:?}"
    );
    for v in &m.vertices {
        let radial = (Vec3::from(v.position) - Vec3::new(0.0, 5.0, 0.0)) * 2.0;
        assert!((radial - Vec3::from(v.normal)).length() < 1e-4);
        let t = Vec3::new(v.tangent[0], v.tangent[1], v.tangent[2]);
        assert!(t.dot(Vec3::from(v.normal)).abs() < 1e-5);
    }
    // A snake turned 90° about y lies along z.
    let s = scene("[mesh]\nbuiltin = \"snake\"\nrotate_deg = [0, 90, 0]").unwrap();
    let (lo, hi) = s.mesh.load().unwrap().bounds();
    assert!(hi[2] - lo[2] > 1.8 && hi[0] - lo[0] < 0.8, "{lo:?} {hi:?}");
    // The OBJ route reports missing files with their resolved path.
    let s = scene("[mesh]\npath = \"nowhere.obj\"").unwrap();
    let e = err_text(s.mesh.load());
    assert!(e.contains("/scenes/nowhere.obj"), "{e}");
}

#[test]
fn scene_errors_are_clear() {
    let cases: &[(&str, &[&str])] = &[
        (
            "[camera]\nfov = 30\n",
            &["/scenes/s.toml", "line 2", "unknown field `fov`"],
        ),
        (
            "[camera]\neye = [0, 0, 1]\n[cameras]\n",
            &["line 3", "unknown field `cameras`"],
        ),
        (
            "\n\n[output]\nwidth = \"big\"\n",
            &["line 4", "invalid type"],
        ),
        ("[output]\nwidth = -3\n", &["line 2"]),
        ("[output]\nwidth = 0\n", &["[output] width = 0", "1..=8192"]),
        ("[output]\nheight = 9000\n", &["height = 9000"]),
        ("[output]\nexposure = 0\n", &["exposure"]),
        ("[output]\nexposure = -1\n", &["exposure"]),
        ("[output]\nbackground = [0, -1, 0]\n", &["background"]),
        ("[camera]\nfov_y_deg = 0\n", &["fov_y_deg"]),
        ("[camera]\nfov_y_deg = 180\n", &["fov_y_deg"]),
        ("[camera]\nfov_y_deg = nan\n", &["fov_y_deg"]),
        ("[camera]\nnear = 0\n", &["near"]),
        ("[camera]\nnear = 2\nfar = 1\n", &["far"]),
        (
            "[camera]\neye = [1, 2, 3]\ntarget = [1, 2, 3]\n",
            &["same point"],
        ),
        (
            "[camera]\neye = [0, 5, 0]\ntarget = [0, 0, 0]\n",
            &["parallel"],
        ),
        ("[camera]\nup = [0, 0, 0]\n", &["zero vector"]),
        ("[camera]\neye = [inf, 0, 0]\n", &["eye", "finite"]),
        (
            "[light]\ndirection = [0, 0, 0]\n",
            &["[light] direction", "zero"],
        ),
        ("[light]\nintensity = -1\n", &["intensity"]),
        ("[mesh]\nscale = 0\nbuiltin = \"plane\"\n", &["scale"]),
        ("[mesh]\nscale = 1\n", &["path", "builtin"]),
        (
            "[mesh]\nbuiltin = \"cube\"\n",
            &["cube", "snake, sphere, plane"],
        ),
        (
            "[mesh]\nbuiltin = \"plane\"\npath = \"a.obj\"\n",
            &["not both"],
        ),
        (
            "[mesh]\nbuiltin = \"plane\"\ntranslate = [0, 1]\n",
            &["line 3"],
        ),
        ("[material]\nterms = 100\n", &["[material]", "terms"]),
        (
            "[material]\nlambda_step_nm = 3\n",
            &["[material]", "wavelength step"],
        ),
        (
            "[material]\ncolour = 1\n",
            &["line 2", "unknown field `colour`"],
        ),
        ("[texture]\nw_diffuse = 0.5\n", &["missing field `path`"]),
        (
            "[texture]\npath = \"t.png\"\nw_diffuse = 2\n",
            &["w_diffuse"],
        ),
        ("this is not toml", &["line 1"]),
    ];
    for (text, wants) in cases {
        let e = err_text(scene(text));
        assert!(!e.contains('\n'), "one line: {e}");
        for w in *wants {
            assert!(e.contains(w), "for {text:?}: `{e}` lacks `{w}`");
        }
    }
    let d = tmp_dir("scenefile");
    assert!(matches!(
        Scene::load(&d.join("none.toml")),
        Err(Error::Io { .. })
    ));
    let f = d.join("ok.toml");
    std::fs::write(&f, "[mesh]\nbuiltin = \"plane\"\n").unwrap();
    assert_eq!(
        Scene::load(&f).unwrap().mesh.builtin.as_deref(),
        Some("plane")
    );
    let _ = std::fs::remove_dir_all(d);
}

// ---------------------------------------------------------------------------------------
// Image output

#[test]
fn write_image_picks_the_format_by_extension() {
    let d = tmp_dir("images");
    let px: Vec<[f32; 3]> = (0..12).map(|i| [i as f32 / 12.0, 0.25, 2.0]).collect();
    image_io::write_image(&d.join("a.EXR"), 4, 3, &px, 0.5, "test radiance").unwrap();
    assert_eq!(
        image_io::exr_units(&d.join("a.EXR")).unwrap().as_deref(),
        Some("test radiance, × exposure 0.5"),
        "an EXR says what its numbers are"
    );
    let (w, h, back) = image_io::read_exr(&d.join("a.EXR")).unwrap();
    assert_eq!((w, h), (4, 3));
    for (a, b) in px.iter().zip(&back) {
        assert_eq!(a.map(|c| c * 0.5), *b, "EXR is linear and exposed");
    }
    image_io::write_image(&d.join("a.png"), 4, 3, &px, 1.0, "").unwrap();
    let (w, h, back) = image_io::read_png_rgb8(&d.join("a.png")).unwrap();
    assert_eq!((w, h), (4, 3));
    assert_eq!(back[0], [0, 137, 255]);
    // Reading with the wrong reader is an error, not a silent conversion.
    assert!(image_io::read_exr(&d.join("a.png")).is_err());
    assert!(image_io::read_png_rgb8(&d.join("a.EXR")).is_err());
    let e = err_text(image_io::write_image(&d.join("a.tiff"), 4, 3, &px, 1.0, ""));
    assert!(e.contains("a.tiff") && e.contains(".png"), "{e}");
    // An unwritable place is an I/O error naming the path.
    let nowhere = d.join("no/such/dir/x.png");
    match image_io::write_image(&nowhere, 4, 3, &px, 1.0, "") {
        Err(Error::Io { path, .. }) => assert_eq!(path, nowhere),
        other => panic!("{other:?}"),
    }
    // Overwriting replaces the file completely and leaves no temporaries.
    image_io::write_image(&d.join("a.png"), 1, 1, &[[1.0; 3]], 1.0, "").unwrap();
    assert_eq!(
        image_io::read_png_rgb8(&d.join("a.png")).unwrap().2,
        vec![[255; 3]]
    );
    let names: Vec<_> = std::fs::read_dir(&d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 2, "{names:?}");
    let _ = std::fs::remove_dir_all(d);
}

#[test]
fn golden_comparison_tolerates_small_noise_and_catches_shifts() {
    let w = 32;
    let img: Vec<[f32; 3]> = (0..w * w)
        .map(|i| {
            let (x, y) = ((i % w) as f32 / w as f32, (i / w) as f32 / w as f32);
            [x, y * y, 0.5 * (1.0 - x)]
        })
        .collect();
    let noisy: Vec<[f32; 3]> = img
        .iter()
        .enumerate()
        .map(|(i, p)| p.map(|c| c + if i % 2 == 0 { 2e-3 } else { -2e-3 }))
        .collect();
    let d = image_io::compare_images(&noisy, &img);
    assert!(d.max_abs < 2.1e-3 && d.p95_delta_e < 2.0, "{d}");
    let tinted: Vec<[f32; 3]> = img.iter().map(|p| [p[0] * 0.7, p[1], p[2]]).collect();
    let d = image_io::compare_images(&tinted, &img);
    assert!(d.p95_delta_e > 3.0, "{d}");
}

/// The default close-up: the camera sees many scales of the trunk, and a good share of the
/// visible, lit scale corners is in first-order diffraction of the measured Elaphe skin. Its
/// ridges run along the tangent (along the body), so the orders are at `|v| = λ/d` with
/// `d = 1.144 µm` (0.33 ≤ |v| ≤ 0.68 over 380–780 nm) and `u` near 0: within ±0.1, the
/// half-width of the grown field's fan-shaped lobe in its BRDF map (README figure).
#[test]
fn default_close_up_shows_scales_in_first_order() {
    let s = Scene::default_scene();
    let mesh = s.mesh.load().unwrap();
    let vp = s.camera.view_proj(s.output.aspect());
    let (period, mut visible, mut coloured) = (1.144f32, 0, 0);
    let wi = s.light.towards_light();
    for v in &mesh.vertices {
        let c = vp * Vec3::from(v.position).extend(1.0);
        let p = c.xyz() / c.w;
        if c.w <= 0.0 || p.x.abs() > 1.0 || p.y.abs() > 1.0 {
            continue;
        }
        let n = Vec3::from(v.normal);
        let wr = (s.camera.eye() - Vec3::from(v.position)).normalize();
        if n.dot(wi) <= 0.05 || n.dot(wr) <= 0.05 {
            continue;
        }
        visible += 1;
        let t = Vec3::new(v.tangent[0], v.tangent[1], v.tangent[2]);
        let b = n.cross(t) * v.tangent[3];
        let (u, vv) = (-(wi + wr).dot(t), -(wi + wr).dot(b));
        if u.abs() < 0.1 && vv.abs() > 0.38 / period && vv.abs() < 0.78 / period {
            coloured += 1;
        }
    }
    println!("{coloured} of {visible} visible lit corners in first order");
    assert!(visible > 1000, "{visible}");
    assert!(coloured * 10 > visible, "{coloured} of {visible}");
    // The texture is the built-in skin, and its UVs cover the body.
    let t = s.texture.as_ref().unwrap();
    let (w, h, px) = t.load().unwrap();
    assert_eq!(px.len(), (w * h) as usize);
}

/// A mesh far outside float32 scene units (coordinates of 1e30, or a micrometre-sized
/// model) is recentred at the origin and scaled to 2 units, and says so; negative indices
/// are the same faces as positive ones; a mesh in ordinary units is left as it is.
#[test]
fn meshes_outside_the_scene_units_are_recentred_and_rescaled_with_a_note() {
    for (text, scale) in [
        (
            "v 1e30 1e30 0\nv 1.001e30 1e30 0\nv 1e30 1.001e30 0\nf 1 2 3\n",
            "1e30",
        ),
        ("v 0 0 0\nv 1e-6 0 0\nv 0 1e-6 0\nf 1 2 3\n", "1e-6"),
    ] {
        let m = obj(text).unwrap();
        let (lo, hi) = m.bounds();
        let (lo, hi) = (Vec3::from(lo), Vec3::from(hi));
        assert!(
            ((hi - lo).length() - 2.0).abs() < 1e-4,
            "{scale}: {lo} {hi}"
        );
        assert!(((hi + lo) * 0.5).length() < 1e-4, "{scale}: {lo} {hi}");
        assert_eq!(m.repairs.len(), 1, "{scale}: {:?}", m.repairs);
        assert!(m.repairs[0].contains("recentred at the origin and scaled by"));
        assert_eq!(m.vertices[0].normal, [0.0, 0.0, 1.0], "{scale}");
    }
    let plain = obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    assert!(plain.repairs.is_empty(), "{:?}", plain.repairs);
    let negative = obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n").unwrap();
    assert_eq!(negative.vertices, plain.vertices);
    assert_eq!(negative.indices, plain.indices);
}
