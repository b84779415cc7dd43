//! Shared helpers of the GPU tests: a validated renderer (or a loud skip when the machine
//! has no Vulkan at all, which fails instead under `DIFFRACT_REQUIRE_VULKAN=1`, as CI runs),
//! the validation canary check, and materials for small fast cases.
#![allow(dead_code)]

pub mod golden;

use std::path::Path;

use diffract::heightfield::HeightField;
use diffract::material::{Material, PreparedMaterial, Terms};
use diffract::render::Renderer;
use diffract::scene::Scene;
use diffract::spectrum::Expansion;
use diffract::Error;

/// A renderer with validation ON. `None` (with a printed notice) only when no Vulkan loader
/// or device exists; any other failure (e.g. a missing validation layer) fails the test.
/// With `DIFFRACT_REQUIRE_VULKAN=1` (CI on a machine that has Vulkan) a missing device
/// fails too.
pub fn renderer() -> Option<Renderer> {
    match Renderer::new(true) {
        Ok(r) => Some(r),
        Err(Error::NoVulkan(msg)) if vulkan_required() => {
            panic!("DIFFRACT_REQUIRE_VULKAN=1 but {msg}")
        }
        Err(Error::NoVulkan(msg)) => {
            eprintln!("SKIPPED: no Vulkan device on this machine ({msg})");
            None
        }
        Err(e) => panic!("cannot create a validated renderer: {e}"),
    }
}

/// Whether every GPU test must run (`DIFFRACT_REQUIRE_VULKAN=1`, set by CI): a missing
/// driver then fails the test instead of skipping it.
pub fn vulkan_required() -> bool {
    std::env::var("DIFFRACT_REQUIRE_VULKAN").is_ok_and(|v| v == "1")
}

/// For a test that runs the `diffract` binary: whether the run failed only because the
/// machine has no Vulkan driver (its one error line is `error: Vulkan unavailable: ...`),
/// so the test may skip with a notice. Under `DIFFRACT_REQUIRE_VULKAN=1` that panics
/// instead. Any other failure, a real Vulkan error included, is `false`: the test reports it.
pub fn binary_found_no_vulkan(o: &std::process::Output) -> bool {
    if o.status.success() {
        return false;
    }
    let err = String::from_utf8_lossy(&o.stderr);
    if !err
        .lines()
        .any(|l| l.starts_with("error: Vulkan unavailable:"))
    {
        return false;
    }
    if vulkan_required() {
        panic!(
            "DIFFRACT_REQUIRE_VULKAN=1 but diffract found no Vulkan: {}",
            err.trim()
        );
    }
    eprintln!("SKIPPED: no Vulkan driver on this machine ({})", err.trim());
    true
}

/// Fails if the validation layer reported anything.
pub fn assert_no_validation(r: &Renderer) {
    assert_eq!(
        r.validation_messages(),
        0,
        "validation messages: {:#?}",
        r.validation_report()
    );
}

/// A small material: few terms and a coarse λ step so lavapipe renders in well under a second.
pub fn small_material(
    heightfield: &str,
    expansion: Expansion,
    terms: usize,
    radius: usize,
) -> Material {
    Material {
        heightfield: heightfield.into(),
        expansion,
        terms: Terms::Fixed(terms),
        window_radius: radius,
        lambda_step_nm: 10,
        ..Material::default()
    }
}

pub fn prepare(m: &Material) -> PreparedMaterial {
    m.prepare(None, &diffract::report::Stderr)
        .unwrap_or_else(|e| panic!("preparing {}: {e}", m.heightfield))
}

/// ωr of map pixel (i, j) exactly as the fragment shader computes it (float32), or `None`
/// outside the unit disk.
pub use diffract::render::map_direction;

/// ωi as the renderer uploads it (f64 direction rounded to float32).
pub fn uploaded_direction(theta_deg: f64, phi_deg: f64) -> [f64; 3] {
    diffract::brdf::direction(theta_deg, phi_deg).map(|c| c as f32 as f64)
}

