//! Helpers shared by the bad-input and hardening tests: what a directory holds, to show
//! that a refused command changed nothing, and a child whose output is read while it runs.

// Each test binary that includes this module uses its own part of it.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::thread::JoinHandle;

/// A child's stdout and stderr, read to their ends on threads of their own, so that a
/// child writing more than a pipe holds cannot block while the caller waits for it.
pub struct Drained {
    out: JoinHandle<Vec<u8>>,
    err: JoinHandle<Vec<u8>>,
}

impl Drained {
    /// Stdout and stderr, once the child has closed them.
    pub fn join(self) -> (Vec<u8>, Vec<u8>) {
        (self.out.join().unwrap(), self.err.join().unwrap())
    }
}

/// Starts `cmd` with no stdin and its stdout and stderr [`Drained`].
pub fn spawn_drained(cmd: &mut Command) -> (Child, Drained) {
    use std::io::Read;
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let drain = |mut r: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut v = Vec::new();
            r.read_to_end(&mut v).unwrap();
            v
        })
    };
    let out = drain(Box::new(child.stdout.take().unwrap()));
    let err = drain(Box::new(child.stderr.take().unwrap()));
    (child, Drained { out, err })
}

/// Every file under `dir` (not following links), with its bytes or link target.
pub fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            let meta = std::fs::symlink_metadata(&p).unwrap();
            if meta.is_dir() {
                out.insert(p.clone(), b"<dir>".to_vec());
                stack.push(p);
            } else if meta.file_type().is_symlink() {
                let t = std::fs::read_link(&p).unwrap();
                out.insert(p, t.to_string_lossy().as_bytes().to_vec());
            } else if !meta.is_file() {
                // A FIFO would block a read: its kind is what is compared.
                out.insert(p, b"<not a regular file>".to_vec());
            } else {
                out.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}
