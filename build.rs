//! Compiles every `glsl/*.vert`, `*.frag` and `*.comp` to SPIR-V in `OUT_DIR` with shaderc, so the
//! binary embeds shaders that were checked at build time. `#include "x.glsl"` resolves to
//! `glsl/x.glsl`. A GLSL error fails the build and prints `file:line: message`.

use std::path::{Path, PathBuf};

fn main() {
    let glsl_dir = PathBuf::from(env_or_exit("CARGO_MANIFEST_DIR")).join("glsl");
    let out_dir = PathBuf::from(env_or_exit("OUT_DIR"));
    // New files in glsl/ must trigger a rebuild too, not only edits of known ones.
    println!("cargo:rerun-if-changed={}", glsl_dir.display());

    let mut entries: Vec<PathBuf> = match std::fs::read_dir(&glsl_dir) {
        Ok(rd) => rd.filter_map(|e| e.ok().map(|e| e.path())).collect(),
        Err(e) => fail(&format!("{}: {e}", glsl_dir.display())),
    };
    entries.sort();

    let compiler = match shaderc::Compiler::new() {
        Ok(c) => c,
        Err(e) => fail(&format!("cannot start shaderc: {e}")),
    };
    let mut failed = false;
    for path in &entries {
        println!("cargo:rerun-if-changed={}", path.display());
        let kind = match path.extension().and_then(|e| e.to_str()) {
            Some("vert") => shaderc::ShaderKind::Vertex,
            Some("frag") => shaderc::ShaderKind::Fragment,
            Some("comp") => shaderc::ShaderKind::Compute,
            _ => continue, // *.glsl are includes, compiled as part of the stages.
        };
        if let Err(msg) = compile(&compiler, &glsl_dir, path, kind, &out_dir) {
            eprintln!("{msg}");
            println!(
                "cargo:warning={}",
                msg.lines().next().unwrap_or("shader error")
            );
            failed = true;
        }
    }
    if failed {
        fail("GLSL compilation failed (messages above are file:line: error)");
    }
}

/// Compiles one stage to `OUT_DIR/<file name>.spv`.
fn compile(
    compiler: &shaderc::Compiler,
    glsl_dir: &Path,
    path: &Path,
    kind: shaderc::ShaderKind,
    out_dir: &Path,
) -> Result<(), String> {
    let source = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut options =
        shaderc::CompileOptions::new().map_err(|e| format!("shaderc options: {e}"))?;
    // Vulkan 1.0 / SPIR-V 1.0: the oldest target, so any Vulkan driver can load the module.
    options.set_target_env(
        shaderc::TargetEnv::Vulkan,
        shaderc::EnvVersion::Vulkan1_0 as u32,
    );
    options.set_optimization_level(shaderc::OptimizationLevel::Performance);
    options.set_warnings_as_errors();
    let dir = glsl_dir.to_path_buf();
    options.set_include_callback(move |name, _ty, _from, _depth| {
        let inc = dir.join(name);
        let content = std::fs::read_to_string(&inc)
            .map_err(|e| format!("cannot include {}: {e}", inc.display()))?;
        Ok(shaderc::ResolvedInclude {
            resolved_name: inc.display().to_string(),
            content,
        })
    });
    let file_name = path.display().to_string();
    let artifact = compiler
        .compile_into_spirv(&source, kind, &file_name, "main", Some(&options))
        .map_err(|e| match e {
            shaderc::Error::CompilationError(_, msg) => msg,
            other => format!("{file_name}: {other}"),
        })?;
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| format!("{file_name}: non-UTF-8 file name"))?;
    let out = out_dir.join(format!("{name}.spv"));
    std::fs::write(&out, artifact.as_binary_u8()).map_err(|e| format!("{}: {e}", out.display()))
}

fn env_or_exit(key: &str) -> String {
    std::env::var(key).unwrap_or_else(|_| fail(&format!("{key} is not set")))
}

fn fail(msg: &str) -> ! {
    eprintln!("error: {msg}");
    std::process::exit(1);
}
