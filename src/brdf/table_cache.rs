//! The on-disk cache of sampled `G` tables ([`Slices`]): building one at 1 nm takes
//! minutes on a small CPU, so a render, a profile or a viewer that asks for the same
//! material, region and sampling again loads it. Same rules as the term cache: a versioned
//! binary file keyed by a hash of everything the table depends on (every height sample,
//! grid, `dH`, coherence length, region, `(u, v)` spacing, `w` nodes, wavelength step), a
//! trailing checksum, atomic writes; a corrupt or stale file is reported and rebuilt.
//! Samples are stored as float32 (what the GPU receives); headers in f64.
//!
//! Layout (little-endian): `"DIFFGTAB"  u32 version  u64 key  u64 nu  u64 nv  u64 nw
//! nw × f64 w  nu·nv·nw·3 × f32  u64 FNV-1a checksum of every byte before it`.

use std::path::Path;

use super::table::{sample_g_kept, Response, Slices, TableSpec};
use crate::cache::{mark_used, CacheDir, Fnv1a, TABLE_FILES};
use crate::heightfield::HeightField;
use crate::report::Report;
use crate::Result;

const MAGIC: &[u8; 8] = b"DIFFGTAB";
/// Bump when the layout or the meaning of `G` changes.
pub const FORMAT_VERSION: u32 = 1;

/// Hash of everything the samples depend on.
pub fn key(hf: &HeightField, coherence_um: f64, spec: &TableSpec, w_nodes: &[f64]) -> u64 {
    let mut h = Fnv1a::new();
    h.bytes(MAGIC);
    h.u64(u64::from(FORMAT_VERSION));
    h.u64(hf.nx() as u64);
    h.u64(hf.ny() as u64);
    h.u64(hf.dh_um().to_bits());
    for &v in hf.heights_um() {
        h.u64(v.to_bits());
    }
    h.u64(coherence_um.to_bits());
    for v in spec.region.lo.iter().chain(&spec.region.hi) {
        h.u64(v.to_bits());
    }
    h.u64(spec.texel_uv.to_bits());
    h.u64(u64::from(spec.step_nm));
    match spec.response {
        Response::Relative => {}
        Response::Radiance {
            coherence_um,
            r0,
            scale,
        } => {
            h.bytes(b"radiance");
            for v in [coherence_um, r0, scale] {
                h.u64(v.to_bits());
            }
        }
    }
    for w in w_nodes {
        h.u64(w.to_bits());
    }
    h.finish()
}

/// A table file's bytes but its checksum: what needs the slices.
fn unsealed(s: &Slices, key: u64) -> Vec<u8> {
    let mut out = Vec::with_capacity(44 + s.w.len() * 8 + s.nu * s.nv * s.w.len() * 12 + 8);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    for v in [key, s.nu as u64, s.nv as u64, s.w.len() as u64] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for w in &s.w {
        out.extend_from_slice(&w.to_le_bytes());
    }
    for plane in &s.data {
        for t in plane {
            for c in t {
                out.extend_from_slice(&(*c as f32).to_le_bytes());
            }
        }
    }
    out
}

/// `out` with its checksum appended: a whole table file.
fn seal(mut out: Vec<u8>) -> Vec<u8> {
    let mut h = Fnv1a::new();
    h.bytes(&out);
    out.extend_from_slice(&h.finish().to_le_bytes());
    out
}

