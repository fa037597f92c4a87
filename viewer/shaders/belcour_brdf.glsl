// Belcour 2018, "Efficient rendering of layered materials using an atomic
// decomposition with statistical operators": the analytic layered model of
// training/belcour.py (method ``belcour``, statistics at wi as in the paper),
// line for line, tested against it in tests/viewer/test_belcour_glsl.py.
//
// The stack comes as atoms, top to bottom (u_bc_kind: BC_INTERFACE, BC_MEDIUM,
// BC_CONDUCTOR, BC_DIELECTRIC or BC_DIFFUSE, constants the code fills in), and
// the project's tables as textures: u_bc_dielectric (mu, alpha, eta) holds
// R_down, T_down, R_up, T_up; u_bc_schlick (mu, alpha) the conductor's terms
// A, B, C (FGD = r0 A + (1 - r0) B - b C, b OpenPBR's F82-tint coefficient). Lookups interpolate by hand between texel fetches, as the
// Python's grid_sample (align_corners) does, at float precision whatever the
// GPU's filtering hardware. What depends on the material alone -- each diffuse
// slab's hemispherical reflectances above and below and its ior -- is computed
// by the Python (viewer/belcour_gpu.py) and comes as uniforms.
//
// Directions are in the local frame (z = normal); wi to the light, wo to the
// viewer; the value excludes every cosine.

//@INCLUDE belcour_kinds
uniform int u_bc_n;                        // atoms in use
uniform int u_bc_kind[BC_MAX_ATOMS];
uniform float u_bc_roughness[BC_MAX_ATOMS];
uniform float u_bc_ior[BC_MAX_ATOMS];      // relative ior below over above (interfaces, dielectric base)
uniform vec3 u_bc_color[BC_MAX_ATOMS];     // r0 (conductor) or albedo (medium, diffuse)
uniform vec3 u_bc_sigma_t[BC_MAX_ATOMS];   // optical depth along the normal per channel (medium)
uniform vec3 u_bc_f82[BC_MAX_ATOMS];       // OpenPBR's F82-tint coefficient b (conductor; 0: Schlick)
uniform int u_bc_slab[BC_MAX_ATOMS];       // 1: the atom is a diffuse slab (a scattering medium, the diffuse base)
uniform vec3 u_bc_r_above[BC_MAX_ATOMS];   // a slab's hemispherical reflectance of the stack above it
uniform vec3 u_bc_r_below[BC_MAX_ATOMS];   // ... of it and the stack below it
uniform float u_bc_eta[BC_MAX_ATOMS];      // a slab's absolute ior
uniform float u_bc_sample_w[BC_MAX_ATOMS];      // the lobe strategy's mixture weights (see sample_lobe)
uniform float u_bc_sample_alpha[BC_MAX_ATOMS];  // ... and roughnesses
uniform float u_bc_body_w[BC_MAX_ATOMS];   // the same mixture without the coat's lobe (all 0: no lobe left)
uniform vec2 u_bc_coat;  // the top interface's (roughness, ior) when it is a coat, estimated apart; ior 1: none
uniform sampler3D u_bc_dielectric;
uniform sampler2D u_bc_schlick;

//@INCLUDE microfacet.glsl

const float BC_ALPHA_MIN = 0.01;
const float BC_ALPHA_MAX = 0.999;

float bc_r2v(float a) {
    float p = pow(clamp(a, 0.0, BC_ALPHA_MAX), 1.1);
    return p / (1.0 - p);
}

float bc_v2r(float s) {
    s = max(s, 0.0);
    return pow(s / (1.0 + s), 1.0 / 1.1);
}

vec3 bc_div(vec3 a, vec3 b) {
    return vec3(b.x > 0.0 ? a.x / b.x : 0.0, b.y > 0.0 ? a.y / b.y : 0.0, b.z > 0.0 ? a.z / b.z : 0.0);
}

float bc_div(float a, float b) { return b > 0.0 ? a / b : 0.0; }

float bc_mean(vec3 v) { return (v.x + v.y + v.z) / 3.0; }

// Continuous texel coordinates of the table axes (uniform in sqrt(mu),
// sqrt(alpha) over [0.01, 1] and eta over [1, 2]; nodes at the ends).
float bc_cmu(float mu, int n) { return sqrt(clamp(mu, 0.0, 1.0)) * float(n - 1); }
float bc_calpha(float a, int n) {
    return (sqrt(clamp(a, BC_ALPHA_MIN, 1.0)) - 0.1) / 0.9 * float(n - 1);
}
float bc_ceta(float eta, int n) { return (clamp(eta, 1.0, 2.0) - 1.0) * float(n - 1); }

