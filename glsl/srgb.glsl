// XYZ → linear sRGB (MODEL §5, IEC 61966-2-1; the D65 white is in the colour weights). GLSL
// matrices are column-major: columns listed. Shared by the fragment stages (colour.glsl)
// and the compute stages of environment light (env_common.glsl, env_resolve.comp).
#ifndef SRGB_GLSL
#define SRGB_GLSL

const mat3 XYZ_TO_SRGB = mat3(
    3.2406, -0.9689, 0.0557,
    -1.5372, 1.8758, -0.2040,
    -0.4986, 0.0415, 1.0570);

#endif
