#version 450
// Full-screen triangle for BRDF maps (thesis §5): the fragment shader derives ωr from the
// pixel position, so the vertex stage only covers the target. Vertices (−1,−1), (3,−1),
// (−1,3) cover the [−1,1]² clip square with a single triangle (no diagonal seam).

// The mesh stage's interface (diffraction.vert): tangent frame, ωr, texture coordinates.
layout(location = 0) out vec3 outTangent;
layout(location = 1) out vec3 outWr;
layout(location = 2) out vec2 outUv;
layout(location = 3) out vec3 outBitangent;
layout(location = 4) out vec3 outNormal;

void main() {
    vec2 p = vec2(float((gl_VertexIndex << 1) & 2), float(gl_VertexIndex & 2));
    // The map's fragment shader ignores these; they are written so the interface between
    // the stages is complete.
    outTangent = vec3(1.0, 0.0, 0.0);
    outWr = vec3(0.0, 0.0, 1.0);
    outUv = p;
    outBitangent = vec3(0.0, 1.0, 0.0);
    outNormal = vec3(0.0, 0.0, 1.0);
    gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0);
}
