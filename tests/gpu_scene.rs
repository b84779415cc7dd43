//! Mesh rendering of the default scene (thesis Algorithms 2–4): the image is finite, shows
//! diffraction colours where the grating diffracts and the background elsewhere, matches a
//! golden image within a ΔE tolerance, and never trips the validation layer.

mod gpu_util;

use std::path::{Path, PathBuf};

use diffract::brdf;
use diffract::colour::xyz_to_linear_srgb;
use diffract::image_io;
use diffract::render::{Picture, Renderer};
use diffract::scene::Scene;
use gpu_util::*;

/// The flat-scales example (the first default scene, whose colours these tests check) at 64×64.
fn default_scene_64() -> Scene {
    let mut scene = Scene::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/examples/flat_scales.toml"),
    )
    .expect("flat_scales example");
    scene.output.width = 64;
    scene.output.height = 64;
    scene
}

fn render(r: &mut Renderer, scene: &Scene) -> Picture {
    let p = prepare(&scene.material);
    r.render_scene(scene, &p).expect("render scene")
}

fn output_dir() -> PathBuf {
    let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-output");
    std::fs::create_dir_all(&d).expect("create target/test-output");
    d
}

/// The default scene renders: finite everywhere, the background where nothing is hit, the
/// snake where it is, and no validation message. (With 65 µm coherence its diffraction
/// lobes are narrower than a 64×64 pixel, so it is not where colours are checked.)
#[test]
fn default_scene_renders_cleanly() {
    let Some(mut r) = renderer() else { return };
    let scene = default_scene_64();
    let frame = render(&mut r, &scene);
    assert_no_validation(&r);
    assert_eq!((frame.width, frame.height), (64, 64));
    assert!(frame.rgb.iter().flatten().all(|c| c.is_finite()));
    let bg = scene.output.background;
    for (x, y) in [(0, 0), (63, 0), (0, 63), (63, 63)] {
        assert_eq!(frame.at(x, y), bg, "corner ({x},{y}) is background");
    }
    let covered = frame.rgb.iter().filter(|p| **p != bg).count();
    assert!(covered > 60, "the snake covers only {covered} pixels");
    assert!(frame.gpu_ms.is_some(), "lavapipe and GPUs have timestamps");
}

/// A plane with the blazed 2.5 µm grating, seen head-on through a narrow camera, lit 13°
/// off the normal (tests/golden/rainbow_64.toml): the first order spreads the spectrum
/// across the middle rows (where v ≈ 0), shortest wavelengths nearest the specular side —
/// the grating equation λ = d·u sorts blue, green and red from left to right.
fn rainbow_scene() -> Scene {
    Scene::from_toml_str(
        include_str!("golden/rainbow_64.toml"),
        Path::new("tests/golden/rainbow_64.toml"),
    )
    .expect("rainbow scene")
}

#[test]
fn rainbow_plane_orders_colours_by_wavelength() {
    let Some(mut r) = renderer() else { return };
    let scene = rainbow_scene();
    let frame = render(&mut r, &scene);
    assert_no_validation(&r);
    assert!(frame.rgb.iter().flatten().all(|c| c.is_finite()));
    image_io::write_png_srgb(
        &output_dir().join("rainbow_64_actual.png"),
        frame.width,
        frame.height,
        &frame.rgb,
        1.0,
    )
    .expect("write rainbow");

    // Saturated, bright pixels: the spectrum.
    let saturated = |p: [f32; 3]| {
        let hi = p.iter().fold(0f32, |a, b| a.max(*b));
        let lo = p.iter().fold(f32::MAX, |a, b| a.min(*b));
        hi > 0.1 && lo < 0.3 * hi
    };
    let coloured = frame.rgb.iter().filter(|p| saturated(**p)).count();
    assert!(coloured >= 40, "only {coloured} coloured pixels");
    // Far from v = 0 the surface is dark.
    for y in [0, 8, 55, 63] {
        for x in 0..64 {
            let p = frame.at(x, y);
            assert!(
                p.iter().all(|c| c.abs() < 1e-3),
                "row {y} lit at {x}: {p:?}"
            );
        }
    }
    // Along the middle row the dominant primary moves blue → green → red.
    let row = frame.height / 2;
    let argmax = |c: usize| {
        (0..frame.width)
            .max_by(|a, b| frame.at(*a, row)[c].total_cmp(&frame.at(*b, row)[c]))
            .unwrap()
    };
    let (r_col, g_col, b_col) = (argmax(0), argmax(1), argmax(2));
    assert!(
        b_col < g_col && g_col < r_col,
        "blue at {b_col}, green at {g_col}, red at {r_col}"
    );
}

