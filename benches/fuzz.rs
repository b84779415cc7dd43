//! Long fuzz run (issue #10) of every parser of user files: the property tests of
//! `tests/proptest_parsers.rs` run a few thousand cases in CI; this runs mutational fuzzing
//! for a fixed time (`FUZZ_SECS`, default 120) over seeds of each format — a valid PNG,
//! `.f32` + sidecar, OBJ, scene TOML, query CSV and term cache file — with byte flips,
//! insertions, deletions, splices of format tokens and truncation. Meshes and scenes also
//! come from a grammar (`obj-grammar`, `scene-grammar`): well-formed lines with awkward
//! values (negative and out-of-range indices, coordinates of 1e30 and 3.4e38, degenerate and
//! unlit faces, missing normals; scene keys with extreme numbers), which byte flips rarely
//! reach; a scene whose mesh is the built-in plane is loaded with its fuzzed placement. The
//! scene grammar also writes `[environment]` and `[[disc_light]]` tables with extreme numbers;
//! a scene that parses has its lights checked and its environment loaded (a built-in map
//! with the fuzzed intensity and rotation, or the fuzzed map file). Environment maps are
//! fuzzed as files too (`env-hdr`, `env-exr`: byte mutations of a small valid Radiance HDR
//! and OpenEXR map, through `EnvMap::load`). `FUZZ_ONLY` (comma-separated target names)
//! runs only those targets. Any panic is caught, its input saved under the temp directory and counted, and so is a hang:
//! an input that takes more than `FUZZ_HANG_MS` (default 2000) to parse. Exits non-zero if
//! there was either. Run with `cargo bench --bench fuzz`.

use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use diffract::brdf::query::parse_queries;
use diffract::heightfield::HeightField;
use diffract::light::env::{EnvMap, EnvSource};
use diffract::mesh::Mesh;
use diffract::scene::Scene;
use diffract::spectrum::cache;

/// xorshift64*: deterministic from `FUZZ_SEED`.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const TOKENS: &[&[u8]] = &[
    b"\n",
    b" = ",
    b"[",
    b"]",
    b",",
    b"1e309",
    b"nan",
    b"-1",
    b"0",
    b"9999999999999999999",
    b"v ",
    b"f ",
    b"/",
    b"//",
    b"\"",
    b"[camera]\n",
    b"[mesh]\n",
    b"[material]\n",
    b"nx = ",
    b"dh_um = ",
    b"\xef\xbb\xbf",
    b"\xff",
    b"\0",
    b"terms = ",
    b"inf",
    b"#",
    b"[environment]\n",
    b"[[disc_light]]\n",
    b"map = ",
    b"-Y 8 +X 4\n",
    b"-Y 99999999 +X 99999999\n",
    b"#?RADIANCE\n",
    b"FORMAT=32-bit_rle_rgbe\n",
    b"\x02\x02",
    b"v/1\x01",
    b"channels\0chlist\0",
];

fn mutate(rng: &mut Rng, seed: &[u8]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.below(8) {
        match rng.below(6) {
            0 if !b.is_empty() => {
                let i = rng.below(b.len());
                b[i] ^= 1 << rng.below(8);
            }
            1 if !b.is_empty() => {
                let i = rng.below(b.len());
                b[i] = rng.next() as u8;
            }
            2 => {
                let i = rng.below(b.len() + 1);
                let t = TOKENS[rng.below(TOKENS.len())];
                b.splice(i..i, t.iter().copied());
            }
            3 if !b.is_empty() => {
                let i = rng.below(b.len());
                let n = rng.below(16).min(b.len() - i);
                b.drain(i..i + n);
            }
            4 => b.truncate(rng.below(b.len() + 1)),
            _ => {
                let i = rng.below(b.len() + 1);
                let n = rng.below(8);
                let junk: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
                b.splice(i..i, junk);
            }
        }
    }
    b
}

/// One of a few awkward numbers or a random one, as OBJ or TOML text.
fn number(rng: &mut Rng) -> String {
    const AWKWARD: &[&str] = &[
        "0", "1", "-1", "0.5", "1e30", "-1e30", "3.4e38", "1e-30", "1e-45", "2", "-0", "1e4",
        "1e-4", "65", "0.0001",
    ];
    if rng.below(3) == 0 {
        format!("{:.3}", (rng.next() % 2000) as f64 / 100.0 - 10.0)
    } else {
        AWKWARD[rng.below(AWKWARD.len())].to_string()
    }
}