// Lower node and weight of a continuous coordinate x in [0, n - 1].
int bc_node(float x, int n, out float t) {
    int i = min(int(floor(x)), n - 2);
    t = x - float(i);
    return i;
}

// Trilinear lookup of the dielectric table: (R_down, T_down, R_up, T_up).
vec4 bc_dielectric(float mu, float a, float eta) {
    ivec3 n = textureSize(u_bc_dielectric, 0);
    vec3 t;
    ivec3 i = ivec3(bc_node(bc_cmu(mu, n.x), n.x, t.x), bc_node(bc_calpha(a, n.y), n.y, t.y),
                    bc_node(bc_ceta(eta, n.z), n.z, t.z));
    vec4 c00 = mix(texelFetch(u_bc_dielectric, i, 0), texelFetch(u_bc_dielectric, i + ivec3(1, 0, 0), 0), t.x);
    vec4 c10 = mix(texelFetch(u_bc_dielectric, i + ivec3(0, 1, 0), 0),
                   texelFetch(u_bc_dielectric, i + ivec3(1, 1, 0), 0), t.x);
    vec4 c01 = mix(texelFetch(u_bc_dielectric, i + ivec3(0, 0, 1), 0),
                   texelFetch(u_bc_dielectric, i + ivec3(1, 0, 1), 0), t.x);
    vec4 c11 = mix(texelFetch(u_bc_dielectric, i + ivec3(0, 1, 1), 0),
                   texelFetch(u_bc_dielectric, i + ivec3(1, 1, 1), 0), t.x);
    return mix(mix(c00, c10, t.y), mix(c01, c11, t.y), t.z);
}

// Bilinear lookup of the conductor's table: (A, B, C).
vec3 bc_schlick(float mu, float a) {
    ivec2 n = textureSize(u_bc_schlick, 0);
    vec2 t;
    ivec2 i = ivec2(bc_node(bc_cmu(mu, n.x), n.x, t.x), bc_node(bc_calpha(a, n.y), n.y, t.y));
    vec3 c0 = mix(texelFetch(u_bc_schlick, i, 0).xyz, texelFetch(u_bc_schlick, i + ivec2(1, 0), 0).xyz, t.x);
    vec3 c1 = mix(texelFetch(u_bc_schlick, i + ivec2(0, 1), 0).xyz,
                  texelFetch(u_bc_schlick, i + ivec2(1, 1), 0).xyz, t.x);
    return mix(c0, c1, t.y);
}

vec3 bc_conductor_albedo(float mu, float a, vec3 r0, vec3 b) {
    vec3 abc = bc_schlick(mu, a);
    return max(r0 * abc.x + (1.0 - r0) * abc.y - b * abc.z, 0.0);
}

// What atom k does to a lobe arriving at cosine cti.
struct BcStats {
    float ctt;
    vec3 R12, T12, R21, T21;
    float s_r12, s_t12, s_r21, s_t21, j12, j21;
};

BcStats bc_atom_stats(int k, float cti) {
    BcStats s;
    s.ctt = cti;
    s.R12 = s.T12 = s.R21 = s.T21 = vec3(0.0);
    s.s_r12 = s.s_t12 = s.s_r21 = s.s_t21 = 0.0;
    s.j12 = s.j21 = 1.0;
    int kind = u_bc_kind[k];
    float a = u_bc_roughness[k];
    float eta = u_bc_ior[k];
    if (kind == BC_INTERFACE) {
        float ctt = sqrt(clamp(1.0 - (1.0 - cti * cti) / (eta * eta), 1e-8, 1.0));
        vec4 down = bc_dielectric(cti, a, eta);
        vec4 up = bc_dielectric(ctt, a, eta);
        s.ctt = ctt;
        s.R12 = vec3(down.x);
        s.T12 = vec3(down.y);
        s.R21 = vec3(up.z);
        s.T21 = vec3(up.w);
        s.s_r12 = s.s_r21 = bc_r2v(a);
        // the paper's transmitted-roughness scaling through the ior ratio
        s.s_t12 = bc_r2v(a * 0.5 * abs(ctt * eta - cti) / (ctt * eta));
        s.s_t21 = bc_r2v(a * 0.5 * abs(cti / eta - ctt) / max(cti / eta, 1e-8));
        s.j12 = ctt * eta / max(cti, 1e-8);
        s.j21 = cti / (ctt * eta);
    } else if (kind == BC_MEDIUM) {  // Beer-Lambert along the mean
        s.T12 = s.T21 = exp(-u_bc_sigma_t[k] / max(cti, 1e-8));
    } else {  // a reflecting base
        s.R12 = kind == BC_CONDUCTOR ? bc_conductor_albedo(cti, a, u_bc_color[k], u_bc_f82[k])
                                     : vec3(bc_dielectric(cti, a, eta).x);
        s.s_r12 = s.s_r21 = bc_r2v(a);
    }
    return s;
}

