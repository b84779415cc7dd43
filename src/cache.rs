//! The on-disk cache that the DFT terms ([`crate::spectrum::cache`]), the sampled tables
//! ([`crate::brdf::table_cache`]) and their packed texels
//! ([`crate::render::variant`]'s `packed`) share: the keys (64-bit FNV-1a over everything a
//! file depends on) and file names, reading and writing a file's bytes, the directory's
//! size cap and its least-recently-used eviction, the listing, and the removal of temporary
//! files left by writers that died. Each cache owns its file format; this module never
//! looks inside a file.
//!
//! The directory is capped at [`cache_max_bytes`] (`DIFFRACT_CACHE_MAX`, default
//! [`DEFAULT_CACHE_MAX`]): after a write the least recently used files (mtime, refreshed
//! on every hit by [`mark_used`]) are removed until the total fits. Temporary files of
//! writers that died (`.terms-*.tmp-PID-N`, `.gtable-*.tmp-PID-N`) are removed when a later
//! run opens the directory ([`CacheDir::open`]).

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use crate::report::Report;
use crate::{Error, Result};

/// Default cap of the cache directory (bytes).
pub const DEFAULT_CACHE_MAX: u64 = 2 << 30;

/// File-name prefix of the DFT-term files.
pub const TERM_FILES: &str = "terms-";
/// File-name prefix of the sampled `G` tables of the table variants.
pub const TABLE_FILES: &str = "gtable-";
/// File-name prefix of the cached validity cells (the scalar model against RCWA).
pub const VALIDITY_FILES: &str = "validity-";
/// File-name prefix of the GPU-ready tables: a sampled table pre-filtered, fitted and
/// packed into the texels a draw uploads.
pub const PACKED_FILES: &str = "gpack-";
/// Prefixes of the cache's files: all count towards the cap and are listed and cleared.
pub const FILE_PREFIXES: [&str; 4] = [TERM_FILES, TABLE_FILES, VALIDITY_FILES, PACKED_FILES];

/// 64-bit FNV-1a's step over little-endian 64-bit words (eight bytes a multiply: a 300 MB
/// table is checked in a tenth of the byte-wise hash's time), fed incrementally. Not
/// cryptographic: it guards against corruption and accidental reuse, not against an
/// adversary who edits cache files.
#[derive(Clone, Copy)]
pub struct Fnv1a {
    state: u64,
    /// The bytes not yet a whole word, little-endian from the low byte, and their number.
    tail: u64,
    tail_len: u32,
}

impl Default for Fnv1a {
    fn default() -> Self {
        Self::new()
    }
}

impl Fnv1a {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;

    pub fn new() -> Self {
        Self {
            state: Self::OFFSET,
            tail: 0,
            tail_len: 0,
        }
    }

    fn word(&mut self, w: u64) {
        self.state ^= w;
        self.state = self.state.wrapping_mul(Self::PRIME);
    }

    /// Adds `data`: the same hash however a stream is cut into calls.
    pub fn bytes(&mut self, mut data: &[u8]) {
        while self.tail_len > 0 {
            let Some((&b, rest)) = data.split_first() else {
                return;
            };
            self.push(b);
            data = rest;
        }
        let mut words = data.chunks_exact(8);
        for w in &mut words {
            let mut le = [0u8; 8];
            le.copy_from_slice(w);
            self.word(u64::from_le_bytes(le));
        }
        for &b in words.remainder() {
            self.push(b);
        }
    }

    fn push(&mut self, b: u8) {
        self.tail |= u64::from(b) << (8 * self.tail_len);
        self.tail_len += 1;
        if self.tail_len == 8 {
            let w = self.tail;
            self.tail = 0;
            self.tail_len = 0;
            self.word(w);
        }
    }

    pub fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }

    /// The hash: a last partial word is added with its length.
    pub fn finish(mut self) -> u64 {
        if self.tail_len > 0 {
            let w = self.tail ^ (u64::from(self.tail_len) << 59);
            self.word(w);
        }
        self.state
    }
}

/// The file a cache with file-name prefix `prefix` stores under `key`.
pub fn file_name(prefix: &str, key: u64) -> String {
    format!("{prefix}{key:016x}.bin")
}

/// A cache directory opened for one lookup: its cap read and the temporaries of dead
/// writers removed.
pub struct CacheDir<'a> {
    dir: &'a Path,
    max: u64,
}