fn decode(data: &[u8], key: u64, w_nodes: &[f64]) -> std::result::Result<Slices, String> {
    let u64_at = |i: usize| -> Option<u64> {
        data.get(i..i + 8)
            .and_then(|b| b.try_into().ok())
            .map(u64::from_le_bytes)
    };
    if data.len() < 44 || &data[..8] != MAGIC {
        return Err("not a diffract table file".into());
    }
    let version = u32::from_le_bytes([data[8], data[9], data[10], data[11]]);
    if version != FORMAT_VERSION {
        return Err(format!(
            "format version {version}, expected {FORMAT_VERSION}"
        ));
    }
    let (Some(k), Some(nu), Some(nv), Some(nw)) = (u64_at(12), u64_at(20), u64_at(28), u64_at(36))
    else {
        return Err("truncated header".into());
    };
    if k != key {
        return Err("stale (another material or sampling)".into());
    }
    let (nu, nv, nw) = (nu as usize, nv as usize, nw as usize);
    if nw != w_nodes.len() || nu > super::table::MAX_NODES_UV || nv > super::table::MAX_NODES_UV {
        return Err(format!("{nu}×{nv}×{nw} nodes do not match the request"));
    }
    let body = 44 + nw * 8;
    let len = body + nu * nv * nw * 12 + 8;
    if data.len() != len {
        return Err(format!("{} bytes, expected {len}", data.len()));
    }
    let mut h = Fnv1a::new();
    h.bytes(&data[..len - 8]);
    if u64_at(len - 8) != Some(h.finish()) {
        return Err("checksum mismatch (corrupt file)".into());
    }
    let w: Vec<f64> = (0..nw)
        .filter_map(|i| u64_at(44 + i * 8).map(f64::from_bits))
        .collect();
    if w.iter()
        .zip(w_nodes)
        .any(|(a, b)| a.to_bits() != b.to_bits())
    {
        return Err("w nodes do not match the request".into());
    }
    let f32_at = |i: usize| f32::from_le_bytes([data[i], data[i + 1], data[i + 2], data[i + 3]]);
    let data = (0..nw)
        .map(|k| {
            (0..nu * nv)
                .map(|t| {
                    let at = body + ((k * nu * nv + t) * 3) * 4;
                    [0, 1, 2].map(|c| f64::from(f32_at(at + 4 * c)))
                })
                .collect()
        })
        .collect();
    Ok(Slices { nu, nv, w, data })
}

/// [`sample_g`](super::table::sample_g) through the cache in `dir` (none: always build). A valid file
/// `gtable-{key:016x}.bin` is loaded (`progress` is not called); a missing one is built
/// and written; a corrupt or stale one is reported to `report` as a warning, rebuilt and
/// overwritten. Failing to write only warns.
pub fn sample_g_cached(
    hf: &HeightField,
    coherence_um: f64,
    spec: &TableSpec,
    w_nodes: &[f64],
    dir: Option<&Path>,
    report: &dyn Report,
    progress: &(dyn Fn() + Sync),
) -> Result<Slices> {
    sample_g_cached_kept(hf, coherence_um, spec, w_nodes, None, dir, report, progress)
}

/// [`sample_g_cached`] over only the wavelengths `keep` ([`sample_g_kept`]); the kept
/// list is part of the key (a table of every wavelength keeps its old key).
#[allow(clippy::too_many_arguments)]
pub fn sample_g_cached_kept(
    hf: &HeightField,
    coherence_um: f64,
    spec: &TableSpec,
    w_nodes: &[f64],
    keep: Option<&[usize]>,
    dir: Option<&Path>,
    report: &dyn Report,
    progress: &(dyn Fn() + Sync),
) -> Result<Slices> {
    let build = || sample_g_kept(hf, coherence_um, spec, w_nodes, keep, progress);
    sample_g_cached_by(
        hf,
        coherence_um,
        spec,
        w_nodes,
        keep,
        dir,
        None,
        report,
        &build,
    )
    .map(|(s, _)| s)
}

