//! The on-disk term cache: a versioned binary file holding one [`TermStack`], keyed by a
//! hash of everything the stack depends on (every height sample, grid, `dH`, expansion,
//! term count, stored band, format version). A file is trusted only if its magic, version,
//! key, sizes and trailing checksum all match; anything else is reported as
//! [`Error::Cache`] and [`terms_cached`] recomputes. This module owns the file format, the
//! directory's size cap and its housekeeping; it never computes terms itself.
//!
//! Terms are stored as float32: the GPU samples RG32F (or narrower formats derived from
//! it), so no variant reads more, and the file is half the size. A stack that goes through
//! the cache is rounded to float32 before it is used, so a first run (computed) and a
//! second run (loaded) see identical values; `--no-cache` keeps the f64 terms. Files are
//! written and read streaming: neither side holds a second copy of the stack in memory.
//!
//! The directory is capped at [`cache_max_bytes`] (`DIFFRACT_CACHE_MAX`, default
//! [`DEFAULT_CACHE_MAX`]): after a write the least recently used files (mtime, refreshed
//! on every hit) are removed until the total fits. Temporary files of writers that died
//! (`.terms-*.tmp-PID-N`) are removed when a later run opens the cache.
//!
//! Layout (all little-endian):
//! ```text
//! "DFTTERMS"  u32 version  u64 key
//! u8 expansion (0 Taylor, 1 Chebyshev)  u8 precision (4: f32, 8: f64)
//! u64 nx  u64 ny  f64 dH
//! u64 band.x0  u64 band.y0  u64 band.width  u64 band.height
//! u64 term_count  f64 max_deviation_um  f64 half_range_um
//! term_count × (f64 re_min, re_max, im_min, im_max)
//! term_count × width·height × (re, im) in the stored precision
//! u64 FNV-1a checksum of every byte before it
//! ```

use std::io::{BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use super::num_complex::Complex64;
use super::{reachable_band, Band, Expansion, Extrema, TermRequest, TermStack};
use crate::fsutil::write_replacing;
use crate::heightfield::HeightField;
use crate::{Error, Result};

const MAGIC: &[u8; 8] = b"DFTTERMS";
/// Bump whenever the layout or the meaning of a stored term changes: old files then read
/// as stale instead of being misinterpreted. Version 2: float32 terms, precision byte.
pub const FORMAT_VERSION: u32 = 2;
/// Bytes before the extrema: magic, version, key, expansion, precision, nx, ny, dH, band,
/// count, max deviation, half range.
const HEADER_LEN: usize = 8 + 4 + 8 + 1 + 1 + 8 + 8 + 8 + 4 * 8 + 8 + 8 + 8;
/// Stacks never hold more terms than [`TermRequest::validate`] allows (T ≤ 64).
const MAX_TERMS: usize = 65;
/// Default cap of the cache directory (bytes) when `DIFFRACT_CACHE_MAX` is not set.
pub const DEFAULT_CACHE_MAX: u64 = 2 << 30;

/// How the terms are stored in a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Precision {
    F32,
    F64,
}

impl Precision {
    fn bytes(self) -> usize {
        match self {
            Precision::F32 => 4,
            Precision::F64 => 8,
        }
    }
}

/// 64-bit FNV-1a, fed incrementally. Not cryptographic: it guards against corruption and
/// accidental reuse, not against an adversary who edits cache files.
#[derive(Clone, Copy)]
pub(crate) struct Fnv1a(u64);

impl Fnv1a {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;

    pub(crate) fn new() -> Self {
        Self(Self::OFFSET)
    }
    pub(crate) fn bytes(&mut self, data: &[u8]) {
        for &b in data {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(Self::PRIME);
        }
    }
    pub(crate) fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }
    pub(crate) fn finish(self) -> u64 {
        self.0
    }
}

fn expansion_code(e: Expansion) -> u8 {
    match e {
        Expansion::Taylor => 0,
        Expansion::Chebyshev => 1,
    }
}

/// The band a request keeps: the whole spectrum for `full_band`, else the reachable band.
fn requested_band(hf: &HeightField, req: &TermRequest) -> Band {
    if req.full_band {
        Band {
            x0: 0,
            y0: 0,
            width: hf.nx(),
            height: hf.ny(),
        }
    } else {
        reachable_band(hf, req.lambda_min_um, req.window_radius)
    }
}

/// Hash of everything a term stack depends on. `λ_min` and the window radius enter only
/// through the band they imply, so requests that store the same texels share a file.
pub fn cache_key(hf: &HeightField, req: &TermRequest) -> u64 {
    let mut h = Fnv1a::new();
    h.bytes(MAGIC);
    h.u64(u64::from(FORMAT_VERSION));
    h.u64(hf.nx() as u64);
    h.u64(hf.ny() as u64);
    h.u64(hf.dh_um().to_bits());
    for &v in hf.heights_um() {
        h.u64(v.to_bits());
    }
    h.bytes(&[expansion_code(req.expansion)]);
    h.u64(req.max_term as u64);
    let band = requested_band(hf, req);
    for v in [band.x0, band.y0, band.width, band.height] {
        h.u64(v as u64);
    }
    h.finish()
}

