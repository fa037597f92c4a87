// Tone-mapping operators: linear scene radiance (already scaled by 2^EV) to
// display-linear [0, 1]; the GLSL twin of viewer/tonemap.py (sources and
// constants are documented there). Functions only: the caller supplies the
// mode constants (modes.glsl_defines(ToneMap): TONEMAP_LINEAR, TONEMAP_ACES,
// TONEMAP_AGX, TONEMAP_NEUTRAL) and does the sRGB encoding.

vec3 tm_linear(vec3 x) {
    return clamp(x, 0.0, 1.0);
}

// Narkowicz 2015 fitted ACES, no 0.6 pre-scale.
vec3 tm_aces(vec3 x) {
    x = max(x, 0.0);
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

// AgX base: inset, log2 over [-12.47393, 4.026069] EV, Wrensch's polynomial
// sigmoid, outset, 2.2 power back to display-linear.
vec3 tm_agx_sigmoid(vec3 x) {
    vec3 x2 = x * x;
    vec3 x4 = x2 * x2;
    return 15.5 * x4 * x2 - 40.14 * x4 * x + 31.96 * x4 - 6.868 * x2 * x
         + 0.4298 * x2 + 0.1191 * x - 0.00232;
}

vec3 tm_agx(vec3 x) {
    const mat3 inset = mat3(
        0.842479062253094, 0.0423282422610123, 0.0423756549057051,
        0.0784335999999992, 0.878468636469772, 0.0784336,
        0.0792237451477643, 0.0791661274605434, 0.879142973793104);
    const mat3 outset = mat3(
        1.19687900512017, -0.0528968517574562, -0.0529716355144438,
        -0.0980208811401368, 1.15190312990417, -0.0980434501171241,
        -0.0990297440797205, -0.0989611768448433, 1.15107367264116);
    const float min_ev = -12.47393;
    const float max_ev = 4.026069;
    vec3 v = inset * max(x, 0.0);
    v = clamp(log2(max(v, 1e-10)), min_ev, max_ev);
    v = tm_agx_sigmoid((v - min_ev) / (max_ev - min_ev));
    v = outset * v;
    return clamp(pow(max(v, 0.0), vec3(2.2)), 0.0, 1.0);
}

// Khronos PBR Neutral, reference implementation.
vec3 tm_neutral(vec3 color) {
    const float start = 0.8 - 0.04;
    const float desaturation = 0.15;
    color = max(color, 0.0);
    float x = min(color.r, min(color.g, color.b));
    float offset = x < 0.08 ? x - 6.25 * x * x : 0.04;
    color -= offset;
    float peak = max(color.r, max(color.g, color.b));
    if (peak < start) return clamp(color, 0.0, 1.0);
    const float d = 1.0 - start;
    float new_peak = 1.0 - d * d / (peak + d - start);
    color *= new_peak / peak;
    float g = 1.0 - 1.0 / (desaturation * (peak - new_peak) + 1.0);
    return clamp(mix(color, vec3(new_peak), g), 0.0, 1.0);
}

// The operator `op` (a TONEMAP_* constant) after an exposure of `ev` stops.
vec3 tm_apply(vec3 radiance, int op, float ev) {
    vec3 x = radiance * exp2(ev);
    if (op == TONEMAP_ACES) return tm_aces(x);
    if (op == TONEMAP_AGX) return tm_agx(x);
    if (op == TONEMAP_NEUTRAL) return tm_neutral(x);
    return tm_linear(x);
}