// The statistics of the stack lit from cosine mu: per reflecting atom its
// lobe's energy and roughness, per diffuse slab the energy of the mean chain
// arriving at its top and the chain's cosine inside it.
vec3 bc_lobe_energy[BC_MAX_ATOMS];
float bc_lobe_alpha[BC_MAX_ATOMS];
vec3 bc_slab_T[BC_MAX_ATOMS];
float bc_slab_mu[BC_MAX_ATOMS];

void bc_decompose(float mu) {
    float cti = clamp(mu, 1e-4, 1.0);
    vec3 R0i = vec3(0.0), Ri0 = vec3(0.0), T0i = vec3(1.0), Ti0 = vec3(1.0);
    float s_ri0 = 0.0, s_t0i = 0.0, s_ti0 = 0.0, j0i = 1.0, ji0 = 1.0;
    for (int k = 0; k < BC_MAX_ATOMS; ++k) {
        bc_lobe_energy[k] = vec3(0.0);
        bc_lobe_alpha[k] = 1.0;
        bc_slab_T[k] = vec3(0.0);
        bc_slab_mu[k] = 1.0;
    }
    for (int k = 0; k < u_bc_n; ++k) {
        if (u_bc_slab[k] != 0) {
            bc_slab_T[k] = T0i;
            bc_slab_mu[k] = cti;
        }
        if (u_bc_kind[k] == BC_DIFFUSE) break;
        BcStats st = bc_atom_stats(k, cti);
        vec3 denom = 1.0 - Ri0 * st.R12;
        vec3 m_R0i = bc_div(T0i * st.R12 * Ti0, denom);
        vec3 m_Ri0 = bc_div(st.T21 * Ri0 * st.T12, denom);
        float m_rr = bc_mean(bc_div(Ri0 * st.R12, denom));
        // the variance of the lobe this atom reflects: down through the stack, reflect, back up
        float s_r0m = s_ti0 + j0i * (s_t0i + st.s_r12 + m_rr * (st.s_r12 + s_ri0));
        bc_lobe_energy[k] = m_R0i;
        bc_lobe_alpha[k] = clamp(bc_v2r(s_r0m), BC_ALPHA_MIN, 1.0);
        vec3 e_Ri0 = st.R21 + m_Ri0;
        float s_rim = st.s_t12 + st.j12 * (st.s_t21 + s_ri0 + m_rr * (st.s_r12 + s_ri0));
        float new_s_ri0 = bc_div(bc_mean(st.R21) * st.s_r21 + bc_mean(m_Ri0) * s_rim, bc_mean(e_Ri0));
        float new_s_t0i = st.j12 * s_t0i + st.s_t12 + st.j12 * (st.s_r12 + s_ri0) * m_rr;
        float new_s_ti0 = ji0 * st.s_t21 + s_ti0 + ji0 * (st.s_r12 + s_ri0) * m_rr;
        R0i += m_R0i;
        T0i = bc_div(T0i * st.T12, denom);
        Ri0 = e_Ri0;
        Ti0 = bc_div(st.T21 * Ti0, denom);
        s_ri0 = new_s_ri0;
        s_t0i = new_s_t0i;
        s_ti0 = new_s_ti0;
        j0i *= st.j12;
        ji0 *= st.j21;
        cti = st.ctt;
    }
}

// What a medium scatters out of a lobe crossing it at cosine mu and that
// escapes the slab (Hapke's multiple-scattering albedo of isotropic scatterers).
vec3 bc_scattered(int k, float mu) {
    vec3 g = sqrt(1.0 - u_bc_color[k]);
    return (1.0 - g) / (1.0 + g) * (1.0 - exp(-u_bc_sigma_t[k] / max(mu, 1e-8)));
}

// Atom k's own microfacet reflection at roughness a (its Fresnel at the outer
// half vector, GGX D, Smith G) over its directional albedo at wi.
vec3 bc_lobe_shape(int k, vec3 wi, vec3 wo, float a) {
    vec3 h;
    float dg = microfacet_reflection(wi, wo, a, h);
    float cos_h = dot(wi, h);
    int kind = u_bc_kind[k];
    if (kind == BC_CONDUCTOR) {
        vec3 r0 = u_bc_color[k], b = u_bc_f82[k];
        float c = min(abs(cos_h), 1.0), m = 1.0 - c;
        vec3 F = clamp(r0 + (1.0 - r0) * pow(m, 5.0) - b * (c * pow(m, 6.0)), 0.0, 1.0);  // F82 tint
        return bc_div(F * dg, bc_conductor_albedo(wi.z, a, r0, b));
    }
    float eta = u_bc_ior[k];
    return vec3(bc_div(fresnel_dielectric(cos_h, eta) * dg, bc_dielectric(wi.z, a, eta).x));
}

