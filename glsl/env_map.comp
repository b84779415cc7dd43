#version 450
// A BRDF map lit by an environment map (MODEL §10), one invocation per pixel: N samples
// per pixel of L_o = ∫ L(ωi)·f_r·cos θi dωi, combining two samplers by multiple importance
// sampling (power heuristic, one sample of each a round):
//  - the BRDF: (u, v) drawn from a piecewise-constant density fitted to the table's G at
//    the CDF node nearest the pixel's specular w (a random choice between the two nearest,
//    weighted by distance, so the density is a mixture of the two), dωi = du dv / cos θi;
//  - the environment: a pixel drawn by luminance, uniform in solid angle inside it.
// Random numbers: the 5-dimensional R-sequence (Roberts' generalised golden ratio), with a
// per-pixel Cranley–Patterson rotation from a hash of the pixel. G is the chebyshev-w model
// of a table summed with radiance weights (brdf::env_reference): f_r/W per XYZ channel, so
// L_o,c = ∫ L_c·C·G_c du dv with the environment's RGB turned into XYZ on the CPU and
// applied channel by channel (the usual approximation: the dispersion is in G, not in the
// light). Mirrors brdf::env_reference and src/render/env.rs.
layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params {
    vec4 regionLo;   // xyz: lower corner (u0, v0, w0) of the table
    vec4 regionHi;   // xyz: upper corner
    vec4 sunWi;      // xyz: towards the sun (tangent space), w: its irradiance (0: none)
    vec4 white;      // xyz: D65's white XYZ (the sun's colour), w: Schlick R0
    vec4 cdfLo;      // xy: (u, v) of the G density's first bin corner, z: first CDF node w, w: node step
    vec4 cdfStep;    // xy: bin size in u and v
    ivec4 tableDims; // x: nu, y: nv, z: K (Chebyshev terms)
    ivec4 cdfDims;   // x: bins along u, y: along v, z: CDF nodes in w
    ivec4 envDims;   // x: W, y: H, z: samples per pixel, w: map size S
    ivec4 flags;     // x: Fresnel, y: shadowing, z: environment can be sampled, w: seed
    vec4 envRot;     // x: cos, y: sin of the map's rotation about +Y
} P;
layout(std430, set = 0, binding = 1) readonly buffer Coeff { float coeff[]; };
layout(std430, set = 0, binding = 2) readonly buffer EnvXyz { float envXyz[]; };
// Marginal CDF over rows (H + 1), conditional CDFs over columns (H·(W + 1)), then the
// density in solid angle of each pixel (W·H).
layout(std430, set = 0, binding = 3) readonly buffer EnvCdf { float envCdf[]; };
// Per CDF node: marginal over v bins (nbv + 1), conditionals over u bins (nbv·(nbu + 1)),
// then the density in (u, v) of each bin (nbu·nbv).
layout(std430, set = 0, binding = 4) readonly buffer GCdf { float gCdf[]; };
// The sum over the samples so far (the CPU divides by their number): each dispatch adds
// samples [base, base + count); the first also adds the sun, times the total.
layout(std430, set = 0, binding = 5) buffer Out { vec4 outXyz[]; };
layout(push_constant) uniform Chunk { int base; int count; } chunk;

const float PI = 3.14159265358979;

// --- the BRDF: C(ωi, ωr)·G(u, v, w) -------------------------------------------------------

float gain(vec3 wi, vec3 wr) {
    float ci = wi.z, cr = wr.z;
    if (ci <= 0.0 || cr <= 0.0) return 0.0;
    float w = ci + cr;
    vec3 h = wi + wr;
    float onePlus = 0.5 * dot(h, h);
    float c = onePlus * onePlus / (w * w * ci * cr);
    h /= length(h);
    float cosRH = clamp(dot(wr, h), 0.0, 1.0);
    if (P.flags.x != 0) {
        float r0 = P.white.w;
        float m = 1.0 - cosRH;
        c *= (r0 + (1.0 - r0) * m * m * m * m * m) / r0;
    }
    if (P.flags.y != 0) {
        float k = cosRH > 0.0 ? 2.0 * h.z / cosRH : 0.0;
        c *= min(1.0, min(k * cr, k * ci));
    }
    return (isnan(c) || isinf(c)) ? 0.0 : c;
}

