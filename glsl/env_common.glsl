// The estimator of one surface point under every light, L_o = ∫ L(ωi)·f·cos θi dωi
// (MODEL §10), shared by the environment-lit compute stages (env_map.glsl: a BRDF map;
// env_scene.glsl: the pixels of a scene's G-buffer): its parameters and buffers (set 1),
// the samplers (the BRDF's density over (u, v), the environment by luminance, disc lights
// uniform in their cone) and the sums. The BRDF itself is the variant's: build.rs compiles
// each variant's fragment file with its shade.glsl main() replaced by one of these stages,
// so `diffractionXyz(ωi, ωr)` = C·G in XYZ is the very function the raster pass calls,
// reading the variant's set 0 (its table or DFT terms, built in radiance units: the
// colour weights carry f_r/ρ, src/render/env.rs). Mirrors brdf::env_reference.
//
// Per direction the integrand is that of thesis Algorithm 4 with absolute units:
//   L(ωi)·cos θi·[(1 − w_d)·f_r + ((1 − α) + w_d)·t],   f_r = C·G (per du dv: cos θi dωi
//   = du dv), α = min(1, |F|) at the half vector, t the texture's albedo (linear sRGB);
// without a texture w_d = 0 and t = 0. The diffraction part is summed per XYZ channel (the
// dispersion is in G, not in the light), the texture part per linear-sRGB channel.
#ifndef ENV_COMMON_GLSL
#define ENV_COMMON_GLSL

layout(local_size_x = 64) in;

layout(std430, set = 1, binding = 0) readonly buffer EnvParams {
    vec4 blend;      // x: w_diffuse (0 without a texture), y: probability of the environment among the light samples, z: m, a light sample every m-th sample, w: the BRDF's scale to radiance
    vec4 cdfLo;      // xy: (u, v) of the G density's first bin corner, z: first CDF node w, w: node step
    vec4 cdfStep;    // xy: bin size in u and v
    vec4 envRot;     // x: cos, y: sin of the map's rotation about +Y
    ivec4 cdfDims;   // x: bins along u, y: along v, z: CDF nodes in w, w: samples per noise batch
    ivec4 envDims;   // x: W, y: H, z: samples per pixel, w: invocations (map side², or the G-buffer pixels of this pass)
    ivec4 lightDims; // x: point lights, y: disc lights, z: texture blending, w: a BRDF map's side
    ivec4 sequence;  // x: pixels that share a sequence, y: the environment can be sampled, z: seed, w: G-buffer pixels whose neighbours follow the G-buffer (0: none)
} P;
layout(std430, set = 1, binding = 1) readonly buffer EnvXyz { float envXyz[]; };
// Marginal CDF over rows (H + 1), conditional CDFs over columns (H·(W + 1)), then the
// density in solid angle of each pixel (W·H).
layout(std430, set = 1, binding = 2) readonly buffer EnvCdf { float envCdf[]; };
// Per CDF node: marginal over v bins (nbv + 1), conditionals over u bins (nbv·(nbu + 1)),
// then the density in (u, v) at each bin corner ((nbu + 1)·(nbv + 1)), bilinear inside a bin.
layout(std430, set = 1, binding = 3) readonly buffer GCdf { float gCdf[]; };
// The sums over the samples so far (the CPU divides by their number): each dispatch adds
// samples [base, base + count); the first also adds the point lights. The stage decides
// what a pixel holds (env_map.glsl, env_scene.glsl).
layout(std430, set = 1, binding = 4) buffer Out { vec4 outSum[]; };
// Point lights (2 vec4 each: towards the light in world space; irradiance XYZ), then disc
// lights (3 vec4 each: towards the centre, w: cos of the angular radius; radiance XYZ,
// w: solid angle; x: probability among the light samples), then the environment's
// irradiance E(n) = ∫ L cos dω (linear sRGB) at IRR_W×IRR_H normals placed like the map's
// pixel centres (world frame).
layout(std430, set = 1, binding = 5) readonly buffer Lights { vec4 lights[]; };
layout(push_constant) uniform Chunk { int base; int count; } chunk;

const int IRR_W = 128;
const int IRR_H = 64;

#include "srgb.glsl"

