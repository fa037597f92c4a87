// The clear coat of a material code (neural/coat.py, SPEC section 6): the
// closed-form GGX reflection of the top interface, (roughness, ior) = c; an
// ior of 1 is "no coat". Sampled exactly by its visible normals, with the
// share of samples coat_probability (the same heuristic as torch).
//@INCLUDE microfacet.glsl
//@INCLUDE sampling.glsl
// NB_ANISO: the coat of a code with an anisotropic tail (anisotropy.glsl); NB_COAT_ANISO is its
// anisotropy vector, NB_BODY_ANISO the body's, whose proxy is stretched (neural_brdf.glsl: u_aniso).
#ifdef NB_ANISO
//@INCLUDE anisotropy.glsl
#endif

vec2 coat_params(vec2 c) { return vec2(clamp(c.x, 0.005, 1.0), clamp(c.y, 1.0, 3.0)); }

float coat_eval(vec3 wi, vec3 wo, vec2 c) {
    c = coat_params(c);
    if (c.y <= 1.0) return 0.0;
#ifdef NB_ANISO
    return coat_reflection_aniso(wi, wo, c, NB_COAT_ANISO);
#else
    return dielectric_reflection(wi, wo, c.x, c.y);
#endif
}

float coat_probability(vec3 w, vec2 c) {
    c = coat_params(c);
    if (c.y <= 1.0 + 1e-4) return 0.0;
    return clamp(sqrt(fresnel_dielectric(clamp(w.z, 0.0, 1.0), c.y)), 0.05, 0.95);
}

vec3 coat_sample(vec3 w, vec2 u, vec2 c) {
#ifdef NB_ANISO
    return coat_sample_aniso(w, u, coat_params(c), NB_COAT_ANISO);
#else
    vec3 m = sample_vndf(w, coat_params(c).x, u);
    return 2.0 * dot(w, m) * m - w;
#endif
}

float coat_pdf(vec3 w, vec3 l, vec2 c) {
#ifdef NB_ANISO
    return coat_pdf_aniso(w, l, coat_params(c), NB_COAT_ANISO);
#else
    return pdf_ggx_reflection(w, l, coat_params(c).x);
#endif
}

// A material code's sampler (neural/sampling.py coated_sample / coated_pdf):
// the coat's lobe with probability coat_probability, else the body's proxy
// (s, w); u.x picks and is rescaled to stay uniform for the proxy.
#ifdef NB_ANISO
#define NB_PROXY_SAMPLE(v, u, s, w) sample_proxy_aniso(v, u, s, w, NB_BODY_ANISO)
#define NB_PROXY_PDF(v, l, s, w) pdf_proxy_aniso(v, l, s, w, NB_BODY_ANISO)
#else
#define NB_PROXY_SAMPLE(v, u, s, w) sample_proxy(v, u, s, w)
#define NB_PROXY_PDF(v, l, s, w) pdf_proxy(v, l, s, w)
#endif
vec3 coated_sample(vec3 wo, vec3 u, vec2 c, float s, float w) {
    float pc = coat_probability(wo, c);
    if (u.x < pc) return coat_sample(wo, u.yz, c);
    u.x = clamp((u.x - pc) / max(1.0 - pc, 1e-6), 0.0, 1.0 - 1e-7);
    return NB_PROXY_SAMPLE(wo, u, s, w);
}

float coated_pdf(vec3 wo, vec3 wi, vec2 c, float s, float w) {
    float pc = coat_probability(wo, c);
    float p = (1.0 - pc) * NB_PROXY_PDF(wo, wi, s, w);
    return pc > 0.0 ? p + pc * coat_pdf(wo, wi, c) : p;
}
