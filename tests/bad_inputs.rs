//! The bad-input corpus: a table of broken or hostile inputs (images, `.f32` files and their
//! sidecars, OBJ meshes, scene TOML, query CSV, cache files, numeric flags, output paths),
//! each run through the `diffract` binary. Every failing case must give a non-zero exit,
//! exactly one `error:` line containing a given phrase, no panic, and leave every file that
//! existed before byte-for-byte as it was (no output either). Cases that must succeed with a
//! warning (a corrupt cache is recomputed) say so.
//!
//! Every case runs with no Vulkan driver (`VK_ICD_FILENAMES` pointing nowhere): errors must
//! be found before the device is opened, so a missing driver message instead of the expected
//! one means the check came too late.

mod files_util;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use files_util::snapshot;

/// What a case must produce.
#[derive(Clone, Copy)]
enum Expect {
    /// Non-zero exit, one `error:` line containing the phrase, no file changed or created.
    Fail(&'static str),
    /// Exit 0, no `error:` line, stderr contains the phrase; old files unchanged.
    Warn(&'static str),
    /// Exit 0 and no `error:` line; old files unchanged.
    Ok,
}

struct Case {
    name: &'static str,
    /// Files to create in the case's directory before the run.
    setup: Box<dyn Fn(&Path) + Sync>,
    /// Arguments; `{d}` is replaced by the case's directory.
    args: Vec<&'static str>,
    /// Extra environment (`{d}` replaced too).
    env: Vec<(&'static str, &'static str)>,
    expect: Expect,
}

fn case(
    name: &'static str,
    setup: impl Fn(&Path) + Sync + 'static,
    args: &[&'static str],
    expect: Expect,
) -> Case {
    Case {
        name,
        setup: Box::new(setup),
        args: args.to_vec(),
        env: Vec::new(),
        expect,
    }
}

impl Case {
    fn env(mut self, k: &'static str, v: &'static str) -> Self {
        self.env.push((k, v));
        self
    }
}

// ---- file makers -------------------------------------------------------------------------

fn put(p: &Path, bytes: impl AsRef<[u8]>) {
    if let Some(d) = p.parent() {
        std::fs::create_dir_all(d).unwrap();
    }
    std::fs::write(p, bytes).unwrap();
}

/// An 8×8 8-bit grayscale PNG with a sidecar: a valid tiny height field.
fn grey_png(p: &Path) {
    let img = image::GrayImage::from_fn(8, 8, |x, y| image::Luma([(x * 29 + y * 3) as u8]));
    img.save(p).unwrap();
    put(&p.with_extension("toml"), "dh_um = 0.1\nh_max_um = 0.2\n");
}

fn png_bytes() -> Vec<u8> {
    let d = std::env::temp_dir().join(format!("diffract-bad-png-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    let p = d.join("x.png");
    image::GrayImage::from_fn(8, 8, |x, _| image::Luma([x as u8]))
        .save(&p)
        .unwrap();
    std::fs::read(&p).unwrap()
}

fn f32_field(p: &Path, n: usize, sidecar: &str) {
    let bytes: Vec<u8> = (0..n * n)
        .flat_map(|i| (0.01 * (i % 7) as f32).to_le_bytes())
        .collect();
    put(p, bytes);
    put(&p.with_extension("toml"), sidecar);
}

fn link(target: &str, p: &Path) {
    std::os::unix::fs::symlink(target, p).unwrap();
}

const HEADER: &str = "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm\n";

fn queries(p: &Path) {
    put(p, format!("{HEADER}30,0,30,180,500\n"));
}

/// A tiny valid setup for `brdf`: `hf.png` (+ sidecar) and `q.csv`.
fn brdf_base(d: &Path) {
    grey_png(&d.join("hf.png"));
    queries(&d.join("q.csv"));
}

const BRDF: [&str; 8] = [
    "brdf",
    "--heightfield",
    "{d}/hf.png",
    "--queries",
    "{d}/q.csv",
    "--terms",
    "2",
    "--no-cache",
];

fn brdf_with(extra: &[&'static str]) -> Vec<&'static str> {
    let mut v = BRDF.to_vec();
    v.extend_from_slice(extra);
    v
}

fn scene(d: &Path, text: &str) {
    grey_png(&d.join("hf.png"));
    put(&d.join("s.toml"), text);
}

const SCENE_OK: &str = "[material]\nheightfield = \"hf.png\"\nterms = 1\n\n[output]\nwidth = 8\nheight = 8\n\n[mesh]\npath = \"m.obj\"\n";

fn obj_scene(d: &Path, obj: &[u8]) {
    scene(d, SCENE_OK);
    put(&d.join("m.obj"), obj);
}

// ---- the table ----------------------------------------------------------------------------

fn corpus() -> Vec<Case> {
    use Expect::*;
    let out = ["--out", "{d}/r.csv"];
    vec![
        // Images (height fields read by `brdf`).
        case(
            "png: empty file",
            |d| {
                brdf_base(d);
                put(&d.join("e.png"), b"");
                put(&d.join("e.toml"), "dh_um = 0.1\nh_max_um = 1\n");
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/e.png",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("e.png"),
        ),
        case(
            "png: truncated",
            |d| {
                brdf_base(d);
                put(&d.join("t.png"), &png_bytes()[..40]);
                put(&d.join("t.toml"), "dh_um = 0.1\nh_max_um = 1\n");
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/t.png",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("t.png"),
        ),
        case(
            "png: random bytes",
            |d| {
                brdf_base(d);
                let junk: Vec<u8> = (0..4096u32)
                    .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
                    .collect();
                put(&d.join("j.png"), junk);
                put(&d.join("j.toml"), "dh_um = 0.1\nh_max_um = 1\n");
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/j.png",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("j.png"),
        ),
        case(
            "png: colour image",
            |d| {
                brdf_base(d);
                image::RgbImage::from_pixel(4, 4, image::Rgb([1, 2, 3]))
                    .save(d.join("c.png"))
                    .unwrap();
                put(&d.join("c.toml"), "dh_um = 0.1\nh_max_um = 1\n");
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/c.png",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("c.png"),
        ),
        case(
            "png: a directory",
            |d| {
                brdf_base(d);
                std::fs::create_dir_all(d.join("dir.png")).unwrap();
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/dir.png",
                "--dh-um",
                "0.1",
                "--hmax-um",
                "1",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("not a regular file"),
        ),
        case(
            "png: /dev/zero",
            |d| {
                brdf_base(d);
                link("/dev/zero", &d.join("z.png"));
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/z.png",
                "--dh-um",
                "0.1",
                "--hmax-um",
                "1",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("not a regular file"),
        ),
        case(
            "png: missing",
            brdf_base,
            &[
                "brdf",
                "--heightfield",
                "{d}/none.png",
                "--dh-um",
                "0.1",
                "--hmax-um",
                "1",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("none.png"),
        ),
        case(
            "image: unknown extension",
            |d| {
                brdf_base(d);
                put(&d.join("x.jpg"), b"\xff\xd8\xff");
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/x.jpg",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("unknown height-field format"),
        ),
        case(
            "png: no scale anywhere",
            |d| {
                brdf_base(d);
                image::GrayImage::new(4, 4).save(d.join("n.png")).unwrap();
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/n.png",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("pixel size unknown"),
        ),
        // Raw .f32 height fields.
        case(
            "f32: shorter than the sidecar says",
            |d| {
                brdf_base(d);
                put(&d.join("s.f32"), [0u8; 10]);
                put(&d.join("s.toml"), "nx = 4\nny = 4\ndh_um = 0.1\n");
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/s.f32",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("truncated or wrong sidecar"),
        ),
        case(
            "f32: sidecar says 16 KB, file is /dev/zero",
            |d| {
                brdf_base(d);
                link("/dev/zero", &d.join("z.f32"));
                put(&d.join("z.toml"), "nx = 64\nny = 64\ndh_um = 0.1\n");
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/z.f32",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("not a regular file"),
        ),
        case(
            "f32: file far longer than the sidecar says",
            |d| {
                brdf_base(d);
                put(&d.join("l.f32"), vec![0u8; 1 << 20]);
                put(&d.join("l.toml"), "nx = 4\nny = 4\ndh_um = 0.1\n");
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/l.f32",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("1048576 bytes"),
        ),
        case(
            "f32: no sidecar",
            |d| {
                brdf_base(d);
                put(&d.join("ns.f32"), [0u8; 64]);
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/ns.f32",
                "--dh-um",
                "0.1",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("need `nx` and `ny`"),
        ),
        case(
            "f32: sidecar size beyond the limit",
            |d| {
                brdf_base(d);
                f32_field(
                    &d.join("b.f32"),
                    4,
                    "nx = 100000\nny = 100000\ndh_um = 0.1\n",
                );
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/b.f32",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("exceeds the limit"),
        ),
        case(
            "f32: a NaN sample",
            |d| {
                brdf_base(d);
                let mut b = vec![0u8; 64];
                b[20..24].copy_from_slice(&f32::NAN.to_le_bytes());
                put(&d.join("nan.f32"), b);
                put(&d.join("nan.toml"), "nx = 4\nny = 4\ndh_um = 0.1\n");
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/nan.f32",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
            ],
            Fail("not finite"),
        ),
        // Sidecars.
        case(
            "sidecar: syntax error",
            |d| {
                brdf_base(d);
                put(&d.join("hf.toml"), "dh_um = 0.1\nh_max_um = = 1\n");
            },
            &brdf_with(&out),
            Fail("line 2, column"),
        ),
        case(
            "sidecar: unknown key",
            |d| {
                brdf_base(d);
                put(&d.join("hf.toml"), "dh_um = 0.1\nh_max_um = 1\nscale = 3\n");
            },
            &brdf_with(&out),
            Fail("unknown field"),
        ),
        case(
            "sidecar: negative pixel size",
            |d| {
                brdf_base(d);
                put(&d.join("hf.toml"), "dh_um = -0.1\nh_max_um = 1\n");
            },
            &brdf_with(&out),
            Fail("dH"),
        ),
        case(
            "sidecar: NaN height scale",
            |d| {
                brdf_base(d);
                put(&d.join("hf.toml"), "dh_um = 0.1\nh_max_um = nan\n");
            },
            &brdf_with(&out),
            Fail("h_max_um"),
        ),
        case(
            "sidecar: nx disagrees with the image",
            |d| {
                brdf_base(d);
                put(&d.join("hf.toml"), "dh_um = 0.1\nh_max_um = 1\nnx = 9\n");
            },
            &brdf_with(&out),
            Fail("nx = 9"),
        ),
        case(
            "sidecar: a directory",
            |d| {
                brdf_base(d);
                std::fs::remove_file(d.join("hf.toml")).unwrap();
                std::fs::create_dir_all(d.join("hf.toml")).unwrap();
            },
            &brdf_with(&out),
            Fail("not a regular file"),
        ),
        // OBJ meshes (scene renders). None of them may open the device: the mesh is read
        // and checked first, so a check after the device opens fails the case.
        case(
            "obj: /dev/zero",
            |d| {
                scene(d, SCENE_OK);
                link("/dev/zero", &d.join("m.obj"));
            },
            &[
                "render",
                "--scene",
                "{d}/s.toml",
                "-o",
                "{d}/o.png",
                "--no-cache",
            ],
            Fail("not a regular file"),
        ),
        case(
            "obj: missing",
            |d| scene(d, SCENE_OK),
            &[
                "render",
                "--scene",
                "{d}/s.toml",
                "-o",
                "{d}/o.png",
                "--no-cache",
            ],
            Fail("m.obj"),
        ),
        case(
            "obj: empty",
            |d| obj_scene(d, b""),
            &[
                "render",
                "--scene",
                "{d}/s.toml",
                "-o",
                "{d}/o.png",
                "--no-cache",
            ],
            Fail("m.obj"),
        ),
        case(
            "obj: face index out of range",
            |d| obj_scene(d, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"),
            &[
                "render",
                "--scene",
                "{d}/s.toml",
                "-o",
                "{d}/o.png",
                "--no-cache",
            ],
            Fail("m.obj"),
        ),
        case(
            "obj: binary junk",
            |d| obj_scene(d, &[0xffu8, 0xfe, 0x00, 0x01, 0x80].repeat(200)),
            &[
                "render",
                "--scene",
                "{d}/s.toml",
                "-o",
                "{d}/o.png",
                "--no-cache",
            ],
            Fail("m.obj"),
        ),
        case(
            "obj: vertices but no faces",
            |d| obj_scene(d, b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"),
            &[
                "render",
                "--scene",
                "{d}/s.toml",
                "-o",
                "{d}/o.png",
                "--no-cache",
            ],
            Fail("no triangles"),
        ),
        case(
            "obj: NaN coordinate",
            |d| obj_scene(d, b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n"),
            &[
                "render",
                "--scene",
                "{d}/s.toml",
                "-o",
                "{d}/o.png",
                "--no-cache",
            ],
            Fail("not finite"),
        ),
        case(
            "obj: not UTF-8",
            |d| obj_scene(d, b"v 0 0 0\nv 1 0 0\nv 0 1 0\n# \xff\nf 1 2 3\n"),
            &[
                "render",
                "--scene",
                "{d}/s.toml",
                "-o",
                "{d}/o.png",
                "--no-cache",
            ],
            Fail("invalid UTF-8"),
        ),
        // The scene's texture and a render's height field are read before the device too.
        case(
            "png: truncated scene texture",
            |d| {
                scene(
                    d,
                    "[material]\nheightfield = \"hf.png\"\nterms = 1\n\n[output]\nwidth = 8\nheight = 8\n\n[texture]\npath = \"t.png\"\n",
                );
                put(&d.join("t.png"), &png_bytes()[..40]);
            },
            &[
                "render",
                "--scene",
                "{d}/s.toml",
                "-o",
                "{d}/o.png",
                "--no-cache",
            ],
            Fail("t.png"),
        ),
        case(
            "png: truncated height field of a BRDF map",
            |d| {
                put(&d.join("t.png"), &png_bytes()[..40]);
                put(&d.join("t.toml"), "dh_um = 0.1\nh_max_um = 1\n");
            },
            &[
                "render",
                "--brdf-map",
                "--size",
                "8",
                "--heightfield",
                "{d}/t.png",
                "-o",
                "{d}/o.exr",
                "--no-cache",
            ],
            Fail("t.png"),
        ),
        case(
            "png: truncated height field of a profile",
            |d| {
                put(&d.join("t.png"), &png_bytes()[..40]);
                put(&d.join("t.toml"), "dh_um = 0.1\nh_max_um = 1\n");
            },
            &["profile", "--heightfield", "{d}/t.png", "--no-cache"],
            Fail("t.png"),
        ),
        // Scene TOML.
        case(
            "scene: syntax error",
            |d| scene(d, "[camera]\neye = [0, 1\n"),
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("line 3, column 1: invalid array; expected"),
        ),
        case(
            "scene: unknown key",
            |d| scene(d, "[camera]\nzoom = 2\n"),
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("unknown field"),
        ),
        case(
            "scene: semantic error has line and column",
            |d| scene(d, "[output]\nwidth = 8\n\n[camera]\nfov_y_deg = 200\n"),
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("line 5, column 1: [camera] fov_y_deg"),
        ),
        case(
            "scene: mesh path and builtin",
            |d| scene(d, "[mesh]\nbuiltin = \"sphere\"\npath = \"m.obj\"\n"),
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("line 3, column 1: [mesh]"),
        ),
        case(
            "scene: scale_quads on a mesh that is not scaly-snake",
            |d| scene(d, "[mesh]\nbuiltin = \"sphere\"\nscale_quads = 4\n"),
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("scale_quads applies to builtin"),
        ),
        case(
            "scene: /dev/zero",
            |d| link("/dev/zero", &d.join("z.toml")),
            &["render", "--scene", "{d}/z.toml", "-o", "{d}/o.png"],
            Fail("not a regular file"),
        ),
        case(
            "scene: its height field is /dev/zero",
            |d| {
                put(
                    &d.join("s.toml"),
                    "[material]\nheightfield = \"z.png\"\ndh_um = 0.1\nh_max_um = 0.2\n",
                );
                link("/dev/zero", &d.join("z.png"));
            },
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("not a regular file"),
        ),
        case(
            "scene: missing",
            |_| {},
            &["render", "--scene", "{d}/none.toml", "-o", "{d}/o.png"],
            Fail("none.toml"),
        ),
        case(
            "scene: not UTF-8",
            |d| put(&d.join("s.toml"), b"[camera]\nfov_y_deg = 3\xff\n"),
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("not UTF-8"),
        ),
        case(
            "scene: larger than a scene can be",
            |d| put(&d.join("s.toml"), format!("# {}\n", "x".repeat(1 << 21))),
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("at most"),
        ),
        // Query CSV.
        case(
            "csv: wrong header",
            |d| {
                brdf_base(d);
                put(&d.join("q.csv"), "theta,phi\n1,2\n");
            },
            &brdf_with(&out),
            Fail("header must be"),
        ),
        case(
            "csv: every bad row is reported",
            |d| {
                brdf_base(d);
                put(
                    &d.join("q.csv"),
                    format!("{HEADER}30,0,30,180,500\n30,x,30,180,500\n10,0,10,0,500\n1,2,3\n"),
                );
            },
            &brdf_with(&out),
            Fail("2 bad rows: line 3: phi_i_deg = 'x' is not a number; line 5: expected 5 columns"),
        ),
        case(
            "csv: many bad rows are cut after 20",
            |d| {
                brdf_base(d);
                put(
                    &d.join("q.csv"),
                    format!("{HEADER}{}", "1,2,3,4,9999\n".repeat(30)),
                );
            },
            &brdf_with(&out),
            Fail("30 bad rows"),
        ),
        case(
            "csv: /dev/zero",
            |d| {
                brdf_base(d);
                std::fs::remove_file(d.join("q.csv")).unwrap();
                link("/dev/zero", &d.join("q.csv"));
            },
            &brdf_with(&out),
            Fail("not a regular file"),
        ),
        case(
            "csv: empty",
            |d| {
                brdf_base(d);
                put(&d.join("q.csv"), "");
            },
            &brdf_with(&out),
            Fail("empty file"),
        ),
        case(
            "csv: not UTF-8",
            |d| {
                brdf_base(d);
                put(&d.join("q.csv"), b"theta_i_deg\xff\n");
            },
            &brdf_with(&out),
            Fail("not UTF-8"),
        ),
        case(
            "csv: wavelength out of range",
            |d| {
                brdf_base(d);
                put(&d.join("q.csv"), format!("{HEADER}30,0,30,180,900\n"));
            },
            &brdf_with(&out),
            Fail("lambda_nm = 900"),
        ),
        case(
            "csv: a UTF-8 byte-order mark is accepted",
            |d| {
                brdf_base(d);
                put(
                    &d.join("q.csv"),
                    format!("\u{feff}{HEADER}30,0,30,180,500\n"),
                );
            },
            &brdf_with(&out),
            Ok,
        ),
        // Cache files: a bad one is reported, recomputed and replaced; never fatal.
        // The runner fills the cache first and then breaks its files (see `break_cache`).
        case(
            "cache: truncated term file",
            brdf_base,
            &[
                "brdf",
                "--heightfield",
                "{d}/hf.png",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
                "--terms",
                "2",
                "--cache-dir",
                "{d}/cache",
            ],
            Warn("too short"),
        ),
        case(
            "cache: term file overwritten with junk",
            brdf_base,
            &[
                "brdf",
                "--heightfield",
                "{d}/hf.png",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
                "--terms",
                "2",
                "--cache-dir",
                "{d}/cache",
            ],
            Warn("bad magic"),
        ),
        case(
            "cache: term file with one flipped byte",
            brdf_base,
            &[
                "brdf",
                "--heightfield",
                "{d}/hf.png",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
                "--terms",
                "2",
                "--cache-dir",
                "{d}/cache",
            ],
            Warn("checksum mismatch"),
        ),
        case(
            "cache: DIFFRACT_CACHE_MAX is not a size",
            brdf_base,
            &[
                "brdf",
                "--heightfield",
                "{d}/hf.png",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
                "--terms",
                "2",
                "--cache-dir",
                "{d}/cache",
            ],
            Fail("DIFFRACT_CACHE_MAX"),
        )
        .env("DIFFRACT_CACHE_MAX", "lots"),
        case(
            "cache: a stack larger than the cap is not written",
            brdf_base,
            &[
                "brdf",
                "--heightfield",
                "{d}/hf.png",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
                "--terms",
                "2",
                "--cache-dir",
                "{d}/cache",
            ],
            Warn("not cached"),
        )
        .env("DIFFRACT_CACHE_MAX", "100"),
        case(
            "cache: clear on a file",
            |d| put(&d.join("notadir"), b"x"),
            &["cache", "clear", "--cache-dir", "{d}/notadir"],
            Fail("notadir"),
        ),
        // Numeric flags.
        case(
            "flag: --dh-um 1e18 does not overflow (refused: dH above 1 mm)",
            brdf_base,
            &brdf_with(&["--dh-um", "1e18", "--out", "{d}/r.csv"]),
            Fail("the pixel size must lie in [0.0001, 1000] µm"),
        ),
        case(
            "flag: --terms 65",
            brdf_base,
            &[
                "brdf",
                "--heightfield",
                "{d}/hf.png",
                "--queries",
                "{d}/q.csv",
                "--terms",
                "65",
                "--out",
                "{d}/r.csv",
            ],
            Fail("at most 64 terms"),
        ),
        case(
            "flag: --coherence-um nan",
            brdf_base,
            &brdf_with(&["--coherence-um", "nan", "--out", "{d}/r.csv"]),
            Fail("coherence"),
        ),
        case(
            "flag: eval-grating --step-deg 1e-5",
            |_| {},
            &["eval-grating", "--step-deg", "1e-5", "--no-cache"],
            Fail("step-deg"),
        ),
        case(
            "flag: eval-grating --azimuth nan",
            |_| {},
            &["eval-grating", "--azimuth", "nan", "--no-cache"],
            Fail("invalid azimuth"),
        ),
        case(
            "flag: eval-grating with a billion wavelengths",
            |_| {},
            &[
                "eval-grating",
                "--lambdas-nm",
                "400",
                "700",
                "1e-7",
                "--no-cache",
            ],
            Fail("wavelengths"),
        ),
        case(
            "flag: render --brdf-map --size 0",
            |_| {},
            &["render", "--brdf-map", "--size", "0", "-o", "{d}/m.exr"],
            Fail("BRDF map size"),
        ),
        case(
            "flag: render --brdf-map --theta-i 91",
            |_| {},
            &["render", "--brdf-map", "--theta-i", "91", "-o", "{d}/m.exr"],
            Fail("theta-i"),
        ),
        case(
            "flag: render --brdf-map --per-vertex",
            |_| {},
            &["render", "--brdf-map", "--per-vertex", "-o", "{d}/m.exr"],
            Fail("a BRDF map has no vertices"),
        ),
        case(
            "flag: render --variant volume --per-vertex",
            |_| {},
            &[
                "render",
                "--variant",
                "volume",
                "--per-vertex",
                "-o",
                "{d}/o.png",
            ],
            Fail("'volume' has no per-vertex evaluation"),
        ),
        case(
            "flag: --size without --brdf-map",
            |_| {},
            &["render", "--size", "64", "-o", "{d}/o.png"],
            Fail("--size only apply with --brdf-map"),
        ),
        case(
            "flag: --theta-i and --png without --brdf-map",
            |_| {},
            &["render", "--theta-i", "10", "--png", "-o", "{d}/o.exr"],
            Fail("--theta-i, --png only apply with --brdf-map"),
        ),
        case(
            "flag: --png with a PNG output",
            |_| {},
            &["render", "--brdf-map", "--png", "-o", "{d}/m.png"],
            Fail("--png adds a PNG beside an .exr"),
        ),
        case(
            "flag: --width 0",
            |_| {},
            &["render", "--width", "0", "-o", "{d}/o.png"],
            Fail("image size"),
        ),
        case(
            "flag: profile scores more pixels than the map has",
            |_| {},
            &[
                "profile",
                "--size",
                "2",
                "--pixels",
                "1000000",
                "--no-cache",
            ],
            Fail("invalid pixels: 1000000 spread + 8 brightest; a 2² map has 4 pixels"),
        ),
        // Output paths.
        case(
            "output: directory does not exist",
            |_| {},
            &["render", "-o", "{d}/missing/o.png"],
            Fail("does not exist"),
        ),
        case(
            "output: the height field itself",
            |d| grey_png(&d.join("hf.png")),
            &[
                "render",
                "--brdf-map",
                "--heightfield",
                "{d}/hf.png",
                "-o",
                "{d}/hf.png",
            ],
            Fail("refusing to overwrite"),
        ),
        case(
            "output: a scene render onto its height field",
            |d| grey_png(&d.join("hf.png")),
            &["render", "--heightfield", "{d}/hf.png", "-o", "{d}/hf.png"],
            Fail("refusing to overwrite"),
        ),
        case(
            "output: the --png sibling is the height field",
            |d| grey_png(&d.join("hf.png")),
            &[
                "render",
                "--brdf-map",
                "--heightfield",
                "{d}/hf.png",
                "-o",
                "{d}/hf.exr",
                "--png",
            ],
            Fail("--png image"),
        ),
        case(
            "output: brdf --out is the query file",
            brdf_base,
            &brdf_with(&["--out", "{d}/q.csv"]),
            Fail("refusing to overwrite"),
        ),
        case(
            "output: brdf --out is the height field's sidecar",
            brdf_base,
            &brdf_with(&["--out", "{d}/hf.toml"]),
            Fail("sidecar"),
        ),
        case(
            "output: brdf --out is a directory",
            brdf_base,
            &brdf_with(&["--out", "{d}"]),
            Fail("is a directory"),
        ),
        case(
            "output: heightfield -o X.f32 beside X.png",
            |d| grey_png(&d.join("hf.png")),
            &[
                "heightfield",
                "--kind",
                "sinusoidal",
                "--size-um",
                "2",
                "--dh-um",
                "0.0625",
                "-o",
                "{d}/hf.f32",
            ],
            Fail("also the sidecar of"),
        ),
        case(
            "output: heightfield into a missing directory",
            |_| {},
            &[
                "heightfield",
                "--kind",
                "sinusoidal",
                "--size-um",
                "2",
                "--dh-um",
                "0.0625",
                "-o",
                "{d}/no/hf.png",
            ],
            Fail("does not exist"),
        ),
        case(
            "output: profile --csv is the height field",
            |d| grey_png(&d.join("hf.png")),
            &[
                "profile",
                "--heightfield",
                "{d}/hf.png",
                "--csv",
                "{d}/hf.png",
                "--no-cache",
            ],
            Fail("refusing to overwrite"),
        ),
        case(
            "output: unsupported image format",
            |_| {},
            &["render", "-o", "{d}/o.jpg"],
            Fail("o.jpg"),
        ),
        // The output policy, one or more cases per command that writes.
        case(
            "output: render onto the height field its scene names",
            |d| scene(d, SCENE_HF_ONLY),
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/hf.png"],
            Fail("refusing to overwrite an input"),
        ),
        case(
            "output: render onto its scene's texture",
            |d| {
                scene(
                    d,
                    &format!("{SCENE_HF_ONLY}\n[texture]\npath = \"t.png\"\n"),
                );
                put(&d.join("t.png"), png_bytes());
            },
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/t.png"],
            Fail("is the texture"),
        ),
        case(
            "output: brdf --out is a link to the query file",
            |d| {
                brdf_base(d);
                link("q.csv", &d.join("r.csv"));
            },
            &brdf_with(&["--out", "{d}/r.csv"]),
            Fail("is the query CSV"),
        ),
        case(
            "output: heightfield --from-sample onto the sample",
            |d| grey_png(&d.join("hf.png")),
            &[
                "heightfield",
                "--from-sample",
                "{d}/hf.png",
                "-o",
                "{d}/hf.png",
            ],
            Fail("refusing to overwrite an input"),
        ),
        case(
            "output: heightfield --from-sample X.png -o X.f32 (the sample's sidecar)",
            |d| grey_png(&d.join("hf.png")),
            &[
                "heightfield",
                "--from-sample",
                "{d}/hf.png",
                "-o",
                "{d}/hf.f32",
            ],
            Fail("height-field sidecar"),
        ),
        case(
            "output: eval-grating --plot onto its height field",
            |d| grey_png(&d.join("hf.png")),
            &[
                "eval-grating",
                "--heightfield",
                "{d}/hf.png",
                "--no-cache",
                "--plot",
                "{d}/hf.png",
            ],
            Fail("refusing to overwrite an input"),
        ),
        case(
            "output: eval-grating --plot onto its sidecar",
            |d| grey_png(&d.join("hf.png")),
            &[
                "eval-grating",
                "--heightfield",
                "{d}/hf.png",
                "--no-cache",
                "--plot",
                "{d}/hf.toml",
            ],
            Fail("height-field sidecar"),
        ),
        case(
            "output: eval-grating --plot onto its .f32 height field",
            |d| f32_field(&d.join("hf.f32"), 8, "nx = 8\nny = 8\ndh_um = 0.1\n"),
            &[
                "eval-grating",
                "--heightfield",
                "{d}/hf.f32",
                "--no-cache",
                "--plot",
                "{d}/hf.f32",
            ],
            Fail("refusing to overwrite an input"),
        ),
        case(
            "output: profile --csv and --plot are one file",
            |_| {},
            &[
                "profile",
                "--no-cache",
                "--csv",
                "{d}/p.out",
                "--plot",
                "{d}/p.out",
            ],
            Fail("--plot and --csv are both"),
        ),
        case(
            "output: profile --plot onto its height field's sidecar",
            |d| grey_png(&d.join("hf.png")),
            &[
                "profile",
                "--heightfield",
                "{d}/hf.png",
                "--no-cache",
                "--plot",
                "{d}/hf.toml",
            ],
            Fail("height-field sidecar"),
        ),
        case(
            "output: stability -o DIR holding its height field as stability.png",
            |d| grey_png(&d.join("stability.png")),
            &[
                "stability",
                "--heightfield",
                "{d}/stability.png",
                "--no-gpu",
                "-o",
                "{d}",
            ],
            Fail("refusing to overwrite an input"),
        ),
        case(
            "output: stability -o names a file",
            |d| put(&d.join("report"), "keep"),
            &["stability", "--no-gpu", "-o", "{d}/report"],
            Fail("not a directory"),
        ),
        case(
            "output: view --screenshot onto its scene's height field",
            |d| scene(d, SCENE_HF_ONLY),
            &[
                "view",
                "--scene",
                "{d}/s.toml",
                "--frames",
                "1",
                "--screenshot",
                "{d}/hf.png",
            ],
            Fail("refusing to overwrite an input"),
        ),
        case(
            "output: view --screenshot is a link to its height field",
            |d| {
                scene(d, SCENE_HF_ONLY);
                link("hf.png", &d.join("shot.png"));
            },
            &[
                "view",
                "--scene",
                "{d}/s.toml",
                "--frames",
                "1",
                "--screenshot",
                "{d}/shot.png",
            ],
            Fail("is the height field"),
        ),
        case(
            "output: cache clear in a directory that is a file",
            |d| put(&d.join("c"), "not a cache"),
            &["cache", "clear", "--cache-dir", "{d}/c"],
            Fail("Not a directory"),
        ),
        // Numbers of stability and profile, checked like render's.
        case(
            "flag: stability --tolerance nan",
            |_| {},
            &["stability", "--no-gpu", "--tolerance", "nan", "-o", "{d}/s"],
            Fail("invalid tolerance: NaN; must be in [1e-6, 1)"),
        ),
        case(
            "flag: stability --tolerance 0",
            |_| {},
            &["stability", "--no-gpu", "--tolerance", "0", "-o", "{d}/s"],
            Fail("tolerance"),
        ),
        case(
            "flag: stability --tolerance -1 (a negative number parses)",
            |_| {},
            &["stability", "--no-gpu", "--tolerance", "-1", "-o", "{d}/s"],
            Fail("tolerance"),
        ),
        case(
            "flag: stability --tolerance inf",
            |_| {},
            &["stability", "--no-gpu", "--tolerance", "inf", "-o", "{d}/s"],
            Fail("tolerance"),
        ),
        case(
            "flag: stability --map-size 0",
            |_| {},
            &["stability", "--map-size", "0", "-o", "{d}/s"],
            Fail("map-size"),
        ),
        case(
            "flag: stability --fixed-terms 65",
            |_| {},
            &[
                "stability",
                "--no-gpu",
                "--fixed-terms",
                "65",
                "-o",
                "{d}/s",
            ],
            Fail("fixed-terms"),
        ),
        case(
            "flag: stability --hmax-um -0.1",
            |_| {},
            &["stability", "--no-gpu", "--hmax-um", "-0.1", "-o", "{d}/s"],
            Fail("hmax-um"),
        ),
        case(
            "flag: stability --theta-i nan",
            |_| {},
            &["stability", "--no-gpu", "--theta-i", "nan", "-o", "{d}/s"],
            Fail("theta-i"),
        ),
        case(
            "flag: profile --table-texel 0",
            |_| {},
            &["profile", "--no-cache", "--table-texel", "0"],
            Fail("table texel: 0; must be positive"),
        ),
        case(
            "flag: profile --table-texel -1 (a negative number parses)",
            |_| {},
            &["profile", "--no-cache", "--table-texel", "-1"],
            Fail("table texel: -1; must be positive"),
        ),
        case(
            "flag: profile --table-w-nodes 1",
            |_| {},
            &["profile", "--no-cache", "--table-w-nodes", "1"],
            Fail("table w nodes"),
        ),
        case(
            "flag: profile --table-step-nm 3",
            |_| {},
            &["profile", "--no-cache", "--table-step-nm", "3"],
            Fail("wavelength step"),
        ),
        case(
            "flag: profile --table-budget-mb 0",
            |_| {},
            &["profile", "--no-cache", "--table-budget-mb", "0"],
            Fail("table budget"),
        ),
        case(
            "flag: profile --mesh-quads 0",
            |_| {},
            &["profile", "--no-cache", "--mesh-quads", "0"],
            Fail("mesh-quads"),
        ),
        case(
            "flag: render --table-texel nan",
            |_| {},
            &["render", "--table-texel", "nan", "-o", "{d}/o.png"],
            Fail("table texel"),
        ),
        // Argument errors from the parser: one line, exit 1, like every other error.
        case(
            "flag: unknown flag",
            |_| {},
            &["render", "--bogus", "-o", "{d}/o.png"],
            Fail("unexpected argument '--bogus'"),
        ),
        case(
            "flag: a value that is no number",
            |_| {},
            &["profile", "--size", "big"],
            Fail("invalid value 'big' for '--size <SIZE>'"),
        ),
        case(
            "flag: a value outside the enum",
            |_| {},
            &["render", "--variant", "fastest", "-o", "{d}/o.png"],
            Fail("possible values"),
        ),
    ]
}

/// A scene of a height field beside it and nothing else to read.
const SCENE_HF_ONLY: &str =
    "[material]\nheightfield = \"hf.png\"\nterms = 1\n\n[output]\nwidth = 8\nheight = 8\n";

// ---- the runner ---------------------------------------------------------------------------

/// A case that runs longer than this hangs (a FIFO read, a loop): it fails and is killed.
const HANG_SECS: u64 = 120;

/// Runs `cmd` to its end and collects its output, or kills it after `secs` (`None`).
fn output_within(cmd: &mut Command, secs: u64) -> Option<Output> {
    let (mut child, drained) = files_util::spawn_drained(cmd);
    let start = std::time::Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed().as_secs() >= secs {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let (stdout, stderr) = drained.join();
    Some(Output {
        status,
        stdout,
        stderr,
    })
}

fn run(c: &Case, root: &Path, index: usize) -> Result<(), String> {
    let d = root.join(format!("case{index:02}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    (c.setup)(&d);
    let ds = d.to_str().unwrap();
    let args: Vec<String> = c.args.iter().map(|a| a.replace("{d}", ds)).collect();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_diffract"));
    cmd.args(&args).env("DIFFRACT_CACHE", "");
    // No case may need the device: every error is found before it opens.
    cmd.env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json");
    for (k, v) in &c.env {
        cmd.env(k, v.replace("{d}", ds));
    }
    if let Some(rest) = c.name.strip_prefix("cache: ") {
        if rest.starts_with("t") {
            // Fill the cache, then break each term file the way the case says.
            let o = cmd.output().unwrap();
            if !o.status.success() {
                return Err(format!(
                    "first run failed: {}",
                    String::from_utf8_lossy(&o.stderr)
                ));
            }
            for e in std::fs::read_dir(d.join("cache")).unwrap().flatten() {
                let mut b = std::fs::read(e.path()).unwrap();
                match rest {
                    "truncated term file" => b.truncate(30),
                    "term file overwritten with junk" => b.fill(0x5a),
                    _ => {
                        let mid = b.len() / 2;
                        b[mid] ^= 4;
                    }
                }
                std::fs::write(e.path(), b).unwrap();
            }
        }
    }
    let before = snapshot(&d);
    let Some(o) = output_within(&mut cmd, HANG_SECS) else {
        return Err(format!("hung: killed after {HANG_SECS} s: {args:?}"));
    };
    let after = snapshot(&d);
    let err = String::from_utf8_lossy(&o.stderr);
    let ctx = || format!("{args:?}\nstatus {:?}\nstderr:\n{err}", o.status.code());
    if err.contains("panicked") || o.status.code().is_none_or(|c| c > 1) {
        return Err(format!("panic or crash (every error exits 1): {}", ctx()));
    }
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
    let other: Vec<&str> = err
        .lines()
        .filter(|l| !l.starts_with("warning:") && !l.starts_with("error"))
        .collect();
    match c.expect {
        Expect::Fail(needle) => {
            if o.status.success() {
                return Err(format!("expected failure: {}", ctx()));
            }
            if errors.len() != 1 || !other.is_empty() {
                return Err(format!("expected exactly one error line: {}", ctx()));
            }
            if !errors[0].starts_with("error: ") || !errors[0].contains(needle) {
                return Err(format!("'{needle}' not in the error line: {}", ctx()));
            }
            if before != after {
                let changed: Vec<_> = after
                    .keys()
                    .chain(before.keys())
                    .filter(|k| before.get(*k) != after.get(*k))
                    .collect();
                return Err(format!("files changed {changed:?}: {}", ctx()));
            }
        }
        Expect::Warn(_) | Expect::Ok => {
            if !o.status.success() || !errors.is_empty() {
                return Err(format!("expected success: {}", ctx()));
            }
            if let Expect::Warn(needle) = c.expect {
                if !err.contains(needle) {
                    return Err(format!("'{needle}' not in stderr: {}", ctx()));
                }
            }
            for (k, v) in &before {
                let is_cache = k.starts_with(d.join("cache"));
                if !is_cache && after.get(k) != Some(v) {
                    return Err(format!("{} changed: {}", k.display(), ctx()));
                }
            }
        }
    }
    Ok(())
}

#[test]
fn corpus_has_at_least_40_cases_across_every_kind() {
    let cases = corpus();
    eprintln!("bad-input corpus: {} cases", cases.len());
    assert!(cases.len() >= 40, "{} cases", cases.len());
    for kind in [
        "png", "f32", "sidecar", "obj", "scene", "csv", "cache", "flag", "output",
    ] {
        assert!(
            cases.iter().filter(|c| c.name.starts_with(kind)).count() >= 3,
            "fewer than 3 {kind} cases"
        );
    }
}

#[test]
fn every_bad_input_gives_one_error_line_and_touches_nothing() {
    let root = std::env::temp_dir().join(format!("diffract-bad-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let cases = corpus();
    // Two workers: the machine running CI may have few cores.
    let failures = std::sync::Mutex::new(Vec::new());
    let next = std::sync::atomic::AtomicUsize::new(0);
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some(c) = cases.get(i) else { break };
                if let Err(msg) = run(c, &root, i) {
                    failures.lock().unwrap().push(format!("[{}] {msg}", c.name));
                }
            });
        }
    });
    let failures = failures.into_inner().unwrap();
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n\n")
    );
    let _ = std::fs::remove_dir_all(&root);
}

// ---- outputs that are devices, pipes and descriptors ---------------------------------------

mod gpu_util;

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-dev-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn diffract(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_diffract"));
    c.args(args).env("DIFFRACT_CACHE", "");
    c
}

fn is_char_device(p: &str) -> bool {
    use std::os::unix::fs::FileTypeExt;
    std::fs::metadata(p).is_ok_and(|m| m.file_type().is_char_device())
}

/// Temporary files a replacing write would have left or renamed in `/dev`.
fn dev_temporaries() -> Vec<String> {
    std::fs::read_dir("/dev")
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp-"))
        .collect()
}

fn brdf_args(d: &Path, out: &str) -> Vec<String> {
    BRDF.iter()
        .map(|a| a.replace("{d}", d.to_str().unwrap()))
        .chain(["--out".to_string(), out.to_string()])
        .collect()
}

/// `/dev/null` as an output is written into and stays the character device (tests and CI run
/// as root, where replacing it through a temporary file and a rename would succeed).
#[test]
fn outputs_onto_dev_null_write_into_the_device() {
    let d = scratch("null");
    brdf_base(&d);
    assert!(is_char_device("/dev/null"));
    let o = diffract(&[])
        .args(brdf_args(&d, "/dev/null"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(is_char_device("/dev/null"), "brdf --out replaced /dev/null");
    let o = diffract(&[
        "eval-grating",
        "--heightfield",
        "builtin:blazed",
        "--no-cache",
        "--terms",
        "6",
        "--lambdas-nm",
        "400",
        "700",
        "50",
        "--step-deg",
        "0.05",
        "--plot",
        "/dev/null",
    ])
    .output()
    .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        is_char_device("/dev/null"),
        "eval-grating --plot replaced /dev/null"
    );
    assert!(dev_temporaries().is_empty(), "{:?}", dev_temporaries());
    let _ = std::fs::remove_dir_all(&d);
}

/// `profile` needs the GPU: a tiny profile of one variant writes its CSV into `/dev/null`,
/// which stays a character device.
#[test]
fn profile_csv_onto_dev_null_keeps_the_device() {
    let d = scratch("profile");
    grey_png(&d.join("hf.png"));
    let hf = d.join("hf.png");
    let o = diffract(&[
        "profile",
        "--heightfield",
        hf.to_str().unwrap(),
        "--size",
        "16",
        "--pixels",
        "8",
        "--brightest",
        "4",
        "--frames",
        "1",
        "--mesh-size",
        "0",
        "--variant-terms",
        "2",
        "--only",
        "thesis: taylor R=1",
        "--no-cache",
        "--csv",
        "/dev/null",
    ])
    .output()
    .unwrap();
    if gpu_util::binary_found_no_vulkan(&o) {
        return;
    }
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        is_char_device("/dev/null"),
        "profile --csv replaced /dev/null"
    );
    assert!(dev_temporaries().is_empty(), "{:?}", dev_temporaries());
    let _ = std::fs::remove_dir_all(&d);
}

/// A named pipe as an output: its reader gets the CSV, and the pipe is still a pipe.
#[test]
fn an_output_fifo_is_written_into() {
    use std::io::Read;
    use std::os::unix::fs::FileTypeExt;
    let d = scratch("fifo");
    brdf_base(&d);
    let fifo = d.join("answers");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: `c` is a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0, "mkfifo");
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || {
            let mut s = String::new();
            std::fs::File::open(&fifo)
                .unwrap()
                .read_to_string(&mut s)
                .unwrap();
            s
        })
    };
    let o = diffract(&[])
        .args(brdf_args(&d, fifo.to_str().unwrap()))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = reader.join().unwrap();
    assert!(
        text.starts_with("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm,rho,X,Y,Z\n"),
        "{text}"
    );
    assert_eq!(text.lines().count(), 2, "{text}");
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
    let _ = std::fs::remove_dir_all(&d);
}

/// `--out /dev/stdout` writes the answers to standard output: onto a pipe, and onto a file
/// the shell opened (`> r.csv` truncates and the answers replace the old text; `>> log`
/// appends). `/dev/stdout` stays the link it was.
#[test]
fn dev_stdout_as_an_output_reaches_standard_output() {
    let d = scratch("stdout");
    brdf_base(&d);
    let o = diffract(&[])
        .args(brdf_args(&d, "/dev/stdout"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let piped = String::from_utf8(o.stdout).unwrap();
    assert!(piped.starts_with("theta_i_deg,"), "{piped}");
    assert_eq!(piped.lines().count(), 2, "{piped}");

    let log = d.join("log.txt");
    std::fs::write(&log, "earlier line\n").unwrap();
    let f = std::fs::OpenOptions::new().append(true).open(&log).unwrap();
    let o = diffract(&[])
        .args(brdf_args(&d, "/dev/stdout"))
        .stdout(f)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        std::fs::read_to_string(&log).unwrap(),
        format!("earlier line\n{piped}")
    );

    let fresh = d.join("fresh.csv");
    std::fs::write(
        &fresh,
        "stale text that is longer than nothing\n".repeat(20),
    )
    .unwrap();
    let f = std::fs::File::create(&fresh).unwrap(); // truncates, like `>`
    let o = diffract(&[])
        .args(brdf_args(&d, "/dev/stdout"))
        .stdout(f)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read_to_string(&fresh).unwrap(), piped);
    assert!(std::fs::symlink_metadata("/dev/stdout")
        .unwrap()
        .file_type()
        .is_symlink());
    let _ = std::fs::remove_dir_all(&d);
}

// ---- numbers, sizes and outputs checked before any work, one test per command -------------

mod bomb;
use bomb::png_bomb;

/// Runs `cases` like the corpus does (no Vulkan driver, so every refusal must come before
/// the device opens) and reports every case that failed.
fn run_cases(tag: &str, cases: Vec<Case>) {
    let root = std::env::temp_dir().join(format!("diffract-bad-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let failures: Vec<String> = cases
        .iter()
        .enumerate()
        .filter_map(|(i, c)| run(c, &root, i).err().map(|m| format!("[{}] {m}", c.name)))
        .collect();
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n\n")
    );
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn a_png_bomb_is_a_valid_png_of_the_size_it_claims() {
    // The generator's own check, on a size the image crate may decode here.
    let img = image::load_from_memory(&png_bomb(300)).unwrap().to_luma8();
    assert_eq!(img.dimensions(), (300, 300));
    assert!(img.pixels().all(|p| p.0 == [0]));
}

#[test]
fn render_checks_numbers_environment_and_mesh_file_before_any_work() {
    use Expect::*;
    let render = |extra: &[&'static str]| {
        let mut v = vec!["render", "-o", "{d}/o.png"];
        v.extend_from_slice(extra);
        v
    };
    let cases = vec![
        case(
            "flag: render --size -inf (an integer option takes a leading '-')",
            |_| {},
            &render(&["--brdf-map", "--size", "-inf"]),
            Fail("invalid value '-inf' for '--size <SIZE>': not a whole number"),
        ),
        case(
            "flag: render --exposure 1e300 (beyond float32)",
            |_| {},
            &render(&["--exposure", "1e300"]),
            Fail("1e300 is beyond float32's range"),
        ),
        case(
            "flag: render --exposure 1e30 (beyond the exposure range)",
            |_| {},
            &render(&["--exposure", "1e30"]),
            Fail("invalid exposure: 1e30; expected 1e-6 to 1e6"),
        ),
        case(
            "flag: render --table-budget-mb -1",
            |_| {},
            &render(&["--table-budget-mb", "-1"]),
            Fail("-1 is below 0; expected a whole number"),
        ),
        case(
            "flag: render --table-budget-mb nan",
            |_| {},
            &render(&["--table-budget-mb", "nan"]),
            Fail("'nan' for '--table-budget-mb <TABLE_BUDGET_MB>': not a number; expected a whole number"),
        ),
        case(
            "flag: render --table-step-nm 0.5",
            |_| {},
            &render(&["--table-step-nm", "0.5"]),
            Fail("not a whole number; expected a whole number"),
        ),
        case(
            "flag: render --table-step-nm 200 (cannot resolve the spectrum)",
            |_| {},
            &render(&["--table-step-nm", "200"]),
            Fail("invalid table step: 200 nm; expected at most 20 nm"),
        ),
        case(
            "flag: render --table-step-nm 400",
            |_| {},
            &render(&["--table-step-nm", "400"]),
            Fail("expected at most 20 nm"),
        ),
        case(
            "flag: render --table-texel 1e-320",
            |_| {},
            &render(&["--table-texel", "1e-320"]),
            Fail("invalid table texel: 1e-320; expected at least 1e-6"),
        ),
        case(
            "env: render with DIFFRACT_CACHE_MAX=lots",
            |_| {},
            &render(&["--brdf-map", "--size", "8"]),
            Fail("invalid DIFFRACT_CACHE_MAX: 'lots'"),
        )
        .env("DIFFRACT_CACHE_MAX", "lots"),
        case(
            "output: render -o a dangling link into a missing directory",
            |d| link("gone/x.png", &d.join("o.png")),
            &render(&["--brdf-map", "--size", "8"]),
            Fail("directory"),
        ),
    ];
    run_cases("render", cases);
}

#[test]
fn heightfield_refuses_periods_it_cannot_resolve_and_bombs() {
    use Expect::*;
    let hf = |kind: &'static str, period: &'static str| -> Vec<&'static str> {
        vec![
            "heightfield",
            "--kind",
            kind,
            "--period-um",
            period,
            "-o",
            "{d}/x.png",
        ]
    };
    let cases = vec![
        case(
            "flag: heightfield sinusoidal --period-um 1e-10",
            |_| {},
            &hf("sinusoidal", "1e-10"),
            Fail("invalid period: 1e-10 µm is shorter than two"),
        ),
        case(
            "flag: heightfield sinusoidal --period-um 1e-320",
            |_| {},
            &hf("sinusoidal", "1e-320"),
            Fail("invalid period"),
        ),
        case(
            "flag: heightfield elaphe --period-um 1e-10",
            |_| {},
            &hf("elaphe", "1e-10"),
            Fail("invalid period"),
        ),
        case(
            "flag: heightfield xenopeltis --period-um 1e-10",
            |_| {},
            &hf("xenopeltis", "1e-10"),
            Fail("invalid period"),
        ),
        case(
            "png: heightfield --from-sample a PNG bomb",
            |d| {
                put(&d.join("bomb.png"), png_bomb(20000));
                put(&d.join("bomb.toml"), "dh_um = 0.1\nh_max_um = 0.2\n");
            },
            &[
                "heightfield",
                "--from-sample",
                "{d}/bomb.png",
                "-o",
                "{d}/g.png",
            ],
            Fail("its header says 20000×20000 pixels; at most 4096 a side"),
        ),
    ];
    run_cases("heightfield", cases);
}

#[test]
fn brdf_refuses_a_single_sample_and_a_png_bomb_from_the_header() {
    use Expect::*;
    let cases = vec![
        case(
            "f32: brdf on a 1×1 height field",
            |d| {
                queries(&d.join("q.csv"));
                f32_field(&d.join("one.f32"), 1, "dh_um = 0.1\nnx = 1\nny = 1\n");
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/one.f32",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
                "--no-cache",
            ],
            Fail("size 1×1 is a single sample"),
        ),
        case(
            "png: brdf on a PNG bomb",
            |d| {
                queries(&d.join("q.csv"));
                put(&d.join("bomb.png"), png_bomb(20000));
                put(&d.join("bomb.toml"), "dh_um = 0.1\nh_max_um = 0.2\n");
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/bomb.png",
                "--queries",
                "{d}/q.csv",
                "--out",
                "{d}/r.csv",
                "--no-cache",
            ],
            Fail("its header says 20000×20000 pixels"),
        ),
        case(
            "f32: brdf --method model on a one-row height field works like reference",
            |d| {
                queries(&d.join("q.csv"));
                let bytes: Vec<u8> = (0..64)
                    .flat_map(|i| (0.01 * (i % 7) as f32).to_le_bytes())
                    .collect();
                put(&d.join("row.f32"), bytes);
                put(&d.join("row.toml"), "dh_um = 0.09\nnx = 64\nny = 1\n");
            },
            &[
                "brdf",
                "--heightfield",
                "{d}/row.f32",
                "--queries",
                "{d}/q.csv",
                "--out",
                "/dev/null",
                "--no-cache",
                "--method",
                "model",
            ],
            Ok,
        ),
    ];
    run_cases("brdf", cases);
}

#[test]
fn stability_refuses_a_tolerance_no_float32_evaluator_resolves() {
    use Expect::*;
    let cases = vec![case(
        "flag: stability --tolerance 1e-320",
        |_| {},
        &[
            "stability",
            "--no-gpu",
            "--tolerance",
            "1e-320",
            "-o",
            "{d}/s",
        ],
        Fail("invalid tolerance: 1e-320; must be in [1e-6, 1)"),
    )];
    run_cases("stability", cases);
}

/// An output in a directory this process may not write is refused before any work, and
/// nothing is created. Run as an unprivileged user where the test runs as root (root
/// writes anywhere); without root, the directory's mode alone does it.
#[test]
fn an_output_in_a_read_only_directory_is_refused_before_any_work() {
    use std::os::unix::fs::PermissionsExt;
    use std::os::unix::process::CommandExt;
    let d = scratch("readonly");
    std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o755)).unwrap();
    let ro = d.join("ro");
    std::fs::create_dir(&ro).unwrap();
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
    let mut cmd = diffract(&["render", "-o"]);
    cmd.arg(ro.join("x.exr"))
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json");
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } == 0 {
        cmd.uid(65534).gid(65534);
    }
    let o = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("cannot be written (read-only or permission denied)"),
        "{err}"
    );
    assert_eq!(std::fs::read_dir(&ro).unwrap().count(), 0);
    let _ = std::fs::remove_dir_all(&d);
}

/// An output that is a dangling link is written through: the file it names is created
/// and the link stays a link (the policy for a link to a file).
#[test]
fn an_output_onto_a_dangling_link_creates_its_file_and_keeps_the_link() {
    let d = scratch("dangling");
    brdf_base(&d);
    std::fs::create_dir(d.join("sub")).unwrap();
    let out = d.join("answers.csv");
    link("sub/new.csv", &out);
    let o = diffract(&[])
        .args(brdf_args(&d, out.to_str().unwrap()))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(std::fs::symlink_metadata(&out)
        .unwrap()
        .file_type()
        .is_symlink());
    let text = std::fs::read_to_string(d.join("sub/new.csv")).unwrap();
    assert!(text.starts_with("theta_i_deg,"), "{text}");
    let _ = std::fs::remove_dir_all(&d);
}

/// A 16×8 OpenEXR environment map of uniform radiance `v`.
fn env_exr(p: &Path, v: f32) {
    let img = image::Rgb32FImage::from_pixel(16, 8, image::Rgb([v, v, v]));
    image::DynamicImage::ImageRgb32F(img).save(p).unwrap();
}

fn fifo(p: &Path) {
    let c = std::ffi::CString::new(p.to_str().unwrap()).unwrap();
    // SAFETY: a valid NUL-terminated path; mkfifo only creates the node.
    assert_eq!(
        unsafe { libc::mkfifo(c.as_ptr(), 0o644) },
        0,
        "mkfifo {}",
        p.display()
    );
}

/// A Radiance `.hdr` whose header claims `w`×`h`, with no pixel data after it.
fn hdr_header(p: &Path, w: u32, h: u32) {
    put(
        p,
        format!("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n"),
    );
}

/// A Gwyddion Simple Field of `nx`×`ny` heights `f(i, j)` in metres, 100 nm pixels.
fn gsf(p: &Path, nx: usize, ny: usize, f: impl Fn(usize, usize) -> f32) {
    let mut b = format!(
        "Gwyddion Simple Field 1.0\nXRes = {nx}\nYRes = {ny}\nXReal = {}\nYReal = {}\n\
         XYUnits = m\nZUnits = m\n",
        nx as f64 * 1e-7,
        ny as f64 * 1e-7
    )
    .into_bytes();
    b.resize(b.len() + 4 - b.len() % 4, 0);
    for j in 0..ny {
        for i in 0..nx {
            b.extend_from_slice(&f(i, j).to_le_bytes());
        }
    }
    put(p, b);
}

#[test]
fn a_refusal_after_loading_a_scan_prints_only_its_error() {
    use Expect::*;
    let wave = |i: usize, _| 1e-7 * (i as f32 / 3.0).sin();
    let cases = vec![
        case(
            "scan: a 64×1 scan under the default levelling",
            move |d| gsf(&d.join("row.gsf"), 64, 1, wave),
            &["render", "--heightfield", "{d}/row.gsf", "-o", "{d}/o.png"],
            Fail("a 64×1 field is too small to level"),
        ),
        case(
            "scan: validity of a flat scan",
            |d| gsf(&d.join("flat.gsf"), 64, 64, |_, _| 0.0),
            &["validity", "--heightfield", "{d}/flat.gsf"],
            Fail("no ridges"),
        ),
        case(
            "scan: a field too tall for the tolerance",
            |d| {
                gsf(&d.join("tall.gsf"), 64, 64, |i, _| {
                    5e-6 * (i as f32 / 3.0).sin()
                })
            },
            &[
                "render",
                "--heightfield",
                "{d}/tall.gsf",
                "--tolerance",
                "1e-6",
                "-o",
                "{d}/o.png",
            ],
            Fail("no supported expansion meets the tolerance"),
        ),
    ];
    run_cases("scan-lines", cases);
}

#[test]
fn environment_maps_lights_and_levels_keep_the_contract() {
    use Expect::*;
    let map_render = |extra: &[&'static str]| {
        let mut v = vec!["render", "--brdf-map", "--size", "8", "-o", "{d}/o.exr"];
        v.extend_from_slice(extra);
        v
    };
    let lit = |d: &Path, text: &str| put(&d.join("s.toml"), text);
    let cases = vec![
        case(
            "output: profile --csv onto its --env map",
            |d| env_exr(&d.join("e.exr"), 1.0),
            &[
                "profile",
                "--only",
                "env",
                "--env",
                "{d}/e.exr",
                "--csv",
                "{d}/e.exr",
            ],
            Fail("e.exr is the environment map"),
        ),
        case(
            "output: profile --plot onto a hard link of its --env map",
            |d| {
                env_exr(&d.join("e.exr"), 1.0);
                std::fs::hard_link(d.join("e.exr"), d.join("p.png")).unwrap();
            },
            &[
                "profile",
                "--only",
                "env",
                "--env",
                "{d}/e.exr",
                "--plot",
                "{d}/p.png",
            ],
            Fail("is the environment map"),
        ),
        case(
            "output: view --screenshot onto a hard link of its --env map",
            |d| {
                env_exr(&d.join("e.exr"), 1.0);
                std::fs::hard_link(d.join("e.exr"), d.join("l.png")).unwrap();
            },
            &[
                "view",
                "--env",
                "{d}/e.exr",
                "--screenshot",
                "{d}/l.png",
                "--frames",
                "1",
            ],
            Fail("l.png is the environment map"),
        ),
        case(
            "output: render -o onto the scene's [environment] map through a symbolic link",
            |d| {
                env_exr(&d.join("e.exr"), 1.0);
                link("e.exr", &d.join("o.exr"));
                put(&d.join("s.toml"), "[environment]\nmap = \"e.exr\"\n");
            },
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.exr"],
            Fail("is the environment map"),
        ),
        case(
            "input: a FIFO as render --env (a BRDF map)",
            |d| fifo(&d.join("f.hdr")),
            &map_render(&["--env", "{d}/f.hdr"]),
            Fail("f.hdr: not a regular file; the environment map must be a file"),
        ),
        case(
            "input: a FIFO as render --env (a scene)",
            |d| fifo(&d.join("f.exr")),
            &["render", "--env", "{d}/f.exr", "-o", "{d}/o.png"],
            Fail("not a regular file"),
        ),
        case(
            "input: a FIFO as profile --env",
            |d| fifo(&d.join("f.hdr")),
            &["profile", "--only", "env", "--env", "{d}/f.hdr"],
            Fail("not a regular file"),
        ),
        case(
            "input: a FIFO as view --env",
            |d| fifo(&d.join("f.hdr")),
            &["view", "--env", "{d}/f.hdr", "--frames", "1"],
            Fail("not a regular file"),
        ),
        case(
            "input: a FIFO as a scene's [environment] map",
            |d| {
                fifo(&d.join("f.hdr"));
                put(&d.join("s.toml"), "[environment]\nmap = \"f.hdr\"\n");
            },
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("not a regular file"),
        ),
        case(
            "input: a directory named like a map",
            |d| std::fs::create_dir_all(d.join("dir.exr")).unwrap(),
            &map_render(&["--env", "{d}/dir.exr"]),
            Fail("not a regular file"),
        ),
        case(
            "input: a FIFO as the height field",
            |d| fifo(&d.join("hf.png")),
            &map_render(&["--heightfield", "{d}/hf.png"]),
            Fail("not a regular file"),
        ),
        case(
            "light: --env-intensity 1e38 on a map",
            |d| env_exr(&d.join("e.exr"), 1.0),
            &map_render(&["--env", "{d}/e.exr", "--env-intensity", "1e38"]),
            Fail("= 1.000e38: must be 0 or within 1e-30 to 1e30"),
        ),
        case(
            "light: --env-intensity 3.4e38 on a map",
            |d| env_exr(&d.join("e.exr"), 1.0),
            &map_render(&["--env", "{d}/e.exr", "--env-intensity", "3.4e38"]),
            Fail("carried in float32 on the device"),
        ),
        case(
            "light: --env-intensity 1e39 on a map (beyond float32)",
            |d| env_exr(&d.join("e.exr"), 1.0),
            &map_render(&["--env", "{d}/e.exr", "--env-intensity", "1e39"]),
            Fail("carried in float32 on the device"),
        ),
        case(
            "light: --env-intensity 1e300 on a map",
            |d| env_exr(&d.join("e.exr"), 1.0),
            &map_render(&["--env", "{d}/e.exr", "--env-intensity", "1e300"]),
            Fail("carried in float32 on the device"),
        ),
        case(
            "light: a map of 1e20 under --env-intensity 1e20",
            |d| env_exr(&d.join("e.exr"), 1e20),
            &map_render(&["--env", "{d}/e.exr", "--env-intensity", "1e20"]),
            Fail("= 1.000e40"),
        ),
        case(
            "light: --env-intensity 1e-40 (lost to float32's underflow)",
            |_| {},
            &map_render(&["--env", "builtin:white", "--env-intensity", "1e-40"]),
            Fail("must be 0 or within 1e-30 to 1e30"),
        ),
        case(
            "light: [environment] intensity = 1e300",
            move |d| {
                lit(
                    d,
                    "[environment]\nmap = \"builtin:sky\"\nintensity = 1e300\n",
                )
            },
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("[environment] intensity = 1.000e300"),
        ),
        case(
            "light: [[disc_light]] intensity = 1e38",
            move |d| lit(d, "[[disc_light]]\nintensity = 1e38\n"),
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("[disc_light] 1: intensity × colour = 1.000e38"),
        ),
        case(
            "light: a small [[disc_light]] whose radiance passes float32's range",
            move |d| {
                lit(
                    d,
                    "[[disc_light]]\nintensity = 1e25\nangular_diameter_deg = 0.001\n",
                )
            },
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("radiance intensity × colour / solid angle"),
        ),
        case(
            "light: [[disc_light]] colour [1e20, 0, 0] at intensity 1e20",
            move |d| {
                lit(
                    d,
                    "[[disc_light]]\nintensity = 1e20\ncolour = [1e20, 0.0, 0.0]\n",
                )
            },
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("intensity × colour = 1.000e40"),
        ),
        case(
            "light: [light] intensity = 1e36",
            move |d| lit(d, "[light]\nintensity = 1e36\n"),
            &["render", "--scene", "{d}/s.toml", "-o", "{d}/o.png"],
            Fail("[light] intensity = 1.000e36"),
        ),
        case(
            "light: --env-noise without any environment",
            |_| {},
            &["render", "--env-noise", "0.3", "-o", "{d}/o.png"],
            Fail("--env-seed and --no-sun need an environment"),
        ),
        case(
            "light: --env-seed without any environment",
            |_| {},
            &["render", "--env-seed", "3", "-o", "{d}/o.png"],
            Fail("--env-seed and --no-sun need an environment"),
        ),
        case(
            "map: an 8194×4097 map is over the budget, by its header",
            |d| hdr_header(&d.join("big.hdr"), 8194, 4097),
            &map_render(&["--env", "{d}/big.hdr"]),
            Fail("needs 1209 MB"),
        ),
        case(
            "flag: --level \"\" (no step at all)",
            |_| {},
            &["render", "--level", "", "-o", "{d}/o.png"],
            Fail("has an empty step"),
        ),
        case(
            "flag: --level \",,\"",
            |_| {},
            &["render", "--level", ",,", "-o", "{d}/o.png"],
            Fail("has an empty step"),
        ),
        case(
            "flag: --theta-i 1e300 reads as a number",
            |_| {},
            &map_render(&["--theta-i", "1e300"]),
            Fail("invalid theta-i: 1.000e300°; expected 0° to 90°"),
        ),
    ];
    run_cases("lights", cases);
}
