// The BRDF of a view as a material code (SPEC section 6, coat split): the
// clear coat in closed form (coat.glsl, uniform u_coat or the texel's coat
// NB_COAT) plus the neural decoder's body at the material's latents (uniform
// u_nb_share). The lit view importance-samples the coat's visible normals
// mixed with the body's learned proxy pdf (u_proxy_sigma, u_proxy_w,
// computed once per material on the CPU), as neural/sampling.py coated_sample.
// NB_BODY_TABLE: the body from the material's baked table (body_table.glsl; the
// code then supplies no decoder), else the decoder itself. NB_GUIDE_TABLE (the
// decoder at a uniform latent): the body's table is compiled in too, as the lit
// pass's resampling target (NB_BODY_GUIDE, lit_shade.glsl ris_target); the
// decoder stays the body.
// NB_ANISO: a code with an anisotropic tail (anisotropy.glsl): u_aniso = (the coat's anisotropy
// vector, the body's), u_body_alpha the body's masking alpha; the body is read at its warped pair,
// plus u_body_glow (per channel) times glow_basis, unwarped.
// NB_BODY_SCALE: a calibrated code's body times its scale (body_scale.glsl, the walk's energy).
#if defined(NB_BODY_TABLE) || defined(NB_GUIDE_TABLE)
//@INCLUDE body_table.glsl
#define NB_BODY_GUIDE(wi, wo) nb_table(wi, wo)
#endif
#ifdef NB_BODY_TABLE
#define NB_BODY(wi, wo) nb_table(wi, wo)
#else
//@INCLUDE neural_decoder.glsl
#define NB_BODY(wi, wo) nb_decode(wi, wo)
#endif
//@INCLUDE sampling.glsl
#ifdef NB_ANISO
uniform vec4 u_aniso;
uniform float u_body_alpha;
uniform vec3 u_body_glow;
#define NB_COAT_ANISO u_aniso.xy
#define NB_BODY_ANISO u_aniso.zw
#endif
//@INCLUDE coat.glsl
uniform float u_proxy_sigma;
uniform float u_proxy_w;
#ifndef NB_COAT
uniform vec2 u_coat;  // (roughness, ior); ior 1: no coat
#define NB_COAT u_coat
#endif
#ifdef NB_BODY_SCALE
//@INCLUDE body_scale.glsl
#define NB_SCALED(v, wi, wo) ((v) * nb_scale_pair(wi, wo))
#else
#define NB_SCALED(v, wi, wo) (v)
#endif
#ifdef NB_ANISO
vec3 nb_body(vec3 wi, vec3 wo) {
    vec3 a, b;
    float c_ior = coat_params(NB_COAT).y;
    float j = body_warp(wi, wo, vec3(u_aniso.zw, u_body_alpha), c_ior, a, b);
    return NB_SCALED((j > 0.0 ? NB_BODY(a, b) * j : vec3(0.0)) + u_body_glow * glow_basis(wi, wo, c_ior), wi, wo);
}
#ifdef NB_BODY_GUIDE  // the resampling target warped as the body is (a round target under a stretched body: fireflies)
vec3 nb_guide_aniso(vec3 wi, vec3 wo) {
    vec3 a, b;
    float c_ior = coat_params(NB_COAT).y;
    float j = body_warp(wi, wo, vec3(u_aniso.zw, u_body_alpha), c_ior, a, b);
    return (j > 0.0 ? nb_table(a, b) * j : vec3(0.0)) + u_body_glow * glow_basis(wi, wo, c_ior);
}
#undef NB_BODY_GUIDE
#define NB_BODY_GUIDE(wi, wo) nb_guide_aniso(wi, wo)
#endif
#else
#define nb_body(wi, wo) NB_SCALED(NB_BODY(wi, wo), wi, wo)
#endif
vec3 brdf(vec3 wi, vec3 wo) { return nb_body(wi, wo) + vec3(coat_eval(wi, wo, NB_COAT)); }
// The split for the lit pass (lit_shade.glsl): body and coat estimated apart.
#define NB_SPLIT_COAT 1
vec3 body_brdf(vec3 wi, vec3 wo) { return nb_body(wi, wo); }
vec3 sample_body(vec3 wo, vec3 u) { return NB_PROXY_SAMPLE(wo, u, u_proxy_sigma, u_proxy_w); }
float pdf_body(vec3 wo, vec3 wi) { return NB_PROXY_PDF(wo, wi, u_proxy_sigma, u_proxy_w); }
vec2 coat_code() { return NB_COAT; }
vec3 sample_lobe(vec3 wo, vec3 u) { return coated_sample(wo, u, NB_COAT, u_proxy_sigma, u_proxy_w); }
float pdf_lobe(vec3 wo, vec3 wi) { return coated_pdf(wo, wi, NB_COAT, u_proxy_sigma, u_proxy_w); }
