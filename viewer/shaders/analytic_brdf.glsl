// Closed-form BRDFs (SPEC section 5) and, for layered stacks, the analytic
// layering approximation of training/analytic_layering.py (the same model,
// tested against it in tests/viewer/test_analytic_glsl.py): each interface's
// rough reflection plus what lies below seen along the smoothly refracted
// directions, scaled by the Fresnel transmittances in and out, the 1 / eta^2
// of the solid-angle compression and the slab's extinction along both
// refracted paths. Scattering in the media and inter-reflections are ignored.
// It is a baseline for comparison, not the ground truth.
//
// Directions are in the local frame (z = normal); wi to the light, wo to the
// viewer; the value excludes every cosine.

const int MAX_INTERFACES = 2;
uniform int u_num_interfaces;                 // interfaces above the base
uniform float u_if_roughness[MAX_INTERFACES];
uniform float u_if_ior[MAX_INTERFACES];      // relative IOR (below / above)
uniform vec3 u_med_sigma_t[MAX_INTERFACES];    // per channel (a coloured absorbing coat)
uniform int u_base_type;                      // BASE_CONDUCTOR, BASE_DIFFUSE or BASE_DIELECTRIC (reflection only)
uniform float u_base_roughness;
uniform float u_base_ior;
uniform vec3 u_base_color;                    // conductor r0 or diffuse albedo
uniform vec3 u_base_f82;                      // conductor: OpenPBR's F82-tint coefficient b (0: Schlick)

//@INCLUDE microfacet.glsl

// OpenPBR's F82-tint conductor Fresnel: Schlick minus b cos (1 - cos)^6 (neural/microfacet.py fresnel_f82).
vec3 fresnel_f82(float cos_i, vec3 r0, vec3 b) {
    float c = min(abs(cos_i), 1.0);
    float m = 1.0 - c;
    float m5 = m * m * m * m * m;
    return clamp(r0 + (1.0 - r0) * m5 - b * (c * m5 * m), 0.0, 1.0);
}

vec3 conductor_brdf(vec3 wi, vec3 wo, float a, vec3 r0, vec3 b) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);
    vec3 h;
    float dg = microfacet_reflection(wi, wo, a, h);
    return fresnel_f82(dot(wi, h), r0, b) * dg;
}

vec3 base_brdf(vec3 wi, vec3 wo) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);
    if (u_base_type == BASE_CONDUCTOR) return conductor_brdf(wi, wo, u_base_roughness, u_base_color, u_base_f82);
    if (u_base_type == BASE_DIFFUSE) return u_base_color / PI;
    return vec3(dielectric_reflection(wi, wo, u_base_roughness, u_base_ior));
}

// Direction refracted into the layer below a smooth interface (pointing away, upward).
vec3 refract_up(vec3 w, float eta) {
    vec2 xy = w.xy / eta;
    return vec3(xy, sqrt(max(1.0 - dot(xy, xy), 1e-12)));
}

vec3 brdf(vec3 wi, vec3 wo) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);
    // Directions inside every slab, top down.
    vec3 di[MAX_INTERFACES + 1];
    vec3 dout[MAX_INTERFACES + 1];
    di[0] = wi;
    dout[0] = wo;
    for (int k = 0; k < MAX_INTERFACES; ++k) {
        if (k < u_num_interfaces) {
            di[k + 1] = refract_up(di[k], u_if_ior[k]);
            dout[k + 1] = refract_up(dout[k], u_if_ior[k]);
        }
    }
    // Bottom up: base, then each slab and interface above it.
    vec3 f = base_brdf(di[u_num_interfaces], dout[u_num_interfaces]);
    for (int k = MAX_INTERFACES - 1; k >= 0; --k) {
        if (k >= u_num_interfaces) continue;
        vec3 a = di[k + 1], b = dout[k + 1];
        vec3 tau = u_med_sigma_t[k];
        float path = 1.0 / a.z + 1.0 / b.z;
        float eta = u_if_ior[k];
        float ti = 1.0 - fresnel_dielectric(di[k].z, eta);
        float to = 1.0 - fresnel_dielectric(dout[k].z, eta);
        f = vec3(dielectric_reflection(di[k], dout[k], u_if_roughness[k], eta))
            + (ti * to * exp(-tau * path) / (eta * eta)) * f;
    }
    return f;
}

// Roughness of the sharpest lobe a shader should importance-sample: the top
// interface's, or the base's for a single layer.
float lobe_roughness() {
    if (u_num_interfaces > 0) return u_if_roughness[0];
    return u_base_type == BASE_DIFFUSE ? 1.0 : u_base_roughness;
}

// The lit view's lobe strategy: GGX visible normals of that roughness.
//@INCLUDE sampling.glsl
vec3 sample_lobe(vec3 wo, vec3 u) { return reflect(-wo, sample_vndf(wo, lobe_roughness(), u.xy)); }
float pdf_lobe(vec3 wo, vec3 wi) { return pdf_ggx_reflection(wo, wi, lobe_roughness()); }
