// Anisotropic material codes (neural/anisotropy.py, SPEC section 10), compiled in by NB_ANISO:
// a code's tail holds the coat's and the body's anisotropy vectors v = a (cos 2 rho, sin 2 rho),
// the body's masking alpha and, per channel, the glow of a scattering medium (glow_basis). The coat is anisotropic GGX in closed form (alpha_x = alpha_0 / k,
// alpha_y = alpha_0 k, k = sqrt(1 - a), in the tangent frame turned by rho); the body is the decoder
// (or its table) at the pair turned so its half vector becomes the stretched one, times J
// (neural/anisotropy.py body_pair: D's Jacobian and ratio, the cosines, the masking ratio). Directions are in
// the shading frame, whose x is the surface's tangent (shading_frame.glsl under NB_ANISO).
// Needs PI (common.glsl).

// (k, cos rho, sin rho) of an anisotropy vector.
vec3 aniso_stretch(vec2 v) {
    float a = min(length(v), 0.95);
    if (a <= 0.0) return vec3(1.0, 1.0, 0.0);
    float t = 0.5 * atan(v.y, v.x);
    return vec3(sqrt(1.0 - a), cos(t), sin(t));
}

// Directions in the frame turned by (cos, sin) about z, and back.
vec3 aniso_turn(vec3 w, vec2 cs) { return vec3(cs.x * w.x + cs.y * w.y, cs.x * w.y - cs.y * w.x, w.z); }
vec3 aniso_unturn(vec3 w, vec2 cs) { return aniso_turn(w, vec2(cs.x, -cs.y)); }

// A half vector stretched as the body's (h' ~ (k h_x, h_y / k, h_z) in the tangent frame), or unstretched.
vec3 aniso_stretched(vec3 h, vec3 k, bool inverse) {
    float kk = inverse ? 1.0 / k.x : k.x;
    vec3 hf = aniso_turn(h, k.yz);
    return normalize(aniso_unturn(vec3(kk * hf.x, hf.y / kk, hf.z), k.yz));
}


float ggx_d_aniso(vec3 m, float ax, float ay) {
    if (m.z <= 0.0) return 0.0;
    float s = m.x * m.x / (ax * ax) + m.y * m.y / (ay * ay) + m.z * m.z;
    return 1.0 / (PI * ax * ay * s * s);
}

// Smith G1 of a direction (the visible side's test left to the caller).
float smith_g1_dir_aniso(vec3 w, float ax, float ay) {
    float t = (ax * ax * w.x * w.x + ay * ay * w.y * w.y) / max(w.z * w.z, 1e-30);
    return 2.0 / (1.0 + sqrt(1.0 + t));
}

// The anisotropic coat's frame: (alpha_x, alpha_y) of (alpha_0, ior) = c and anisotropy vector v, and the
// pair turned into its tangent frame with their half vector.
vec2 aniso_coat_frame(inout vec3 a, inout vec3 b, vec2 c, vec2 v, out vec3 h) {
    vec3 k = aniso_stretch(v);
    a = aniso_turn(a, k.yz);
    b = aniso_turn(b, k.yz);
    h = normalize(a + b);
    return vec2(c.x / k.x, c.x * k.x);
}

// The anisotropic coat's reflection (c in the legal range).
float coat_reflection_aniso(vec3 wi, vec3 wo, vec2 c, vec2 v) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return 0.0;
    vec3 h;
    vec2 al = aniso_coat_frame(wi, wo, c, v, h);
    if (dot(wi, h) <= 0.0) return 0.0;
    float g = smith_g1_dir_aniso(wi, al.x, al.y) * smith_g1_dir_aniso(wo, al.x, al.y);
    return fresnel_dielectric(dot(wi, h), c.y) * ggx_d_aniso(h, al.x, al.y) * g / max(4.0 * wi.z * wo.z, 1e-30);
}

vec3 coat_sample_aniso(vec3 w, vec2 u, vec2 c, vec2 v) {
    vec3 k = aniso_stretch(v);
    vec3 wf = aniso_turn(w, k.yz);
    vec3 m = sample_vndf2(wf, c.x / k.x, c.x * k.x, u);
    return aniso_unturn(2.0 * dot(wf, m) * m - wf, k.yz);
}

