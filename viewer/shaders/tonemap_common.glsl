// Linear radiance -> display: exposure (stops), the tone mapper named by
// u_tonemap (a TONEMAP_* constant: linear, fitted ACES, AgX, Khronos PBR
// Neutral; see tonemap_operators.glsl and its numpy twin viewer/tonemap.py),
// sRGB encoding.
uniform float u_exposure;
uniform int u_tonemap;    // a TONEMAP_* constant (unused where NB_TONEMAP_OP fixes it)

//@INCLUDE tonemap_operators.glsl

vec3 srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}

// NB_TONEMAP_OP (a TONEMAP_* constant) compiles one operator in, not every one behind u_tonemap:
// llvmpipe runs the straight-line code of every branch under a mask.
vec3 display(vec3 c) {
#ifdef NB_TONEMAP_OP
    return srgb(tm_apply(max(c, vec3(0.0)), NB_TONEMAP_OP, u_exposure));
#else
    return srgb(tm_apply(max(c, vec3(0.0)), u_tonemap, u_exposure));
#endif
}
