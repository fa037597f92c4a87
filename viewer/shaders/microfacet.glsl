// GGX microfacet distribution and separable Smith masking (SPEC section 5).

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
