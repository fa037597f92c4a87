// The clear coat of a material code (neural/coat.py, SPEC section 6): the
// closed-form GGX reflection of the top interface, (roughness, ior) = c; an
// ior of 1 is "no coat". Sampled exactly by its visible normals, with the
// share of samples coat_probability (the same heuristic as torch).
//@INCLUDE microfacet.glsl
//@INCLUDE sampling.glsl

vec2 coat_params(vec2 c) { return vec2(clamp(c.x, 0.005, 1.0), clamp(c.y, 1.0, 3.0)); }

float coat_eval(vec3 wi, vec3 wo, vec2 c) {
    c = coat_params(c);
    if (c.y <= 1.0) return 0.0;
    return dielectric_reflection(wi, wo, c.x, c.y);
}

float coat_probability(vec3 w, vec2 c) {
    c = coat_params(c);
    if (c.y <= 1.0 + 1e-4) return 0.0;
    return clamp(sqrt(fresnel_dielectric(clamp(w.z, 0.0, 1.0), c.y)), 0.05, 0.95);
}

vec3 coat_sample(vec3 w, vec2 u, vec2 c) {
    vec3 m = sample_vndf(w, coat_params(c).x, u);
    return 2.0 * dot(w, m) * m - w;
}

float coat_pdf(vec3 w, vec3 l, vec2 c) { return pdf_ggx_reflection(w, l, coat_params(c).x); }

// A material code's sampler (neural/sampling.py coated_sample / coated_pdf):
// the coat's lobe with probability coat_probability, else the body's proxy
// (s, w); u.x picks and is rescaled to stay uniform for the proxy.
vec3 coated_sample(vec3 wo, vec3 u, vec2 c, float s, float w) {
    float pc = coat_probability(wo, c);
    if (u.x < pc) return coat_sample(wo, u.yz, c);
    u.x = clamp((u.x - pc) / max(1.0 - pc, 1e-6), 0.0, 1.0 - 1e-7);
    return sample_proxy(wo, u, s, w);
}

float coated_pdf(vec3 wo, vec3 wi, vec2 c, float s, float w) {
    float pc = coat_probability(wo, c);
    float p = (1.0 - pc) * pdf_proxy(wo, wi, s, w);
    return pc > 0.0 ? p + pc * coat_pdf(wo, wi, c) : p;
}