/// File size of a stack of `count` terms over `texels` texels, `None` on overflow.
fn file_len(count: usize, texels: usize, precision: Precision) -> Option<usize> {
    texels
        .checked_mul(2 * precision.bytes())
        .and_then(|b| b.checked_add(32))
        .and_then(|b| b.checked_mul(count))
        .and_then(|b| b.checked_add(HEADER_LEN + 8))
}

/// A writer that feeds everything it writes to the checksum.
struct Hashing<W> {
    inner: W,
    hash: Fnv1a,
}

impl<W: Write> Hashing<W> {
    fn put(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.hash.bytes(bytes);
        self.inner.write_all(bytes)
    }
}

fn encode(
    stack: &TermStack,
    key: u64,
    precision: Precision,
    out: impl Write,
    path: &Path,
) -> Result<()> {
    let texels = stack.band.width * stack.band.height;
    if stack.extrema.len() != stack.terms.len()
        || stack.terms.iter().any(|t| t.len() != texels)
        || stack.terms.len() > MAX_TERMS
    {
        return Err(Error::invalid(
            "term stack",
            format!(
                "{} terms, {} extrema, band {}×{}: inconsistent sizes, not cached",
                stack.terms.len(),
                stack.extrema.len(),
                stack.band.width,
                stack.band.height
            ),
        ));
    }
    let io = |e: std::io::Error| Error::io(path, e);
    let mut w = Hashing {
        inner: out,
        hash: Fnv1a::new(),
    };
    w.put(MAGIC).map_err(io)?;
    w.put(&FORMAT_VERSION.to_le_bytes()).map_err(io)?;
    w.put(&key.to_le_bytes()).map_err(io)?;
    w.put(&[expansion_code(stack.expansion), precision.bytes() as u8])
        .map_err(io)?;
    let mut header = Vec::with_capacity(HEADER_LEN);
    for v in [stack.nx as u64, stack.ny as u64] {
        header.extend_from_slice(&v.to_le_bytes());
    }
    header.extend_from_slice(&stack.dh_um.to_le_bytes());
    for v in [
        stack.band.x0,
        stack.band.y0,
        stack.band.width,
        stack.band.height,
        stack.terms.len(),
    ] {
        header.extend_from_slice(&(v as u64).to_le_bytes());
    }
    header.extend_from_slice(&stack.max_deviation_um.to_le_bytes());
    header.extend_from_slice(&stack.half_range_um.to_le_bytes());
    for e in &stack.extrema {
        for v in [e.re_min, e.re_max, e.im_min, e.im_max] {
            header.extend_from_slice(&v.to_le_bytes());
        }
    }
    w.put(&header).map_err(io)?;
    let mut chunk = Vec::with_capacity(1 << 16);
    for term in &stack.terms {
        for c in term {
            match precision {
                Precision::F32 => {
                    chunk.extend_from_slice(&(c.re as f32).to_le_bytes());
                    chunk.extend_from_slice(&(c.im as f32).to_le_bytes());
                }
                Precision::F64 => {
                    chunk.extend_from_slice(&c.re.to_le_bytes());
                    chunk.extend_from_slice(&c.im.to_le_bytes());
                }
            }
            if chunk.len() >= 1 << 16 {
                w.put(&chunk).map_err(io)?;
                chunk.clear();
            }
        }
    }
    w.put(&chunk).map_err(io)?;
    let sum = w.hash.finish();
    w.inner.write_all(&sum.to_le_bytes()).map_err(io)?;
    Ok(())
}

/// Writes `stack` under `key` in `precision`. The bytes go to a temporary file in the same
/// directory that is then renamed over `path`, so a crash or full disk never leaves a
/// half-written cache (and an interrupt removes the temporary file, see `fsutil`).
pub fn save(path: &Path, stack: &TermStack, key: u64, precision: Precision) -> Result<()> {
    write_replacing(path, |w| encode(stack, key, precision, w, path))
}

/// Little-endian reader over a stream that feeds the checksum; `None` at a short read.
struct Reader<R> {
    inner: R,
    hash: Fnv1a,
}

impl<R: Read> Reader<R> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let mut b = [0u8; N];
        self.inner.read_exact(&mut b).ok()?;
        self.hash.bytes(&b);
        Some(b)
    }
    fn u64(&mut self) -> Option<u64> {
        self.take::<8>().map(u64::from_le_bytes)
    }
    fn f64(&mut self) -> Option<f64> {
        self.take::<8>().map(f64::from_le_bytes)
    }
    fn f32(&mut self) -> Option<f64> {
        self.take::<4>().map(|b| f64::from(f32::from_le_bytes(b)))
    }
    fn usize(&mut self) -> Option<usize> {
        self.u64().and_then(|v| usize::try_from(v).ok())
    }
}

