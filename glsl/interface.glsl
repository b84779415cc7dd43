// Shared interface of the diffraction shaders: specialisation constants (MODEL §7: one
// SPIR-V module per variant, one pipeline per feature set), the descriptor bindings every
// variant has (0, 2, 3) and constants. Binding 1 (and 4 onwards) belong to the variant:
// flss.frag's DFT terms, the table variants' G tables. Included by every stage; the Rust side
// mirrors the layout in src/render/mod.rs (`ParamsUbo`) and src/render/variant/.
#ifndef INTERFACE_GLSL
#define INTERFACE_GLSL

// --- specialisation constants --------------------------------------------------------
layout(constant_id = 0) const int TERMS = 8;           // highest term index T (terms 0..T)
layout(constant_id = 1) const int WINDOW_RADIUS = 1;   // gather radius R: (2R+1)² taps
layout(constant_id = 2) const int LAMBDA_STEP_NM = 5;  // Δλ; divides 400 nm
layout(constant_id = 3) const int EXPANSION = 0;       // EXPANSION_TAYLOR / _CHEBYSHEV
layout(constant_id = 4) const bool SHADOWING = true;   // Stam's V-cavity S
layout(constant_id = 5) const bool FRESNEL = true;     // Schlick R/R0
layout(constant_id = 6) const bool TEXTURE_BLENDING = false; // thesis Algorithm 4
layout(constant_id = 7) const int STORAGE = 0;         // STORAGE_RG32F / _RG16F / _UNORM16
layout(constant_id = 8) const int OUTPUT_MODE = 0;     // MODE_MESH / _MAP_XYZ / _MAP_SPECTRAL / _MAP_DISPLAY
layout(constant_id = 9) const int TABLE_TERMS = 16;    // table variants: coefficients K

const int EXPANSION_TAYLOR = 0;
const int EXPANSION_CHEBYSHEV = 1;
const int STORAGE_RG32F = 0;
const int STORAGE_RG16F = 1;
const int STORAGE_UNORM16 = 2;
const int MODE_MESH = 0;
const int MODE_MAP_XYZ = 1;
const int MODE_MAP_SPECTRAL = 2;
// The viewer's map: XYZ as linear sRGB × exposure (params.lighting.y) for an sRGB target.
const int MODE_MAP_DISPLAY = 3;

const int LAMBDA_MIN_NM = 380;
const int LAMBDA_MAX_NM = 780;
// Samples of the trapezoid rule over [380, 780] nm (MODEL §5). Binding 2 may hold fewer:
// the renderer leaves out wavelengths whose weight cannot matter (loop over its length).
// Capacity of the per-term decode table; Material::validate caps T at 64.
const int MAX_TERMS = 65;
// Capacity of the light's disc directions; light::MAX_DISK_SAMPLES on the CPU.
const int MAX_DISK_SAMPLES = 256;
const float PI = 3.14159265358979;
// Nodes of the uniform sky's table; light::sky::TAIL_NODES on the CPU.
const int SKY_TAIL_NODES = 16;
// Most levels of a table pre-filtered for a pixel's footprint; brdf::table::MAX_LEVELS.
const int MAX_TABLE_LEVELS = 6;

// The pixel's footprint in (u, v) = −(ωi + ωr)_xy at the light's centre: xy its change
// across one pixel along x, zw along y. shade.glsl sets it in mesh mode before the variant
// evaluates; elsewhere (maps, compute stages) it stays 0, a point.
vec4 gUvFootprint = vec4(0.0);

// --- descriptor set 0 ----------------------------------------------------------------
layout(set = 0, binding = 0, std140) uniform Params {
    vec4 eyeWorld;        // xyz: eye position in world space (mesh mode)
    vec4 lightDirWorld;   // xyz: direction the light travels, world space (mesh mode)
    vec4 lighting;        // x: light intensity, y: exposure, z: w_diffuse (Algorithm 4), w: the uniform sky's radiance (sky.glsl)
    vec4 mapWi;           // xyz: ωi of a BRDF map (tangent space), w: λ in µm (spectral map)
    vec4 mapInfo;         // x: map size S in pixels
    ivec4 spectrumSize;   // x: N_x, y: N_y, z: b_x = floor(N_x/2), w: b_y = floor(N_y/2)
    ivec4 band;           // x0, y0, width, height of the stored texels
    vec4 lookup;          // x: dH (µm), y: 1/(2σx²), z: 1/(2σy²), w: Chebyshev half range A (µm)
    vec4 shading;         // x: Schlick R0, y: texture gain, z: 1/S, the picture's scale (1/Response::scale)
    ivec4 lightInfo;      // x: directions over the light's disc in lightDisk (1: a point light)
    // The uniform sky's J(cos θr) at cos θr = i/(SKY_TAIL_NODES − 1) (light::sky::tail_table).
    vec4 skyTail[SKY_TAIL_NODES / 4];
    // Per term: value = (x + stored.r * y, z + stored.g * w) (thesis eq. 1.1 inverted).
    vec4 decode[MAX_TERMS];
    // Mesh mode: xyz towards a point of the light's disc (world space, unit), w its weight;
    // the weights of the first lightInfo.x entries sum to 1 (light::sun_disk_samples).
    vec4 lightDisk[MAX_DISK_SAMPLES];
} params;

// Per spectral sample j: xyz = CIE weight of ColourTable::weights[j], w = λ_j in nm; only
// the kept samples when the renderer leaves some out (src/leave_out.rs).
layout(set = 0, binding = 2, std430) readonly buffer ColourWeights {
    vec4 colourWeights[];
};

// Surface texture of Algorithm 4 (a 1×1 white dummy when the scene has none).
layout(set = 0, binding = 3) uniform sampler2D surfaceTexture;

#endif
