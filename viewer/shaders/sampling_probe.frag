// Sampling probe: pixel k holds coated_sample from the k-th (wi, u) item of
// u_pairs (texel 2k = wi, 2k + 1 = u) and its coated_pdf, for tests against
// torch (u_coat with ior 1: the proxy alone).
//@INCLUDE common.glsl
//@INCLUDE sampling.glsl
//@INCLUDE coat.glsl
uniform sampler2D u_pairs;
uniform int u_pairs_w;
uniform int u_target_w;
uniform float u_sigma;
uniform float u_w;
uniform vec2 u_coat;
out vec4 frag;
vec3 item(int i) { return texelFetch(u_pairs, ivec2(i % u_pairs_w, i / u_pairs_w), 0).xyz; }
void main() {
    int k = int(gl_FragCoord.y) * u_target_w + int(gl_FragCoord.x);
    vec3 wi = item(2 * k);
    vec3 wo = coated_sample(wi, item(2 * k + 1), u_coat, u_sigma, u_w);
    frag = vec4(wo, coated_pdf(wi, wo, u_coat, u_sigma, u_w));
}
