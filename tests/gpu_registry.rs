//! The variant registry: every registered variant renders a BRDF map on lavapipe with
//! validation on, every one is listed, parsed, profiled (unless it is a debug view) and in
//! the Markdown table, and the `coverage` debug view colours a map whose region is known:
//! `0.1 + 0.8·(û, v̂, ŵ)` where a lookup falls inside the table region, magenta outside.

mod gpu_util;

use clap::ValueEnum;
use diffract::brdf::table::Region;
use diffract::brdf::uvw;
use diffract::render::variant::{markdown_table, Family};
use diffract::render::{TableOptions, VariantKind};
use gpu_util::*;

fn scratch(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("diffract-registry-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

const SIZE: u32 = 16;
const THETA: f64 = 30.0;

#[test]
fn every_registered_variant_renders_a_map() {
    let Some(mut r) = renderer() else { return };
    let dir = scratch("all");
    let prepared = prepare(&periodic_material(&dir, 8, 20));
    r.set_table_options(TableOptions {
        texel_uv: Some(0.02),
        step_nm: Some(20),
        ..TableOptions::default()
    });
    for kind in VariantKind::ALL {
        r.set_variant(kind);
        let frame = r
            .render_brdf_map(&prepared, THETA, 0.0, SIZE, None)
            .unwrap_or_else(|e| panic!("{kind}: {e}"));
        assert_eq!(
            frame.variant.name.split(' ').next(),
            Some(kind.name()),
            "{kind} reports itself"
        );
        let mut lit = 0;
        for j in 0..SIZE {
            for i in 0..SIZE {
                let c = frame.at(i, j);
                assert!(
                    c.iter().all(|x| x.is_finite()),
                    "{kind}: pixel {i},{j} {c:?}"
                );
                if map_direction(i, j, SIZE).is_some() && c[1] > 0.0 {
                    lit += 1;
                }
            }
        }
        assert!(lit > 0, "{kind}: an all-black map");
    }
    assert_no_validation(&r);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn every_registered_variant_is_listed_parsed_profiled_and_tabled() {
    let list = diffract::render::variant::list();
    let table = markdown_table();
    let rows = diffract::profile::standard_variants(12);
    for kind in VariantKind::ALL {
        let name = kind.name();
        assert!(list.contains(name), "`variants` lists {name}");
        assert!(table.contains(&format!("`{name}`")), "the table has {name}");
        assert_eq!(
            VariantKind::from_str(name, false),
            Ok(kind),
            "--variant {name}"
        );
        assert_eq!(VariantKind::named(name), Some(kind));
        assert!(!kind.summary().is_empty());
        assert!(
            diffract::gpu::shaders::spirv(kind.fragment_file()).is_some(),
            "{name}: glsl/{} is compiled",
            kind.fragment_file()
        );
        if let Some(pv) = kind.per_vertex_file() {
            assert!(
                diffract::gpu::shaders::spirv(pv).is_some(),
                "{name}: glsl/{pv}"
            );
        }
        let profiled = rows.iter().any(|v| v.kind == kind);
        assert_eq!(
            profiled,
            kind.family() != Family::Debug,
            "{name}: profiled unless a debug view"
        );
    }
    assert_eq!(
        VariantKind::from_str("default", false),
        Ok(VariantKind::Default)
    );
    assert_eq!(VariantKind::Default.resolve(), VariantKind::DEFAULT);
    assert!(VariantKind::from_str("nonsense", false).is_err());
}

/// The map's lookup of pixel `(i, j)` as the shader computes it.
fn lookup(wi: [f64; 3], i: u32, j: u32) -> Option<[f64; 3]> {
    map_direction(i, j, SIZE).map(|wr| uvw(wi, wr))
}

#[test]
fn coverage_colours_inside_by_fraction_and_outside_magenta() {
    let Some(mut r) = renderer() else { return };
    let dir = scratch("coverage");
    let prepared = prepare(&periodic_material(&dir, 8, 20));
    let wi = uploaded_direction(THETA, 0.0);
    r.set_variant(VariantKind::Coverage);

    // The region the map reaches: every pixel inside, coloured by its fraction.
    let full = Region::brdf_map(wi).widened(1e-5);
    // Half of it in u: the pixels with u above the middle fall outside.
    let mid = 0.5 * (full.lo[0] + full.hi[0]);
    let half = Region {
        hi: [mid, full.hi[1], full.hi[2]],
        ..full
    };
    for (region, pinned) in [(full, false), (half, true)] {
        r.set_table_region(pinned.then_some(region));
        let frame = r
            .render_brdf_map(&prepared, THETA, 0.0, SIZE, None)
            .expect("coverage map");
        assert!(frame.variant.name.contains("1 lookup per fragment"));
        let (mut inside, mut outside) = (0, 0);
        for j in 0..SIZE {
            for i in 0..SIZE {
                let c = frame.at(i, j);
                let Some(p) = lookup(wi, i, j) else {
                    assert_eq!(c, [0.0; 3], "outside the disk: black");
                    continue;
                };
                // Pixels within float32 rounding of the region's edge may go either way.
                let e = region.extent();
                let f: [f64; 3] = std::array::from_fn(|a| (p[a] - region.lo[a]) / e[a]);
                if f.iter()
                    .any(|x| (x.abs() < 1e-4) || ((x - 1.0).abs() < 1e-4))
                {
                    continue;
                }
                if f.iter().all(|x| (0.0..=1.0).contains(x)) {
                    inside += 1;
                    for a in 0..3 {
                        let want = 0.1 + 0.8 * f[a];
                        assert!(
                            (c[a] as f64 - want).abs() < 1e-3,
                            "pixel {i},{j} channel {a}: {} vs {want}",
                            c[a]
                        );
                    }
                } else {
                    outside += 1;
                    assert_eq!(c, [1.0, 0.0, 1.0], "pixel {i},{j} outside: magenta");
                }
            }
        }
        assert!(inside > 20, "{inside} inside");
        if pinned {
            assert!(outside > 20, "{outside} outside the half region");
        } else {
            assert_eq!(outside, 0, "the map's own region holds every lookup");
        }
    }
    assert_no_validation(&r);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn the_readme_variant_table_is_the_registry_s() {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md"))
        .expect("README.md");
    let begin = "<!-- variants:begin -->\n";
    let start = readme.find(begin).expect("README marks the variants table") + begin.len();
    let end = readme[start..]
        .find("<!-- variants:end -->")
        .expect("README ends the variants table")
        + start;
    assert_eq!(
        &readme[start..end],
        markdown_table(),
        "README's variant table is stale: paste `diffract variants --markdown`"
    );
}

#[test]
fn the_docs_fetch_table_is_the_registry_s() {
    let docs = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/variants.md"))
        .expect("docs/variants.md");
    let begin = "<!-- fetches:begin -->\n";
    let start = docs.find(begin).expect("docs mark the fetch table") + begin.len();
    let end = docs[start..]
        .find("<!-- fetches:end -->")
        .expect("docs end the fetch table")
        + start;
    assert_eq!(
        &docs[start..end],
        diffract::render::variant::markdown_fetches(),
        "docs/variants.md's fetch table is stale: paste `diffract variants --fetches`"
    );
}

/// `diffract variants` reads its fetches and memory from the code that prepares the
/// variants: for the same material, options and map, what it lists is what `render` draws.
#[test]
fn listed_fetches_and_memory_are_what_render_draws() {
    use diffract::render::variant::{map_region, FetchInputs, TableFormat};
    let Some(mut r) = renderer() else { return };
    let dir = scratch("figures");
    let prepared = prepare(&periodic_material(&dir, 8, 20));
    let table = TableOptions {
        texel_uv: Some(0.02),
        step_nm: Some(20),
        format: TableFormat::Rgba16f,
        ..TableOptions::default()
    };
    r.set_table_options(table);
    r.set_leave_out(true);
    let (lo, hi) = prepared.heightfield.range();
    let inputs = FetchInputs {
        terms: prepared.terms(),
        material: &prepared.material,
        table: &table,
        region: map_region(diffract::brdf::direction(THETA, 0.0)),
        h_range_um: hi - lo,
        leave_out: true,
        heightfield: Some(&prepared.heightfield),
    };
    for kind in VariantKind::ALL {
        r.set_variant(kind);
        let frame = r
            .render_brdf_map(&prepared, THETA, 0.0, SIZE, None)
            .unwrap_or_else(|e| panic!("{kind}: {e}"));
        let drawn = &frame.variant;
        let listed = kind.fetches(&inputs);
        // dhillon's fit, chebyshev-w's terms left out and pq's taps may take fewer than
        // the bound.
        if matches!(
            kind,
            VariantKind::Dhillon | VariantKind::Pq | VariantKind::ChebyshevW
        ) {
            assert!(
                drawn.fetches <= listed,
                "{kind}: {} > {listed}",
                drawn.fetches
            );
        } else {
            assert_eq!(drawn.fetches, listed, "{kind}: fetches");
        }
        if let Some(fp) = kind.footprint(&inputs) {
            let fp = fp.unwrap();
            if fp.at_most {
                assert!(drawn.gpu_bytes <= fp.bytes, "{kind}: memory");
            } else {
                assert_eq!(drawn.gpu_bytes, fp.bytes, "{kind}: memory");
            }
        }
    }
    assert_no_validation(&r);
    let _ = std::fs::remove_dir_all(dir);
}

/// The hand-written lists of variants stay the registry's: a variant added by its file, its
/// GLSL and its registry line, and missed in one of them, fails here. The viewer's `V` key
/// (docs/viewer.md), the table variants in docs/tables.md and in docs/stability.md's
/// narrow-region table, and each table variant's
/// default `w` nodes where `--table-w-nodes` states them (its help and `TableOptions`).
#[test]
fn the_hand_written_lists_name_every_registered_variant() {
    let read = |f: &str| {
        std::fs::read_to_string(format!("{}/{f}", env!("CARGO_MANIFEST_DIR")))
            .unwrap_or_else(|e| panic!("{f}: {e}"))
    };
    let viewer = read("docs/viewer.md");
    let v_row = viewer
        .lines()
        .find(|l| l.starts_with("| `V` |"))
        .expect("docs/viewer.md has the V key's row");
    let tables = read("docs/tables.md");
    let stability = read("docs/stability.md");
    let stability = stability
        .lines()
        .find(|l| l.starts_with("| case | h_max (µm) | max G |"))
        .expect("docs/stability.md has the narrow-region table")
        .to_string();
    let help = std::process::Command::new(env!("CARGO_BIN_EXE_diffract"))
        .args(["render", "--help"])
        .output()
        .expect("render --help");
    let help = String::from_utf8_lossy(&help.stdout).replace('\n', " ");
    let help = help.split_whitespace().collect::<Vec<_>>().join(" ");
    for kind in VariantKind::ALL {
        let name = kind.name();
        assert!(
            v_row.contains(&format!("`{name}`")),
            "docs/viewer.md's V row misses {name}: {v_row}"
        );
        if kind.family() == Family::Table {
            assert!(
                tables.contains(&format!("`{name}`")),
                "docs/tables.md misses {name}"
            );
            assert!(
                stability.contains(&format!(" {name} |")),
                "docs/stability.md's narrow-region table misses {name}: {stability}"
            );
            let nodes = TableOptions::default().w_nodes_for(kind);
            let stated = format!("{name} {nodes}");
            assert!(
                help.contains(&stated),
                "render --help's --table-w-nodes does not state '{stated}': {help}"
            );
        }
    }
}