vec4 splineWeights(float f) {
    float f2 = f * f, f3 = f2 * f;
    return vec4((1.0 - f) * (1.0 - f) * (1.0 - f), 3.0 * f3 - 6.0 * f2 + 4.0,
                -3.0 * f3 + 3.0 * f2 + 3.0 * f + 1.0, f3) / 6.0;
}

// G(u, v, w) ≥ 0 of the chebyshev-w model (cubic B-spline planes, Clenshaw in w); 0 outside.
vec3 tableG(vec3 uvw) {
    vec3 f = (uvw - P.regionLo.xyz) / (P.regionHi.xyz - P.regionLo.xyz);
    if (any(lessThan(f, vec3(0.0))) || any(greaterThan(f, vec3(1.0)))) return vec3(0.0);
    int nu = P.tableDims.x, nv = P.tableDims.y, k = P.tableDims.z;
    vec2 t = f.xy * vec2(nu - 1, nv - 1);
    ivec2 i = clamp(ivec2(floor(t)), ivec2(0), ivec2(nu - 2, nv - 2));
    vec2 x = t - vec2(i);
    vec4 wx = splineWeights(x.x), wy = splineWeights(x.y);
    int su = nu + 2, plane = su * (nv + 2);
    float xw = 2.0 * f.z - 1.0;
    vec3 b1 = vec3(0.0), b2 = vec3(0.0), c0 = vec3(0.0);
    for (int j = k - 1; j >= 0; --j) {
        vec3 c = vec3(0.0);
        for (int b = 0; b < 4; ++b) {
            for (int a = 0; a < 4; ++a) {
                int o = 3 * (j * plane + (i.y + b) * su + i.x + a);
                c += wx[a] * wy[b] * vec3(coeff[o], coeff[o + 1], coeff[o + 2]);
            }
        }
        if (j == 0) { c0 = c; break; }
        vec3 b0 = c + 2.0 * xw * b1 - b2;
        b2 = b1;
        b1 = b0;
    }
    return max(c0 + xw * b1 - b2, vec3(0.0));
}

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

// Tangent frame of the map's patch (MODEL §10): N = +Y, T = +X, B = N × T = −Z.
vec3 toWorld(vec3 t) { return vec3(t.x, t.z, -t.y); }
vec3 toTangent(vec3 d) { return vec3(d.x, -d.z, d.y); }

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
    return m * ((nbv + 1) + nbv * (nbu + 1) + nbu * nbv);
}

