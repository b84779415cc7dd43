// A texture read over the pixel's footprint (fragment stages): about the mean of the texels
// the pixel covers. The footprint's longer axis (of the screen derivatives of uv) is split
// into FOOTPRINT_TAPS equal parts, each read trilinearly at the mip level of the part or of
// the shorter axis, whichever is longer: one read at the longer axis's level would blur the
// shorter one, and the skin's thin dark rims with it, where the surface is seen at a grazing
// angle. The level is taken half a level finer than the part's width (gradients × 2^−½):
// trilinear filtering's kernel (the texel's box, the bilinear tent, the blend of two levels)
// is wider than the part; measured against 16×16 samples a pixel, −½ is nearer than 0 or −1
// (docs/results/whole-picture.md). The level is computed here, once for the four taps, and
// each tap reads it (textureLod): the hardware's level from gradients (textureGrad) takes
// the longer of the two gradients too, but blends their lengths differently and measured
// further (ΔE2000 p99 2.96 against 2.93), at the same time. A fixed count of taps:
// lavapipe runs a loop to its longest count over a group of pixels.
#ifndef FOOTPRINT_TEXTURE_GLSL
#define FOOTPRINT_TEXTURE_GLSL

const int FOOTPRINT_TAPS = 4;

vec4 textureOverFootprint(sampler2D t, vec2 uv) {
    vec2 size = vec2(textureSize(t, 0));
    vec2 dx = dFdx(uv);
    vec2 dy = dFdy(uv);
    bool xLonger = length(dx * size) >= length(dy * size);
    vec2 major = xLonger ? dx : dy;
    vec2 minor = xLonger ? dy : dx;
    vec2 gMajor = 0.70710678 * major / float(FOOTPRINT_TAPS);
    vec2 gMinor = 0.70710678 * minor;
    vec4 sum = vec4(0.0);
    // log2 of the longer of the part and the shorter axis, in texels of the finest level.
    vec2 partTexels = gMajor * size;
    vec2 minorTexels = gMinor * size;
    float longer2 = max(dot(partTexels, partTexels), dot(minorTexels, minorTexels));
    float lod = 0.5 * log2(max(longer2, 1e-12));
    for (int k = 0; k < FOOTPRINT_TAPS; ++k) {
        float s = (float(k) + 0.5) / float(FOOTPRINT_TAPS) - 0.5;
        sum += textureLod(t, uv + s * major, lod);
    }
    return sum / float(FOOTPRINT_TAPS);
}

#endif
