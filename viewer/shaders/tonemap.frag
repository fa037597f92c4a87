// Linear HDR -> display: exposure, tone mapping (0 linear, 1 ACES filmic
// after Narkowicz 2015), sRGB encoding. The accumulation holds the sum of
// u_passes passes.
uniform sampler2D u_hdr;
uniform float u_passes;
uniform float u_exposure;   // stops
uniform int u_tonemap;
in vec2 v_uv;
out vec4 frag;

vec3 aces(vec3 x) {
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

vec3 srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}

void main() {
    vec3 c = texture(u_hdr, v_uv).rgb / max(u_passes, 1.0) * exp2(u_exposure);
    c = u_tonemap == 1 ? aces(c) : c;
    frag = vec4(srgb(c), 1.0);
}