float nodeDensity(int m, vec2 uv) {
    int nbu = P.cdfDims.x, nbv = P.cdfDims.y;
    vec2 b = (uv - P.cdfLo.xy) / P.cdfStep.xy;
    if (any(lessThan(b, vec2(0.0))) || b.x >= float(nbu) || b.y >= float(nbv)) return 0.0;
    int base = nodeBase(m) + (nbv + 1) + nbv * (nbu + 1);
    return gCdf[base + int(b.y) * nbu + int(b.x)];
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

vec2 sampleBrdf(vec3 xi, int m0, int m1, float t) {
    int m = xi.z < t ? m1 : m0;
    int nbu = P.cdfDims.x, nbv = P.cdfDims.y;
    int base = nodeBase(m);
    float fr, fc;
    int row = invertCdf(false, base, nbv, xi.x, fr);
    int col = invertCdf(false, base + (nbv + 1) + row * (nbu + 1), nbu, xi.y, fc);
    return P.cdfLo.xy + (vec2(col, row) + vec2(fc, fr)) * P.cdfStep.xy;
}

// --- sequences ------------------------------------------------------------------------------

uint hash(uint x) {
    x ^= x >> 16; x *= 0x7feb352du; x ^= x >> 15; x *= 0x846ca68bu; x ^= x >> 16;
    return x;
}

float unitFloat(uint x) { return float(x >> 8) * (1.0 / 16777216.0); }

void main() {
    uint idx = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 64u;
    int S = P.envDims.w;
    if (idx >= uint(S * S)) return;
    int px = int(idx) % S, py = int(idx) / S;
    float x = 2.0 * (float(px) + 0.5) / float(S) - 1.0;
    float y = 1.0 - 2.0 * (float(py) + 0.5) / float(S);
    float r2 = x * x + y * y;
    if (r2 >= 1.0) { outXyz[idx] = vec4(0.0, 0.0, 0.0, 1.0); return; }
    int n = P.envDims.z;
    vec3 wr = vec3(x, y, sqrt(1.0 - r2));
    vec3 sum = vec3(0.0);
    // The sun: a point light of irradiance sunWi.w, D65 white.
    if (chunk.base == 0 && P.sunWi.w > 0.0) {
        vec3 wi = P.sunWi.xyz;
        float c = gain(wi, wr);
        if (c > 0.0) sum += float(n) * P.sunWi.w * wi.z * c * tableG(-wi - wr) * P.white.xyz;
    }
    // R5: α_k = φ^−k, φ the real root of x⁶ = x + 1, as 32-bit fixed-point fractions so
    // that the n-th point is exact for every n (x_n = rot + n·α mod 1, wrapping).
    const uint alpha[5] = uint[5](3785032106u, 3335640776u, 2939605022u, 2590590015u,
                                  2283013049u);
    uint h = hash(idx * 9781u + uint(P.flags.w) * 6271u + 1u);
    uint rot[5];
    for (int d = 0; d < 5; ++d) { h = hash(h + uint(d)); rot[d] = h; }
    int m0, m1;
    float tw;
    nodesOf(-2.0 * wr.z, m0, m1, tw);
    vec3 envSum = vec3(0.0);
    for (int s = chunk.base; s < chunk.base + chunk.count; ++s) {
        float xi[5];
        for (int d = 0; d < 5; ++d) xi[d] = unitFloat(rot[d] + uint(s + 1) * alpha[d]);
        // The BRDF's sample: (u, v), then ωi; f·cos θi / p_ω = C·G / p_uv.
        vec2 uv = sampleBrdf(vec3(xi[0], xi[1], xi[2]), m0, m1, tw);
        vec2 ixy = -uv - wr.xy;
        float s2 = dot(ixy, ixy);
        float pUv = brdfDensity(uv, m0, m1, tw);
        if (s2 < 1.0 && pUv > 0.0) {
            vec3 wi = vec3(ixy, sqrt(1.0 - s2));
            float c = gain(wi, wr);
            if (c > 0.0) {
                int p = envPixel(toWorld(wi));
                float pb = pUv * wi.z;
                float pe = P.flags.z != 0 ? envPdf(p) : 0.0;
                float mis = pb * pb / (pb * pb + pe * pe);
                envSum += envRadiance(p) * c * tableG(vec3(uv, -wi.z - wr.z)) * (mis / pUv);
            }
        }
        // The environment's sample: f·cos θi / p_ω.
        if (P.flags.z != 0) {
            int p;
            vec3 wi = toTangent(sampleEnv(vec2(xi[3], xi[4]), p));
            float c = wi.z > 0.0 ? gain(wi, wr) : 0.0;
            float pe = envPdf(p);
            if (c > 0.0 && pe > 0.0) {
                vec2 uv2 = -wi.xy - wr.xy;
                float pb = brdfDensity(uv2, m0, m1, tw) * wi.z;
                float mis = pe * pe / (pb * pb + pe * pe);
                envSum += envRadiance(p) * c * tableG(vec3(uv2, -wi.z - wr.z)) * wi.z * (mis / pe);
            }
        }
    }
    sum += envSum;
    vec3 before = chunk.base == 0 ? vec3(0.0) : outXyz[idx].xyz;
    outXyz[idx] = vec4(before + ((any(isnan(sum)) || any(isinf(sum))) ? vec3(0.0) : sum), 1.0);
}