// wo's chain: the energy that reaches each slab along it (the diffuse light's
// exit), kept for the wo it was made for (a pixel's evaluations share their wo).
float bc_exit_mu = -1.0;
vec3 bc_exit_T[BC_MAX_ATOMS];

// The model's value with the reflecting atoms' lobes from ``first_lobe`` on
// (0: the whole BRDF; 1: without the top interface's lobe, the coat).
vec3 bc_eval(vec3 wi, vec3 wo, int first_lobe) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);
    if (wo.z != bc_exit_mu) {
        bc_decompose(wo.z);
        for (int k = 0; k < BC_MAX_ATOMS; ++k) bc_exit_T[k] = bc_slab_T[k];
        bc_exit_mu = wo.z;
    }
    bc_decompose(wi.z);
    vec3 f = vec3(0.0);
    for (int k = 0; k < u_bc_n; ++k) {
        if (u_bc_slab[k] != 0) {
            vec3 up;
            if (u_bc_kind[k] == BC_DIFFUSE) {
                up = bc_slab_T[k] * u_bc_color[k];
            } else {
                up = 0.5 * bc_slab_T[k] * bc_scattered(k, bc_slab_mu[k]) * (1.0 + u_bc_r_below[k]);
            }
            vec3 series = 1.0 / (1.0 - u_bc_r_above[k] * u_bc_r_below[k]);
            f += up * series * bc_exit_T[k] / (PI * u_bc_eta[k] * u_bc_eta[k]);
        }
        int kind = u_bc_kind[k];
        if (k >= first_lobe && (kind == BC_INTERFACE || kind == BC_CONDUCTOR || kind == BC_DIELECTRIC))
            f += bc_lobe_energy[k] * bc_lobe_shape(k, wi, wo, bc_lobe_alpha[k]);
    }
    return f;
}

vec3 brdf(vec3 wi, vec3 wo) { return bc_eval(wi, wo, 0); }

// The split for the lit pass (lit_shade.glsl): where the top atom is a coat
// (an interface over more stack), its lobe -- the interface's own GGX
// reflection, energy R12 times shape F D G / R12 -- is the closed-form coat
// (coat.glsl) and is estimated apart with its visible normals; the body is
// the rest, sampled by the mixture of the other lobes.
//@INCLUDE coat.glsl
#define NB_SPLIT_COAT 1
vec2 coat_code() { return u_bc_coat; }
vec3 body_brdf(vec3 wi, vec3 wo) { return bc_eval(wi, wo, u_bc_coat.y > 1.0 ? 1 : 0); }

// The lit view's lobe strategy: a mixture of GGX visible-normal reflections,
// one per lobe at its roughness at normal incidence, weighted by its energy
// there (u_bc_sample_w sums to 1); the environment and cosine strategies take
// the diffuse slabs by MIS. The body's (the split's) is the same mixture
// without the coat's lobe (u_bc_body_w); with no lobe left (a coat over a
// diffuse base), the cosine lobe.
//@INCLUDE sampling.glsl
vec3 bc_sample_mixture(vec3 wo, vec3 u, float w[BC_MAX_ATOMS]) {
    int pick = -1;
    float acc = 0.0;
    for (int k = 0; k < u_bc_n; ++k) {
        if (w[k] <= 0.0) continue;
        pick = k;
        acc += w[k];
        if (u.z < acc) break;
    }
    if (pick < 0) {
        float unused;
        return sample_cosine(u.xy, unused);
    }
    return reflect(-wo, sample_vndf(wo, u_bc_sample_alpha[pick], u.xy));
}

float bc_pdf_mixture(vec3 wo, vec3 wi, float w[BC_MAX_ATOMS]) {
    float p = 0.0, total = 0.0;
    for (int k = 0; k < u_bc_n; ++k) {
        if (w[k] <= 0.0) continue;
        total += w[k];
        p += w[k] * pdf_ggx_reflection(wo, wi, u_bc_sample_alpha[k]);
    }
    return total > 0.0 ? p : pdf_cosine(wi);
}

vec3 sample_lobe(vec3 wo, vec3 u) { return bc_sample_mixture(wo, u, u_bc_sample_w); }
float pdf_lobe(vec3 wo, vec3 wi) { return bc_pdf_mixture(wo, wi, u_bc_sample_w); }
vec3 sample_body(vec3 wo, vec3 u) { return bc_sample_mixture(wo, u, u_bc_body_w); }
float pdf_body(vec3 wo, vec3 wi) { return bc_pdf_mixture(wo, wi, u_bc_body_w); }
