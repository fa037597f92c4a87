// Display of one or two accumulations: A alone, A | B side by side, an A/B
// wipe at u_wipe, a false-colour relative error |A - B| / (B + 0.01) over
// [0, u_err_scale] (blue -> green -> red), the HDR-FLIP map u_flip (computed
// on the CPU by viewer/reference/compare.py) in magma, or the linear blend of A and B
// (interpolation of BRDF values). Exposure, tone mapping and sRGB: tonemap_common.glsl.
// While B has no image yet (u_pending), what would show B shows a grey hatch instead.
// NB_PLAIN: a program of its own for A alone (no compare, no blend, nothing pending),
// the window's every frame; llvmpipe runs every branch's straight-line code under a mask.
//@INCLUDE tonemap_common.glsl
uniform sampler2D u_a;
uniform sampler2D u_b;
uniform float u_passes_a;
uniform float u_passes_b;
uniform int u_mode;       // a COMPARE_* constant: A alone, side by side, wipe, error
uniform int u_blend;      // 1: (1 - u_wipe) A + u_wipe B (with COMPARE_OFF)
uniform float u_wipe;     // 0..1, x of the wipe line
uniform float u_err_scale;
uniform sampler2D u_flip;  // HDR-FLIP per pixel, 0..1 (COMPARE_FLIP)
uniform int u_pending;     // 1: B has no image yet (its side: the placeholder's hatch)
uniform vec2 u_hatch;      // the hatch's two greys, display values
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

vec3 magma(float t) {  // matplotlib's magma, a degree-6 polynomial fit (mattz, CC0)
    const vec3 c0 = vec3(-0.002136485053939582, -0.000749655052795221, -0.005386127855323933);
    const vec3 c1 = vec3(0.2516605407371642, 0.6775232436837668, 2.494026599312351);
    const vec3 c2 = vec3(8.353717279216625, -3.577719514958484, 0.3144679030132573);
    const vec3 c3 = vec3(-27.66873308576866, 14.26473078096533, -13.64921318813922);
    const vec3 c4 = vec3(52.17613981234068, -27.94360607168351, 12.94416944238394);
    const vec3 c5 = vec3(-50.76852536473588, 29.04658282127291, 4.23415299384598);
    const vec3 c6 = vec3(18.65570506591883, -11.48977351997711, -5.601961508734096);
    t = clamp(t, 0.0, 1.0);
    return clamp(c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * (c5 + t * c6))))), 0.0, 1.0);
}

// Diagonal stripes of two greys, 8 pixels wide, in display values: no exposure makes them a material.
vec3 hatch() {
    return vec3(mod(floor((gl_FragCoord.x + gl_FragCoord.y) / 8.0), 2.0) < 1.0 ? u_hatch.x : u_hatch.y);
}

#ifdef NB_PLAIN
void main() {
    frag = vec4(display(texture(u_a, v_uv).rgb / max(u_passes_a, 1.0)), 1.0);
}
#else
void main() {
    if (u_pending == 1 && u_blend == 0) {
        bool on_b = u_mode == COMPARE_SIDE ? v_uv.x >= 0.5
                  : u_mode == COMPARE_WIPE ? v_uv.x >= u_wipe + 0.002
                  : u_mode == COMPARE_ERROR || u_mode == COMPARE_FLIP;
        if (on_b) { frag = vec4(hatch(), 1.0); return; }
    }
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
    } else if (u_mode == COMPARE_FLIP) {
        frag = vec4(magma(texture(u_flip, v_uv).r), 1.0);
        return;
    } else if (u_mode == COMPARE_ERROR) {
        vec3 rel = abs(a - b) / (abs(b) + 0.01);
        frag = vec4(ramp((rel.r + rel.g + rel.b) / 3.0 / max(u_err_scale, 1e-6)), 1.0);
        return;
    }
    frag = vec4(display(a), 1.0);
}
#endif
