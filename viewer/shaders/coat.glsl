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
