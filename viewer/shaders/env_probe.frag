// Environment probe: pixel k holds sample_env of the k-th uniform pair of
// u_pairs (texel 2k; texel 2k + 1 unused) and its pdf, for tests against numpy.
//@INCLUDE common.glsl
//@INCLUDE environment.glsl
uniform sampler2D u_pairs;
uniform int u_pairs_w;
uniform int u_target_w;
out vec4 frag;
void main() {
    int k = int(gl_FragCoord.y) * u_target_w + int(gl_FragCoord.x);
    int i = 2 * k;
    vec2 u = texelFetch(u_pairs, ivec2(i % u_pairs_w, i / u_pairs_w), 0).xy;
    float pdf;
    vec3 d = sample_env(u, pdf);
    frag = vec4(d, pdf_env(d) > 0.0 ? pdf : -1.0);
}
