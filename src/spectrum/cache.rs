//! The on-disk term cache: a versioned binary file holding one [`TermStack`], keyed by a
//! hash of everything the stack depends on (every height sample, grid, `dH`, expansion,
//! term count, stored band, format version). A file is trusted only if its magic, version,
//! key, sizes and trailing checksum all match; anything else is reported as
//! [`Error::Cache`] and [`terms_cached`] recomputes. This module owns the file format; it
//! never computes terms itself.
//!
//! Terms are stored as float32: the GPU samples RG32F (or narrower formats derived from
//! it), so no variant reads more, and the file is half the size. A stack that goes through
//! the cache is rounded to float32 before it is used, so a first run (computed) and a
//! second run (loaded) see identical values; `--no-cache` keeps the f64 terms. Files are
//! written and read streaming: neither side holds a second copy of the stack in memory.
//!
//! The directory, its key hashing, size cap, eviction and the cleanup of temporary files
//! are [`crate::cache`]'s, shared with the table cache.
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
use std::path::Path;

use super::num_complex::Complex64;
use super::{reachable_band, Band, Expansion, Extrema, TermRequest, TermStack};
use crate::cache::{mark_used, CacheDir, Fnv1a, TERM_FILES};
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
/// to keep the directory under [`crate::cache::cache_max_bytes`]; a corrupt or stale one is a one-line
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
    let cache = CacheDir::open(dir)?;
    let key = cache_key(hf, req);
    let path = cache.file(TERM_FILES, key);
    match load(&path, key) {
        Ok(stack) if matches_request(&stack, hf, req) => {
            mark_used(&path);
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
    if bytes > cache.max_bytes() {
        report.warn(&format!(
            "the terms take {} MiB, more than the cache cap of {} MiB \
             (DIFFRACT_CACHE_MAX); not cached",
            bytes >> 20,
            cache.max_bytes() >> 20
        ));
        return Ok(stack);
    }
    let saved = cache.store(&path, |p| save(p, &stack, key, Precision::F32));
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
