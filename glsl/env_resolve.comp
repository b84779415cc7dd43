#version 450
// The viewer's progressive environment-lit picture, resolved into the texels of a swapchain
// image (src/view/env.rs): one invocation per pixel of a rectangle of the window. The
// running sums of env_scene.comp or env_map.comp hold k samples plus the point lights
// weighted by the cap N (they are added once, at base 0, times N); the point lights alone
// (a dispatch of 0 samples) are at `points`. So the mean after k samples is
// (sum − (1 − k/N)·points)/k, which is the offscreen render's sum/N at k = N. Then the
// picture goes as `render` writes a PNG: over the mirror scale, times the exposure, the
// scene's tone curve, the sRGB transfer curve, 8 bits.

layout(local_size_x = 64) in;

// Per pixel of the picture: 2 vec4s (a scene: the diffraction part in XYZ, the texture
// part in linear sRGB) or 1 (a BRDF map: XYZ).
layout(std430, set = 0, binding = 0) readonly buffer Sums { vec4 sums[]; };
layout(std430, set = 0, binding = 1) readonly buffer Points { vec4 points[]; };
// Per pixel of the rectangle: the background's linear sRGB (already over the mirror
// scale) and, as the bits of w, the index of the picture's pixel (0xffffffff: background).
layout(std430, set = 0, binding = 2) readonly buffer Pixels { vec4 pixels[]; };
// The window's texels, 4 bytes each in the swapchain's order.
layout(std430, set = 0, binding = 3) writeonly buffer Texels { uint texels[]; };

layout(push_constant) uniform Resolve {
    ivec4 rect;      // x, y, width, height of the rectangle in the window
    int windowWidth;
    int outputs;     // vec4s per picture pixel: 2 (scene) or 1 (map)
    int bgra;        // 1: B8G8R8A8, 0: R8G8B8A8
    int filmic;      // 1: the extended Reinhard curve with white point `white`
    float k;         // samples in the sums
    float n;         // the cap the point lights are weighted by
    float exposure;
    float invScale;  // 1 / mirror scale
    float white;
} r;

const mat3 XYZ_TO_SRGB = mat3(
    3.2406, -0.9689, 0.0557,
    -1.5372, 1.8758, -0.2040,
    -0.4986, 0.0415, 1.0570);

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
        float keep = 1.0 - r.k / r.n;
        uint o = uint(r.outputs);
        vec3 xyz = (sums[o * at].xyz - keep * points[o * at].xyz) / r.k;
        c = XYZ_TO_SRGB * xyz;
        if (o == 2u) c += (sums[o * at + 1u].xyz - keep * points[o * at + 1u].xyz) / r.k;
        c *= r.invScale;
    }
    c *= r.exposure;
    vec3 e = vec3(encode(c.r), encode(c.g), encode(c.b));
    uvec3 b = uvec3(floor(e * 255.0 + 0.5));
    if (r.bgra != 0) b = b.bgr;
    uint x = uint(r.rect.x) + idx % uint(r.rect.z), y = uint(r.rect.y) + idx / uint(r.rect.z);
    texels[y * uint(r.windowWidth) + x] = b.r | (b.g << 8) | (b.b << 16) | (255u << 24);
}