impl<'a> CacheDir<'a> {
    /// Reads the cap ([`cache_max_bytes`]; a nonsense `DIFFRACT_CACHE_MAX` is the error)
    /// and removes stale temporaries ([`clean_stale_temps`]).
    pub fn open(dir: &'a Path) -> Result<Self> {
        let max = cache_max_bytes()?;
        clean_stale_temps(dir);
        Ok(Self { dir, max })
    }

    /// The path of the file stored under `key` by the cache with file-name prefix `prefix`.
    pub fn file(&self, prefix: &str, key: u64) -> PathBuf {
        self.dir.join(file_name(prefix, key))
    }

    /// The cap in bytes: a file larger than this is not stored.
    pub fn max_bytes(&self) -> u64 {
        self.max
    }

    /// Stores a file: creates the directory, has `save` write `path` (which it replaces
    /// atomically, see [`crate::fsutil::write_replacing`]) and evicts the least recently
    /// used files, never `path`, until the directory fits the cap.
    pub fn store(&self, path: &Path, save: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
        std::fs::create_dir_all(self.dir).map_err(|e| Error::io(self.dir, e))?;
        save(path)?;
        evict(self.dir, self.max, Some(path)).map(|_| ())
    }
}

impl CacheDir<'_> {
    /// The bytes of the file at `path` (one of this cache's), at most `limit`: `None` when
    /// there is none. A file that cannot be read is reported (`…; rebuilding`) and is `None`
    /// too: the caller rebuilds what it held.
    pub fn read(
        &self,
        path: &Path,
        what: &str,
        limit: u64,
        report: &dyn Report,
    ) -> Option<Vec<u8>> {
        match crate::fsutil::read_bounded(path, what, limit) {
            Ok(data) => Some(data),
            Err(Error::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => {
                report.warn(&format!("{e}; rebuilding"));
                None
            }
        }
    }

    /// Stores `bytes` at `path` ([`Self::store`]). A cache file is diffract's own: replaced,
    /// never written into (a FIFO or a link left at its path must not receive it). A
    /// failure is a warning naming the cache (`what`), never an error of the caller's work.
    pub fn write(&self, path: &Path, bytes: &[u8], what: &str, report: &dyn Report) {
        let saved = self.store(path, |p| {
            crate::fsutil::write_replacing(p, |w| {
                std::io::Write::write_all(w, bytes).map_err(|e| Error::io(p, e))
            })
        });
        if let Err(e) = saved {
            report.warn(&format!("could not write the {what}: {e}"));
        }
    }
}

/// Whether [`CacheDir::write_behind`] writes on a thread of its own (the command line's
/// choice, [`write_behind_from_now`]) or at once (a library caller's default, so a file is
/// there when the call returns).
static BEHIND: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// The writes still running behind the command, and the warnings of those that ended.
static PENDING: std::sync::Mutex<(Vec<std::thread::JoinHandle<()>>, Vec<String>)> =
    std::sync::Mutex::new((Vec::new(), Vec::new()));

/// From now on, large cache files are written behind the work that made them: the command
/// goes on drawing while the file is encoded and written. [`finish_writes`] waits for them.
pub fn write_behind_from_now() {
    BEHIND.store(true, std::sync::atomic::Ordering::Relaxed);
}

/// Waits for every cache file still being written behind the work and reports the
/// warnings of those that failed. A command calls it before its last line, so its wall
/// time counts the writes, and a file is whole (or absent) when the process ends.
pub fn finish_writes(report: &dyn Report) {
    let handles = match PENDING.lock() {
        Ok(mut p) => std::mem::take(&mut p.0),
        Err(_) => return,
    };
    for h in handles {
        let _ = h.join();
    }
    let warnings = PENDING
        .lock()
        .map(|mut p| std::mem::take(&mut p.1))
        .unwrap_or_default();
    for w in warnings {
        report.warn(&w);
    }
}

