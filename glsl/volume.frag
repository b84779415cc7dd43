#version 450
// Variant `volume`: G(u, v, w) in a 3D texture, one trilinear fetch per pixel (the floor of
// MODEL §7's cost table).
#include "interface.glsl"
#include "gain.glsl"
#include "table.glsl"

layout(set = 0, binding = 1) uniform sampler3D gVolume;

vec3 diffractionXyz(vec3 wi, vec3 wr) {
    float gainC = gainFactor(wi, wr);
    vec3 f;
    if (gainC == 0.0 || !tableFraction(-wi - wr, f)) {
        return vec3(0.0);
    }
    vec3 n = tableInfo.nodes.xyz;
    vec3 t = vec3(nodeCentred(f.xy, n.xy), (f.z * (n.z - 1.0) + 0.5) / n.z);
    return gainC * max(texture(gVolume, t).rgb, vec3(0.0)); // G ≥ 0
}

#include "shade.glsl"