/// Mesh mode against the CPU model: Algorithm 2's tangent frame, ωi/ωr and the lighting
/// factors (cosθi · intensity · exposure, XYZ → linear sRGB) per pixel, where the exact
/// pixel ray is intersected with the plane in f64.
#[test]
fn plane_pixels_match_cpu_model() {
    let Some(mut r) = renderer() else { return };
    let scene = plane_scene(3.0);
    let p = prepare(&scene.material);
    let frame = r.render_scene(&scene, &p).expect("render plane");
    assert_no_validation(&r);
    let (w, h) = (frame.width, frame.height);
    let max = frame.rgb.iter().flatten().fold(0.0f32, |a, b| a.max(*b)) as f64;
    assert!(max > 0.05, "max {max}: the orders were missed");

    let inv = scene
        .camera
        .view_proj(scene.output.aspect())
        .as_dmat4()
        .inverse();
    let eye = glam::DVec3::from(scene.camera.eye.map(|c| c as f64));
    // The sun's disc (the scene's default 0.53°, 8 directions): the shader sums the shaded
    // colour over these directions with their weights; the plane's tangent frame is the
    // world frame.
    let disk: Vec<(glam::DVec3, f64)> = scene
        .light
        .disk_samples()
        .iter()
        .map(|s| {
            (
                glam::DVec3::from(s.towards_light.map(f64::from)),
                s.weight as f64,
            )
        })
        .collect();
    assert_eq!(disk.len(), 8, "the plane scene uses the default disc");
    // A scene is radiance over its scale: each wavelength weighted by f_r/ρ (MODEL §10).
    let colour =
        brdf::table::Response::radiance(p.material.coherence_um, &p.shading).colour(&p.colour);
    let scale = scene.light.intensity as f64 * scene.output.exposure as f64;
    let mut pixels: Vec<(u32, u32)> = (0..w).map(|i| (i, h / 2)).collect();
    pixels.extend((0..12).map(|k| ((k * 37 + 5) % w, (k * 23 + 3) % h)));
    let mut coloured = 0;
    for (i, j) in pixels {
        let hit = plane_hit(&inv, i, j, w, h);
        let gpu = frame.at(i, j);
        if hit.x.abs() > 0.99 || hit.y.abs() > 0.99 {
            // Off the plane (or too close to its edge to tell): skip edge pixels.
            if hit.x.abs() > 1.01 || hit.y.abs() > 1.01 {
                assert_eq!(gpu, [0.1, 0.2, 0.3], "background at ({i},{j})");
            }
            continue;
        }
        let wr = (eye - hit).normalize();
        let mut expected = [0.0f64; 3];
        for &(wi, weight) in &disk {
            let xyz = brdf::model::xyz(
                p.stack.get().unwrap(),
                p.terms(),
                &p.window,
                &p.shading,
                &colour,
                wi.to_array(),
                wr.to_array(),
            );
            let rgb = xyz_to_linear_srgb(xyz);
            for c in 0..3 {
                expected[c] += weight * wi.z * scale * rgb[c];
            }
        }
        for c in 0..3 {
            let err = (gpu[c] as f64 - expected[c]).abs();
            assert!(
                err <= 3e-3 * max + 1e-5,
                "pixel ({i},{j}) channel {c}: GPU {} vs CPU {} (max {max})",
                gpu[c],
                expected[c]
            );
        }
        let (lo, hi) = (
            gpu.iter().fold(f32::MAX, |a, b| a.min(*b)),
            gpu.iter().fold(0f32, |a, b| a.max(*b)),
        );
        if hi > 0.02 && hi - lo > 0.5 * hi {
            coloured += 1;
        }
    }
    assert!(
        coloured >= 3,
        "only {coloured} saturated pixels on the middle row"
    );
}