float coat_pdf_aniso(vec3 w, vec3 l, vec2 c, vec2 v) {
    if (w.z <= 0.0 || l.z <= 0.0) return 0.0;
    vec3 h;
    vec2 al = aniso_coat_frame(w, l, c, v, h);
    float g1 = smith_g1_dir_aniso(w, al.x, al.y);
    return g1 * max(dot(w, h), 0.0) * ggx_d_aniso(h, al.x, al.y) / w.z / (4.0 * max(dot(w, h), 1e-8));
}

// Directions refracted through a smooth interface of relative ior eta, in and out (neural/anisotropy.py
// _inside, _outside: a direction past the critical angle leaves grazing, at AN_LIFT_Z).
const float AN_LIFT_Z = 0.02;
const float AN_TRANSMITTANCE_CAP = 2.0;
vec3 aniso_inside(vec3 w, float eta) {
    vec2 t = w.xy / eta;
    return vec3(t, sqrt(max(1.0 - dot(t, t), 0.0)));
}
vec3 aniso_outside(vec3 w, float eta) {
    vec2 t = w.xy * eta;
    float n = length(t), most = sqrt(1.0 - AN_LIFT_Z * AN_LIFT_Z);
    if (n > most) t *= most / max(n, 1e-12);
    return vec3(t, sqrt(max(1.0 - dot(t, t), 0.0)));
}
// A direction under AN_LIFT_Z raised to it along its azimuth (_lifted).
vec3 aniso_lifted(vec3 w) {
    if (w.z >= AN_LIFT_Z) return w;
    vec2 xy = w.xy / max(length(w.xy), 1e-12);
    return vec3(xy * sqrt(1.0 - AN_LIFT_Z * AN_LIFT_Z), AN_LIFT_Z);
}
// How low the decoder is read (FLOOR_Z_BARE, FLOOR_Z_COATED): a warped direction w2 under
// min(floor, the z of its unwarped w) is raised to it along its azimuth (_floored).
const float AN_FLOOR_Z_BARE = 1.0;
const float AN_FLOOR_Z_COATED = 0.35;
vec3 aniso_floored(vec3 w2, vec3 w, float floor_z) {
    float f = min(floor_z, max(w.z, AN_LIFT_Z));
    if (w2.z >= f) return w2;
    vec2 xy = w2.xy / max(length(w2.xy), 1e-12);
    return vec3(xy * sqrt(max(1.0 - f * f, 0.0)), f);
}

// The pair turned so its half vector becomes the stretched one (warp_pair).
void aniso_warp(vec3 wi, vec3 wo, vec3 k, out vec3 wi2, out vec3 wo2, out float r) {
    vec3 h = normalize(wi + wo);
    vec3 hp = aniso_stretched(h, k, false);
    vec3 n = cross(h, hp);
    float c = dot(h, hp);
    float inv = 1.0 / max(1.0 + c, 1e-12);
    wi2 = wi * c + cross(n, wi) + n * dot(n, wi) * inv;
    wo2 = wo * c + cross(n, wo) + n * dot(n, wo) * inv;
    r = hp.z / max(h.z, 1e-12);
}

