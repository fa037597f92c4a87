// Decoder probe: pixel k of the target holds nb_decode at the k-th (wi, wo)
// pair of u_pairs (texel 2k = wi, 2k + 1 = wo). Tests and the decoder-only
// benchmark use it. With a latent texture (snippet nb_share = latent_texture.glsl)
// the share comes from the texture at uv = (texel 2k .w, texel 2k + 1 .w).
//@INCLUDE common.glsl
//@INCLUDE nb_share
//@INCLUDE neural_decoder.glsl
uniform sampler2D u_pairs;
uniform int u_pairs_w;   // texels per row of u_pairs
uniform int u_target_w;  // pixels per row of the target
out vec4 frag;
vec3 pair_texel(int i) { return texelFetch(u_pairs, ivec2(i % u_pairs_w, i / u_pairs_w), 0).xyz; }
void main() {
    int k = int(gl_FragCoord.y) * u_target_w + int(gl_FragCoord.x);
#ifdef NB_TEXTURED
    nb_load_share(vec2(texelFetch(u_pairs, ivec2((2 * k) % u_pairs_w, (2 * k) / u_pairs_w), 0).w,
                       texelFetch(u_pairs, ivec2((2 * k + 1) % u_pairs_w, (2 * k + 1) / u_pairs_w), 0).w));
#endif
    frag = vec4(nb_decode(pair_texel(2 * k), pair_texel(2 * k + 1)), 1.0);
}