/// A well-formed OBJ with awkward content: vertices, normals and UVs with extreme values,
/// faces of 3 to 6 corners with positive, negative, zero and out-of-range indices in every
/// corner format.
fn obj_grammar(rng: &mut Rng) -> Vec<u8> {
    let mut s = String::new();
    let (mut nv, mut nt, mut nn) = (0i64, 0i64, 0i64);
    for _ in 0..1 + rng.below(40) {
        match rng.below(6) {
            0 | 1 => {
                s += &format!("v {} {} {}\n", number(rng), number(rng), number(rng));
                nv += 1;
            }
            2 => {
                s += &format!("vn {} {} {}\n", number(rng), number(rng), number(rng));
                nn += 1;
            }
            3 => {
                s += &format!("vt {} {}\n", number(rng), number(rng));
                nt += 1;
            }
            _ => {
                let index = |rng: &mut Rng, n: i64| -> i64 {
                    match rng.below(8) {
                        0 => 0,
                        1 => n + 1,
                        2 => -(rng.below(n.max(1) as usize + 2) as i64) - 1,
                        _ => rng.below(n.max(1) as usize) as i64 + 1,
                    }
                };
                s += "f";
                let form = rng.below(4);
                for _ in 0..3 + rng.below(4) {
                    let v = index(rng, nv);
                    s += &match form {
                        0 => format!(" {v}"),
                        1 => format!(" {v}/{}", index(rng, nt)),
                        2 => format!(" {v}//{}", index(rng, nn)),
                        _ => format!(" {v}/{}/{}", index(rng, nt), index(rng, nn)),
                    };
                }
                s += "\n";
            }
        }
    }
    s.into_bytes()
}

/// A scene file from its real sections and keys with awkward values; the mesh is the
/// built-in plane half of the time, so its placement is fuzzed too.
fn scene_grammar(rng: &mut Rng) -> Vec<u8> {
    const KEYS: &[(&str, &[&str])] = &[
        (
            "camera",
            &["eye", "target", "up", "fov_y_deg", "near", "far"],
        ),
        (
            "light",
            &[
                "direction",
                "intensity",
                "angular_diameter_deg",
                "disk_samples",
            ],
        ),
        (
            "mesh",
            &[
                "translate",
                "rotate_deg",
                "scale",
                "scale_roll_deg",
                "scale_pitch_deg",
            ],
        ),
        (
            "material",
            &["tolerance", "coherence_um", "window_radius", "terms"],
        ),
        (
            "output",
            &["width", "height", "exposure", "supersample", "background"],
        ),
    ];
    let mut s = String::new();
    for (section, keys) in KEYS {
        if rng.below(3) == 0 {
            continue;
        }
        s += &format!("[{section}]\n");
        if *section == "mesh" && rng.below(2) == 0 {
            s += "builtin = \"plane\"\n";
        }
        for key in keys.iter() {
            if rng.below(2) == 0 {
                continue;
            }
            let vector = matches!(
                *key,
                "eye" | "target" | "up" | "direction" | "translate" | "rotate_deg" | "background"
            );
            let value = if vector {
                format!("[{}, {}, {}]", number(rng), number(rng), number(rng))
            } else {
                number(rng)
            };
            s += &format!("{key} = {value}\n");
        }
    }
    if rng.below(2) == 0 {
        s += "[environment]\n";
        const MAPS: &[&str] = &[
            "builtin:white",
            "builtin:sky",
            "builtin:studio",
            "builtin:nothing",
            "env.hdr",
            "env.exr",
            "missing.hdr",
            "env.png",
            "",
        ];
        if rng.below(8) != 0 {
            s += &format!("map = \"{}\"\n", MAPS[rng.below(MAPS.len())]);
        }
        for key in ["intensity", "rotate_deg"] {
            if rng.below(2) == 0 {
                s += &format!("{key} = {}\n", toml_number(rng));
            }
        }
    }
    for _ in 0..rng.below(4) {
        s += "[[disc_light]]\n";
        for key in [
            "direction",
            "angular_diameter_deg",
            "colour",
            "intensity",
            "disk_samples",
        ] {
            if rng.below(3) == 0 {
                continue;
            }
            let value = match key {
                "direction" | "colour" => format!(
                    "[{}, {}, {}]",
                    toml_number(rng),
                    toml_number(rng),
                    toml_number(rng)
                ),
                "disk_samples" => {
                    const COUNTS: &[&str] = &["0", "1", "16", "256", "257", "-1", "4294967296"];
                    COUNTS[rng.below(COUNTS.len())].to_string()
                }
                _ => toml_number(rng),
            };
            s += &format!("{key} = {value}\n");
        }
    }
    s.into_bytes()
}

