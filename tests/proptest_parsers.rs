//! Property tests: arbitrary and mutated bytes fed to every parser of user files (PNG and
//! `.f32` height fields with their sidecars, OBJ, scene TOML, query CSV, term cache files)
//! must give `Ok` or an `Err`, never a panic. About 3 000 cases in all, a few seconds in
//! release; `cargo bench --bench fuzz` runs the same properties far longer.

use std::path::{Path, PathBuf};

use diffract::brdf::query::parse_queries;
use diffract::heightfield::HeightField;
use diffract::mesh::Mesh;
use diffract::scene::Scene;
use diffract::spectrum::cache;
use proptest::prelude::*;

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-prop-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A file name unique to this call, so parallel test threads never share one.
fn unique(ext: &str) -> PathBuf {
    use std::sync::atomic::{AtomicU64, Ordering};
    static N: AtomicU64 = AtomicU64::new(0);
    dir().join(format!("f{}.{ext}", N.fetch_add(1, Ordering::Relaxed)))
}

fn valid_png() -> Vec<u8> {
    let p = unique("png");
    image::GrayImage::from_fn(16, 8, |x, y| image::Luma([(x * 13 + y * 7) as u8]))
        .save(&p)
        .unwrap();
    let b = std::fs::read(&p).unwrap();
    let _ = std::fs::remove_file(&p);
    b
}

/// A valid cache file and the key it is stored under.
fn valid_cache() -> (Vec<u8>, u64) {
    let hf = HeightField::new(8, 6, 0.1, (0..48).map(|i| (i % 5) as f64 * 0.02).collect()).unwrap();
    let req = diffract::spectrum::TermRequest {
        expansion: diffract::spectrum::Expansion::Chebyshev,
        max_term: 2,
        lambda_min_um: 0.38,
        window_radius: 1,
        full_band: false,
    };
    let d = dir().join("cache");
    let stack = cache::terms_cached(&hf, &req, Some(&d), &diffract::report::Stderr).unwrap();
    let key = cache::cache_key(&hf, &req);
    let p = d.join(format!("terms-{key:016x}.bin"));
    assert!(cache::load(&p, key).is_ok());
    drop(stack);
    (std::fs::read(&p).unwrap(), key)
}

/// Byte-level mutations of a valid file: flips, truncation, insertion, overwrite.
fn mutated(base: Vec<u8>) -> impl Strategy<Value = Vec<u8>> {
    let n = base.len();
    (
        prop::collection::vec((0..n.max(1), any::<u8>()), 0..6),
        0..=n,
        prop::option::of(prop::collection::vec(any::<u8>(), 0..16)),
    )
        .prop_map(move |(flips, cut, insert)| {
            let mut b = base.clone();
            for (i, v) in flips {
                if i < b.len() {
                    b[i] ^= v;
                }
            }
            b.truncate(cut.max(1));
            if let Some(ins) = insert {
                let at = b.len() / 2;
                b.splice(at..at, ins);
            }
            b
        })
}

fn load_hf(bytes: &[u8], ext: &str, sidecar: &str) -> diffract::Result<HeightField> {
    let p = unique(ext);
    std::fs::write(&p, bytes).unwrap();
    std::fs::write(p.with_extension("toml"), sidecar).unwrap();
    let r = HeightField::load(&p, None, None);
    let _ = std::fs::remove_file(&p);
    let _ = std::fs::remove_file(p.with_extension("toml"));
    r
}

fn load_cache(bytes: &[u8], key: u64) -> diffract::Result<diffract::spectrum::TermStack> {
    let p = unique("bin");
    std::fs::write(&p, bytes).unwrap();
    let r = cache::load(&p, key);
    let _ = std::fs::remove_file(&p);
    r
}

const CSV_HEADER: &str = "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm\n";

