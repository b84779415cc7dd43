//! A table variant's GPU texels as they are uploaded ([`Packed`]), and their cache: a draw
//! whose table was built before reads the packed texels and uploads them, skipping the
//! sampled table's decoding, the disc pre-filter, the fit and the packing (about 0.45 s of
//! the default scene's warm render on 2 cores). Used where no f64 model of the table is
//! kept (`render`, `view`); `profile` keeps the model and takes the full path.

use std::path::Path;

use super::TableFormat;
use crate::brdf::table::{Region, Truncation};
use crate::cache::{mark_used, CacheDir, Fnv1a, PACKED_FILES};
use crate::report::Report;

const MAGIC: &[u8; 8] = b"DIFFPACK";
/// Bump when the layout of the texels or of the file changes.
const VERSION: u64 = 4;
/// Header: magic, version, key, 8 sizes, format, 6 region bounds, the series' truncation
/// (4 words), byte count.
const HEADER: usize = 8 + 8 + 8 + 8 * 8 + 8 + 6 * 8 + 4 * 8 + 8;

/// The texels of a table as one image: `planes` coefficient planes of `nu × nv` nodes,
/// stored `pu × pv` texels a layer in `layers` layers of `format`, over `region`, with
/// `levels` levels pre-filtered for a pixel's footprint (`brdf::table::Levelled`; 1: none).
#[derive(Debug, Clone, PartialEq)]
pub struct Packed {
    pub nu: usize,
    pub nv: usize,
    pub pu: usize,
    pub pv: usize,
    pub planes: usize,
    pub layers: usize,
    pub fetches: usize,
    pub levels: usize,
    pub format: TableFormat,
    pub region: Region,
    pub bytes: Vec<u8>,
    /// Summed-area planes (`(nu + 1) × (nv + 1)` texels, `layers` layers, float32) for box
    /// reads at a pixel's footprint; empty where the table has none.
    pub summed: Vec<u8>,
    /// The series terms kept of those the nodes gave (`chebyshev-w`); `None` for a table
    /// that is no such series.
    pub terms: Option<Truncation>,
}