// --- CDF inversion --------------------------------------------------------------------------

// The interval i of the CDF at base[0..n] holding xi, and the fraction through it.
int invertCdf(bool env, int base, int n, float xi, out float frac) {
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        float c = env ? envCdf[base + mid + 1] : gCdf[base + mid + 1];
        if (c <= xi) lo = mid + 1; else hi = mid;
    }
    float a = env ? envCdf[base + lo] : gCdf[base + lo];
    float b = env ? envCdf[base + lo + 1] : gCdf[base + lo + 1];
    frac = b > a ? clamp((xi - a) / (b - a), 0.0, 1.0) : 0.5;
    return lo;
}

// --- the environment ------------------------------------------------------------------------

// World → the map's own frame (rotated back about +Y) → pixel index.
int envPixel(vec3 d) {
    float c = P.envRot.x, s = P.envRot.y;
    vec3 m = vec3(c * d.x - s * d.z, d.y, s * d.x + c * d.z);
    int W = P.envDims.x, H = P.envDims.y;
    float x = fract(0.5 + atan(m.x, -m.z) / (2.0 * PI));
    float y = acos(clamp(m.y, -1.0, 1.0)) / PI;
    int col = min(int(x * float(W)), W - 1);
    int row = min(int(y * float(H)), H - 1);
    return row * W + col;
}

vec3 envRadiance(int p) { return vec3(envXyz[3 * p], envXyz[3 * p + 1], envXyz[3 * p + 2]); }

float envPdf(int p) {
    int W = P.envDims.x, H = P.envDims.y;
    return envCdf[(H + 1) + H * (W + 1) + p];
}

// A world direction drawn by luminance; its pixel in p.
vec3 sampleEnv(vec2 xi, out int p) {
    int W = P.envDims.x, H = P.envDims.y;
    float fr, fc;
    int row = invertCdf(true, 0, H, xi.x, fr);
    int col = invertCdf(true, (H + 1) + row * (W + 1), W, xi.y, fc);
    p = row * W + col;
    float x = (float(col) + fc) / float(W);
    float top = cos(float(row) / float(H) * PI), bottom = cos(float(row + 1) / float(H) * PI);
    float ct = mix(top, bottom, fr);
    float st = sqrt(max(0.0, 1.0 - ct * ct));
    float phi = (x - 0.5) * 2.0 * PI;
    vec3 m = vec3(st * sin(phi), ct, -st * cos(phi));
    float c = P.envRot.x, s = P.envRot.y;
    return vec3(c * m.x + s * m.z, m.y, -s * m.x + c * m.z);
}

// --- the BRDF's density over (u, v) ---------------------------------------------------------

int nodeBase(int m) {
    int nbu = P.cdfDims.x, nbv = P.cdfDims.y;
    return m * ((nbv + 1) + nbv * (nbu + 1) + (nbu + 1) * (nbv + 1));
}

// The density at the corners of cell (col, row) of node m: (0, 0), (1, 0), (0, 1), (1, 1).
vec4 cellCorners(int m, int col, int row) {
    int nbu = P.cdfDims.x, nbv = P.cdfDims.y;
    int c = nodeBase(m) + (nbv + 1) + nbv * (nbu + 1) + row * (nbu + 1) + col;
    return vec4(gCdf[c], gCdf[c + 1], gCdf[c + nbu + 1], gCdf[c + nbu + 2]);
}

// Bilinear between the corners of the cell holding uv; 0 outside the region.
float nodeDensity(int m, vec2 uv) {
    int nbu = P.cdfDims.x, nbv = P.cdfDims.y;
    vec2 b = (uv - P.cdfLo.xy) / P.cdfStep.xy;
    if (any(lessThan(b, vec2(0.0))) || b.x >= float(nbu) || b.y >= float(nbv)) return 0.0;
    int col = int(b.x), row = int(b.y);
    vec2 f = b - vec2(col, row);
    vec4 k = cellCorners(m, col, row);
    return mix(mix(k.x, k.y, f.x), mix(k.z, k.w, f.x), f.y);
}

