//! Beyond the bad-input table: the term cache's temporary files (removed on
//! Ctrl-C, cleaned after a crash), its size cap and `diffract cache list|clear`, and the
//! memory limit of the precompute, all through the binary.

mod files_util;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_diffract"));
    c.env("DIFFRACT_CACHE", "").env_remove("DIFFRACT_CACHE_MAX");
    c
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-hard-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// An `n`² .f32 height field of ridges with its sidecar.
fn field(d: &Path, n: usize, dh: f64) -> PathBuf {
    let p = d.join(format!("f{n}.f32"));
    let bytes: Vec<u8> = (0..n * n)
        .flat_map(|i| (0.2 * ((i % n) as f32 * 0.7).sin() + 0.001 * (i % 13) as f32).to_le_bytes())
        .collect();
    std::fs::write(&p, bytes).unwrap();
    std::fs::write(
        p.with_extension("toml"),
        format!("nx = {n}\nny = {n}\ndh_um = {dh}\n"),
    )
    .unwrap();
    p
}

fn queries(d: &Path) -> PathBuf {
    let q = d.join("q.csv");
    std::fs::write(
        &q,
        "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm\n30,0,30,180,500\n",
    )
    .unwrap();
    q
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn brdf(hf: &Path, q: &Path, out: &Path, cache: &Path, terms: &str) -> Command {
    let mut c = bin();
    c.args(["brdf", "--heightfield"])
        .arg(hf)
        .arg("--queries")
        .arg(q)
        .arg("--out")
        .arg(out)
        .arg("--cache-dir")
        .arg(cache)
        .args(["--terms", terms]);
    c
}

#[test]
fn interrupt_during_a_cache_write_leaves_no_temporary_file() {
    let d = scratch("int");
    let hf = field(&d, 1024, 0.09);
    let q = queries(&d);
    let cache = d.join("cache");
    let mut child = brdf(&hf, &q, &d.join("r.csv"), &cache, "30")
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    // Wait for the temporary cache file to appear, then interrupt like Ctrl-C does.
    let start = Instant::now();
    let mut seen = false;
    while start.elapsed() < Duration::from_secs(120) {
        if names(&cache).iter().any(|n| n.contains(".tmp-")) {
            seen = true;
            break;
        }
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(seen, "no temporary cache file was ever seen");
    let killed = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    // The write may just have finished; either way no temporary file may remain.
    let left = names(&cache);
    assert!(
        !left.iter().any(|n| n.contains(".tmp-")),
        "left behind: {left:?}; stderr: {err}"
    );
    if !out.status.success() {
        assert_eq!(out.status.code(), Some(130), "{err}");
        assert!(err.contains("error: interrupted"), "{err}");
    }
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn temporaries_of_dead_runs_are_removed_and_live_ones_kept() {
    let d = scratch("stale");
    let hf = field(&d, 32, 0.05);
    let q = queries(&d);
    let cache = d.join("cache");
    std::fs::create_dir_all(&cache).unwrap();
    // PIDs above the kernel's pid_max (4 194 304 at most) never belong to a process.
    let dead = cache.join(".terms-00000000000000ff.bin.tmp-999999999-0");
    let live = cache.join(format!(
        ".terms-00000000000000ee.bin.tmp-{}-0",
        std::process::id()
    ));
    std::fs::write(&dead, vec![0u8; 4096]).unwrap();
    std::fs::write(&live, b"x").unwrap();
    let o = brdf(&hf, &q, &d.join("r.csv"), &cache, "2")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!dead.exists(), "{:?}", names(&cache));
    assert!(live.exists());
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn cache_is_capped_lru_and_can_be_listed_and_cleared() {
    let d = scratch("cap");
    let hf = field(&d, 64, 0.05);
    let q = queries(&d);
    let cache = d.join("cache");
    let sizes: Vec<u64> = ["1", "2", "3"]
        .iter()
        .map(|t| {
            let o = brdf(&hf, &q, &d.join("r.csv"), &cache, t).output().unwrap();
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            std::thread::sleep(Duration::from_millis(20));
            std::fs::read_dir(&cache)
                .unwrap()
                .flatten()
                .map(|e| e.metadata().unwrap().len())
                .max()
                .unwrap()
        })
        .collect();
    assert_eq!(names(&cache).len(), 3);
    // Use T = 1 again (refreshing it), then add T = 4 under a cap that holds two files:
    // T = 2 and T = 3 are the least recently used and go.
    let o = brdf(&hf, &q, &d.join("r.csv"), &cache, "1")
        .output()
        .unwrap();
    assert!(o.status.success());
    std::thread::sleep(Duration::from_millis(20));
    let t4 = sizes[2] + (sizes[2] - sizes[1]);
    let cap = sizes[0] + t4 + 10;
    let o = brdf(&hf, &q, &d.join("r.csv"), &cache, "4")
        .env("DIFFRACT_CACHE_MAX", cap.to_string())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let total: u64 = std::fs::read_dir(&cache)
        .unwrap()
        .flatten()
        .map(|e| e.metadata().unwrap().len())
        .sum();
    assert!(total <= cap, "{total} > {cap}: {:?}", names(&cache));
    assert_eq!(names(&cache).len(), 2, "{:?}", names(&cache));

    let list = bin()
        .args(["cache", "list", "--cache-dir"])
        .arg(&cache)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&list.stdout);
    assert!(list.status.success());
    assert!(text.contains("T=1 ") && text.contains("T=4 "), "{text}");
    assert!(text.contains("2 file(s)"), "{text}");
    let clear = bin()
        .args(["cache", "clear", "--cache-dir"])
        .arg(&cache)
        .output()
        .unwrap();
    assert!(clear.status.success());
    assert!(String::from_utf8_lossy(&clear.stdout).contains("removed 2 file(s)"));
    assert!(names(&cache).is_empty());
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn cache_files_are_float32() {
    let d = scratch("f32");
    let hf = field(&d, 64, 0.05);
    let q = queries(&d);
    let cache = d.join("cache");
    let o = brdf(&hf, &q, &d.join("r.csv"), &cache, "3")
        .output()
        .unwrap();
    assert!(o.status.success());
    let list = bin()
        .args(["cache", "list", "--cache-dir"])
        .arg(&cache)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&list.stdout);
    assert!(text.contains("F32"), "{text}");
    // 4 terms of the band × 8 bytes per texel plus headers: about half the f64 size.
    let len = std::fs::read_dir(&cache)
        .unwrap()
        .flatten()
        .map(|e| e.metadata().unwrap().len())
        .next()
        .unwrap();
    let band = 64 * 64;
    assert!(len < (4 * band * 8 + 1024) as u64, "{len}");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn precompute_beyond_the_memory_limit_is_refused_before_any_work() {
    let d = scratch("mem");
    let hf = field(&d, 4096, 0.0923);
    let q = queries(&d);
    let (kb, o) = peak_kb(
        bin()
            .args(["brdf", "--heightfield"])
            .arg(&hf)
            .arg("--queries")
            .arg(&q)
            .arg("--out")
            .arg(d.join("r.csv"))
            .args(["--no-cache", "--terms", "30"]),
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("the limit is 1.0 GB"), "{err}");
    assert!(err.contains("--terms"), "{err}");
    assert!(!d.join("r.csv").exists());
    eprintln!("peak RSS of the refused request: {kb} kB");
    // Loading 64 MB of heights (128 MB as f64) is all it does: far from the 1 GB it refused.
    assert!(kb < 500_000, "peak RSS {kb} kB for a refused request");
    let _ = std::fs::remove_dir_all(&d);
}

/// Runs `cmd` to the end and returns its peak RSS (kB) with its output. The peak is the
/// child's own `ru_maxrss`, which `wait4` reports for exactly that process (no other test's
/// children are counted, and no external tool is needed).
// The child is reaped by `wait4` below, which clippy does not see.
#[allow(clippy::zombie_processes)]
fn peak_kb(cmd: &mut Command) -> (u64, std::process::Output) {
    use std::os::unix::process::ExitStatusExt;
    let (child, drained) = files_util::spawn_drained(cmd);
    let pid = child.id() as libc::pid_t;
    let mut status = 0;
    // SAFETY: an all-zero `rusage` is a valid value of this plain C struct.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    loop {
        // SAFETY: `pid` is this process's child, not yet waited for (`child` is never waited
        // on, and dropping it does not wait); `status` and `usage` are valid for writing.
        let r = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
        if r == pid {
            break;
        }
        let e = std::io::Error::last_os_error();
        assert_eq!(e.kind(), std::io::ErrorKind::Interrupted, "wait4: {e}");
    }
    let (stdout, stderr) = drained.join();
    let o = std::process::Output {
        status: std::process::ExitStatus::from_raw(status),
        stdout,
        stderr,
    };
    // Linux reports ru_maxrss in kB.
    (usage.ru_maxrss as u64, o)
}

/// Memory at the documented limit: the largest request the limit allows at 2048²
/// (`T = 14`) runs in well under 4 GB of peak RSS, and one over it is refused before it
/// takes memory.
#[test]
fn precompute_at_the_memory_limit_stays_under_4_gb() {
    let d = scratch("peak");
    let hf = field(&d, 2048, 0.0923);
    let q = queries(&d);
    let out = d.join("r.csv");
    let mut ok = bin();
    ok.args(["brdf", "--heightfield"])
        .arg(&hf)
        .arg("--queries")
        .arg(&q)
        .arg("--out")
        .arg(&out)
        .args(["--no-cache", "--terms", "14"]);
    let (kb, o) = peak_kb(&mut ok);
    eprintln!("peak RSS at the limit: {kb} kB");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(kb < 4_000_000, "peak RSS {kb} kB at the limit");
    let mut over = bin();
    over.args(["brdf", "--heightfield"])
        .arg(&hf)
        .arg("--queries")
        .arg(&q)
        .arg("--out")
        .arg(d.join("r2.csv"))
        .args(["--no-cache", "--terms", "30"]);
    let (kb, o) = peak_kb(&mut over);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("the limit is 1.0 GB"));
    assert!(kb < 500_000, "peak RSS {kb} kB for a refused request");
    let _ = std::fs::remove_dir_all(&d);
}

mod bomb;

/// A PNG whose header claims 20000×20000 pixels (400 MB of grey, 2.5 MB of file) is refused
/// from its header by every command that reads a height field, in well under 100 MB of
/// peak memory: nothing is decoded.
#[test]
fn a_png_bomb_is_refused_from_its_header_in_little_memory() {
    let d = scratch("bomb");
    let png = d.join("bomb.png");
    std::fs::write(&png, bomb::png_bomb(20000)).unwrap();
    std::fs::write(d.join("bomb.toml"), "dh_um = 0.1\nh_max_um = 0.2\n").unwrap();
    let q = queries(&d);
    let mut brdf = bin();
    brdf.args(["brdf", "--no-cache", "--heightfield"])
        .arg(&png)
        .arg("--queries")
        .arg(&q)
        .arg("--out")
        .arg(d.join("r.csv"));
    let mut grow = bin();
    grow.args(["heightfield", "--from-sample"])
        .arg(&png)
        .arg("-o")
        .arg(d.join("g.png"));
    for (name, cmd) in [
        ("brdf --heightfield", &mut brdf),
        ("heightfield --from-sample", &mut grow),
    ] {
        let (kb, o) = peak_kb(cmd);
        let err = String::from_utf8_lossy(&o.stderr);
        eprintln!("{name}: peak RSS {kb} kB; {}", err.trim());
        assert_eq!(o.status.code(), Some(1), "{name}: {err}");
        assert!(
            err.contains("its header says 20000×20000 pixels"),
            "{name}: {err}"
        );
        assert!(
            kb < 100_000,
            "{name}: peak RSS {kb} kB for a refused PNG bomb"
        );
    }
    let _ = std::fs::remove_dir_all(&d);
}
