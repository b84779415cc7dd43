//! Files in and out. Every file a command writes goes through one output policy:
//!
//! - [`check_outputs`], before any work: each output can be written, none is an input of
//!   the command (the same path or the same file through a link), and no two outputs are
//!   the same file;
//! - [`write_atomically`]: a regular file (new or existing) is written to a temporary sibling
//!   and renamed into place only when complete, so a failure never leaves a half-written file
//!   where a good one (or nothing) was; a character device or a FIFO (`/dev/null`,
//!   `/dev/stdout`, a named pipe) is written into and never replaced.
//!
//! Inputs are read with a size bound ([`read_bounded`]).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use crate::{Error, Result};

/// Writes an output the user named. An existing character device or FIFO is opened and
/// written into (`/dev/null` stays a device, a pipe's reader gets the bytes). Anything else
/// is written through a temporary sibling file that is renamed into place only after
/// `write` succeeded and the data reached the disk; when `path` is a symbolic link to a
/// file, that file is replaced and the link kept. On any failure the temporary file is
/// removed and an existing `path` is left untouched. I/O errors name `path`.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<()>,
) -> Result<()> {
    if let Ok(meta) = std::fs::metadata(path) {
        if is_stream(&meta) {
            return write_into(path, false, write);
        }
        // `/dev/stdout` redirected to a file (`> out.csv`, `>> log`): the shell's file,
        // appended to like the shell would, instead of a new file renamed over it.
        if meta.is_file() && names_a_descriptor(path) {
            return write_into(path, true, write);
        }
    }
    let link_target = std::fs::symlink_metadata(path)
        .is_ok_and(|m| m.file_type().is_symlink())
        .then(|| link_destination(path))
        .flatten();
    replace(link_target.as_deref().unwrap_or(path), path, write)
}

/// Where the symbolic link `path` leads, following a chain of links: the file it names
/// when that exists, else the path the last link names (a dangling link), which the write
/// then creates, keeping the link. `None` for a loop or a chain of more than 40 links.
fn link_destination(path: &Path) -> Option<PathBuf> {
    if let Ok(c) = path.canonicalize() {
        return Some(c);
    }
    let mut p = path.to_path_buf();
    for _ in 0..40 {
        match std::fs::read_link(&p) {
            Ok(t) if t.is_absolute() => p = t,
            Ok(t) => p = p.parent().unwrap_or(Path::new(".")).join(t),
            Err(_) => return Some(p),
        }
    }
    None
}

/// Writes `path` through a temporary sibling and a rename, whatever `path` is now (a link
/// or a special file there is replaced, not followed): for files diffract owns, such as
/// the term cache, where writing into a FIFO someone left there would block.
pub fn write_replacing(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<()>,
) -> Result<()> {
    replace(path, path, write)
}

/// A character device or a FIFO: written into, never replaced.
fn is_stream(meta: &std::fs::Metadata) -> bool {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    t.is_char_device() || t.is_fifo()
}

/// Whether `path` leads to an open file descriptor (`/dev/stdout`, `/dev/fd/1`,
/// `/proc/self/fd/1`): it lies in `/proc` or `/dev/fd`, or its links lead there.
fn names_a_descriptor(path: &Path) -> bool {
    let mut p = path.to_path_buf();
    for _ in 0..40 {
        if p.starts_with("/proc") || p.starts_with("/dev/fd") {
            return true;
        }
        match std::fs::read_link(&p) {
            Ok(t) if t.is_absolute() => p = t,
            Ok(t) => p = p.parent().unwrap_or(Path::new("/")).join(t),
            Err(_) => return false,
        }
    }
    false
}

/// Opens an existing file (a character device, a FIFO, or with `append` the file behind a
/// descriptor) for writing and writes into it.
fn write_into(
    path: &Path,
    append: bool,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<()>,
) -> Result<()> {
    let file = std::fs::OpenOptions::new()
        .write(true)
        .append(append)
        .open(path)
        .map_err(|e| Error::io(path, e))?;
    let mut w = BufWriter::new(file);
    write(&mut w)?;
    w.into_inner()
        .map_err(|e| Error::write(path, e.into_error()))?;
    Ok(())
}