// The point of [0, 1) whose CDF under the density ∝ mix(p0, p1, t) is u.
float sampleLinear(float u, float p0, float p1) {
    float d = p0 + sqrt(max(mix(p0 * p0, p1 * p1, u), 0.0));
    float t = d > 0.0 ? u * (p0 + p1) / d : u;
    return clamp(t, 0.0, 0.99999994);
}

// The two CDF nodes around the pixel's specular w and the weight of the second.
void nodesOf(float wSpec, out int m0, out int m1, out float t) {
    float x = clamp((wSpec - P.cdfLo.z) / P.cdfLo.w, 0.0, float(P.cdfDims.z - 1));
    m0 = int(floor(x));
    m1 = min(m0 + 1, P.cdfDims.z - 1);
    t = x - float(m0);
}

float brdfDensity(vec2 uv, int m0, int m1, float t) {
    return (1.0 - t) * nodeDensity(m0, uv) + t * nodeDensity(m1, uv);
}

// A (u, v) drawn from the density of node m0 or m1 (weight t of m1), and in pdf the
// mixture's density there.
vec2 sampleBrdf(vec3 xi, int m0, int m1, float t, out float pdf) {
    int m = xi.z < t ? m1 : m0;
    int nbu = P.cdfDims.x, nbv = P.cdfDims.y;
    int base = nodeBase(m);
    float fr, fc;
    int row = invertCdf(false, base, nbv, xi.x, fr);
    int col = invertCdf(false, base + (nbv + 1) + row * (nbu + 1), nbu, xi.y, fc);
    // Inside the cell, the bilinear density: v by its marginal, then u given v.
    vec4 k = cellCorners(m, col, row);
    float y = sampleLinear(fr, k.x + k.y, k.z + k.w);
    float x = sampleLinear(fc, mix(k.x, k.z, y), mix(k.y, k.w, y));
    vec2 uv = P.cdfLo.xy + (vec2(col, row) + vec2(x, y)) * P.cdfStep.xy;
    // One node (the density is one envelope over w): its bilinear value at the point.
    pdf = m0 == m1 ? mix(mix(k.x, k.y, x), mix(k.z, k.w, x), y) : brdfDensity(uv, m0, m1, t);
    return uv;
}

// --- sequences ------------------------------------------------------------------------------

uint hash(uint x) {
    x ^= x >> 16; x *= 0x7feb352du; x ^= x >> 15; x *= 0x846ca68bu; x ^= x >> 16;
    return x;
}

float unitFloat(uint x) { return float(x >> 8) * (1.0 / 16777216.0); }

// --- disc lights ----------------------------------------------------------------------------

// Radiance XYZ of every light at world direction d (the environment's pixel penv, or its
// own pixel when penv < 0) and the density in solid angle of the light sampler there.
// lDisc: the disc lights' part of it.
vec3 radianceAt(vec3 d, int penv, out float pLight, out vec3 lDisc) {
    int p = penv >= 0 ? penv : envPixel(d);
    lDisc = vec3(0.0);
    pLight = P.sequence.y != 0 ? P.blend.y * envPdf(p) : 0.0;
    int base = 2 * P.lightDims.x;
    for (int j = 0; j < P.lightDims.y; ++j) {
        vec4 axis = lights[base + 3 * j];
        if (dot(d, axis.xyz) >= axis.w) {
            vec4 rad = lights[base + 3 * j + 1];
            lDisc += rad.xyz;
            pLight += lights[base + 3 * j + 2].x / rad.w;
        }
    }
    return envRadiance(p) + lDisc;
}

// The environment's irradiance at the world normal n: bilinear between the table's
// normals (wrapping in azimuth).
vec3 irradianceAt(vec3 n) {
    int base = 2 * P.lightDims.x + 3 * P.lightDims.y;
    float x = fract(0.5 + atan(n.x, -n.z) / (2.0 * PI)) * float(IRR_W) - 0.5;
    float y = clamp(acos(clamp(n.y, -1.0, 1.0)) / PI * float(IRR_H) - 0.5, 0.0, float(IRR_H - 1));
    int i0 = int(floor(x)), j0 = min(int(floor(y)), IRR_H - 2);
    float fx = x - float(i0), fy = y - float(j0);
    int ia = (i0 + IRR_W) % IRR_W, ib = (i0 + 1 + IRR_W) % IRR_W;
    vec3 a = lights[base + j0 * IRR_W + ia].xyz, b = lights[base + j0 * IRR_W + ib].xyz;
    vec3 c = lights[base + (j0 + 1) * IRR_W + ia].xyz, d = lights[base + (j0 + 1) * IRR_W + ib].xyz;
    return mix(mix(a, b, fx), mix(c, d, fx), fy);
}