/// Map pixel containing direction (x, y) of the disk.
pub fn pixel_of(x: f64, y: f64, size: u32) -> (u32, u32) {
    let s = size as f64;
    let i = (((x + 1.0) * s / 2.0).floor() as i64).clamp(0, size as i64 - 1);
    let j = (((1.0 - y) * s / 2.0).floor() as i64).clamp(0, size as i64 - 1);
    (i as u32, j as u32)
}

/// Light polar angle (φ = 0) whose mirror direction is exactly the centre of pixel `i` of
/// the middle row of an odd-sized map: there `u = v = 0` in float32 too, so the specular
/// peak and (for gratings along x) the diffraction orders along the row are sampled on
/// their peaks instead of on the far tails of the coherence window.
pub fn theta_for_specular_pixel(i: u32, size: u32) -> f64 {
    assert!(size % 2 == 1, "the middle row has y = 0 only for odd sizes");
    let x = map_direction(i, size / 2, size).expect("pixel inside the disk")[0];
    (-x).asin().to_degrees()
}

/// About `n` pixels of an S×S map worth checking: the centre, the specular pixel, every
/// other pixel of its row (where a grating along x diffracts), near-grazing pixels by the
/// disk edge, and a deterministic scatter.
pub fn sample_pixels(size: u32, wi: [f64; 3], n: usize) -> Vec<(u32, u32)> {
    let (spec_col, spec_row) = pixel_of(-wi[0], -wi[1], size);
    let mut px = vec![(size / 2, size / 2), (spec_col, spec_row)];
    for i in (0..size).step_by(2) {
        px.push((i, spec_row));
    }
    for k in 0..6 {
        let a = k as f64 * std::f64::consts::PI / 3.0 + 0.3;
        px.push(pixel_of(0.975 * a.cos(), 0.975 * a.sin(), size));
    }
    let mut state = 0x2545_f491_u64;
    for _ in 0..n {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let i = ((state >> 33) % size as u64) as u32;
        let j = ((state >> 17) % size as u64) as u32;
        px.push((i, j));
    }
    px.retain(|&(i, j)| map_direction(i, j, size).is_some());
    px.sort_unstable();
    px.dedup();
    px
}

/// A 65 µm patch of 130² samples (dH = 0.5 µm) saved as `dir/field.f32`: 13 copies of a
/// 5 µm ridge along x and 5 copies of a 13 µm wave along y, so both axes are periodic
/// with 3 taps each (nmm finds a dominant period, pq whole copies of one), with `terms`
/// fixed terms and a `lambda_step_nm` step.
pub fn periodic_material(dir: &Path, terms: usize, lambda_step_nm: u32) -> Material {
    let n = 130;
    let tau = 2.0 * std::f64::consts::PI;
    let h = (0..n * n)
        .map(|i| {
            let (c, r) = ((i % n) as f64, (i / n) as f64);
            0.1 * (1.0 + (tau * c / 10.0).sin()) + 0.04 * (1.0 + (tau * r / 26.0).cos())
        })
        .collect();
    let path = dir.join("field.f32");
    HeightField::new(n, n, 0.5, h).unwrap().save(&path).unwrap();
    Material {
        heightfield: path.to_string_lossy().into_owned(),
        terms: Terms::Fixed(terms),
        lambda_step_nm,
        ..Material::default()
    }
}

/// The built-in plane (facing +z, tangent +x, so the blazed grating's lines run along y)
/// seen head-on from `eye_z` on the z axis through a 63² camera; light 30° from the normal
/// in the xz plane, so several diffraction orders of the 2.5 µm grating cross the middle
/// row of the image, where v = 0; the default 0.53° sun of 8 directions.
pub fn plane_scene(eye_z: f64) -> Scene {
    let text = format!(
        r#"
[camera]
eye = [0.0, 0.0, {eye_z:?}]
target = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_y_deg = 35.0
[light]
direction = [-0.5, 0.0, -0.8660254037844386]
intensity = 1.5
[mesh]
builtin = "plane"
[material]
heightfield = "builtin:blazed"
terms = 6
window_radius = 1
lambda_step_nm = 10
[output]
width = 63
height = 63
exposure = 20.0
background = [0.1, 0.2, 0.3]
"#
    );
    Scene::from_toml_str(&text, Path::new("plane.toml")).expect("plane scene")
}

