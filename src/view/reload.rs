//! Shader hot reload: polls the modification times of `glsl/*`, recompiles every stage with
//! shaderc (the options of `build.rs`) and hands out the SPIR-V by file name. A compile error
//! is returned as shaderc's `file:line: error` text and the last good SPIR-V is kept, so the
//! viewer keeps drawing with its current pipeline.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use crate::{Error, Result};

/// Watches one glsl directory.
pub struct ShaderReload {
    dir: PathBuf,
    compiler: shaderc::Compiler,
    stamps: HashMap<PathBuf, SystemTime>,
    good: HashMap<String, Vec<u8>>,
}

impl ShaderReload {
    /// Starts watching `dir` (its current files count as seen; nothing is compiled yet).
    pub fn new(dir: &Path) -> Result<Self> {
        let compiler = shaderc::Compiler::new()
            .map_err(|e| Error::invalid("shader reload", format!("cannot start shaderc: {e}")))?;
        let mut r = Self {
            dir: dir.to_path_buf(),
            compiler,
            stamps: HashMap::new(),
            good: HashMap::new(),
        };
        r.stamps = r.scan()?;
        Ok(r)
    }

    /// The directory watched.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn scan(&self) -> Result<HashMap<PathBuf, SystemTime>> {
        let rd = std::fs::read_dir(&self.dir).map_err(|e| Error::io(&self.dir, e))?;
        let mut stamps = HashMap::new();
        for entry in rd.flatten() {
            let path = entry.path();
            if let Ok(t) = entry.metadata().and_then(|m| m.modified()) {
                stamps.insert(path, t);
            }
        }
        Ok(stamps)
    }

    /// Whether any file was added, removed or modified since the last call.
    pub fn changed(&mut self) -> Result<bool> {
        let now = self.scan()?;
        let changed = now != self.stamps;
        self.stamps = now;
        Ok(changed)
    }

    /// Recompiles every `*.vert` and `*.frag`. On success the new SPIR-V becomes the last
    /// good set and is returned; on a compile error the message (`file:line: error: ...`)
    /// is returned and the last good set is unchanged.
    pub fn compile_all(&mut self) -> std::result::Result<&HashMap<String, Vec<u8>>, String> {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(&self.dir)
            .map_err(|e| format!("{}: {e}", self.dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        entries.sort();
        let mut out = HashMap::new();
        let mut errors = Vec::new();
        for path in &entries {
            let kind = match path.extension().and_then(|e| e.to_str()) {
                Some("vert") => shaderc::ShaderKind::Vertex,
                Some("frag") => shaderc::ShaderKind::Fragment,
                _ => continue,
            };
            match compile(&self.compiler, &self.dir, path, kind) {
                Ok(spirv) => {
                    let name = path
                        .file_name()
                        .map(|n| n.to_string_lossy().into_owned())
                        .unwrap_or_default();
                    out.insert(name, spirv);
                }
                Err(msg) => errors.push(msg),
            }
        }
        if !errors.is_empty() {
            return Err(errors.join("\n"));
        }
        self.good = out;
        Ok(&self.good)
    }

    /// The last SPIR-V set that compiled (empty before the first success).
    pub fn last_good(&self) -> &HashMap<String, Vec<u8>> {
        &self.good
    }
}

/// One stage, as build.rs compiles it (Vulkan 1.0, performance, warnings are errors,
/// `#include "x.glsl"` from the same directory).
fn compile(
    compiler: &shaderc::Compiler,
    dir: &Path,
    path: &Path,
    kind: shaderc::ShaderKind,
) -> std::result::Result<Vec<u8>, String> {
    let source = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut options =
        shaderc::CompileOptions::new().map_err(|e| format!("shaderc options: {e}"))?;
    options.set_target_env(
        shaderc::TargetEnv::Vulkan,
        shaderc::EnvVersion::Vulkan1_0 as u32,
    );
    options.set_optimization_level(shaderc::OptimizationLevel::Performance);
    options.set_warnings_as_errors();
    let inc_dir = dir.to_path_buf();
    options.set_include_callback(move |name, _ty, _from, _depth| {
        let inc = inc_dir.join(name);
        let content = std::fs::read_to_string(&inc)
            .map_err(|e| format!("cannot include {}: {e}", inc.display()))?;
        Ok(shaderc::ResolvedInclude {
            resolved_name: inc.display().to_string(),
            content,
        })
    });
    let file_name = path.display().to_string();
    compiler
        .compile_into_spirv(&source, kind, &file_name, "main", Some(&options))
        .map(|a| a.as_binary_u8().to_vec())
        .map_err(|e| match e {
            shaderc::Error::CompilationError(_, msg) => msg.trim_end().to_string(),
            other => format!("{file_name}: {other}"),
        })
}
