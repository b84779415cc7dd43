#!/usr/bin/env bash
# Regenerates the figures (and the profiler's CSV tables) under assets/figures/ that the
# README and docs/ show, each with the command its caption names.
#
#   scripts/figures.sh                         every figure
#   scripts/figures.sh --quick                 only the cheap ones (about a minute each)
#   scripts/figures.sh viewer_snake stability_matrix    only these (names as listed by --list)
#   scripts/figures.sh --list                  names, costs and what each one shows
#
# It builds the release binary once (cargo build --release; CARGO_TARGET_DIR is honoured),
# runs every command in a scratch directory with a scratch term/table cache (so a figure
# never depends on what an earlier run left in the user's cache), and moves each result into
# assets/figures/ only when its command succeeded. The viewer figures need Xvfb (xvfb-run).
#
# Costs are rough wall times on a 2-core VM with Mesa lavapipe (the GPU is emulated on the
# CPU); on a real GPU everything but the CPU reference sums is far faster. "slow" figures
# are skipped by --quick.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
out=$root/assets/figures

# name | cost | what it is (one line). The order is the order of a full run.
registry=(
    "eval_grating_measured_elaphe|cheap|grating-equation figure on the measured crop (~30 s)"
    "viewer_snake|cheap|viewer screenshot, default scene, 256² (~1 min)"
    "viewer_map|cheap|viewer screenshot with the BRDF map, 256×128 (~1 min)"
    "stability_matrix|slow|stability heat map, full matrix with the GPU (~4-30 min)"
    "validity_map_default|cheap|validity map: scalar model vs RCWA, default scene's material (~1 min)"
    # Each map first builds the default table variant's table at 1 nm (~10 min under load),
    # unless the scratch cache already holds one for its field, light and region.
    "brdf_map_elaphe_60deg|slow|BRDF map, Elaphe-like grating, θi = 60°, 384² (~10 min)"
    "brdf_map_synthetic_elaphe_60deg_128|slow|the same at 128² (~10 min)"
    "brdf_map_blazed_60deg|slow|BRDF map, blazed grating, θi = 60°, 384² (~10 min)"
    "brdf_map_measured_tiled_60deg|slow|BRDF map, measured AFM crop tiled, φi = 90°, 128² (~10 min)"
    "brdf_map_measured_grown_60deg|slow|BRDF map, measured crop grown to 960², φi = 90°, 128² (~10 min)"
    "default_closeup|slow|default scene, 512² (cold table build ~90 s, up to 8 min under load)"
    "lit_sun|cheap|default scene in the sun, 256² (~10 s)"
    "lit_sky|slow|default scene under builtin:sky and the sun, 256², 64 samples (~1-2 min)"
    "lit_studio|slow|default scene under builtin:studio, no sun, 256², 64 samples (~15 s after lit_sky)"
    "closeup_scales|slow|default scene through a 10° lens, 384² (~3-8 min)"
    "default_snake|slow|flat-scales example scene, 512² (table build, ~2-5 min)"
    "profile_elaphe|slow|profiler: error against GPU time, Elaphe-like, 128² (~30-60 min)"
    "profile_blazed_pq|slow|profiler: PQ and NMM against FLSS, blazed, 65² (~5-10 min)"
    "profile_blazed|slow|profiler CSV: FLSS and chebyshev-w, blazed, 65² (~5 min)"
    "profile_per_vertex_q1|slow|profiler CSV: per vertex, default scene mesh, 1 quad a scale (~10 min)"
    "profile_per_vertex_q6|slow|profiler CSV: per vertex, default scene mesh, 6 quads a scale (~10 min)"
)

usage() {
    sed -n '2,9p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
}

quick=0
list=0
wanted=()
for a in "$@"; do
    case $a in
        --quick) quick=1 ;;
        --list) list=1 ;;
        -h | --help) usage; exit 0 ;;
        -*) echo "error: unknown option $a (see --help)" >&2; exit 2 ;;
        *) wanted+=("$a") ;;
    esac
done