/// The sun's disc is integrated, not sampled once: the disc render equals the weighted sum
/// of point-light renders from each of its directions (one draw, the loop in the shader),
/// and it differs from the point light at the disc's centre where the orders are (the
/// disc, 0.0093 rad across, is wider than a coherence lobe, ~0.005 in `u`).
#[test]
fn sun_disc_is_the_weighted_sum_of_its_point_lights() {
    let Some(mut r) = renderer() else { return };
    let scene = plane_scene(3.0);
    let p = prepare(&scene.material);
    let disc = r.render_scene(&scene, &p).expect("render the disc");
    let point_scene = |towards: [f32; 3]| {
        let mut s = scene.clone();
        s.light.direction = towards.map(|c| -c);
        s.light.angular_diameter_deg = 0.0;
        s.light.disk_samples = 1;
        s
    };
    let samples = scene.light.disk_samples();
    assert_eq!(samples.len(), 8);
    let mut sum = vec![[0.0f64; 3]; disc.rgb.len()];
    for s in &samples {
        let f = r
            .render_scene(&point_scene(s.towards_light), &p)
            .expect("render a point light");
        for (acc, px) in sum.iter_mut().zip(&f.rgb) {
            for c in 0..3 {
                acc[c] += s.weight as f64 * px[c] as f64;
            }
        }
    }
    let centre = r
        .render_scene(&point_scene(scene.light.towards_light().to_array()), &p)
        .expect("render the centre");
    assert_no_validation(&r);
    let max = disc.rgb.iter().flatten().fold(0.0f32, |a, b| a.max(*b)) as f64;
    assert!(max > 0.05, "max {max}: the orders were missed");
    let mut worst_sum = 0.0f64;
    let mut worst_centre = 0.0f64;
    for ((d, s), c) in disc.rgb.iter().zip(&sum).zip(&centre.rgb) {
        for k in 0..3 {
            worst_sum = worst_sum.max((d[k] as f64 - s[k]).abs());
            worst_centre = worst_centre.max((d[k] as f64 - c[k] as f64).abs());
        }
    }
    // float32 sums in a different order: a few ulps of the brightest pixel.
    assert!(
        worst_sum <= 1e-5 * max,
        "disc vs Σ weight·point: {worst_sum:e} (max {max})"
    );
    assert!(
        worst_centre >= 0.05 * max,
        "the disc changes the orders by only {worst_centre:e} of max {max}: is it integrated?"
    );
}

