// Sampling probe: pixel k holds sample_proxy from the k-th (wi, u) item of
// u_pairs (texel 2k = wi, 2k + 1 = u) and its pdf_proxy, for tests against torch.
//@INCLUDE common.glsl
//@INCLUDE sampling.glsl
uniform sampler2D u_pairs;
uniform int u_pairs_w;
uniform int u_target_w;
uniform float u_sigma;
uniform float u_w;
out vec4 frag;
vec3 item(int i) { return texelFetch(u_pairs, ivec2(i % u_pairs_w, i / u_pairs_w), 0).xyz; }
void main() {
    int k = int(gl_FragCoord.y) * u_target_w + int(gl_FragCoord.x);
    vec3 wi = item(2 * k);
    vec3 wo = sample_proxy(wi, item(2 * k + 1), u_sigma, u_w);
    frag = vec4(wo, pdf_proxy(wi, wo, u_sigma, u_w));
}