/// Reads the stack stored under `key`. Bad magic, another format version, another key
/// (a stale file), a length that does not match the header, or a checksum mismatch is
/// an [`Error::Cache`]; a missing or unreadable file is an [`Error::Io`]. The file is
/// streamed: memory holds the stack once, and nothing past the length the header implies
/// is read.
pub fn load(path: &Path, key: u64) -> Result<TermStack> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    let cache_err = |msg: String| Error::Cache {
        path: path.to_path_buf(),
        msg,
    };
    if !meta.is_file() {
        return Err(cache_err("not a regular file".into()));
    }
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    decode(BufReader::new(file), meta.len(), key).map_err(cache_err)
}

/// Header fields of a cache file, for `diffract cache list`.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    pub key: u64,
    pub expansion: Expansion,
    pub precision: Precision,
    pub nx: usize,
    pub ny: usize,
    pub dh_um: f64,
    pub band: Band,
    pub count: usize,
}

fn decode_header<R: Read>(r: &mut Reader<R>, len: u64) -> std::result::Result<Header, String> {
    let short = || format!("{len} bytes is too short for a term cache");
    let magic = r.take::<8>().ok_or_else(short)?;
    if &magic != MAGIC {
        return Err("not a term cache (bad magic)".into());
    }
    let version = u32::from_le_bytes(r.take::<4>().ok_or_else(short)?);
    if version != FORMAT_VERSION {
        return Err(format!(
            "format version {version}, this build reads version {FORMAT_VERSION}"
        ));
    }
    if len < (HEADER_LEN + 8) as u64 {
        return Err(short());
    }
    let key = r.u64().ok_or_else(short)?;
    let [code, prec] = r.take::<2>().ok_or_else(short)?;
    let expansion = match code {
        0 => Expansion::Taylor,
        1 => Expansion::Chebyshev,
        c => return Err(format!("unknown expansion code {c}")),
    };
    let precision = match prec {
        4 => Precision::F32,
        8 => Precision::F64,
        p => return Err(format!("unknown precision {p}")),
    };
    let nx = r.usize().ok_or_else(short)?;
    let ny = r.usize().ok_or_else(short)?;
    let dh_um = r.f64().ok_or_else(short)?;
    let x0 = r.usize().ok_or_else(short)?;
    let y0 = r.usize().ok_or_else(short)?;
    let width = r.usize().ok_or_else(short)?;
    let height = r.usize().ok_or_else(short)?;
    let count = r.usize().ok_or_else(short)?;
    if count > MAX_TERMS {
        return Err(format!("{count} terms in the header; at most {MAX_TERMS}"));
    }
    let texels = width
        .checked_mul(height)
        .filter(|_| x0.checked_add(width).is_some_and(|e| e <= nx))
        .filter(|_| y0.checked_add(height).is_some_and(|e| e <= ny))
        .ok_or_else(|| format!("band {x0},{y0} {width}×{height} outside the {nx}×{ny} spectrum"))?;
    // Checked arithmetic: a corrupt header must not make us allocate or overflow.
    let expected = file_len(count, texels, precision);
    if expected.map(|n| n as u64) != Some(len) {
        return Err(match expected {
            Some(n) => {
                format!("size mismatch: header implies {n} bytes, file has {len} (truncated?)")
            }
            None => "size mismatch: header sizes overflow".into(),
        });
    }
    Ok(Header {
        key,
        expansion,
        precision,
        nx,
        ny,
        dh_um,
        band: Band {
            x0,
            y0,
            width,
            height,
        },
        count,
    })
}

/// Decodes a stream of `len` bytes (the file length, checked against the header before
/// anything is allocated).
fn decode(data: impl Read, len: u64, key: u64) -> std::result::Result<TermStack, String> {
    let short = || format!("{len} bytes is too short for a term cache");
    let mut r = Reader {
        inner: data.take(len),
        hash: Fnv1a::new(),
    };
    let h = decode_header(&mut r, len)?;
    if h.key != key {
        return Err(format!(
            "stale: stored key {:016x}, expected {key:016x}",
            h.key
        ));
    }
    let max_deviation_um = r.f64().ok_or_else(short)?;
    let half_range_um = r.f64().ok_or_else(short)?;
    let count = h.count;
    let texels = h.band.width * h.band.height;
    let mut extrema = Vec::with_capacity(count);
    for _ in 0..count {
        let mut v = [0.0; 4];
        for x in &mut v {
            *x = r.f64().ok_or_else(short)?;
        }
        extrema.push(Extrema {
            re_min: v[0],
            re_max: v[1],
            im_min: v[2],
            im_max: v[3],
        });
    }
    let mut terms = Vec::with_capacity(count);
    for _ in 0..count {
        let mut term = Vec::with_capacity(texels);
        for _ in 0..texels {
            let (re, im) = match h.precision {
                Precision::F32 => (r.f32(), r.f32()),
                Precision::F64 => (r.f64(), r.f64()),
            };
            term.push(Complex64::new(re.ok_or_else(short)?, im.ok_or_else(short)?));
        }
        terms.push(term);
    }
    let sum = r.hash.finish();
    let mut stored = [0u8; 8];
    r.inner.read_exact(&mut stored).map_err(|_| short())?;
    if sum != u64::from_le_bytes(stored) {
        return Err("checksum mismatch (corrupt file)".into());
    }
    Ok(TermStack {
        expansion: h.expansion,
        nx: h.nx,
        ny: h.ny,
        dh_um: h.dh_um,
        band: h.band,
        terms,
        extrema,
        max_deviation_um,
        half_range_um,
    })
}
/// Largest term stack held in memory (f64 complex texels × terms), bytes. With the
/// height-field copies, FFT buffers, the float32 upload and (on lavapipe) the GPU image in
/// host memory, a render at this size peaks near 4 GB (README: memory and disk).
pub const MAX_STACK_BYTES: u64 = 1_000_000_000;