/// Thesis Algorithm 4 on a plane away from any diffraction lobe: the pixel is the texture
/// colour times ((1 − α) + w_diffuse) with α = Schlick F, lit by cosθi · intensity, plus
/// the ambient sky integrated over the hemisphere, times the exposure. The texture's top half is red and its bottom half blue, and must appear the
/// right way up (OBJ UVs have v up).
#[test]
fn texture_blending_follows_algorithm_4() {
    let Some(mut r) = renderer() else { return };
    let dir = output_dir();
    let tex_path = dir.join("two_tone.png");
    let (top, bottom) = ([0.6f32, 0.1, 0.05], [0.05f32, 0.1, 0.6]);
    let tex: Vec<[f32; 3]> = (0..16 * 16)
        .map(|i| if i < 128 { top } else { bottom })
        .collect();
    image_io::write_png_srgb(&tex_path, 16, 16, &tex, 1.0).unwrap();
    let toml = format!(
        r#"
[camera]
eye = [0.0, 0.0, 3.0]
target = [0.0, 0.0, 0.0]
fov_y_deg = 30.0
[light]
direction = [0.0, 0.0, -1.0]
intensity = 0.7
[mesh]
builtin = "plane"
[material]
heightfield = "builtin:blazed"
terms = 4
window_radius = 1
lambda_step_nm = 20
[output]
width = 32
height = 32
exposure = 1.5
[texture]
path = "{}"
w_diffuse = 0.3
ambient = 0.2
"#,
        tex_path.display()
    );
    let scene = Scene::from_toml_str(&toml, Path::new("textured.toml")).expect("scene");
    let p = prepare(&scene.material);
    let frame = r.render_scene(&scene, &p).expect("render");
    assert_no_validation(&r);

    let r0 = brdf::schlick_r0(1.5);
    let inv = scene
        .camera
        .view_proj(scene.output.aspect())
        .as_dmat4()
        .inverse();
    let eye = glam::DVec3::new(0.0, 0.0, 3.0);
    let wi = glam::DVec3::Z;
    let alpha = |wi: glam::DVec3, wr: glam::DVec3| {
        let h = (wi + wr).normalize();
        (r0 + (1.0 - r0) * (1.0 - wr.dot(h)).powi(5)).min(1.0)
    };
    // The ambient sky, a uniform radiance 0.2·0.7/π, by its own quadrature over the
    // hemisphere (θi in 400 steps, φi in 800): the texture reflects ((1 − α) + w_d)·cos θi
    // of it per steradian, the diffraction part (1 − w_d)·R(θr) in radiance, over the
    // picture's scale.
    let sky = 0.2 * 0.7 / std::f64::consts::PI;
    let scale = brdf::table::Response::radiance(scene.material.coherence_um, &p.shading).scale();
    let sky_texture = |wr: glam::DVec3| {
        let (nt, np) = (400, 800);
        let mut sum = 0.0;
        for a in 0..nt {
            let theta = (a as f64 + 0.5) / nt as f64 * std::f64::consts::FRAC_PI_2;
            for b in 0..np {
                let phi = (b as f64 + 0.5) / np as f64 * 2.0 * std::f64::consts::PI;
                let w = glam::DVec3::new(
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    theta.cos(),
                );
                sum += ((1.0 - alpha(w, wr)) + 0.3) * theta.cos() * theta.sin();
            }
        }
        sum * (std::f64::consts::FRAC_PI_2 / nt as f64) * (2.0 * std::f64::consts::PI / np as f64)
    };
    // Rows 4 and 27 are far from v = 0 (no diffraction there); columns away from the edges.
    for (j, expected_tex) in [(4u32, top), (27u32, bottom)] {
        for i in [6u32, 12, 19, 25] {
            let hit = plane_hit(&inv, i, j, 32, 32);
            let wr = (eye - hit).normalize();
            let f = alpha(wi, wr);
            let k = ((1.0 - f) + 0.3) * 0.7 * 1.5 + sky * sky_texture(wr) * 1.5;
            let mirror = r0 + (1.0 - r0) * (1.0 - wr.z).powi(5);
            let sky_mirror = sky * 0.7 * mirror / scale * 1.5;
            let gpu = frame.at(i, j);
            for c in 0..3 {
                // The texture went through 8-bit sRGB: compare with that precision.
                let want = expected_tex[c] as f64 * k + sky_mirror;
                assert!(
                    (gpu[c] as f64 - want).abs() <= 0.01 * want + 2e-3,
                    "pixel ({i},{j}) channel {c}: {} vs {want}",
                    gpu[c]
                );
            }
        }
    }
}

/// `render` of the default close-up scene resolves its supersampling and exposure on the
/// CPU: the PNG has the asked size, and the background comes out as the scene gives it
/// (not multiplied by the exposure of 400), while the snake is lit.
#[test]
fn render_command_resolves_supersampling_and_exposure() {
    if renderer().is_none() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("diffract-resolve-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("s.png");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_diffract"))
        .args([
            "render",
            "--variant",
            "flss",
            "--width",
            "24",
            "--height",
            "16",
            "-o",
        ])
        .arg(&out)
        .env("DIFFRACT_CACHE", "")
        .env("DIFFRACT_VALIDATION", "1")
        .output()
        .expect("run diffract");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The expected aliasing error of what it wrote, from its 3×3 samples' spread.
    let stdout = String::from_utf8_lossy(&o.stdout);
    let line = stdout
        .lines()
        .find(|l| l.starts_with("aliasing: expected rel-L2 "))
        .unwrap_or_else(|| panic!("no aliasing line: {stdout}"));
    let e: f64 = line["aliasing: expected rel-L2 ".len()..]
        .split_whitespace()
        .next()
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{line}"));
    assert!(e > 0.0 && e.is_finite(), "{line}");
    assert!(line.contains("3×3 samples"), "{line}");
    let (w, h, px) = image_io::read_png_rgb8(&out).unwrap();
    assert_eq!((w, h), (24, 16));
    let scene = Scene::default_scene();
    let bg = scene.output.background;
    let mut tone = vec![bg];
    image_io::apply_tone(&mut tone, 1.0, scene.output.tone, scene.output.white).unwrap();
    let want = diffract::colour::linear_to_srgb8(tone[0].map(f64::from), 1.0);
    let corner = px[0];
    for c in 0..3 {
        assert!(
            (corner[c] as i32 - want[c] as i32).abs() <= 2,
            "corner {corner:?} vs background {want:?}"
        );
    }
    assert!(px.iter().any(|p| p != &corner), "only background");
    let _ = std::fs::remove_dir_all(dir);
}
