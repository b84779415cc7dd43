#!/usr/bin/env bash
# Installs what diffract needs on a Debian (bookworm or later) machine, as root:
#   Vulkan loader, headers, Mesa's drivers (lavapipe) and the Khronos validation layer;
#   Xvfb for the viewer's tests; shaderc (libshaderc-dev, with glslang-dev and spirv-tools);
#   g++ for the ꟻLIP library that the nv-flip crate compiles.
# Then it makes one complete static shaderc library for the shaderc crate. Debian splits
# shaderc from its dependencies: libshaderc_combined.a lacks glslang and SPIRV-Tools, and the
# shared libshaderc.so leaves glslang's front end undefined (linked with Debian's static
# glslang it crashes at the first compile). Merging the combined archive with glslang's and
# SPIRV-Tools' static archives gives one self-contained libshaderc_combined.a, which
# .cargo/config.toml points the shaderc crate at (SHADERC_LIB_DIR). Where that directory is
# missing, the crate compiles shaderc's C++ from source instead (cmake, ninja, python3;
# about 8 minutes on 2 cores, once per target directory).
set -euo pipefail

packages=(mesa-vulkan-drivers libvulkan1 libvulkan-dev vulkan-validationlayers
          cmake ninja-build python3 xvfb libshaderc-dev glslang-dev spirv-tools g++)
missing=()
for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    if [ "$(id -u)" -ne 0 ]; then
        echo "error: missing packages (run as root to install): ${missing[*]}" >&2
        exit 1
    fi
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq "${missing[@]}" >/dev/null
fi

# The merged shaderc archive (see above); the path is the one in .cargo/config.toml.
out=/usr/local/lib/diffract-shaderc
lib=/usr/lib/$(dpkg-architecture -qDEB_HOST_MULTIARCH 2>/dev/null || echo x86_64-linux-gnu)
parts=(shaderc_combined glslang MachineIndependent GenericCodeGen OSDependent OGLCompiler HLSL
       SPIRV SPIRV-Tools-opt SPIRV-Tools glslang-default-resource-limits)
stamp="$out/parts.txt"
want=$(for p in "${parts[@]}"; do f="$lib/lib$p.a"; [ -f "$f" ] && stat -c '%n %s %Y' "$f"; done)
if [ -f "$out/libshaderc_combined.a" ] && [ "$(cat "$stamp" 2>/dev/null)" = "$want" ]; then
    exit 0
fi
if [ "$(id -u)" -ne 0 ] && [ ! -w "$(dirname "$out")" ]; then
    echo "note: not root; shaderc will be compiled from source by cargo" >&2
    exit 0
fi
mkdir -p "$out"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
{
    echo "CREATE $tmp/libshaderc_combined.a"
    for p in "${parts[@]}"; do
        f="$lib/lib$p.a"
        if [ -f "$f" ]; then
            echo "ADDLIB $f"
        fi
    done
    echo "SAVE"
    echo "END"
} | ar -M
mv "$tmp/libshaderc_combined.a" "$out/libshaderc_combined.a"
echo "$want" > "$stamp"
