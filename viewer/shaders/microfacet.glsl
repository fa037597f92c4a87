// GGX microfacet distribution, separable Smith masking, exact dielectric
// Fresnel and the reflection of a rough interface (SPEC section 5).

float ggx_d(vec3 m, float a) {
    if (m.z <= 0.0) return 0.0;
    float a2 = a * a;
    float s2 = m.x * m.x + m.y * m.y;
    float d = s2 + m.z * m.z * a2;
    return a2 / (PI * d * d);
}

float smith_g1(vec3 w, vec3 m, float a) {
    if (dot(w, m) * w.z <= 0.0) return 0.0;
    float tan2 = (w.x * w.x + w.y * w.y) / max(w.z * w.z, 1e-30);
    return 2.0 / (1.0 + sqrt(1.0 + a * a * tan2));
}

float fresnel_dielectric(float cos_i, float eta) {
    float c = min(abs(cos_i), 1.0);
    float s2t = (1.0 - c * c) / (eta * eta);
    if (s2t >= 1.0) return 1.0;
    float ct = sqrt(1.0 - s2t);
    float rs = (c - eta * ct) / (c + eta * ct);
    float rp = (eta * c - ct) / (eta * c + ct);
    return 0.5 * (rs * rs + rp * rp);
}

// Microfacet reflection with a given Fresnel value, both directions above.
float microfacet_reflection(vec3 wi, vec3 wo, float a, out vec3 h) {
    h = normalize(wi + wo);
    return ggx_d(h, a) * smith_g1(wi, h, a) * smith_g1(wo, h, a) / max(4.0 * wi.z * wo.z, 1e-30);
}

float dielectric_reflection(vec3 wi, vec3 wo, float a, float eta) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return 0.0;
    vec3 h;
    float dg = microfacet_reflection(wi, wo, a, h);
    return fresnel_dielectric(dot(wi, h), eta) * dg;
}