impl CacheDir<'_> {
    /// Stores the bytes `make` encodes at `path`, as [`Self::write`] does, behind the
    /// caller's work once [`write_behind_from_now`] was called: `make` and the write run on
    /// a thread of their own and a failure is reported by [`finish_writes`]. Otherwise at
    /// once. As with [`Self::write`], the caller has held the file's size to the cap.
    pub fn write_behind(
        &self,
        path: PathBuf,
        what: &'static str,
        make: impl FnOnce() -> Vec<u8> + Send + 'static,
        report: &dyn Report,
    ) {
        if !BEHIND.load(std::sync::atomic::Ordering::Relaxed) {
            self.write(&path, &make(), what, report);
            return;
        }
        let (dir, max) = (self.dir.to_path_buf(), self.max);
        let handle = std::thread::spawn(move || {
            let bytes = make();
            let cache = CacheDir { dir: &dir, max };
            let failed = std::sync::Mutex::new(None);
            cache.write(&path, &bytes, what, &Failure(&failed));
            if let Some(w) = failed.into_inner().ok().flatten() {
                if let Ok(mut p) = PENDING.lock() {
                    p.1.push(w);
                }
            }
        });
        match PENDING.lock() {
            Ok(mut p) => p.0.push(handle),
            Err(_) => {
                let _ = handle.join();
            }
        }
    }
}

/// A report that keeps the one warning of a write behind the work, for [`finish_writes`].
struct Failure<'a>(&'a std::sync::Mutex<Option<String>>);

impl Report for Failure<'_> {
    fn warn(&self, line: &str) {
        if let Ok(mut w) = self.0.lock() {
            *w = Some(line.to_string());
        }
    }

    fn note(&self, _: &str) {}

    fn progress(&self, bar: indicatif::ProgressBar) -> indicatif::ProgressBar {
        bar
    }
}

/// Marks a cache file as just used: last use is the mtime, which eviction reads.
pub fn mark_used(path: &Path) {
    let _ = std::fs::File::options()
        .append(true)
        .open(path)
        .and_then(|f| f.set_modified(SystemTime::now()));
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

/// A cache file: path, size and last use.
#[derive(Debug, Clone)]
pub struct Entry {
    pub path: PathBuf,
    pub bytes: u64,
    pub last_used: SystemTime,
}

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

/// Removes temporary files `.terms-*.tmp-PID-N` and `.gtable-*.tmp-PID-N` left in `dir` by
/// writers that died (a crash or `kill -9`; an interrupt removes its own). Returns how many
/// were removed.
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hash_is_the_same_however_a_stream_is_cut_and_tells_lengths_apart() {
        let data: Vec<u8> = (0..1000u32).map(|i| (i * 37 % 251) as u8).collect();
        let whole = {
            let mut h = Fnv1a::new();
            h.bytes(&data);
            h.finish()
        };
        for cut in [1usize, 3, 7, 8, 9, 64, 333] {
            let mut h = Fnv1a::new();
            for piece in data.chunks(cut) {
                h.bytes(piece);
            }
            assert_eq!(h.finish(), whole, "pieces of {cut}");
        }
        let of = |d: &[u8]| {
            let mut h = Fnv1a::new();
            h.bytes(d);
            h.finish()
        };
        // A trailing zero, a zero word and a changed byte anywhere change the hash.
        let mut seen = std::collections::HashSet::new();
        for d in [
            &b""[..],
            b"\0",
            b"ab",
            b"ab\0",
            b"ab\0\0\0\0\0\0\0\0",
            b"ba",
        ] {
            assert!(seen.insert(of(d)), "{d:?}");
        }
        for k in 0..data.len() {
            let mut d = data.clone();
            d[k] ^= 1;
            assert_ne!(of(&d), whole, "byte {k}");
        }
    }

    fn tmpdir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("diffract-cache-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("temp dir");
        d
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
            let p = dir.join(file_name(TERM_FILES, i));
            std::fs::write(&p, vec![0u8; 1000]).unwrap();
            let f = std::fs::File::options().append(true).open(&p).unwrap();
            f.set_modified(t0 + std::time::Duration::from_secs(age))
                .unwrap();
        }
        std::fs::write(dir.join("unrelated.txt"), vec![0u8; 5000]).unwrap();
        // Over the cap by one file: the oldest (key 1, mtime +100) goes, unless kept.
        let keep = dir.join(file_name(TERM_FILES, 1));
        assert_eq!(evict(&dir, 2500, Some(&keep)).unwrap(), 1000);
        assert!(keep.exists() && !dir.join(file_name(TERM_FILES, 2)).exists());
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
}
