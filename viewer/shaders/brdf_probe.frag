// BRDF probe: pixel k of the target holds brdf() -- the BRDF snippet of the
// program's kind (closed form, Belcour) -- at the k-th (wi, wo) pair of
// u_pairs (texel 2k = wi, 2k + 1 = wo), local frame. With NB_PROBE_SAMPLING:
// the snippet's lobe strategy instead, item k = (wo, u) -> (l, pdf_lobe(wo, l))
// with l = sample_lobe(wo, u). Tests use it to check a GLSL BRDF against its
// Python model pair by pair, and its sampler's pdf.
//@INCLUDE common.glsl
//@INCLUDE brdf
uniform sampler2D u_pairs;
uniform int u_pairs_w;   // texels per row of u_pairs
uniform int u_target_w;  // pixels per row of the target
out vec4 frag;
vec3 pair_texel(int i) { return texelFetch(u_pairs, ivec2(i % u_pairs_w, i / u_pairs_w), 0).xyz; }
void main() {
    int k = int(gl_FragCoord.y) * u_target_w + int(gl_FragCoord.x);
#ifdef NB_PROBE_SAMPLING
    vec3 wo = pair_texel(2 * k);
    vec3 l = sample_lobe(wo, pair_texel(2 * k + 1));
    frag = vec4(l, pdf_lobe(wo, l));
#else
    frag = vec4(brdf(pair_texel(2 * k), pair_texel(2 * k + 1)), 1.0);
#endif
}
