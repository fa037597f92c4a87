// Importance sampling helpers for the lit view: cosine-weighted hemisphere
// and GGX visible-normal reflection (Heitz 2018), with their pdfs, combined
// by the balance heuristic in object.frag.
//@INCLUDE microfacet.glsl

vec3 sample_cosine(vec2 u, out float pdf) {
    float r = sqrt(u.x), phi = 2.0 * PI * u.y;
    vec3 w = vec3(r * cos(phi), r * sin(phi), sqrt(max(0.0, 1.0 - u.x)));
    pdf = w.z / PI;
    return w;
}

float pdf_cosine(vec3 w) { return max(w.z, 0.0) / PI; }

// Heitz 2018's visible-normal sampling, stretched by (ax, ay) (an anisotropic interface; ax = ay: GGX's).
vec3 sample_vndf2(vec3 v, float ax, float ay, vec2 u) {
    vec3 vh = normalize(vec3(ax * v.x, ay * v.y, v.z));
    float lensq = vh.x * vh.x + vh.y * vh.y;
    vec3 t1 = lensq > 1e-14 ? vec3(-vh.y, vh.x, 0.0) * inversesqrt(lensq) : vec3(1.0, 0.0, 0.0);
    vec3 t2 = cross(vh, t1);
    float r = sqrt(u.x), phi = 2.0 * PI * u.y;
    float p1 = r * cos(phi), p2 = r * sin(phi);
    float s = 0.5 * (1.0 + vh.z);
    p2 = (1.0 - s) * sqrt(max(0.0, 1.0 - p1 * p1)) + s * p2;
    vec3 nh = p1 * t1 + p2 * t2 + sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2)) * vh;
    return normalize(vec3(ax * nh.x, ay * nh.y, max(1e-6, nh.z)));
}

vec3 sample_vndf(vec3 v, float a, vec2 u) { return sample_vndf2(v, a, a, u); }

float pdf_ggx_reflection(vec3 wo, vec3 wi, float a) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return 0.0;
    vec3 h = normalize(wi + wo);
    float g1 = 2.0 / (1.0 + sqrt(1.0 + a * a * (wo.x * wo.x + wo.y * wo.y) / (wo.z * wo.z)));
    return g1 * max(dot(wo, h), 0.0) * ggx_d(h, a) / wo.z / (4.0 * max(dot(wo, h), 1e-8));
}

// The learned proxy pdf (neural/sampling.py): (1 - w) an isotropic Gaussian of
// width s over the projected half vector, normalised on the unit disk, plus w a
// cosine lobe. Sampled from one direction (the view), reflected about h.
float proxy_disk_norm(float s) { return 2.0 * PI * s * s * (1.0 - exp(-0.5 / (s * s))); }

float pdf_proxy(vec3 v, vec3 l, float s, float w) {
    vec3 h = normalize(v + l);
    if (h.z < 0.0) h = -h;
    float pg = exp(-0.5 * dot(h.xy, h.xy) / (s * s)) / proxy_disk_norm(s) * h.z / (4.0 * max(abs(dot(v, h)), 1e-12));
    return (1.0 - w) * pg + w * max(l.z, 0.0) / PI;
}

vec3 sample_proxy(vec3 v, vec3 u, float s, float w) {
    float phi = 2.0 * PI * u.z;
    if (u.x < w) {
        float r = sqrt(u.y);
        return vec3(r * cos(phi), r * sin(phi), sqrt(max(0.0, 1.0 - u.y)));
    }
    float r = min(s * sqrt(-2.0 * log(1.0 - u.y * (1.0 - exp(-0.5 / (s * s))))), 1.0);
    vec3 h = vec3(r * cos(phi), r * sin(phi), sqrt(max(0.0, 1.0 - r * r)));
    return normalize(2.0 * dot(v, h) * h - v);
}