// The body's warped pair (wi2, wo2) and its factor J (neural/anisotropy.py body_pair): under a coat
// of ior coat_ior > 1 the pair is refracted in, warped there and refracted out; tail = (body vector,
// masking alpha_0).
float body_warp(vec3 wi, vec3 wo, vec3 tail, float coat_ior, out vec3 wi2, out vec3 wo2) {
    vec3 k = aniso_stretch(tail.xy);
    wi2 = wi;
    wo2 = wo;
    if (k.x >= 1.0) return 1.0;
    if (wi.z <= 0.0 || wo.z <= 0.0) return 0.0;
    float eta = max(coat_ior, 1.0);
    vec3 wi_in = aniso_inside(wi, eta), wo_in = aniso_inside(wo, eta);
    vec3 a, b;
    float r;
    aniso_warp(wi_in, wo_in, k, a, b, r);
    float floor_z = eta > 1.0 ? AN_FLOOR_Z_COATED : AN_FLOOR_Z_BARE;
    wi2 = aniso_floored(aniso_outside(aniso_lifted(a), eta), wi, floor_z);
    wo2 = aniso_floored(aniso_outside(aniso_lifted(b), eta), wo, floor_z);
    vec3 wi2_in = aniso_inside(wi2, eta), wo2_in = aniso_inside(wo2, eta);
    float a0 = clamp(tail.z, 0.005, 1.0);
    // D(h') / D(h_e): the pair read is not the warped one where a direction was lifted, clamped or raised (_d_ratio)
    float hpz = r * normalize(wi_in + wo_in).z;
    float hez = normalize(wi2_in + wo2_in).z;
    float d = (hez * hez * (a0 * a0 - 1.0) + 1.0) / (hpz * hpz * (a0 * a0 - 1.0) + 1.0);
    float j = r * r * r * r * d * d * (wi2_in.z * wo2_in.z) / max(wi_in.z * wo_in.z, 1e-12);
    float ax = a0 / k.x, ay = a0 * k.x;
    float aniso = smith_g1_dir_aniso(aniso_turn(wi_in, k.yz), ax, ay) * smith_g1_dir_aniso(aniso_turn(wo_in, k.yz), ax, ay);
    float iso = smith_g1_dir_aniso(wi2_in, a0, a0) * smith_g1_dir_aniso(wo2_in, a0, a0);
    j *= aniso / max(iso, 1e-12);
    if (eta > 1.0) {
        float t = (1.0 - fresnel_dielectric(wi.z, eta)) * (1.0 - fresnel_dielectric(wo.z, eta))
                / max((1.0 - fresnel_dielectric(wi2.z, eta)) * (1.0 - fresnel_dielectric(wo2.z, eta)), 1e-6);
        j *= min(t, AN_TRANSMITTANCE_CAP);
    }
    return j;
}

// The shape of a scattering medium's glow, added to the body unwarped (neural/anisotropy.py glow_basis,
// decision 123): t(wi) t(wo) / pi, t the coat's smooth 1 - F (1 without a coat); 0 below the horizon.
float glow_basis(vec3 wi, vec3 wo, float coat_ior) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return 0.0;
    float eta = max(coat_ior, 1.0);
    return (1.0 - fresnel_dielectric(wi.z, eta)) * (1.0 - fresnel_dielectric(wo.z, eta)) / PI;
}

// The body's proxy of an anisotropic code (neural/sampling.py with v): the Gaussian over the stretched
// half vector, times the stretch's Jacobian (h'_z / h_z)^3; the cosine lobe as it is.
float pdf_proxy_aniso(vec3 v, vec3 l, float s, float w, vec2 bv) {
    vec3 k = aniso_stretch(bv);
    vec3 h = normalize(v + l);
    if (h.z < 0.0) h = -h;
    vec3 q = aniso_stretched(h, k, false);
    float r = q.z / max(h.z, 1e-12);
    float pg = exp(-0.5 * dot(q.xy, q.xy) / (s * s)) / proxy_disk_norm(s) * q.z / (4.0 * max(abs(dot(v, h)), 1e-12));
    return (1.0 - w) * pg * r * r * r + w * max(l.z, 0.0) / PI;
}

vec3 sample_proxy_aniso(vec3 v, vec3 u, float s, float w, vec2 bv) {
    float phi = 2.0 * PI * u.z;
    if (u.x < w) {
        float r = sqrt(u.y);
        return vec3(r * cos(phi), r * sin(phi), sqrt(max(0.0, 1.0 - u.y)));
    }
    float r = min(s * sqrt(-2.0 * log(1.0 - u.y * (1.0 - exp(-0.5 / (s * s))))), 1.0);
    vec3 h = aniso_stretched(vec3(r * cos(phi), r * sin(phi), sqrt(max(0.0, 1.0 - r * r))), aniso_stretch(bv), true);
    return normalize(2.0 * dot(v, h) * h - v);
}
