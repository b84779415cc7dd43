#version 450
// The viewer's progressive environment-lit picture, resolved into the texels of a swapchain
// image (src/view/env.rs): one invocation per pixel of a rectangle of the window. The
// running sums of env_scene.glsl or env_map.glsl hold the samples' sum and their number k,
// and the point lights apart, so a pixel is points + sum/k, as the offscreen render
// reads it. Then the picture goes as `render` writes a PNG: over the mirror scale, times
// the exposure, the scene's tone curve, the sRGB transfer curve, 8 bits.

layout(local_size_x = 64) in;

// Per pixel of the picture: 3 vec4s (a scene, linear sRGB: (sum, k), (squared batch
// sums), (point lights)) or 2 (a BRDF map, XYZ: (sum, k), (point lights)).
layout(std430, set = 0, binding = 0) readonly buffer Sums { vec4 sums[]; };
// Per pixel of the rectangle: the background's linear sRGB (already over the mirror
// scale) and, as the bits of w, the index of the picture's pixel (0xffffffff: background).
layout(std430, set = 0, binding = 1) readonly buffer Pixels { vec4 pixels[]; };
// The window's texels, 4 bytes each in the swapchain's order.
layout(std430, set = 0, binding = 2) writeonly buffer Texels { uint texels[]; };

layout(push_constant) uniform Resolve {
    ivec4 rect;      // x, y, width, height of the rectangle in the window
    int windowWidth;
    int outputs;     // vec4s per picture pixel: 3 (scene) or 2 (map)
    int bgra;        // 1: B8G8R8A8, 0: R8G8B8A8
    int filmic;      // 1: the extended Reinhard curve with white point `white`
    float k;         // samples in the sums (the sums also hold it, per pixel)
    float n;         // the cap
    float exposure;
    float invScale;  // 1 / mirror scale
    float white;
} r;

#include "srgb.glsl"

float encode(float x) {
    if (!(x > 0.0)) return 0.0;
    if (r.filmic != 0) x = x * (1.0 + x / (r.white * r.white)) / (1.0 + x);
    x = min(x, 1.0);
    return x <= 0.0031308 ? 12.92 * x : 1.055 * pow(x, 1.0 / 2.4) - 0.055;
}

void main() {
    uint idx = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 64u;
    if (idx >= uint(r.rect.z * r.rect.w)) return;
    vec4 p = pixels[idx];
    uint at = floatBitsToUint(p.w);
    vec3 c = p.rgb;
    if (at != 0xffffffffu) {
        uint o = uint(r.outputs);
        vec4 sum = sums[o * at];
        c = sums[o * at + o - 1u].xyz + sum.xyz / max(sum.w, 1.0);
        if (o == 2u) c = XYZ_TO_SRGB * c;
        c *= r.invScale;
    }
    c *= r.exposure;
    vec3 e = vec3(encode(c.r), encode(c.g), encode(c.b));
    uvec3 b = uvec3(floor(e * 255.0 + 0.5));
    if (r.bgra != 0) b = b.bgr;
    uint x = uint(r.rect.x) + idx % uint(r.rect.z), y = uint(r.rect.y) + idx / uint(r.rect.z);
    texels[y * uint(r.windowWidth) + x] = b.r | (b.g << 8) | (b.b << 16) | (255u << 24);
}