/// The temporary-file-and-rename write of `target`; errors name `shown` (the path the user
/// gave).
fn replace(
    target: &Path,
    shown: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<()>,
) -> Result<()> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let path = shown;
    let file_name = target.file_name().ok_or_else(|| {
        Error::io(
            path,
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file path"),
        )
    })?;
    let dir = match target.parent() {
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
            .map_err(|e| Error::write(path, e.into_error()))?;
        file.sync_all().map_err(|e| Error::write(path, e))
    });
    let result =
        result.and_then(|()| std::fs::rename(&tmp, target).map_err(|e| Error::io(path, e)));
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
///
/// The handler ends the process with `_exit`, whatever the other threads are doing: every
/// loop of the program (a table build, a term precompute, a mesh's normals) stops at once,
/// with no flag to poll. `exit` would first run the process's exit handlers, among them the
/// Vulkan driver's, which wait for its worker threads and can block while the main thread
/// is inside the driver.
pub fn remove_temps_on_interrupt() {
    let _ = ctrlc::set_handler(|| {
        // The list's lock is only ever held to push or remove one path, never across I/O.
        if let Ok(v) = IN_FLIGHT.lock() {
            for p in v.iter() {
                let _ = std::fs::remove_file(p);
            }
        }
        eprintln!("error: interrupted");
        // SAFETY: _exit ends the process without running exit handlers; nothing after it.
        unsafe { libc::_exit(130) }
    });
}

/// [`write_atomically`] for a byte buffer.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomically(path, |w| {
        w.write_all(bytes).map_err(|e| Error::write(path, e))
    })
}

// ---- the output policy: checked before any work -------------------------------------------

/// An output path must name a file that can be written: a new file in a directory that
/// exists, an existing regular file (replaced), or an existing character device or FIFO
/// (written into). A directory, a block device or a socket is refused.
pub fn check_output(path: &Path) -> Result<()> {
    let bad = |msg: &str| {
        Err(Error::invalid(
            "output",
            format!("{}: {msg}", path.display()),
        ))
    };
    if path.as_os_str().is_empty() {
        return bad("empty path");
    }
    if path.file_name().is_none() {
        return bad("not a file name");
    }
    if let Ok(meta) = std::fs::metadata(path) {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_dir() {
            return bad("is a directory");
        }
        if t.is_block_device() {
            return bad("is a block device; refusing to write over it");
        }
        if t.is_socket() {
            return bad("is a socket; expected a file, a character device or a FIFO");
        }
        if is_stream(&meta) {
            return if writable(path) {
                Ok(())
            } else {
                bad("cannot be written (permission denied)")
            };
        }
    }
    // A link (dangling or not) is written through: what matters is where its file is.
    let is_link = std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
    let target = if is_link {
        match link_destination(path) {
            Some(t) => t,
            None => return bad("is a loop of symbolic links"),
        }
    } else {
        path.to_path_buf()
    };
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => {}
        Ok(_) => return bad(&format!("{} is not a directory", dir.display())),
        Err(_) => return bad(&format!("directory {} does not exist", dir.display())),
    }
    // The file is written beside its target and renamed over it: the directory must take
    // a new file (not read-only, not on a read-only file system).
    if writable(dir) {
        Ok(())
    } else {
        bad(&format!(
            "directory {} cannot be written (read-only or permission denied)",
            dir.display()
        ))
    }
}

/// An output directory the command creates after its work (without parents) and fills with
/// files: an existing one must be a directory this process may write (each file in it still
/// goes through [`check_outputs`]); a new one needs an existing directory above it that this
/// process may write, so that it can be created when the work is done.
pub fn check_output_dir(dir: &Path) -> Result<()> {
    let bad = |msg: String| {
        Err(Error::invalid(
            "output",
            format!("{}: {msg}", dir.display()),
        ))
    };
    if dir.as_os_str().is_empty() {
        return Err(Error::invalid("output", "empty directory path"));
    }
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => {
            return if writable(dir) {
                Ok(())
            } else {
                bad("directory cannot be written (read-only or permission denied)".into())
            };
        }
        Ok(_) => return bad("not a directory".into()),
        Err(_) => {}
    }
    if std::fs::symlink_metadata(dir).is_ok() {
        return bad("is a link to nothing; create its directory or choose another path".into());
    }
    let parent = match dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    match std::fs::metadata(parent) {
        Ok(m) if m.is_dir() => {}
        Ok(_) => return bad(format!("{} is not a directory", parent.display())),
        Err(_) => return bad(format!("directory {} does not exist", parent.display())),
    }
    if writable(parent) {
        Ok(())
    } else {
        bad(format!(
            "cannot be created: directory {} cannot be written (read-only or permission denied)",
            parent.display()
        ))
    }
}

/// Creates an output directory that [`check_output_dir`] accepted, unless it exists.
pub fn create_output_dir(dir: &Path) -> Result<()> {
    match std::fs::create_dir(dir) {
        Err(e) if !(e.kind() == std::io::ErrorKind::AlreadyExists && dir.is_dir()) => {
            Err(Error::io(dir, e))
        }
        _ => Ok(()),
    }
}

