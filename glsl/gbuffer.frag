#version 450
// The G-buffer of a scene's environment-lit pixels (src/render/gbuffer.rs), fragment
// stage: per pixel the interpolated frame made orthonormal (N normalised, T orthogonalised
// against it, B = ±N × T on the side of the interpolated B), ωr towards the eye exactly
// (eye − position, not interpolated directions) in that frame, and the texture's albedo.
// A colour attachment holds four floats, so the sixteen go to four attachments:
//   0: (T, t_r)   1: (B, t_g)   2: (N, t_b)   3: (ωr, 1: covered)
// The clear value (0, 0, 0, 0) marks an uncovered pixel.

layout(location = 0) in vec3 inTangent;
layout(location = 1) in vec3 inBitangent;
layout(location = 2) in vec3 inNormal;
layout(location = 3) in vec3 inPosition;
layout(location = 4) in vec2 inUv;

// The texture's linear albedo, already scaled (a 1×1 black one without a texture).
layout(set = 0, binding = 0) uniform sampler2D albedo;
#include "footprint_texture.glsl"
layout(set = 0, binding = 1, std140) uniform Camera {
    vec4 eye; // xyz: the eye in world space
} camera;

layout(location = 0) out vec4 outTangent;
layout(location = 1) out vec4 outBitangent;
layout(location = 2) out vec4 outNormal;
layout(location = 3) out vec4 outToEye;

void main() {
    float ln = length(inNormal);
    vec3 n = ln > 1e-20 ? inNormal / ln : vec3(0.0, 0.0, 1.0);
    vec3 t0 = inTangent - n * dot(n, inTangent);
    float lt = length(t0);
    vec3 anyPerp = normalize(cross(n, abs(n.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0)));
    vec3 t = lt > 1e-20 ? t0 / lt : anyPerp;
    vec3 c = cross(n, t);
    vec3 b = dot(inBitangent, c) < 0.0 ? -c : c;
    vec3 e = camera.eye.xyz - inPosition;
    float le = length(e);
    vec3 toEye = le > 1e-20 ? e / le : n;
    vec3 wr = vec3(dot(toEye, t), dot(toEye, b), dot(toEye, n));
    vec3 tex = textureOverFootprint(albedo, inUv).rgb;
    outTangent = vec4(t, tex.r);
    outBitangent = vec4(b, tex.g);
    outNormal = vec4(n, tex.b);
    outToEye = vec4(wr, 1.0);
}