/// Text made of the pieces a CSV or TOML parser cares about, so cases get past the first
/// byte more often than uniform noise does.
fn tokens(alphabet: &'static [&'static str]) -> impl Strategy<Value = String> {
    prop::collection::vec(prop::sample::select(alphabet), 0..60).prop_map(|v| v.concat())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn png_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        let _ = load_hf(&bytes, "png", "dh_um = 0.1\nh_max_um = 1\n");
    }

    #[test]
    fn mutated_png_never_panics(bytes in mutated(valid_png())) {
        let _ = load_hf(&bytes, "png", "dh_um = 0.1\nh_max_um = 1\n");
    }

    #[test]
    fn f32_bytes_and_sidecar_sizes_never_panic(
        bytes in prop::collection::vec(any::<u8>(), 0..600),
        nx in 0usize..20,
        ny in prop_oneof![0usize..20, Just(usize::MAX), Just(1usize << 40)],
    ) {
        let _ = load_hf(&bytes, "f32", &format!("nx = {nx}\nny = {ny}\ndh_um = 0.1\n"));
    }

    #[test]
    fn sidecar_text_never_panics(text in tokens(&[
        "nx", "ny", "dh_um", "h_max_um", " = ", "\n", "1", "-3", "0.1", "1e308", "nan", "inf",
        "\"x\"", "[", "]", "#", "9999999999999999999999", "\u{feff}", "=", ".", "'",
    ])) {
        let _ = load_hf(&[0u8; 16], "f32", &text);
    }

    #[test]
    fn cache_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..400), key: u64) {
        let _ = load_cache(&bytes, key);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn mutated_cache_is_rejected_or_identical(bytes in mutated(valid_cache().0)) {
        let (good, key) = valid_cache();
        match load_cache(&bytes, key) {
            Ok(_) => prop_assert_eq!(bytes, good),
            Err(e) => prop_assert!(!e.to_string().is_empty()),
        }
    }

    #[test]
    fn obj_text_never_panics(text in tokens(&[
        "v ", "vn ", "vt ", "f ", "o x\n", "g g\n", "usemtl m\n", "mtllib a.mtl\n", "1", "2",
        "3", "-1", "0", "/", "//", " ", "\n", "1e39", "nan", "0.5", "-0.25", "#", "\\\n",
    ])) {
        let _ = Mesh::from_obj_str(&text, Path::new("fuzz.obj"));
    }

    #[test]
    fn scene_text_never_panics(text in tokens(&[
        "[camera]\n", "[light]\n", "[mesh]\n", "[material]\n", "[output]\n", "[texture]\n",
        "eye = ", "target = ", "up = ", "fov_y_deg = ", "near = ", "far = ", "direction = ",
        "builtin = \"sphere\"", "path = \"m.obj\"", "heightfield = \"builtin:blazed\"",
        "terms = ", "width = ", "height = ", "exposure = ", "[0, 1, 2]", "[0, 0, 0]", "1",
        "0", "-1", "1e40", "nan", "inf", "65", "\n", " ", "\"", "=", "[[a]]\n", "{ x = 1 }",
    ])) {
        let _ = Scene::from_toml_str(&text, Path::new("fuzz.toml"));
    }

    #[test]
    fn csv_text_never_panics(body in tokens(&[
        ",", "\n", "\r\n", "30", "0", "180", "500", "-1", "1e309", "nan", "x", " ", "#",
        "\u{feff}", "780", "380", "",
    ]), header: bool) {
        let text = if header { format!("{CSV_HEADER}{body}") } else { body };
        let _ = parse_queries(Path::new("fuzz.csv"), &text);
    }

    #[test]
    fn arbitrary_unicode_never_panics_any_text_parser(text in "\\PC{0,200}") {
        let _ = parse_queries(Path::new("fuzz.csv"), &text);
        let _ = Scene::from_toml_str(&text, Path::new("fuzz.toml"));
        let _ = Mesh::from_obj_str(&text, Path::new("fuzz.obj"));
    }
}