/// Refuses, before any work, a request whose term stack would exceed [`MAX_STACK_BYTES`],
/// naming the largest `--terms` that fits.
pub fn check_memory(hf: &HeightField, req: &TermRequest) -> Result<()> {
    let band = requested_band(hf, req);
    let per_term = (band.width as u64)
        .saturating_mul(band.height as u64)
        .saturating_mul(16);
    let need = per_term.saturating_mul(req.max_term as u64 + 1);
    if need <= MAX_STACK_BYTES {
        return Ok(());
    }
    let fits = (MAX_STACK_BYTES / per_term.max(1)).saturating_sub(1);
    let gb = |b: u64| b as f64 / 1e9;
    Err(Error::invalid(
        "terms",
        format!(
            "{} terms of a {}×{} spectrum band need {:.1} GB; the limit is {:.1} GB: use \
             --terms {fits} or less, or a smaller height field",
            req.max_term + 1,
            band.width,
            band.height,
            gb(need),
            gb(MAX_STACK_BYTES)
        ),
    ))
}

/// The cap of the cache directory in bytes: `DIFFRACT_CACHE_MAX` (bytes, or with a `K`,
/// `M` or `G` suffix, binary), else [`DEFAULT_CACHE_MAX`]. `0` disables writing.
pub fn cache_max_bytes() -> Result<u64> {
    match std::env::var("DIFFRACT_CACHE_MAX") {
        Ok(v) if !v.trim().is_empty() => parse_size(&v),
        _ => Ok(DEFAULT_CACHE_MAX),
    }
}

/// `"2G"`, `"500M"`, `"64K"`, `"12345"` → bytes.
pub fn parse_size(text: &str) -> Result<u64> {
    let t = text.trim();
    let bad = || {
        Error::invalid(
            "DIFFRACT_CACHE_MAX",
            format!("'{text}'; expected bytes, or a number with K, M or G"),
        )
    };
    let (digits, shift) = match t.char_indices().last() {
        Some((i, 'K' | 'k')) => (&t[..i], 10),
        Some((i, 'M' | 'm')) => (&t[..i], 20),
        Some((i, 'G' | 'g')) => (&t[..i], 30),
        _ => (t, 0),
    };
    let n: u64 = digits.trim().parse().map_err(|_| bad())?;
    n.checked_mul(1u64 << shift).ok_or_else(bad)
}

/// File name of the stack stored under `key`.
fn file_name(key: u64) -> String {
    format!("terms-{key:016x}.bin")
}

/// A cache file: path, size and last use.
#[derive(Debug, Clone)]
pub struct Entry {
    pub path: PathBuf,
    pub bytes: u64,
    pub last_used: SystemTime,
}

/// Prefixes of the cache's files: DFT terms, and the sampled `G` tables of the table
/// variants (`brdf::table_cache`). Both count towards the cap and are listed and cleared.
pub const FILE_PREFIXES: [&str; 2] = ["terms-", "gtable-"];

/// The cache files (`terms-*.bin`, `gtable-*.bin`) of `dir`, least recently used first.
pub fn entries(dir: &Path) -> Result<Vec<Entry>> {
    let rd = match std::fs::read_dir(dir) {
        Ok(rd) => rd,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(Error::io(dir, e)),
    };
    let mut out = Vec::new();
    for entry in rd.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if !(FILE_PREFIXES.iter().any(|p| name.starts_with(p)) && name.ends_with(".bin")) {
            continue;
        }
        let Ok(meta) = entry.metadata() else { continue };
        if !meta.is_file() {
            continue;
        }
        out.push(Entry {
            path: entry.path(),
            bytes: meta.len(),
            last_used: meta.modified().unwrap_or(SystemTime::UNIX_EPOCH),
        });
    }
    out.sort_by_key(|e| e.last_used);
    Ok(out)
}

