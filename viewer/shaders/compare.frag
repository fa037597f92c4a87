// Display of one or two accumulations: A alone, A | B side by side, an A/B
// wipe at u_wipe, a false-colour relative error |A - B| / (B + 0.01) over
// [0, u_err_scale] (blue -> green -> red), or the linear blend of A and B
// (interpolation of BRDF values). Exposure, tone mapping and sRGB as
// tonemap.frag (whose functions it includes).
//@INCLUDE tonemap_common.glsl
uniform sampler2D u_a;
uniform sampler2D u_b;
uniform float u_passes_a;
uniform float u_passes_b;
uniform int u_mode;       // a COMPARE_* constant: A alone, side by side, wipe, error
uniform int u_blend;      // 1: (1 - u_wipe) A + u_wipe B (with COMPARE_OFF)
uniform float u_wipe;     // 0..1, x of the wipe line
uniform float u_err_scale;
in vec2 v_uv;
out vec4 frag;

vec3 ramp(float t) {  // dark blue -> cyan -> green -> yellow -> red
    t = clamp(t, 0.0, 1.0);
    vec3 c = vec3(0.0);
    c.r = smoothstep(0.4, 0.75, t);
    c.g = t < 0.6 ? smoothstep(0.1, 0.45, t) : 1.0 - smoothstep(0.75, 1.0, t);
    c.b = t < 0.35 ? 0.35 + 0.65 * smoothstep(0.0, 0.25, t) : 1.0 - smoothstep(0.35, 0.55, t);
    return c;
}

void main() {
    vec3 a = texture(u_a, v_uv).rgb / max(u_passes_a, 1.0);
    vec3 b = texture(u_b, v_uv).rgb / max(u_passes_b, 1.0);
    if (u_mode == COMPARE_SIDE) {
        vec2 uv = vec2(fract(v_uv.x * 2.0), v_uv.y);
        a = v_uv.x < 0.5 ? texture(u_a, uv).rgb / max(u_passes_a, 1.0) : texture(u_b, uv).rgb / max(u_passes_b, 1.0);
    } else if (u_mode == COMPARE_WIPE) {
        if (abs(v_uv.x - u_wipe) < 0.002) { frag = vec4(1.0); return; }
        a = v_uv.x < u_wipe ? a : b;
    } else if (u_blend == 1) {
        a = mix(a, b, u_wipe);
    } else if (u_mode == COMPARE_ERROR) {
        vec3 rel = abs(a - b) / (abs(b) + 0.01);
        frag = vec4(ramp((rel.r + rel.g + rel.b) / 3.0 / max(u_err_scale, 1e-6)), 1.0);
        return;
    }
    frag = vec4(display(a), 1.0);
}