// A direction uniform in the cone of half-angle acos(cosA) around the unit vector a.
vec3 sampleCone(vec3 a, float cosA, vec2 xi) {
    float ct = 1.0 - xi.x * (1.0 - cosA);
    float st = sqrt(max(0.0, 1.0 - ct * ct));
    float phi = 2.0 * PI * xi.y;
    vec3 e1 = normalize(cross(a, abs(a.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0)));
    vec3 e2 = cross(a, e1);
    return ct * a + st * (cos(phi) * e1 + sin(phi) * e2);
}

// A world direction from the light sampler: the environment (probability blend.y) or a
// disc light (its probability); penv is the environment's pixel, or −1.
vec3 sampleLight(vec2 xi, out int penv) {
    penv = -1;
    float q0 = P.blend.y;
    if (xi.x < q0 || P.lightDims.y == 0) {
        return sampleEnv(vec2(clamp(xi.x / max(q0, 1e-30), 0.0, 1.0), xi.y), penv);
    }
    int base = 2 * P.lightDims.x;
    float acc = q0;
    int last = P.lightDims.y - 1;
    for (int j = 0; j <= last; ++j) {
        float q = lights[base + 3 * j + 2].x;
        if (xi.x < acc + q || j == last) {
            vec4 axis = lights[base + 3 * j];
            float u = clamp((xi.x - acc) / max(q, 1e-30), 0.0, 1.0);
            return sampleCone(axis.xyz, axis.w, vec2(u, xi.y));
        }
        acc += q;
    }
    return vec3(0.0, 1.0, 0.0);
}

// --- one surface point ----------------------------------------------------------------------

// A shaded point: its orthonormal tangent frame in world space, ωr in it, and the texture's
// albedo (linear sRGB; unused without texture blending).
struct Surface {
    vec3 t;
    vec3 b;
    vec3 n;
    vec3 wr;
    vec3 tex;
};

vec3 toWorld(Surface s, vec3 v) { return v.x * s.t + v.y * s.b + v.z * s.n; }
vec3 toTangent(Surface s, vec3 d) { return vec3(dot(d, s.t), dot(d, s.b), dot(d, s.n)); }

// The surfaces of the G-buffer pixels next to the one shaded (right, left, down, up) and
// whether each is covered, set by the scene stage: a point light's (u, v) footprint over
// the pixel, for a variant that reads its table filtered to it, as the raster pass's dFdx
// and dFdy give it (glsl/shade.glsl). None for a map.
Surface gNear[4];
bool gHas[4] = bool[4](false, false, false, false);

// (u, v) of the light towards world direction d at s: −(ωi + ωr) in s's frame.
vec2 uvOf(Surface s, vec3 d) { return -(vec2(dot(d, s.t), dot(d, s.b)) + s.wr.xy); }

// The change of (u, v) = uv (at s) one pixel along an axis: of the differences towards the
// next pixel (gNear[k]) and from the previous (gNear[k + 1]), the smaller, so that a
// neighbour across an edge of the mesh (another scale, the silhouette), where the raster
// pass's quad would extrapolate its own triangle, is not taken; 0 without either.
vec2 uvStep(vec3 d, vec2 uv, int k) {
    vec2 a = uvOf(gNear[k], d) - uv;
    vec2 b = uv - uvOf(gNear[k + 1], d);
    if (gHas[k] && gHas[k + 1]) return dot(a, a) <= dot(b, b) ? a : b;
    return gHas[k] ? a : (gHas[k + 1] ? b : vec2(0.0));
}

// gUvFootprint (interface.glsl) of the light towards d at s: the steps one pixel along x
// and y, as the raster pass's dFdx and dFdy give them, so that chebyshev-w reads the same
// box over the pixel's footprint in both (glsl/chebyshev_w.frag, footprintAt).
void setFootprint(Surface s, vec3 d) {
    vec2 uv = uvOf(s, d);
    gUvFootprint = vec4(uvStep(d, uv, 0), uvStep(d, uv, 2));
}