/// Removes the least recently used files of `dir` until the total is at most `max` bytes,
/// never `keep` (the file just written or read). Returns the bytes removed.
pub fn evict(dir: &Path, max: u64, keep: Option<&Path>) -> Result<u64> {
    let list = entries(dir)?;
    let mut total: u64 = list.iter().map(|e| e.bytes).sum();
    let mut removed = 0;
    for e in list {
        if total <= max {
            break;
        }
        if keep.is_some_and(|k| k == e.path) {
            continue;
        }
        if std::fs::remove_file(&e.path).is_ok() {
            total -= e.bytes;
            removed += e.bytes;
        }
    }
    Ok(removed)
}

/// Whether process `pid` is alive. Without `/proc` nothing is known, and temporaries are
/// then judged by age alone.
fn process_alive(pid: u32) -> Option<bool> {
    let proc_root = Path::new("/proc");
    proc_root
        .is_dir()
        .then(|| proc_root.join(pid.to_string()).exists())
}

/// Removes temporary files `.terms-*.tmp-PID-N` (and `.gtable-*`) left in `dir` by writers that died (a
/// crash or `kill -9`; an interrupt removes its own). Returns how many were removed.
pub fn clean_stale_temps(dir: &Path) -> usize {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut removed = 0;
    for entry in rd.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if !FILE_PREFIXES
            .iter()
            .any(|p| name.starts_with(&format!(".{p}")))
        {
            continue;
        }
        let Some(pid) = name
            .rsplit_once(".tmp-")
            .and_then(|(_, rest)| rest.split('-').next())
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        let dead = match process_alive(pid) {
            Some(alive) => !alive,
            None => entry
                .metadata()
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| t.elapsed().ok())
                .is_some_and(|age| age.as_secs() > 24 * 3600),
        };
        if dead && std::fs::remove_file(entry.path()).is_ok() {
            removed += 1;
        }
    }
    removed
}

/// Rounds every term to float32 (what the cache stores and the GPU samples) and recomputes
/// the extrema of the rounded values.
fn round_to_f32(stack: &mut TermStack) {
    for (term, e) in stack.terms.iter_mut().zip(&mut stack.extrema) {
        let mut x = Extrema {
            re_min: f64::INFINITY,
            re_max: f64::NEG_INFINITY,
            im_min: f64::INFINITY,
            im_max: f64::NEG_INFINITY,
        };
        for c in term.iter_mut() {
            c.re = f64::from(c.re as f32);
            c.im = f64::from(c.im as f32);
            x.re_min = x.re_min.min(c.re);
            x.re_max = x.re_max.max(c.re);
            x.im_min = x.im_min.min(c.im);
            x.im_max = x.im_max.max(c.im);
        }
        *e = x;
    }
}

/// The terms of `hf` for `req`, through the cache in `dir` when one is given: a valid file
/// `terms-{key:016x}.bin` is loaded (and marked as used); a missing one is computed,
/// rounded to float32 and written, after which the least recently used files are evicted
/// to keep the directory under [`cache_max_bytes`]; a corrupt or stale one is a one-line
/// warning to `report`, recomputed and overwritten. Failing to write the cache only warns:
/// the terms are still correct.
pub fn terms_cached(
    hf: &HeightField,
    req: &TermRequest,
    dir: Option<&Path>,
    report: &dyn crate::report::Report,
) -> Result<TermStack> {
    req.validate()?;
    check_memory(hf, req)?;
    let Some(dir) = dir else {
        return super::compute_terms(hf, req);
    };
    let max = cache_max_bytes()?;
    clean_stale_temps(dir);
    let key = cache_key(hf, req);
    let path = dir.join(file_name(key));
    match load(&path, key) {
        Ok(stack) if matches_request(&stack, hf, req) => {
            // Last use is the mtime: LRU eviction reads it.
            let _ = std::fs::File::options()
                .append(true)
                .open(&path)
                .and_then(|f| f.set_modified(SystemTime::now()));
            return Ok(stack);
        }
        Ok(_) => report.warn(&format!(
            "term cache {}: contents do not match the request; recomputing",
            path.display()
        )),
        Err(Error::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => report.warn(&format!("{e}; recomputing")),
    }
    let mut stack = super::compute_terms(hf, req)?;
    round_to_f32(&mut stack);
    let band = stack.band;
    let bytes = file_len(stack.term_count(), band.width * band.height, Precision::F32)
        .unwrap_or(usize::MAX) as u64;
    if bytes > max {
        report.warn(&format!(
            "the terms take {} MiB, more than the cache cap of {} MiB \
             (DIFFRACT_CACHE_MAX); not cached",
            bytes >> 20,
            max >> 20
        ));
        return Ok(stack);
    }
    let saved = std::fs::create_dir_all(dir)
        .map_err(|e| Error::io(dir, e))
        .and_then(|()| save(&path, &stack, key, Precision::F32))
        .and_then(|()| evict(dir, max, Some(&path)));
    if let Err(e) = saved {
        report.warn(&format!("could not write the term cache: {e}"));
    }
    Ok(stack)
}

/// Defence in depth behind the key: a loaded stack must describe this grid and band.
fn matches_request(stack: &TermStack, hf: &HeightField, req: &TermRequest) -> bool {
    stack.nx == hf.nx()
        && stack.ny == hf.ny()
        && stack.dh_um.to_bits() == hf.dh_um().to_bits()
        && stack.expansion == req.expansion
        && stack.term_count() == req.max_term + 1
        && stack.band == requested_band(hf, req)
}

/// The header of a cache file (for listings); bad files give the reason.
pub fn read_header(path: &Path) -> std::result::Result<Header, String> {
    let meta = std::fs::metadata(path).map_err(|e| e.to_string())?;
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let mut r = Reader {
        inner: BufReader::new(file).take(HEADER_LEN as u64),
        hash: Fnv1a::new(),
    };
    decode_header(&mut r, meta.len())
}

/// `diffract cache` options.
#[derive(Debug, Clone, clap::Args)]
pub struct CacheCommandArgs {
    /// What to do.
    #[arg(value_enum, default_value_t = CacheAction::List)]
    pub action: CacheAction,
    /// Directory of the DFT-term cache (default: $DIFFRACT_CACHE or ~/.cache/diffract).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
}

/// `diffract cache list|clear`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CacheAction {
    /// One line per file (size, last use, what it holds) and the total against the cap.
    List,
    /// Remove every term file and stale temporary file.
    Clear,
}

