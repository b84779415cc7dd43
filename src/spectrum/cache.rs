//! The on-disk term cache: a versioned binary file holding one [`TermStack`], keyed by a
//! hash of everything the stack depends on (every height sample, grid, `dH`, expansion,
//! term count, stored band, format version). A file is trusted only if its magic, version,
//! key, sizes and trailing checksum all match; anything else is reported as
//! [`Error::Cache`] and [`terms_cached`] recomputes. This module owns the file format and
//! nothing else: it never computes terms itself.
//!
//! Layout (all little-endian):
//! ```text
//! "DFTTERMS"  u32 version  u64 key
//! u8 expansion (0 Taylor, 1 Chebyshev)  u64 nx  u64 ny  f64 dH
//! u64 band.x0  u64 band.y0  u64 band.width  u64 band.height
//! u64 term_count  f64 max_deviation_um  f64 half_range_um
//! term_count × (f64 re_min, re_max, im_min, im_max)
//! term_count × width·height × (f64 re, f64 im)
//! u64 FNV-1a checksum of every byte before it
//! ```

use std::path::Path;

use super::num_complex::Complex64;
use super::{reachable_band, Band, Expansion, Extrema, TermRequest, TermStack};
use crate::fsutil::write_atomic;
use crate::heightfield::HeightField;
use crate::{Error, Result};

const MAGIC: &[u8; 8] = b"DFTTERMS";
/// Bump whenever the layout or the meaning of a stored term changes: old files then read
/// as stale instead of being misinterpreted.
pub const FORMAT_VERSION: u32 = 1;
/// Bytes before the extrema: magic, version, key, expansion, nx, ny, dH, band, count,
/// max deviation, half range.
const HEADER_LEN: usize = 8 + 4 + 8 + 1 + 8 + 8 + 8 + 4 * 8 + 8 + 8 + 8;
/// Stacks never hold more terms than [`TermRequest::validate`] allows (T ≤ 64).
const MAX_TERMS: usize = 65;

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

fn encode(stack: &TermStack, key: u64) -> Result<Vec<u8>> {
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
    let count = stack.terms.len();
    let mut out = Vec::with_capacity(HEADER_LEN + count * 32 + count * texels * 16 + 8);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&key.to_le_bytes());
    out.push(expansion_code(stack.expansion));
    let u = |out: &mut Vec<u8>, v: u64| out.extend_from_slice(&v.to_le_bytes());
    let f = |out: &mut Vec<u8>, v: f64| out.extend_from_slice(&v.to_le_bytes());
    u(&mut out, stack.nx as u64);
    u(&mut out, stack.ny as u64);
    f(&mut out, stack.dh_um);
    for v in [
        stack.band.x0,
        stack.band.y0,
        stack.band.width,
        stack.band.height,
        count,
    ] {
        u(&mut out, v as u64);
    }
    f(&mut out, stack.max_deviation_um);
    f(&mut out, stack.half_range_um);
    for e in &stack.extrema {
        for v in [e.re_min, e.re_max, e.im_min, e.im_max] {
            f(&mut out, v);
        }
    }
    for term in &stack.terms {
        for c in term {
            f(&mut out, c.re);
            f(&mut out, c.im);
        }
    }
    let mut h = Fnv1a::new();
    h.bytes(&out);
    out.extend_from_slice(&h.finish().to_le_bytes());
    Ok(out)
}

/// Writes `stack` under `key`. The bytes go to a temporary file in the same directory that
/// is then renamed over `path`, so a crash or full disk never leaves a half-written cache.
pub fn save(path: &Path, stack: &TermStack, key: u64) -> Result<()> {
    let bytes = encode(stack, key)?;
    write_atomic(path, &bytes)
}

/// Little-endian reader over a byte slice; every read is bounds-checked by the caller's
/// earlier length check, and returns `None` instead of panicking if that check was wrong.
struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let end = self.pos.checked_add(N)?;
        let bytes = self.data.get(self.pos..end)?.try_into().ok()?;
        self.pos = end;
        Some(bytes)
    }
    fn u64(&mut self) -> Option<u64> {
        self.take::<8>().map(u64::from_le_bytes)
    }
    fn f64(&mut self) -> Option<f64> {
        self.take::<8>().map(f64::from_le_bytes)
    }
    fn usize(&mut self) -> Option<usize> {
        self.u64().and_then(|v| usize::try_from(v).ok())
    }
}