/// Whether this process may write `path` (`access(2)` with `W_OK`: permissions and a
/// read-only file system).
fn writable(path: &Path) -> bool {
    use std::os::unix::ffi::OsStrExt;
    let Ok(c) = std::ffi::CString::new(path.as_os_str().as_bytes()) else {
        return false;
    };
    // SAFETY: `c` is a valid NUL-terminated path; access only reads it.
    unsafe { libc::access(c.as_ptr(), libc::W_OK) == 0 }
}

/// A path made comparable: the canonical path of the file, or of its directory joined with
/// its name when the file does not exist yet.
fn comparable(p: &Path) -> PathBuf {
    if let Ok(c) = p.canonicalize() {
        return c;
    }
    let dir = match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    match (dir.canonicalize(), p.file_name()) {
        (Ok(d), Some(n)) => d.join(n),
        _ => p.to_path_buf(),
    }
}

/// Whether `a` and `b` name the same file: the same device and inode when both exist (hard
/// links, `./x`, symlinks), else the same comparable path.
pub fn same_file(a: &Path, b: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) {
        return ma.dev() == mb.dev() && ma.ino() == mb.ino();
    }
    comparable(a) == comparable(b)
}

/// Refuses when an output names the same file as an input or as another output. `inputs`
/// and `outputs` pair a role ("height field", "--png image") with the path.
pub fn refuse_overwrite(inputs: &[(&str, PathBuf)], outputs: &[(&str, PathBuf)]) -> Result<()> {
    for (k, (out_role, out)) in outputs.iter().enumerate() {
        for (in_role, input) in inputs {
            if same_file(out, input) {
                return Err(Error::invalid(
                    "output",
                    format!(
                        "{out_role} {} is the {in_role} {}; refusing to overwrite an input",
                        out.display(),
                        input.display()
                    ),
                ));
            }
        }
        for (other_role, other) in &outputs[..k] {
            if same_file(out, other) {
                return Err(Error::invalid(
                    "output",
                    format!("{out_role} and {other_role} are both {}", out.display()),
                ));
            }
        }
    }
    Ok(())
}

/// The whole policy for one command: every input that exists is a regular file
/// ([`check_inputs`]), every output passes [`check_output`], and none is an input or another
/// output ([`refuse_overwrite`]). Commands call it before any work.
pub fn check_outputs(inputs: &[(&str, PathBuf)], outputs: &[(&str, PathBuf)]) -> Result<()> {
    check_inputs(inputs)?;
    for (_, o) in outputs {
        check_output(o)?;
    }
    refuse_overwrite(inputs, outputs)
}

/// Every input that exists (through links) is a regular file: a FIFO would block its reader
/// forever, a device would never end, a directory would give a confusing message. A missing
/// input is left to its reader, which names it (an optional sidecar may be absent).
/// Nothing is opened here.
pub fn check_inputs(inputs: &[(&str, PathBuf)]) -> Result<()> {
    for (role, p) in inputs {
        if let Ok(meta) = std::fs::metadata(p) {
            if !meta.is_file() {
                return Err(Error::parse(
                    p,
                    format!("not a regular file; the {role} must be a file"),
                ));
            }
        }
    }
    Ok(())
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

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("diffract-fsutil-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_link_to_a_file_keeps_the_link_and_replaces_its_target() {
        let d = tmp("link");
        let target = d.join("real.csv");
        std::fs::write(&target, b"old").unwrap();
        let link = d.join("out.csv");
        std::os::unix::fs::symlink("real.csv", &link).unwrap();
        write_atomic(&link, b"new").unwrap();
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        // write_replacing (the cache's) replaces the link itself.
        write_replacing(&link, |w| {
            w.write_all(b"own").map_err(|e| Error::io(&link, e))
        })
        .unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().is_file());
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn outputs_are_checked_against_inputs_and_each_other() {
        let d = tmp("policy");
        let input = d.join("hf.png");
        std::fs::write(&input, b"png").unwrap();
        std::os::unix::fs::symlink("hf.png", d.join("alias.png")).unwrap();
        let inputs = [("height field", input.clone())];
        let e = check_outputs(&inputs, &[("--plot", d.join("alias.png"))]).unwrap_err();
        assert!(e.to_string().contains("is the height field"), "{e}");
        let e =
            check_outputs(&[], &[("--csv", d.join("a")), ("--plot", d.join("./a"))]).unwrap_err();
        assert!(e.to_string().contains("--plot and --csv are both"), "{e}");
        assert!(check_outputs(&inputs, &[("--csv", PathBuf::from("/dev/null"))]).is_ok());
        assert!(check_outputs(&inputs, &[("--csv", d.clone())]).is_err());
        let _ = std::fs::remove_dir_all(&d);
    }
}
