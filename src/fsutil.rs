//! Writing files so that a failure never leaves a half-written file where a good one (or
//! nothing) was: every output of diffract goes through [`write_atomically`].

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use crate::{Error, Result};

/// Writes `path` through a temporary sibling file that is renamed into place only after
/// `write` succeeded and the data reached the disk. On any failure the temporary file is
/// removed and an existing `path` is left untouched. I/O errors name `path`.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<()>,
) -> Result<()> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let file_name = path.file_name().ok_or_else(|| {
        Error::io(
            path,
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file path"),
        )
    })?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let tmp = dir.join(format!(
        ".{}.tmp-{}-{}",
        file_name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let file = File::create(&tmp).map_err(|e| Error::io(path, e))?;
    let _registered = InFlight::register(&tmp);
    let mut w = BufWriter::new(file);
    let result = write(&mut w).and_then(|()| {
        let file = w
            .into_inner()
            .map_err(|e| Error::io(path, e.into_error()))?;
        file.sync_all().map_err(|e| Error::io(path, e))
    });
    let result = result.and_then(|()| std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e)));
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Temporary files being written now, removed by the interrupt handler.
static IN_FLIGHT: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Registers a temporary file for the lifetime of the guard.
struct InFlight(PathBuf);

impl InFlight {
    fn register(tmp: &Path) -> Self {
        if let Ok(mut v) = IN_FLIGHT.lock() {
            v.push(tmp.to_path_buf());
        }
        Self(tmp.to_path_buf())
    }
}

impl Drop for InFlight {
    fn drop(&mut self) {
        if let Ok(mut v) = IN_FLIGHT.lock() {
            v.retain(|p| p != &self.0);
        }
    }
}

/// Installs a Ctrl-C / SIGTERM / SIGHUP handler that removes the temporary files of writes
/// in progress (a term cache file can be hundreds of MB) and exits with status 130. Call
/// once, from the binary; a second call (or a host that already set a handler) is ignored.
pub fn remove_temps_on_interrupt() {
    let _ = ctrlc::set_handler(|| {
        if let Ok(v) = IN_FLIGHT.lock() {
            for p in v.iter() {
                let _ = std::fs::remove_file(p);
            }
        }
        eprintln!("error: interrupted");
        std::process::exit(130);
    });
}

/// [`write_atomically`] for a byte buffer.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomically(path, |w| w.write_all(bytes).map_err(|e| Error::io(path, e)))
}

/// Largest scene, sidecar or other TOML file read (bytes): real ones are a few KB.
pub const MAX_TOML_BYTES: u64 = 1 << 20;
/// Largest query CSV read (bytes): about 5 million rows.
pub const MAX_CSV_BYTES: u64 = 256 << 20;
/// Largest OBJ mesh read (bytes).
pub const MAX_OBJ_BYTES: u64 = 512 << 20;
/// Largest PNG read (bytes); decoding is further bounded by the image crate's allocation
/// limit and by the 4096² height-field limit.
pub const MAX_PNG_BYTES: u64 = 256 << 20;

/// Checks that `path` is a regular file of at most `limit` bytes, before anything reads it:
/// a device (`/dev/zero`), a pipe or a directory would otherwise be read without end or
/// give a confusing message. Returns the file's length.
pub fn check_input_file(path: &Path, what: &str, limit: u64) -> Result<u64> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(Error::parse(
            path,
            format!("not a regular file; the {what} must be a file"),
        ));
    }
    if meta.len() > limit {
        return Err(Error::parse(
            path,
            format!(
                "{} bytes; a {what} may have at most {limit} bytes",
                meta.len()
            ),
        ));
    }
    Ok(meta.len())
}

/// Reads at most `limit` bytes of a regular file (see [`check_input_file`]). The read itself
/// is bounded too (`Read::take`), so a file that grows while it is read cannot exhaust memory.
pub fn read_bounded(path: &Path, what: &str, limit: u64) -> Result<Vec<u8>> {
    use std::io::Read;
    let len = check_input_file(path, what, limit)?;
    let file = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut data = Vec::with_capacity(len as usize);
    file.take(limit + 1)
        .read_to_end(&mut data)
        .map_err(|e| Error::io(path, e))?;
    if data.len() as u64 > limit {
        return Err(Error::parse(
            path,
            format!("grew past {limit} bytes while being read"),
        ));
    }
    Ok(data)
}

/// [`read_bounded`] as UTF-8 text, without a leading byte-order mark (editors on Windows
/// write one; it is invisible in a message and must not make a header "differ").
pub fn read_text_bounded(path: &Path, what: &str, limit: u64) -> Result<String> {
    let data = read_bounded(path, what, limit)?;
    let mut text = String::from_utf8(data).map_err(|e| {
        Error::parse(
            path,
            format!(
                "not UTF-8 text (invalid byte at offset {})",
                e.utf8_error().valid_up_to()
            ),
        )
    })?;
    if text.starts_with('\u{feff}') {
        text.drain(..'\u{feff}'.len_utf8());
    }
    Ok(text)
}
