// The accumulation (the sum of u_passes passes) to the display.
//@INCLUDE tonemap_common.glsl
uniform sampler2D u_hdr;
uniform float u_passes;
in vec2 v_uv;
out vec4 frag;

void main() {
    frag = vec4(display(texture(u_hdr, v_uv).rgb / max(u_passes, 1.0)), 1.0);
}