/// Reads the stack stored under `key`. Bad magic, another format version, another key
/// (a stale file), a length that does not match the header, or a checksum mismatch is
/// an [`Error::Cache`]; a missing or unreadable file is an [`Error::Io`].
pub fn load(path: &Path, key: u64) -> Result<TermStack> {
    let data = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    decode(&data, key).map_err(|msg| Error::Cache {
        path: path.to_path_buf(),
        msg,
    })
}

fn decode(data: &[u8], key: u64) -> std::result::Result<TermStack, String> {
    let short = || format!("{} bytes is too short for a term cache", data.len());
    if data.len() < MAGIC.len() || &data[..MAGIC.len()] != MAGIC {
        return Err("not a term cache (bad magic)".into());
    }
    if data.len() < HEADER_LEN + 8 {
        return Err(short());
    }
    let mut r = Reader { data, pos: 8 };
    let version = u32::from_le_bytes(r.take::<4>().ok_or_else(short)?);
    if version != FORMAT_VERSION {
        return Err(format!(
            "format version {version}, this build reads version {FORMAT_VERSION}"
        ));
    }
    let stored_key = r.u64().ok_or_else(short)?;
    let expansion = match r.take::<1>().ok_or_else(short)?[0] {
        0 => Expansion::Taylor,
        1 => Expansion::Chebyshev,
        c => return Err(format!("unknown expansion code {c}")),
    };
    let nx = r.usize().ok_or_else(short)?;
    let ny = r.usize().ok_or_else(short)?;
    let dh_um = r.f64().ok_or_else(short)?;
    let x0 = r.usize().ok_or_else(short)?;
    let y0 = r.usize().ok_or_else(short)?;
    let width = r.usize().ok_or_else(short)?;
    let height = r.usize().ok_or_else(short)?;
    let count = r.usize().ok_or_else(short)?;
    let max_deviation_um = r.f64().ok_or_else(short)?;
    let half_range_um = r.f64().ok_or_else(short)?;
    if count > MAX_TERMS {
        return Err(format!("{count} terms in the header; at most {MAX_TERMS}"));
    }
    let texels = width
        .checked_mul(height)
        .filter(|_| x0.checked_add(width).is_some_and(|e| e <= nx))
        .filter(|_| y0.checked_add(height).is_some_and(|e| e <= ny))
        .ok_or_else(|| format!("band {x0},{y0} {width}×{height} outside the {nx}×{ny} spectrum"))?;
    // Checked arithmetic: a corrupt header must not make us allocate or overflow.
    let expected = texels
        .checked_mul(16)
        .and_then(|b| b.checked_add(32))
        .and_then(|b| b.checked_mul(count))
        .and_then(|b| b.checked_add(HEADER_LEN + 8));
    if expected != Some(data.len()) {
        return Err(match expected {
            Some(n) => format!(
                "size mismatch: header implies {n} bytes, file has {} (truncated?)",
                data.len()
            ),
            None => "size mismatch: header sizes overflow".into(),
        });
    }
    let body = &data[..data.len() - 8];
    let mut h = Fnv1a::new();
    h.bytes(body);
    let stored_sum = u64::from_le_bytes(data[data.len() - 8..].try_into().map_err(|_| short())?);
    if h.finish() != stored_sum {
        return Err("checksum mismatch (corrupt file)".into());
    }
    if stored_key != key {
        return Err(format!(
            "stale: stored key {stored_key:016x}, expected {key:016x}"
        ));
    }
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
            let re = r.f64().ok_or_else(short)?;
            let im = r.f64().ok_or_else(short)?;
            term.push(Complex64::new(re, im));
        }
        terms.push(term);
    }
    Ok(TermStack {
        expansion,
        nx,
        ny,
        dh_um,
        band: Band {
            x0,
            y0,
            width,
            height,
        },
        terms,
        extrema,
        max_deviation_um,
        half_range_um,
    })
}