/// [`number`] or one of TOML's own extremes (infinities, NaN, beyond float32).
fn toml_number(rng: &mut Rng) -> String {
    const EXTREME: &[&str] = &[
        "inf", "-inf", "nan", "1e39", "-1e39", "1e308", "1e-320", "180", "180.0001", "-0.0",
    ];
    if rng.below(3) == 0 {
        EXTREME[rng.below(EXTREME.len())].to_string()
    } else {
        number(rng)
    }
}

/// An 8×4 equirectangular map of small, finite radiance.
fn map_pixels() -> image::Rgb32FImage {
    image::Rgb32FImage::from_fn(8, 4, |x, y| {
        image::Rgb([0.1 * x as f32, 0.5 + 0.2 * y as f32, 2.0])
    })
}

fn main() {
    let secs: u64 = std::env::var("FUZZ_SECS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(120);
    let mut rng = Rng(std::env::var("FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0x9E37_79B9_7F4A_7C15));
    let dir = std::env::temp_dir().join(format!("diffract-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = |name: &str| -> PathBuf { dir.join(name) };

    // Seeds.
    image::GrayImage::from_fn(16, 8, |x, y| image::Luma([(x * 13 + y * 7) as u8]))
        .save(file("seed.png"))
        .unwrap();
    let png = std::fs::read(file("seed.png")).unwrap();
    let f32s: Vec<u8> = (0..16)
        .flat_map(|i| (i as f32 * 0.01).to_le_bytes())
        .collect();
    let sidecar = b"nx = 4\nny = 4\ndh_um = 0.1\n".to_vec();
    let obj = b"o tri\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1\n".to_vec();
    let scene = diffract::scene::DEFAULT_SCENE_TOML.as_bytes().to_vec();
    let csv =
        b"theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm\n30,0,30,180,500\n10,0,20,0,\n"
            .to_vec();
    let hf = HeightField::new(8, 6, 0.1, (0..48).map(|i| (i % 5) as f64 * 0.02).collect()).unwrap();
    let req = diffract::spectrum::TermRequest {
        expansion: diffract::spectrum::Expansion::Chebyshev,
        max_term: 2,
        lambda_min_um: 0.38,
        window_radius: 1,
        full_band: false,
    };
    cache::terms_cached(&hf, &req, Some(&dir), &diffract::report::Stderr).unwrap();
    let key = cache::cache_key(&hf, &req);
    let cache_seed = std::fs::read(dir.join(format!("terms-{key:016x}.bin"))).unwrap();
    let map = map_pixels();
    {
        let f = std::fs::File::create(file("seed.hdr")).unwrap();
        let px: Vec<image::Rgb<f32>> = map.pixels().copied().collect();
        image::codecs::hdr::HdrEncoder::new(std::io::BufWriter::new(f))
            .encode(&px, 8, 4)
            .unwrap();
    }
    map.save(file("seed.exr")).unwrap();
    let hdr = std::fs::read(file("seed.hdr")).unwrap();
    let exr = std::fs::read(file("seed.exr")).unwrap();
    // The seeds themselves must load, or the targets would fuzz nothing but the refusal.
    for seed in ["seed.hdr", "seed.exr"] {
        EnvMap::load(&EnvSource::File(file(seed)), 1.0, 0.0).unwrap();
    }
    // The scene grammar's map files, relative to its scene path.
    std::fs::copy(file("seed.hdr"), file("env.hdr")).unwrap();
    std::fs::copy(file("seed.exr"), file("env.exr")).unwrap();

    // Panics are caught and counted; keep the default hook quiet while fuzzing.
    std::panic::set_hook(Box::new(|_| {}));
    let names = [
        "png",
        "f32",
        "sidecar",
        "obj",
        "scene",
        "csv",
        "cache",
        "obj-grammar",
        "scene-grammar",
        "env-hdr",
        "env-exr",
    ];
    let only: Vec<usize> = match std::env::var("FUZZ_ONLY") {
        Ok(list) => list
            .split(',')
            .map(|n| {
                names
                    .iter()
                    .position(|x| *x == n.trim())
                    .unwrap_or_else(|| {
                        eprintln!("fuzz: unknown target '{n}'; expected one of {names:?}");
                        std::process::exit(2)
                    })
            })
            .collect(),
        Err(_) => (0..names.len()).collect(),
    };
    let hang_ms: u128 = std::env::var("FUZZ_HANG_MS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2000);
    let mut runs = [0u64; 11];
    let mut slowest = [0u128; 11];
    let mut panics = 0u64;
    let mut hangs = 0u64;
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(secs) {
        let which = only[rng.below(only.len())];
        let input = match which {
            0 => mutate(&mut rng, &png),
            1 => mutate(&mut rng, &f32s),
            2 => mutate(&mut rng, &sidecar),
            3 => mutate(&mut rng, &obj),
            4 => mutate(&mut rng, &scene),
            5 => mutate(&mut rng, &csv),
            6 => mutate(&mut rng, &cache_seed),
            7 => obj_grammar(&mut rng),
            8 => scene_grammar(&mut rng),
            9 => mutate(&mut rng, &hdr),
            _ => mutate(&mut rng, &exr),
        };
        let began = Instant::now();
        let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| match which {
            0 => {
                std::fs::write(file("x.png"), &input).unwrap();
                std::fs::write(file("x.toml"), "dh_um = 0.1\nh_max_um = 1\n").unwrap();
                let _ = HeightField::load(&file("x.png"), None, None);
            }
            1 | 2 => {
                let (data, side) = if which == 1 {
                    (&input, &sidecar)
                } else {
                    (&f32s, &input)
                };
                std::fs::write(file("y.f32"), data).unwrap();
                std::fs::write(file("y.toml"), side).unwrap();
                let _ = HeightField::load(&file("y.f32"), None, None);
            }
            3 | 7 => {
                let text = String::from_utf8_lossy(&input);
                let _ = Mesh::from_obj_str(&text, Path::new("fuzz.obj"));
            }
            4 | 8 => {
                let text = String::from_utf8_lossy(&input);
                if let Ok(s) = Scene::from_toml_str(&text, &file("fuzz.toml")) {
                    if s.mesh.builtin.as_deref() == Some("plane") && s.mesh.path.is_none() {
                        let _ = s.mesh.load();
                    }
                    for light in &s.disc_lights {
                        let _ = (light.disk_samples(), light.solid_angle());
                    }
                    if let Some(e) = &s.environment {
                        if let Ok(source) = e.source() {
                            let _ = EnvMap::load(&source, e.intensity, e.rotate_deg);
                        }
                    }
                }
            }
            9 | 10 => {
                let name = if which == 9 { "w.hdr" } else { "w.exr" };
                std::fs::write(file(name), &input).unwrap();
                let _ = EnvMap::load(&EnvSource::File(file(name)), 1.0, 0.0);
            }
            5 => {
                let text = String::from_utf8_lossy(&input);
                let _ = parse_queries(Path::new("fuzz.csv"), &text);
            }
            _ => {
                std::fs::write(file("z.bin"), &input).unwrap();
                let _ = cache::load(&file("z.bin"), key);
            }
        }));
        runs[which] += 1;
        let ms = began.elapsed().as_millis();
        slowest[which] = slowest[which].max(ms);
        if ms > hang_ms {
            hangs += 1;
            let keep = dir.join(format!("hang-{hangs}.{}", names[which]));
            let _ = std::fs::write(&keep, &input);
            eprintln!(
                "fuzz: {ms} ms in the {} parser, input saved to {}",
                names[which],
                keep.display()
            );
        }
        if outcome.is_err() {
            panics += 1;
            let keep = dir.join(format!("panic-{panics}.{}", names[which]));
            let _ = std::fs::write(&keep, &input);
            eprintln!(
                "fuzz: panic in the {} parser, input saved to {}",
                names[which],
                keep.display()
            );
        }
    }
    let total: u64 = runs.iter().sum();
    let per: Vec<String> = only
        .iter()
        .map(|&i| format!("{} {} (slowest {} ms)", names[i], runs[i], slowest[i]))
        .collect();
    println!(
        "fuzz: {total} inputs in {:.0} s ({}), {panics} panic(s), {hangs} hang(s) over {hang_ms} ms",
        start.elapsed().as_secs_f64(),
        per.join(", ")
    );
    if panics == 0 && hangs == 0 {
        let _ = std::fs::remove_dir_all(&dir);
    } else {
        std::process::exit(1);
    }
}
