#version 450
// Variant `coverage`, a debug view: where each pixel's lookups (u, v, w) = −(ωi + ωr) fall
// against the table region a table variant builds for this draw, and how many lookups the
// pixel makes (one per direction over the light's disc; one on a BRDF map).
//   inside:  rgb = 0.1 + 0.8·(û, v̂, ŵ), the lookup's fractions in the region, averaged over
//            the pixel's lookups (every channel strictly between 0.1 and 0.9);
//   outside: magenta (1, 0, 1) when any of the pixel's lookups leaves the region (there a
//            table variant draws black);
//   below the horizon (no light reaches the surface from any direction): black, or on a
//            textured mesh the texture's grey at a third (the surface, for orientation).
// No lighting, exposure or tone: the colours are the data (the renderer's sRGB curve still
// applies to PNG output; EXR keeps them linear).
#include "interface.glsl"
#include "table.glsl"
#include "footprint_texture.glsl"

layout(location = 0) in vec3 inTangent;
layout(location = 1) in vec3 inWr;
layout(location = 2) in vec2 inUv;
layout(location = 3) in vec3 inBitangent;
layout(location = 4) in vec3 inNormal;

layout(location = 0) out vec4 outColour;

const vec3 OUTSIDE = vec3(1.0, 0.0, 1.0);

vec3 safeNormalize(vec3 v) {
    float l = length(v);
    return l > 1e-20 ? v / l : vec3(0.0, 0.0, 1.0);
}

// Adds one lookup's colour to sum (and counts it); false if it falls outside the region.
bool lookup(vec3 wi, vec3 wr, inout vec3 sum, inout int n) {
    if (wi.z <= 0.0) {
        return true;  // no light from this direction: no lookup
    }
    vec3 f;
    if (!tableFraction(-wi - wr, f)) {
        return false;
    }
    sum += 0.1 + 0.8 * f;
    n += 1;
    return true;
}

void main() {
    vec3 sum = vec3(0.0);
    int n = 0;
    bool inside = true;
    if (OUTPUT_MODE == MODE_MESH) {
        vec3 wr = safeNormalize(inWr);
        int samples = clamp(params.lightInfo.x, 1, MAX_DISK_SAMPLES);
        for (int k = 0; k < samples; ++k) {
            vec3 towardsLight = params.lightDisk[k].xyz;
            vec3 wi = safeNormalize(vec3(dot(towardsLight, inTangent),
                                         dot(towardsLight, inBitangent),
                                         dot(towardsLight, inNormal)));
            inside = lookup(wi, wr, sum, n) && inside;
        }
    } else {
        // BRDF map: pixel (i, j), row j from the top, is ωr = (x, y, √(1 − x² − y²)).
        float s = params.mapInfo.x;
        float x = 2.0 * gl_FragCoord.x / s - 1.0;
        float y = 1.0 - 2.0 * gl_FragCoord.y / s;
        float r2 = x * x + y * y;
        if (r2 < 1.0) {
            inside = lookup(params.mapWi.xyz, vec3(x, y, sqrt(1.0 - r2)), sum, n);
        }
    }
    vec3 c = !inside ? OUTSIDE : (n > 0 ? sum / float(n) : vec3(0.0));
    if (OUTPUT_MODE == MODE_MESH && TEXTURE_BLENDING && inside && n == 0) {
        c = vec3(dot(textureOverFootprint(surfaceTexture, inUv).rgb, vec3(0.2126, 0.7152, 0.0722)) / 3.0);
    }
    outColour = vec4(c, 1.0);
}