// Adds scale·L·[(1 − w_d)·C·G] to xyz and the texture part to rgb (header): of the lights
// outside the irradiance table (lOwn) scale·L·((1 − α) + w_d)·t; of the environment only
// −scale·L·α·t, its (1 + w_d)·t·E(n) being added once from the table (a control variate:
// the Monte Carlo part is the small Fresnel term alone).
void addDirection(Surface s, vec3 wi, vec3 l, vec3 lOwn, float scale, inout vec3 xyz,
                  inout vec3 rgb) {
    // The variant's C·G holds radiance over blend.w (src/render/env_brdf.rs).
    xyz += scale * (1.0 - P.blend.x) * P.blend.w * l * diffractionXyz(wi, s.wr);
    if (P.lightDims.z != 0 && wi.z > 0.0) {
        vec3 h = wi + s.wr;
        float lh = length(h);
        float cosRH = lh > 1e-20 ? clamp(dot(s.wr, h / lh), 0.0, 1.0) : 0.0;
        float r0 = params.shading.x;
        float m = 1.0 - cosRH;
        float alpha = min(1.0, abs(r0 + (1.0 - r0) * m * m * m * m * m));
        vec3 k = ((1.0 - alpha) + P.blend.x) * lOwn - alpha * (l - lOwn);
        rgb += scale * (XYZ_TO_SRGB * k) * s.tex;
    }
}

// The lights evaluated in full once per pixel (not sampled): every point light, and the
// texture's environment term (1 + w_d)·t·E(n) from the irradiance table. XYZ of the
// diffraction part in xyz, linear sRGB of the texture part in rgb.
void pointLights(Surface s, out vec3 xyz, out vec3 rgb) {
    xyz = vec3(0.0);
    rgb = vec3(0.0);
    for (int j = 0; j < P.lightDims.x; ++j) {
        vec3 wi = toTangent(s, lights[2 * j].xyz);
        vec3 e = lights[2 * j + 1].xyz;
        setFootprint(s, lights[2 * j].xyz);
        if (wi.z > 0.0) addDirection(s, wi, e, e, wi.z, xyz, rgb);
    }
    // The samples read the table at their point.
    gUvFootprint = vec4(0.0);
    if (P.lightDims.z != 0) rgb += (1.0 + P.blend.x) * irradianceAt(s.n) * s.tex;
    if (any(isnan(xyz)) || any(isinf(xyz))) xyz = vec3(0.0);
    if (any(isnan(rgb)) || any(isinf(rgb))) rgb = vec3(0.0);
}