names=()
for entry in "${registry[@]}"; do
    names+=("${entry%%|*}")
done
if [ "$list" = 1 ]; then
    for entry in "${registry[@]}"; do
        IFS='|' read -r name cost what <<<"$entry"
        printf '%-38s %-6s %s\n' "$name" "$cost" "$what"
    done
    exit 0
fi
for w in "${wanted[@]}"; do
    if ! printf '%s\n' "${names[@]}" | grep -qx -- "$w"; then
        echo "error: no figure named '$w' (scripts/figures.sh --list names them)" >&2
        exit 2
    fi
done

# Which figures this run makes.
todo=()
for entry in "${registry[@]}"; do
    IFS='|' read -r name cost _ <<<"$entry"
    if [ ${#wanted[@]} -gt 0 ]; then
        printf '%s\n' "${wanted[@]}" | grep -qx -- "$name" || continue
    elif [ "$quick" = 1 ] && [ "$cost" = slow ]; then
        continue
    fi
    todo+=("$name")
done

cd "$root"
cargo build --release
bin=${CARGO_TARGET_DIR:-$root/target}/release/diffract
[[ $bin = /* ]] || bin=$root/$bin

scratch=$(mktemp -d "${TMPDIR:-/tmp}/diffract-figures.XXXXXX")
trap 'rm -rf "$scratch"' EXIT
export DIFFRACT_CACHE=$scratch/cache
mkdir -p "$DIFFRACT_CACHE"

d() { "$bin" "$@"; }

# BRDF map: renders the EXR and its PNG into the scratch directory, keeps the PNG.
map() {
    local name=$1
    shift
    d render --brdf-map "$@" -o "$scratch/$name.exr" --png
    mv "$scratch/$name.png" "$out/$name.png"
}

# Runs a viewer screenshot under a virtual X display.
viewer() {
    local name=$1
    shift
    if ! command -v xvfb-run >/dev/null; then
        echo "error: $name needs xvfb-run (the xvfb package)" >&2
        return 1
    fi
    xvfb-run -a -s "-screen 0 640x480x24 -nolisten tcp" \
        "$bin" view "$@" --screenshot "$scratch/$name.png"
    mv "$scratch/$name.png" "$out/$name.png"
}

# Profiler run: keeps the CSV, and the plot when asked for with "plot" first. Always the
# exhaustive set (--full: no time budget), so the figures do not depend on the machine's pace.
profile() {
    local name=$1 plot=$2
    shift 2
    if [ "$plot" = plot ]; then
        d profile --full "$@" --csv "$scratch/$name.csv" --plot "$scratch/$name.png"
        mv "$scratch/$name.png" "$out/$name.png"
    else
        d profile --full "$@" --csv "$scratch/$name.csv"
    fi
    mv "$scratch/$name.csv" "$out/$name.csv"
}

make_figure() {
    local name=$1
    case $name in
        brdf_map_elaphe_60deg)
            map "$name" --heightfield builtin:elaphe --theta-i 60 --size 384 --exposure 30 ;;
        brdf_map_blazed_60deg)
            map "$name" --heightfield builtin:blazed --theta-i 60 --size 384 --exposure 30 ;;
        brdf_map_synthetic_elaphe_60deg_128)
            map "$name" --heightfield builtin:elaphe --theta-i 60 --size 128 --exposure 30 ;;
        brdf_map_measured_tiled_60deg)
            map "$name" --heightfield builtin:elaphe-measured --theta-i 60 --phi-i 90 \
                --size 128 --exposure 300 ;;
        brdf_map_measured_grown_60deg)
            map "$name" --heightfield builtin:elaphe-grown --theta-i 60 --phi-i 90 \
                --size 128 --exposure 300 ;;
        eval_grating_measured_elaphe)
            d eval-grating --heightfield builtin:elaphe-measured --window-radius 3 \
                --azimuth 90 --plot "$scratch/$name.png"
            mv "$scratch/$name.png" "$out/$name.png" ;;
        viewer_snake)
            viewer "$name" --variant chebyshev-w --table-step-nm 20 --table-texel 0.02 \
                --width 256 --height 256 --frames 3 ;;
        viewer_map)
            viewer "$name" --variant chebyshev-w --table-step-nm 20 --table-texel 0.02 \
                --width 256 --height 128 --map --map-exposure 100 --frames 3 ;;
        validity_map_default)
            d validity --lambda-nm 550 --theta-i 0 --plot "$scratch/$name.png"
            mv "$scratch/$name.png" "$out/$name.png" ;;
        stability_matrix)
            DIFFRACT_VALIDATION=1 d stability --full --out "$scratch/stability"
            mv "$scratch/stability/stability.png" "$out/$name.png" ;;
        default_closeup)
            d render -o "$scratch/$name.png"
            mv "$scratch/$name.png" "$out/$name.png" ;;
        lit_sun)
            d render --width 256 --height 256 -o "$scratch/$name.png"
            mv "$scratch/$name.png" "$out/$name.png" ;;
        lit_sky)
            d render --width 256 --height 256 --env builtin:sky --env-samples 64 \
                -o "$scratch/$name.png"
            mv "$scratch/$name.png" "$out/$name.png" ;;
        lit_studio)
            d render --width 256 --height 256 --env builtin:studio --no-sun --env-samples 64 \
                -o "$scratch/$name.png"
            mv "$scratch/$name.png" "$out/$name.png" ;;
        closeup_scales)
            sed 's/^fov_y_deg = 30.0 .*/fov_y_deg = 10.0/' assets/default_scene.toml \
                >"$scratch/tight.toml"
            if cmp -s assets/default_scene.toml "$scratch/tight.toml"; then
                echo "error: $name: assets/default_scene.toml has no 'fov_y_deg = 30.0' line" >&2
                return 1
            fi
            d render --scene "$scratch/tight.toml" --width 384 --height 384 \
                -o "$scratch/$name.png"
            mv "$scratch/$name.png" "$out/$name.png" ;;
        default_snake)
            d render --scene assets/examples/flat_scales.toml -o "$scratch/$name.png"
            mv "$scratch/$name.png" "$out/$name.png" ;;
        profile_elaphe)
            profile "$name" plot --heightfield assets/elaphe.png --size 128 --pixels 1024 \
                --brightest 64 --frames 5 --mesh-size 128 ;;
        profile_blazed_pq)
            profile "$name" plot --heightfield builtin:blazed --size 65 --pixels 256 \
                --brightest 32 --frames 3 --mesh-size 0 \
                --only "taylor R=2,taylor R=2 1nm,nmm taylor R=2,pq taylor,pq taylor 1nm" ;;
        profile_blazed)
            profile "$name" csv --heightfield assets/blazed.png --only "taylor R=2,chebyshev-w" \
                --size 65 --pixels 256 --brightest 32 --frames 3 --mesh-size 0 ;;
        profile_per_vertex_q1 | profile_per_vertex_q6)
            profile "$name" csv --heightfield builtin:elaphe-grown --only "taylor R=2" \
                --size 16 --pixels 8 --brightest 8 --frames 1 --mesh-size 128 --per-vertex \
                --mesh-quads "${name##*_q}" ;;
        *)
            echo "error: no recipe for $name" >&2
            return 1 ;;
    esac
}

failed=()
for name in "${todo[@]}"; do
    echo "== $name" >&2
    start=$SECONDS
    # A subshell with -e of its own: the first failing command ends the figure, and
    # nothing half-made is moved into assets/figures/.
    set +e
    (
        set -e
        make_figure "$name"
    )
    rc=$?
    set -e
    if [ "$rc" = 0 ]; then
        echo "== $name: done in $((SECONDS - start)) s" >&2
    else
        echo "== $name: FAILED after $((SECONDS - start)) s" >&2
        failed+=("$name")
    fi
done
if [ ${#failed[@]} -gt 0 ]; then
    echo "error: ${#failed[@]} figure(s) failed: ${failed[*]}" >&2
    exit 1
fi