impl Packed {
    fn encode(&self, key: u64) -> Vec<u8> {
        let mut out = Vec::with_capacity(HEADER + self.bytes.len() + 8);
        out.extend_from_slice(MAGIC);
        for v in [VERSION, key] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        let format = match self.format {
            TableFormat::Rgba32f => 0u64,
            TableFormat::Rgba16f => 1,
        };
        for v in [
            self.nu,
            self.nv,
            self.pu,
            self.pv,
            self.planes,
            self.layers,
            self.fetches,
            self.levels,
        ] {
            out.extend_from_slice(&(v as u64).to_le_bytes());
        }
        out.extend_from_slice(&format.to_le_bytes());
        for v in self.region.lo.iter().chain(&self.region.hi) {
            out.extend_from_slice(&v.to_le_bytes());
        }
        // `of` = 0: no series.
        let t = self.terms.unwrap_or(Truncation {
            kept: 0,
            of: 0,
            tail: 0.0,
            peak: 0.0,
        });
        for v in [
            t.of as u64,
            t.kept as u64,
            t.tail.to_bits(),
            t.peak.to_bits(),
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(&(self.bytes.len() as u64).to_le_bytes());
        out.extend_from_slice(&self.bytes);
        out.extend_from_slice(&(self.summed.len() as u64).to_le_bytes());
        out.extend_from_slice(&self.summed);
        let mut h = Fnv1a::new();
        h.bytes(&out);
        out.extend_from_slice(&h.finish().to_le_bytes());
        out
    }

    fn decode(data: Vec<u8>, key: u64) -> std::result::Result<Self, String> {
        if data.len() < HEADER + 8 || &data[..8] != MAGIC {
            return Err("not a packed table".into());
        }
        let (body, sum) = data.split_at(data.len() - 8);
        let mut h = Fnv1a::new();
        h.bytes(body);
        if sum != h.finish().to_le_bytes() {
            return Err("checksum mismatch".into());
        }
        let word = |i: usize| {
            let at = 8 + 8 * i;
            u64::from_le_bytes(body[at..at + 8].try_into().unwrap_or([0; 8]))
        };
        if word(0) != VERSION || word(1) != key {
            return Err("another version or key".into());
        }
        let size = |i: usize| usize::try_from(word(i)).map_err(|_| "size overflows".to_string());
        let format = match word(10) {
            0 => TableFormat::Rgba32f,
            1 => TableFormat::Rgba16f,
            f => return Err(format!("unknown texel format {f}")),
        };
        let real = |i: usize| f64::from_bits(word(i));
        let region = Region {
            lo: [real(11), real(12), real(13)],
            hi: [real(14), real(15), real(16)],
        };
        let p = Packed {
            nu: size(2)?,
            nv: size(3)?,
            pu: size(4)?,
            pv: size(5)?,
            planes: size(6)?,
            layers: size(7)?,
            fetches: size(8)?,
            levels: size(9)?,
            format,
            region,
            bytes: Vec::new(),
            summed: Vec::new(),
            terms: (word(17) > 0).then(|| Truncation {
                of: word(17) as usize,
                kept: word(18) as usize,
                tail: real(19),
                peak: real(20),
            }),
        };
        if p.terms.is_some_and(|t| t.kept != p.planes || t.kept > t.of) {
            return Err("series terms do not match the planes".into());
        }
        let expected =
            p.pu.checked_mul(p.pv)
                .and_then(|t| t.checked_mul(p.layers))
                .and_then(|t| t.checked_mul(format.texel_bytes()));
        let count = size(21)?;
        if expected != Some(count) || body.len() < HEADER + count + 8 {
            return Err("texel count does not match its sizes".into());
        }
        let rest = &body[HEADER + count..];
        let summed = u64::from_le_bytes(rest[..8].try_into().unwrap_or([0; 8]));
        let summed_expected = (p.nu + 1)
            .checked_mul(p.nv + 1)
            .and_then(|t| t.checked_mul(p.layers * 16));
        let summed_ok = (summed == 0 || Some(summed as usize) == summed_expected)
            && rest.len() == 8 + summed as usize;
        if !summed_ok {
            return Err("summed-area texel count does not match its sizes".into());
        }
        // The texels stay in the buffer read (moved down over the header), not copied out.
        let summed = rest[8..].to_vec();
        let mut bytes = data;
        bytes.truncate(HEADER + count);
        bytes.drain(..HEADER);
        Ok(Packed { bytes, summed, ..p })
    }
}

/// The packed table stored under `key` in `dir`, if there is a valid one of at most
/// `max_bytes` texels with `nodes` nodes; a damaged file is reported and ignored.
pub fn load(
    dir: &Path,
    key: u64,
    nodes: (usize, usize),
    max_bytes: u64,
    report: &dyn Report,
) -> Option<Packed> {
    let cache = CacheDir::open(dir).ok()?;
    let path = cache.file(PACKED_FILES, key);
    let limit = max_bytes.saturating_add((HEADER + 16) as u64);
    let data = cache.read(&path, "packed table cache", limit, report)?;
    match Packed::decode(data, key) {
        Ok(p) if (p.nu, p.nv) == nodes => {
            mark_used(&path);
            Some(p)
        }
        Ok(_) => None,
        Err(msg) => {
            report.warn(&format!(
                "packed table cache {}: {msg}; rebuilding",
                path.display()
            ));
            None
        }
    }
}

/// Stores `packed` under `key` in `dir` (replacing, never writing into, what is there); a
/// failure is a warning, never an error of the draw. A table over the cache's cap is not
/// stored.
pub fn store(dir: &Path, key: u64, packed: Packed, report: &dyn Report) {
    match CacheDir::open(dir) {
        Ok(cache) => {
            let size = (HEADER + packed.bytes.len() + 8 + packed.summed.len() + 8) as u64;
            // Over the cap it is silently not stored: the sampled table's line says so.
            if size <= cache.max_bytes() {
                let path = cache.file(PACKED_FILES, key);
                let make = move || packed.encode(key);
                cache.write_behind(path, "packed table cache", make, report);
            }
        }
        Err(e) => report.warn(&format!("could not write the packed table cache: {e}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn packed() -> Packed {
        Packed {
            nu: 3,
            nv: 2,
            pu: 5,
            pv: 4,
            planes: 2,
            layers: 1,
            fetches: 4,
            levels: 1,
            format: TableFormat::Rgba16f,
            region: Region {
                lo: [-0.1, -0.2, -2.0],
                hi: [0.1, 0.2, -1.0],
            },
            bytes: (0..5 * 4 * 8).map(|i| i as u8).collect(),
            summed: Vec::new(),
            terms: None,
        }
    }

    #[test]
    fn a_packed_table_round_trips_and_damage_is_refused() {
        let p = packed();
        let data = p.encode(7);
        assert_eq!(Packed::decode(data.clone(), 7), Ok(p));
        assert!(Packed::decode(data.clone(), 8).is_err(), "another key");
        let mut bad = data.clone();
        bad[HEADER + 3] ^= 1;
        assert!(Packed::decode(bad, 7).is_err(), "a flipped texel");
        assert!(
            Packed::decode(data[..data.len() - 1].to_vec(), 7).is_err(),
            "cut short"
        );
        // With summed-area planes: (3 + 1) × (2 + 1) texels of 16 bytes in its one layer.
        let with = Packed {
            summed: (0..4 * 3 * 16).map(|i| (i * 7) as u8).collect(),
            ..packed()
        };
        let data = with.encode(7);
        assert_eq!(Packed::decode(data, 7), Ok(with.clone()));
        // A truncated series keeps its record; one that disagrees with the planes is refused.
        let truncated = Packed {
            terms: Some(Truncation {
                kept: 2,
                of: 5,
                tail: 3.5e-4,
                peak: 0.25,
            }),
            ..packed()
        };
        let data = truncated.encode(7);
        assert_eq!(Packed::decode(data, 7), Ok(truncated.clone()));
        let wrong = Packed {
            planes: 3,
            layers: 3,
            bytes: vec![0; 5 * 4 * 8 * 3],
            ..truncated
        };
        assert!(
            Packed::decode(wrong.encode(7), 7).is_err(),
            "terms ≠ planes"
        );
        let short = Packed {
            summed: vec![1; 4 * 3 * 16 - 16],
            ..packed()
        };
        assert!(
            Packed::decode(short.encode(7), 7).is_err(),
            "summed planes of the wrong size"
        );
    }

    #[test]
    fn a_cached_table_is_read_back_and_a_missing_one_is_none() {
        let dir = std::env::temp_dir().join(format!("diffract-packed-{}", std::process::id()));
        let report = crate::report::Collect::default();
        assert_eq!(load(&dir, 1, (3, 2), 1 << 20, &report), None);
        store(&dir, 1, packed(), &report);
        assert_eq!(load(&dir, 1, (3, 2), 1 << 20, &report), Some(packed()));
        assert_eq!(load(&dir, 1, (4, 2), 1 << 20, &report), None, "other nodes");
        let _ = std::fs::remove_dir_all(dir);
    }
}
