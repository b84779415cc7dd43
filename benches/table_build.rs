//! The table build, CPU f64 against the device, side by side in one run: `cargo bench
//! --bench table_build`. Each case runs `diffract render` with an empty cache (`--no-cache`)
//! once per build (`--table-build cpu`, `device`, and `device-f32` where the device has
//! float64) and reads the `table:` line it prints (where, how long, how large). Cases: the
//! default scene (`diffract render -o x.png`, the table its view reaches) and 128² BRDF maps
//! at θi = 60° of the shipped gratings. Prints a Markdown table for docs/results/.
//!
//! Arguments after `--`: `--step-nm N` (the tables' wavelength step, default 1 as
//! `render` uses; a coarser step scales every build down alike), `--only NAME` (one case:
//! default, blazed, sinusoidal, elaphe-grown), `--builds cpu,device,device-f32`.

use std::process::Command;
use std::time::Instant;

struct Case {
    name: &'static str,
    args: Vec<&'static str>,
}

fn cases() -> Vec<Case> {
    let map = |field: &'static str| {
        vec![
            "--brdf-map",
            "--size",
            "128",
            "--theta-i",
            "60",
            "--heightfield",
            field,
        ]
    };
    vec![
        Case {
            name: "default",
            args: vec![],
        },
        Case {
            name: "blazed",
            args: map("builtin:blazed"),
        },
        Case {
            name: "sinusoidal",
            args: map("builtin:sinusoidal"),
        },
        Case {
            name: "elaphe-grown",
            args: map("builtin:elaphe-grown"),
        },
    ]
}

fn main() {
    let argv: Vec<String> = std::env::args().collect();
    let value = |flag: &str| {
        argv.iter()
            .position(|a| a == flag)
            .and_then(|i| argv.get(i + 1))
            .cloned()
    };
    let step = value("--step-nm").unwrap_or_else(|| "1".into());
    let only = value("--only");
    let builds = value("--builds").unwrap_or_else(|| "cpu,device,device-f32".into());
    let exe = env!("CARGO_BIN_EXE_diffract");
    let out = std::env::temp_dir().join(format!("diffract-bench-table-{}", std::process::id()));
    if let Err(e) = std::fs::create_dir_all(&out) {
        eprintln!("error: {}: {e}", out.display());
        std::process::exit(1);
    }
    println!("| case | build | table | where | build (s) | render wall (s) |");
    println!("|---|---|---|---|---|---|");
    for case in cases() {
        if only.as_deref().is_some_and(|o| o != case.name) {
            continue;
        }
        for build in builds.split(',') {
            let png = out.join(format!("{}-{build}.png", case.name));
            let start = Instant::now();
            let o = Command::new(exe)
                .arg("render")
                .args(&case.args)
                .args([
                    "--no-cache",
                    "--table-step-nm",
                    &step,
                    "--table-build",
                    build,
                    "-o",
                ])
                .arg(&png)
                .output();
            let wall = start.elapsed().as_secs_f64();
            let o = match o {
                Ok(o) => o,
                Err(e) => {
                    eprintln!("error: cannot run {exe}: {e}");
                    std::process::exit(1);
                }
            };
            let stdout = String::from_utf8_lossy(&o.stdout);
            if !o.status.success() {
                println!(
                    "| {} | {build} | — | failed: {} | — | — |",
                    case.name,
                    String::from_utf8_lossy(&o.stderr)
                        .lines()
                        .last()
                        .unwrap_or("")
                );
                continue;
            }
            // "table: <name>, built on <where> in <s> s, <MB> MB"
            let line = stdout
                .lines()
                .find_map(|l| l.strip_prefix("table: "))
                .unwrap_or("(no table line)");
            let (what, rest) = line.split_once(", built on ").unwrap_or((line, ""));
            let (place, tail) = rest.split_once(" in ").unwrap_or((rest, ""));
            let seconds = tail.split(" s").next().unwrap_or("?");
            let mb = tail.rsplit(", ").next().unwrap_or("");
            println!(
                "| {} | {build} | {what}, {mb} | {place} | {seconds} | {wall:.1} |",
                case.name
            );
        }
    }
    let _ = std::fs::remove_dir_all(&out);
}
