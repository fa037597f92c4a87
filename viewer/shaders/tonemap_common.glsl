// Linear radiance -> display: exposure (stops), tone mapping (TONEMAP_LINEAR,
// or TONEMAP_ACES: ACES filmic after Narkowicz 2015), sRGB encoding.
uniform float u_exposure;
uniform int u_tonemap;    // a TONEMAP_* constant

vec3 aces(vec3 x) {
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

vec3 srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}

vec3 display(vec3 c) {
    c *= exp2(u_exposure);
    return srgb(u_tonemap == TONEMAP_ACES ? aces(c) : c);
}