/// [`sample_g_cached_kept`] with the samples made by `build` on a miss (the CPU build, or
/// the device build), and `tag` mixed into the key: builds whose samples differ from the
/// CPU f64 build by more than the file's float32 rounding (a float32 device build) name
/// themselves there and are cached apart; `None` shares the CPU build's files. Returns the
/// samples and whether they were loaded from the cache.
#[allow(clippy::too_many_arguments)]
pub fn sample_g_cached_by(
    hf: &HeightField,
    coherence_um: f64,
    spec: &TableSpec,
    w_nodes: &[f64],
    keep: Option<&[usize]>,
    dir: Option<&Path>,
    tag: Option<&str>,
    report: &dyn Report,
    build: &dyn Fn() -> Result<Slices>,
) -> Result<(Slices, bool)> {
    let Some(dir) = dir else {
        return Ok((build()?, false));
    };
    let (nu, nv) = spec.validate()?;
    let cache = CacheDir::open(dir)?;
    let key = match keep {
        None => key(hf, coherence_um, spec, w_nodes),
        Some(k) => {
            let mut h = Fnv1a::new();
            h.u64(key(hf, coherence_um, spec, w_nodes));
            h.bytes(b"kept wavelengths");
            for &i in k {
                h.u64(i as u64);
            }
            h.finish()
        }
    };
    let key = match tag {
        None => key,
        Some(t) => {
            let mut h = Fnv1a::new();
            h.u64(key);
            h.bytes(b"built by");
            h.bytes(t.as_bytes());
            h.finish()
        }
    };
    let path = cache.file(TABLE_FILES, key);
    // A valid file has exactly this many bytes: read no more than that.
    let expected = (44 + w_nodes.len() * 8 + nu * nv * w_nodes.len() * 12 + 8) as u64;
    if let Some(data) = cache.read(&path, "table cache", expected, report) {
        match decode(&data, key, w_nodes) {
            Ok(s) if s.nu == nu && s.nv == nv => {
                mark_used(&path);
                return Ok((s, true));
            }
            Ok(_) => report.warn(&format!(
                "table cache {}: grid does not match; rebuilding",
                path.display()
            )),
            Err(msg) => report.warn(&format!(
                "table cache {}: {msg}; rebuilding",
                path.display()
            )),
        }
    }
    let s = build()?;
    if expected > cache.max_bytes() {
        report.warn(&format!(
            "the table takes {} MiB, more than the cache cap of {} MiB (DIFFRACT_CACHE_MAX); not cached",
            expected >> 20,
            cache.max_bytes() >> 20
        ));
        return Ok((s, false));
    }
    // The bytes that need the slices here; the checksum and the write behind the work.
    let body = unsealed(&s, key);
    cache.write_behind(path, "table cache", move || seal(body), report);
    Ok((s, false))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::table::Region;

    fn setup() -> (HeightField, TableSpec, Vec<f64>) {
        let n = 32;
        let h = (0..n * n)
            .map(|i| 0.1 * ((i % n) as f64 * 0.7).sin())
            .collect();
        let hf = HeightField::new(n, n, 0.09, h).unwrap();
        let spec = TableSpec {
            region: Region {
                lo: [-0.2, -0.1, -1.6],
                hi: [0.2, 0.1, -1.2],
            },
            texel_uv: 0.05,
            w_nodes: 3,
            step_nm: 100,
            response: crate::brdf::table::Response::Relative,
        };
        (hf, spec, vec![-1.6, -1.4, -1.2])
    }

    #[test]
    fn cached_tables_round_trip_and_corruption_is_rebuilt() {
        let (hf, spec, w) = setup();
        let dir = std::env::temp_dir().join(format!("diffract-gtab-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let built = sample_g_cached(
            &hf,
            65.0,
            &spec,
            &w,
            Some(&dir),
            &crate::report::Stderr,
            &|| (),
        )
        .unwrap();
        let loaded = sample_g_cached(
            &hf,
            65.0,
            &spec,
            &w,
            Some(&dir),
            &crate::report::Stderr,
            &|| panic!("a cached table must not be rebuilt"),
        )
        .unwrap();
        for (a, b) in built
            .data
            .iter()
            .flatten()
            .zip(loaded.data.iter().flatten())
        {
            for c in 0..3 {
                assert_eq!(a[c] as f32, b[c] as f32);
            }
        }
        // Flip one sample byte: the checksum catches it and the table is rebuilt.
        let path = std::fs::read_dir(&dir)
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        let mut bytes = std::fs::read(&path).unwrap();
        let mid = bytes.len() / 2;
        bytes[mid] ^= 0x40;
        std::fs::write(&path, &bytes).unwrap();
        let k = key(&hf, 65.0, &spec, &w);
        assert!(decode(&bytes, k, &w).unwrap_err().contains("checksum"));
        let rebuilt = std::sync::atomic::AtomicUsize::new(0);
        let report = crate::report::Collect::default();
        sample_g_cached(&hf, 65.0, &spec, &w, Some(&dir), &report, &|| {
            rebuilt.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        })
        .unwrap();
        assert!(rebuilt.into_inner() > 0);
        // The rebuild is said to the caller's report, not printed.
        let warnings = report.warnings();
        assert!(
            warnings.len() == 1
                && warnings[0].starts_with("table cache ")
                && warnings[0].contains("checksum")
                && warnings[0].ends_with("; rebuilding"),
            "{warnings:?}"
        );
        // Another coherence length is another key.
        assert_ne!(k, key(&hf, 60.0, &spec, &w));
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Runs `f` on another thread and fails (instead of hanging) when it takes a minute.
    fn within_a_minute<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send(f());
        });
        rx.recv_timeout(std::time::Duration::from_secs(60))
            .expect("the table cache hung on its own path")
    }

    /// A FIFO or a symbolic link left at a `gtable-*.bin` path: the table is built (the
    /// FIFO is not a table), the cache file is replaced through a temporary file and a
    /// rename, nothing is written into the FIFO or through the link, and nothing hangs
    /// (opening a FIFO with no reader for writing, or with no writer for reading, would).
    #[cfg(unix)]
    #[test]
    fn a_fifo_or_link_at_the_cache_path_is_replaced_not_written_into() {
        use std::io::Read;
        use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
        let (hf, spec, w) = setup();
        let dir = std::env::temp_dir().join(format!("diffract-gtab-fifo-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(format!("gtable-{:016x}.bin", key(&hf, 65.0, &spec, &w)));

        // A FIFO, with a reader waiting on it that would see anything written into it.
        let c = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0, "mkfifo");
        let mut reader = std::fs::File::options()
            .read(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(&path)
            .unwrap();
        let built = {
            let (hf, spec, w, dir) = (hf.clone(), spec, w.clone(), dir.clone());
            within_a_minute(move || {
                let builds = std::sync::atomic::AtomicUsize::new(0);
                sample_g_cached(
                    &hf,
                    65.0,
                    &spec,
                    &w,
                    Some(&dir),
                    &crate::report::Stderr,
                    &|| {
                        builds.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    },
                )
                .unwrap();
                builds.into_inner()
            })
        };
        assert!(built > 0, "a FIFO was taken for a table");
        let mut received = Vec::new();
        match reader.read_to_end(&mut received) {
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
            Err(e) => panic!("reading the FIFO: {e}"),
        }
        assert!(
            received.is_empty(),
            "the FIFO received {} bytes",
            received.len()
        );
        let meta = std::fs::symlink_metadata(&path).unwrap();
        assert!(meta.is_file() && !meta.file_type().is_fifo());
        // The file that replaced it is the table: the next call loads it.
        within_a_minute({
            let (hf, spec, w, dir) = (hf.clone(), spec, w.clone(), dir.clone());
            move || {
                sample_g_cached(
                    &hf,
                    65.0,
                    &spec,
                    &w,
                    Some(&dir),
                    &crate::report::Stderr,
                    &|| panic!("the replaced cache file must load"),
                )
                .unwrap()
            }
        });

        // A symbolic link to a file of the user's: the link is replaced, the file kept.
        std::fs::remove_file(&path).unwrap();
        let victim = dir.join("notes.txt");
        std::fs::write(&victim, b"keep me").unwrap();
        std::os::unix::fs::symlink(&victim, &path).unwrap();
        within_a_minute({
            let (hf, spec, w, dir) = (hf.clone(), spec, w.clone(), dir.clone());
            move || {
                sample_g_cached(
                    &hf,
                    65.0,
                    &spec,
                    &w,
                    Some(&dir),
                    &crate::report::Stderr,
                    &|| (),
                )
                .unwrap()
            }
        });
        assert_eq!(std::fs::read(&victim).unwrap(), b"keep me");
        assert!(!std::fs::symlink_metadata(&path)
            .unwrap()
            .file_type()
            .is_symlink());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
