// A spatially varying neural material: the latent's share of the decoder's
// layer 1 per texel (viewer/neural_gpu.py GpuLatentTexture), RGB channels in
// layer groups of NB_WIDTH4 RGBA layers, then one layer of the texel's clear
// coat (roughness, ior, 0, 0). nb_load_share(uv) fetches it once per pixel
// (trilinear by the pixel's footprint when mip-mapped); every nb_decode and
// coat term of the pixel then reads it through NB_SHARE and NB_COAT. Include
// before the decoder.
#define NB_TEXTURED 1
uniform sampler2DArray u_nb_share_tex;
vec3 nb_px_share[NB_WIDTH];
#define NB_SHARE(j) nb_px_share[j]
vec2 nb_px_coat;
#define NB_COAT nb_px_coat

void nb_load_share(vec2 uv) {
    for (int k = 0; k < NB_WIDTH4; ++k) {
        vec4 r = texture(u_nb_share_tex, vec3(uv, float(k)));
        vec4 g = texture(u_nb_share_tex, vec3(uv, float(k + NB_WIDTH4)));
        vec4 b = texture(u_nb_share_tex, vec3(uv, float(k + 2 * NB_WIDTH4)));
        nb_px_share[4 * k] = vec3(r.x, g.x, b.x);
        nb_px_share[4 * k + 1] = vec3(r.y, g.y, b.y);
        nb_px_share[4 * k + 2] = vec3(r.z, g.z, b.z);
        nb_px_share[4 * k + 3] = vec3(r.w, g.w, b.w);
    }
    nb_px_coat = texture(u_nb_share_tex, vec3(uv, float(3 * NB_WIDTH4))).xy;
}