/// The terms of `hf` for `req`, through the cache in `dir` when one is given: a valid file
/// `terms-{key:016x}.bin` is loaded; a missing one is computed and written; a corrupt or
/// stale one is reported on stderr in one line, recomputed and overwritten. Failing to
/// write the cache only warns: the terms are still correct.
pub fn terms_cached(hf: &HeightField, req: &TermRequest, dir: Option<&Path>) -> Result<TermStack> {
    let Some(dir) = dir else {
        return super::compute_terms(hf, req);
    };
    req.validate()?;
    let key = cache_key(hf, req);
    let path = dir.join(format!("terms-{key:016x}.bin"));
    match load(&path, key) {
        Ok(stack) if matches_request(&stack, hf, req) => return Ok(stack),
        Ok(_) => eprintln!(
            "warning: term cache {}: contents do not match the request; recomputing",
            path.display()
        ),
        Err(Error::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => eprintln!("warning: {e}; recomputing"),
    }
    let stack = super::compute_terms(hf, req)?;
    let saved = std::fs::create_dir_all(dir)
        .map_err(|e| Error::io(dir, e))
        .and_then(|()| save(&path, &stack, key));
    if let Err(e) = saved {
        eprintln!("warning: could not write the term cache: {e}");
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
        save(&p, &s, key).expect("save");
        let back = load(&p, key).expect("load");
        assert_eq!(back, s);
        // No temporary left behind.
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn every_flipped_byte_is_detected() {
        let hf = field(2);
        let req = request(1);
        let key = cache_key(&hf, &req);
        let bytes = encode(&stack(&hf, &req), key).unwrap();
        for i in (0..bytes.len()).step_by(7).chain([bytes.len() - 1]) {
            let mut b = bytes.clone();
            b[i] ^= 0x10;
            assert!(decode(&b, key).is_err(), "flip at byte {i} not detected");
        }
    }

    #[test]
    fn flipped_byte_in_file_is_a_cache_error() {
        let hf = field(3);
        let req = request(2);
        let key = cache_key(&hf, &req);
        let dir = tmpdir("flip");
        let p = dir.join("t.bin");
        save(&p, &stack(&hf, &req), key).unwrap();
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
        let bytes = encode(&stack(&hf, &req), key).unwrap();
        for len in [0, 5, 8, 20, HEADER_LEN, bytes.len() / 2, bytes.len() - 1] {
            let err = decode(&bytes[..len], key).unwrap_err();
            assert!(!err.is_empty());
        }
        let err = decode(&bytes[..bytes.len() - 8], key).unwrap_err();
        assert!(err.contains("size mismatch"), "{err}");
    }

    #[test]
    fn other_request_or_field_is_stale() {
        let hf = field(5);
        let req = request(2);
        let key = cache_key(&hf, &req);
        let bytes = encode(&stack(&hf, &req), key).unwrap();

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
            let err = decode(&bytes, k).unwrap_err();
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
        let mut bytes = encode(&stack(&hf, &req), key).unwrap();
        let mut b = bytes.clone();
        b[0] = b'X';
        assert!(decode(&b, key).unwrap_err().contains("magic"));
        bytes[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
        assert!(decode(&bytes, key).unwrap_err().contains("version"));
    }

    #[test]
    fn terms_cached_writes_reuses_and_repairs() {
        let hf = field(9);
        let req = request(3);
        let dir = tmpdir("tc");
        let direct = super::super::compute_terms(&hf, &req).unwrap();
        let first = terms_cached(&hf, &req, Some(&dir)).unwrap();
        assert_eq!(first, direct);
        let file = dir.join(format!("terms-{:016x}.bin", cache_key(&hf, &req)));
        assert_eq!(load(&file, cache_key(&hf, &req)).unwrap(), direct);
        // A corrupt file is recomputed and overwritten with a valid one.
        let mut b = std::fs::read(&file).unwrap();
        b[HEADER_LEN + 3] ^= 0xff;
        std::fs::write(&file, &b).unwrap();
        assert_eq!(terms_cached(&hf, &req, Some(&dir)).unwrap(), direct);
        assert_eq!(load(&file, cache_key(&hf, &req)).unwrap(), direct);
        // A different request gets its own file.
        let other = request(1);
        let second = terms_cached(&hf, &other, Some(&dir)).unwrap();
        assert_eq!(second.term_count(), 2);
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 2);
        // Without a directory nothing is written.
        assert_eq!(terms_cached(&hf, &req, None).unwrap(), direct);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn inconsistent_stack_is_not_written() {
        let hf = field(8);
        let req = request(1);
        let mut s = stack(&hf, &req);
        s.terms[1].pop();
        assert!(encode(&s, 0).is_err());
    }
}