// The sums of this dispatch's samples k ∈ [base, base + count) at a pixel: XYZ of the
// diffraction part, linear sRGB of the texture part, and in sq, per linear-sRGB channel,
// the sum of the squares of the pixel's colour summed over each batch of `batch`
// consecutive samples (batches start at multiples of `batch`; the host estimates the
// pixel's noise from them). key scrambles the sequence; the pixel takes its point
// k·stride + place of it (pixels that share a key interleave one low-discrepancy sequence,
// so that the first n samples of each make the first stride·n points of it). closed: the
// samples of the batches added; dropped: the batches left out for a NaN or an infinity.
void integrate(Surface s, uint key, uint place, uint stride, int batch, out vec3 xyz,
               out vec3 rgb, out vec3 sq, out int closed, out int dropped) {
    xyz = vec3(0.0);
    rgb = vec3(0.0);
    sq = vec3(0.0);
    closed = 0;
    dropped = 0;
    // R5: α_k = φ^−k, φ the real root of x⁶ = x + 1, as 32-bit fixed-point fractions so
    // that the n-th point is exact for every n (x_n = rot + n·α mod 1, wrapping).
    const uint alpha[5] = uint[5](3785032106u, 3335640776u, 2939605022u, 2590590015u,
                                  2283013049u);
    uint h = hash(key * 9781u + uint(P.sequence.z) * 6271u + 1u);
    uint rot[5];
    for (int d = 0; d < 5; ++d) { h = hash(h + uint(d)); rot[d] = h; }
    int m0, m1;
    float tw;
    nodesOf(-2.0 * s.wr.z, m0, m1, tw);
    // Every sample draws from the BRDF; every m-th also from the lights (m = blend.z, so
    // n_l = n/m: the host makes n a multiple of m). Each strategy takes the next point of
    // its own dimensions of the sequence. Power heuristic with the counts:
    // w_b = p_b²/(p_b² + (p_ω/m)²), w_l = 1 − w_b at the same direction.
    bool lightSampling = P.sequence.y != 0 || P.lightDims.y > 0;
    int m = max(1, int(P.blend.z));
    float mf = float(m);
    vec3 bx = vec3(0.0), br = vec3(0.0);
    int opened = chunk.base;
    int end = chunk.base + chunk.count;
    // The last batch added, to take back if the loop was cut short (below).
    vec3 lastX = vec3(0.0), lastR = vec3(0.0), lastSq = vec3(0.0);
    int lastN = 0;
    int k = chunk.base;
    for (; k < end; ++k) {
        uint ib = uint(k) * stride + place + 1u;
        vec3 x3 = vec3(unitFloat(rot[0] + ib * alpha[0]), unitFloat(rot[1] + ib * alpha[1]),
                       unitFloat(rot[2] + ib * alpha[2]));
        // The BRDF's sample: (u, v), then ωi; the integrand per du dv over p_uv.
        float pUv;
        vec2 uv = sampleBrdf(x3, m0, m1, tw, pUv);
        vec2 ixy = -uv - s.wr.xy;
        float s2 = dot(ixy, ixy);
        if (s2 < 1.0 && pUv > 0.0) {
            vec3 wi = vec3(ixy, sqrt(1.0 - s2));
            float pl;
            vec3 own;
            vec3 l = radianceAt(toWorld(s, wi), -1, pl, own);
            // pb > 0 here; the ratio form cannot make 0/0 or ∞/∞ (an infinite ratio gives 0).
            float r = (pl / mf) / (pUv * wi.z);
            addDirection(s, wi, l, own, 1.0 / (1.0 + r * r) / pUv, bx, br);
        }
        // The lights' sample: the integrand per dωi (times cos θi) over p_ω, times m.
        if (lightSampling && k % m == 0) {
            uint il = uint(k / m) * stride + place + 1u;
            vec2 x2 = vec2(unitFloat(rot[3] + il * alpha[3]), unitFloat(rot[4] + il * alpha[4]));
            int p;
            vec3 d = sampleLight(x2, p);
            vec3 wi = toTangent(s, d);
            float pl;
            vec3 own;
            vec3 l = radianceAt(d, p, pl, own);
            if (wi.z > 0.0 && pl > 0.0) {
                float ql = pl / mf;
                float r = brdfDensity(-wi.xy - s.wr.xy, m0, m1, tw) * wi.z / ql;
                addDirection(s, wi, l, own, wi.z / (1.0 + r * r) / ql, bx, br);
            }
        }
        if ((k + 1) % batch == 0 || k + 1 == end) {
            // A batch is added whole, its samples counted in `closed`, or, when it holds
            // a NaN or an infinity, left out and counted in `dropped` (the host reports
            // it). The host divides by `closed`: what a batch the loop never finished
            // or a dropped one would have added is in neither the sum nor the count.
            vec3 c = XYZ_TO_SRGB * bx + br;
            if (any(isnan(c)) || any(isinf(c))) {
                dropped += 1;
                lastN = 0;
            } else {
                sq += c * c;
                xyz += bx;
                rgb += br;
                lastX = bx;
                lastR = br;
                lastSq = c * c;
                lastN = k + 1 - opened;
                closed += lastN;
            }
            opened = k + 1;
            bx = vec3(0.0);
            br = vec3(0.0);
        }
    }
    // A driver that ends an invocation's loops after a fixed count of iterations
    // (llvmpipe: src/render/env.rs, samples_per_dispatch) leaves k short of the end, and
    // the inner loops of the last sample may have been cut too: its batch goes.
    if (k < end && lastN > 0) {
        xyz -= lastX;
        rgb -= lastR;
        sq -= lastSq;
        closed -= lastN;
    }
}

#endif