/// Runs `diffract cache`.
pub fn run(args: &CacheCommandArgs) -> Result<()> {
    let dir = args
        .cache_dir
        .clone()
        .or_else(crate::cachedir::default_cache_dir)
        .ok_or_else(|| {
            Error::invalid(
                "cache directory",
                "none: set DIFFRACT_CACHE or HOME, or give --cache-dir",
            )
        })?;
    let max = cache_max_bytes()?;
    let temps = clean_stale_temps(&dir);
    let list = entries(&dir)?;
    let total: u64 = list.iter().map(|e| e.bytes).sum();
    match args.action {
        CacheAction::List => {
            for e in &list {
                let age = e
                    .last_used
                    .elapsed()
                    .map_or("?".to_string(), |d| format!("{}", d.as_secs()));
                let gtable = e
                    .path
                    .file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with("gtable-"));
                let what = match read_header(&e.path) {
                    _ if gtable => "sampled G table of a table variant".to_string(),
                    Ok(h) => format!(
                        "{}×{} {} T={} band {}×{} {:?}",
                        h.nx,
                        h.ny,
                        h.expansion,
                        h.count.saturating_sub(1),
                        h.band.width,
                        h.band.height,
                        h.precision
                    ),
                    Err(msg) => format!("unreadable: {msg}"),
                };
                println!(
                    "{}  {:>8.1} MiB  used {age} s ago  {what}",
                    e.path.display(),
                    e.bytes as f64 / (1u64 << 20) as f64
                );
            }
            println!(
                "{}: {} file(s), {:.1} MiB of {:.1} MiB (DIFFRACT_CACHE_MAX){}",
                dir.display(),
                list.len(),
                total as f64 / (1u64 << 20) as f64,
                max as f64 / (1u64 << 20) as f64,
                if temps > 0 {
                    format!("; removed {temps} stale temporary file(s)")
                } else {
                    String::new()
                }
            );
        }
        CacheAction::Clear => {
            let mut removed = 0u64;
            let mut count = 0usize;
            for e in &list {
                std::fs::remove_file(&e.path).map_err(|err| Error::io(&e.path, err))?;
                removed += e.bytes;
                count += 1;
            }
            println!(
                "{}: removed {count} file(s), {:.1} MiB{}",
                dir.display(),
                removed as f64 / (1u64 << 20) as f64,
                if temps > 0 {
                    format!(" and {temps} stale temporary file(s)")
                } else {
                    String::new()
                }
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(seed: u64) -> HeightField {
        let (nx, ny) = (16, 12);
        let h = (0..nx * ny)
            .map(|i| ((i as u64 * 2654435761 + seed) % 97) as f64 * 0.01)
            .collect();
        HeightField::new(nx, ny, 0.05, h).expect("valid field")
    }

    fn request(max_term: usize) -> TermRequest {
        TermRequest {
            expansion: Expansion::Chebyshev,
            max_term,
            lambda_min_um: 0.38,
            window_radius: 1,
            full_band: false,
        }
    }

    /// A hand-built stack with distinctive values in every field.
    fn stack(hf: &HeightField, req: &TermRequest) -> TermStack {
        let band = requested_band(hf, req);
        let texels = band.width * band.height;
        let terms: Vec<Vec<Complex64>> = (0..=req.max_term)
            .map(|n| {
                (0..texels)
                    .map(|i| Complex64::new(n as f64 + i as f64 * 1e-3, -(i as f64) / 7.0))
                    .collect()
            })
            .collect();
        let extrema = (0..=req.max_term)
            .map(|n| Extrema {
                re_min: -(n as f64),
                re_max: n as f64 + 0.5,
                im_min: -0.25,
                im_max: 0.125 * n as f64,
            })
            .collect();
        TermStack {
            expansion: req.expansion,
            nx: hf.nx(),
            ny: hf.ny(),
            dh_um: hf.dh_um(),
            band,
            terms,
            extrema,
            max_deviation_um: 0.4,
            half_range_um: 0.48,
        }
    }

    fn enc(s: &TermStack, key: u64, precision: Precision) -> Vec<u8> {
        let mut v = Vec::new();
        encode(s, key, precision, &mut v, Path::new("mem")).unwrap();
        v
    }

    fn dec(b: &[u8], key: u64) -> std::result::Result<TermStack, String> {
        decode(b, b.len() as u64, key)
    }

    fn tmpdir(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("diffract-cache-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("temp dir");
        d
    }

    #[test]
    fn round_trip_is_exact() {
        let hf = field(1);
        let req = request(3);
        let s = stack(&hf, &req);
        let key = cache_key(&hf, &req);
        let dir = tmpdir("rt");
        let p = dir.join("t.bin");
        save(&p, &s, key, Precision::F64).expect("save");
        let back = load(&p, key).expect("load");
        assert_eq!(back, s);
        save(&p, &s, key, Precision::F32).expect("save f32");
        let back = load(&p, key).expect("load f32");
        let mut rounded = s.clone();
        round_to_f32(&mut rounded);
        assert_eq!(back.terms, rounded.terms);
        assert!(std::fs::metadata(&p).unwrap().len() < enc(&s, key, Precision::F64).len() as u64);
        // No temporary left behind.
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn every_flipped_byte_is_detected() {
        let hf = field(2);
        let req = request(1);
        let key = cache_key(&hf, &req);
        for precision in [Precision::F32, Precision::F64] {
            let bytes = enc(&stack(&hf, &req), key, precision);
            for i in (0..bytes.len()).step_by(7).chain([bytes.len() - 1]) {
                let mut b = bytes.clone();
                b[i] ^= 0x10;
                assert!(dec(&b, key).is_err(), "flip at byte {i} not detected");
            }
        }
    }

    #[test]
    fn flipped_byte_in_file_is_a_cache_error() {
        let hf = field(3);
        let req = request(2);
        let key = cache_key(&hf, &req);
        let dir = tmpdir("flip");
        let p = dir.join("t.bin");
        save(&p, &stack(&hf, &req), key, Precision::F32).unwrap();
        let mut b = std::fs::read(&p).unwrap();
        let mid = b.len() / 2;
        b[mid] ^= 1;
        std::fs::write(&p, &b).unwrap();
        let err = load(&p, key).unwrap_err();
        assert!(matches!(err, Error::Cache { .. }), "{err}");
        assert!(err.to_string().contains("checksum"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn truncated_file_is_detected() {
        let hf = field(4);
        let req = request(2);
        let key = cache_key(&hf, &req);
        let bytes = enc(&stack(&hf, &req), key, Precision::F32);
        for len in [0, 5, 8, 20, HEADER_LEN, bytes.len() / 2, bytes.len() - 1] {
            let err = dec(&bytes[..len], key).unwrap_err();
            assert!(!err.is_empty());
        }
        let err = dec(&bytes[..bytes.len() - 8], key).unwrap_err();
        assert!(err.contains("size mismatch"), "{err}");
    }

    #[test]
    fn other_request_or_field_is_stale() {
        let hf = field(5);
        let req = request(2);
        let key = cache_key(&hf, &req);
        let bytes = enc(&stack(&hf, &req), key, Precision::F32);

        let mut taylor = req;
        taylor.expansion = Expansion::Taylor;
        let mut full = req;
        full.full_band = true;
        let other_keys = [
            cache_key(&hf, &request(3)),
            cache_key(&hf, &taylor),
            cache_key(&field(6), &req),
            cache_key(
                &HeightField::new(16, 12, 0.051, hf.heights_um().to_vec()).unwrap(),
                &req,
            ),
        ];
        for k in other_keys {
            assert_ne!(k, key);
            let err = dec(&bytes, k).unwrap_err();
            assert!(err.starts_with("stale"), "{err}");
        }
        // Requests implying the same band and terms share a key; a different band does not.
        let b_req = requested_band(&hf, &req);
        let b_full = requested_band(&hf, &full);
        assert_eq!(b_req == b_full, cache_key(&hf, &full) == key);
        let mut radius = req;
        radius.window_radius = 2;
        assert_eq!(
            requested_band(&hf, &radius) == b_req,
            cache_key(&hf, &radius) == key
        );
    }

    #[test]
    fn bad_magic_and_version_are_cache_errors() {
        let hf = field(7);
        let req = request(0);
        let key = cache_key(&hf, &req);
        let mut bytes = enc(&stack(&hf, &req), key, Precision::F32);
        let mut b = bytes.clone();
        b[0] = b'X';
        assert!(dec(&b, key).unwrap_err().contains("magic"));
        bytes[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
        assert!(dec(&bytes, key).unwrap_err().contains("version"));
    }

    #[test]
    fn terms_cached_writes_reuses_and_repairs() {
        let hf = field(9);
        let req = request(3);
        let dir = tmpdir("tc");
        let exact = super::super::compute_terms(&hf, &req).unwrap();
        let mut direct = exact.clone();
        round_to_f32(&mut direct);
        let first = terms_cached(&hf, &req, Some(&dir), &crate::report::Stderr).unwrap();
        assert_eq!(first, direct);
        let file = dir.join(format!("terms-{:016x}.bin", cache_key(&hf, &req)));
        assert_eq!(load(&file, cache_key(&hf, &req)).unwrap(), direct);
        // A corrupt file is recomputed and overwritten with a valid one.
        let mut b = std::fs::read(&file).unwrap();
        b[HEADER_LEN + 3] ^= 0xff;
        std::fs::write(&file, &b).unwrap();
        let said = crate::report::Collect::default();
        assert_eq!(terms_cached(&hf, &req, Some(&dir), &said).unwrap(), direct);
        let warned = said.warnings();
        assert!(
            warned.len() == 1 && warned[0].ends_with("recomputing"),
            "one warning for the corrupt file: {warned:?}"
        );
        assert_eq!(load(&file, cache_key(&hf, &req)).unwrap(), direct);
        // A different request gets its own file.
        let other = request(1);
        let second = terms_cached(&hf, &other, Some(&dir), &crate::report::Stderr).unwrap();
        assert_eq!(second.term_count(), 2);
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 2);
        // Without a directory nothing is written, and the terms keep f64.
        assert_eq!(
            terms_cached(&hf, &req, None, &crate::report::Stderr).unwrap(),
            exact
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn inconsistent_stack_is_not_written() {
        let hf = field(8);
        let req = request(1);
        let mut s = stack(&hf, &req);
        s.terms[1].pop();
        assert!(encode(&s, 0, Precision::F32, Vec::new(), Path::new("m")).is_err());
    }

    #[test]
    fn sizes_parse_with_suffixes() {
        assert_eq!(parse_size("12345").unwrap(), 12345);
        assert_eq!(parse_size("64K").unwrap(), 64 << 10);
        assert_eq!(parse_size(" 500m ").unwrap(), 500 << 20);
        assert_eq!(parse_size("2G").unwrap(), 2 << 30);
        for bad in ["", "G", "-1", "1.5G", "1T", "99999999999999999999G"] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn eviction_removes_least_recently_used_first() {
        let dir = tmpdir("lru");
        let t0 = SystemTime::now() - std::time::Duration::from_secs(1000);
        for (i, age) in [(0u64, 300), (1, 100), (2, 200)] {
            let p = dir.join(file_name(i));
            std::fs::write(&p, vec![0u8; 1000]).unwrap();
            let f = std::fs::File::options().append(true).open(&p).unwrap();
            f.set_modified(t0 + std::time::Duration::from_secs(age))
                .unwrap();
        }
        std::fs::write(dir.join("unrelated.txt"), vec![0u8; 5000]).unwrap();
        // Over the cap by one file: the oldest (key 1, mtime +100) goes, unless kept.
        let keep = dir.join(file_name(1));
        assert_eq!(evict(&dir, 2500, Some(&keep)).unwrap(), 1000);
        assert!(keep.exists() && !dir.join(file_name(2)).exists());
        assert_eq!(evict(&dir, 0, None).unwrap(), 2000);
        assert!(entries(&dir).unwrap().is_empty());
        assert!(dir.join("unrelated.txt").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn temporaries_of_dead_processes_are_removed() {
        let dir = tmpdir("tmp");
        // PID 0 is never a user process; our own PID is alive.
        let dead = dir.join(".terms-00000000000000aa.bin.tmp-0-0");
        let dead2 = dir.join(format!(".terms-00.bin.tmp-{}-3", u32::MAX - 1));
        let alive = dir.join(format!(".terms-00.bin.tmp-{}-0", std::process::id()));
        let other = dir.join(".other.tmp-0-0");
        for p in [&dead, &dead2, &alive, &other] {
            std::fs::write(p, b"x").unwrap();
        }
        assert_eq!(clean_stale_temps(&dir), 2);
        assert!(!dead.exists() && !dead2.exists() && alive.exists() && other.exists());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn file_len_matches_the_encoding() {
        let hf = field(10);
        let req = request(1);
        let s = stack(&hf, &req);
        let len = enc(&s, 1, Precision::F32).len();
        assert_eq!(
            file_len(s.term_count(), s.band.width * s.band.height, Precision::F32),
            Some(len)
        );
    }
}