/// Where the ray of pixel `(i, j)` of a `w`×`h` image (row `j` from the top, through the
/// pixel's centre) meets the plane z = 0, from the inverse of the camera's view-projection
/// `inv` (f64): the exact hit a plane scene's pixel shows.
pub fn plane_hit(inv: &glam::DMat4, i: u32, j: u32, w: u32, h: u32) -> glam::DVec3 {
    let (near, far) = pixel_ray(inv, i, j, w, h);
    near + (far - near) * (-near.z / (far.z - near.z))
}

/// The world points on the near and far planes under the centre of pixel `(i, j)` of a
/// `w×h` frame, through `inv`, the inverse of the camera's view-projection (Vulkan clip
/// space: row 0 at the top, depth 0 to 1).
pub fn pixel_ray(inv: &glam::DMat4, i: u32, j: u32, w: u32, h: u32) -> (glam::DVec3, glam::DVec3) {
    let ndc = |z: f64| {
        let c = *inv
            * glam::DVec4::new(
                2.0 * (i as f64 + 0.5) / w as f64 - 1.0,
                2.0 * (j as f64 + 0.5) / h as f64 - 1.0,
                z,
                1.0,
            );
        c.truncate() / c.w
    };
    (ndc(0.0), ndc(1.0))
}

/// `render`'s command line with nothing given.
#[derive(clap::Parser)]
struct RenderDefaults {
    #[command(flatten)]
    render: diffract::cli::render::RenderArgs,
}

/// Sets up `r` and prepares `material` exactly as `diffract render` does with no options
/// (its variant, storage, table options but one level, leaving out, the material flags' defaults), with
/// the tables cached in `target/test-output/<cache>` so a rerun skips their build.
pub fn as_render_defaults(r: &mut Renderer, material: &Material, cache: &str) -> PreparedMaterial {
    use clap::Parser;
    let args = RenderDefaults::parse_from(["diffract"]).render;
    let material = args.material.apply(material.clone());
    let (heightfield, plan) = material
        .load_planned(
            &diffract::brdf::truncation::Reach::ALL,
            diffract::brdf::truncation::Precision::F32,
            &diffract::report::Stderr,
        )
        .expect("default material");
    r.set_storage_format(args.gpu.storage);
    r.set_variant(args.gpu.variant);
    // One level: the tests compare pixels with the f64 reference at their centres, not
    // over their footprints.
    r.set_table_options(diffract::render::TableOptions {
        levels: 1,
        ..args.gpu.table.options()
    });
    r.set_leave_out(!args.keep_all);
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("target/test-output")
        .join(cache);
    std::fs::create_dir_all(&dir).unwrap();
    r.set_cache_dir(Some(dir.clone()));
    material
        .prepare_planned(heightfield, plan, Some(&dir), &diffract::report::Stderr)
        .expect("prepare")
}

/// A validated headless device, or `None` (skip, with a notice) where the machine has no
/// Vulkan; under `DIFFRACT_REQUIRE_VULKAN=1` a missing device fails, as [`renderer`].
pub fn device() -> Option<std::sync::Arc<diffract::gpu::Device>> {
    match diffract::gpu::Device::new(true) {
        Ok(d) => Some(d),
        Err(Error::NoVulkan(msg)) if vulkan_required() => {
            panic!("DIFFRACT_REQUIRE_VULKAN=1 but {msg}")
        }
        Err(Error::NoVulkan(msg)) => {
            eprintln!("SKIPPED: no Vulkan device on this machine ({msg})");
            None
        }
        Err(e) => panic!("cannot create a validated device: {e}"),
    }
}
