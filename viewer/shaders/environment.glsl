// Environment lighting (viewer/environment.py): an equirectangular radiance map
// (world z up, rotated by u_env_rotation about z) importance-sampled by
// luminance x sin(theta) through a marginal CDF over rows and a conditional
// CDF per row; the pdf is exact for the piecewise-constant density.
uniform sampler2D u_env;              // W x H linear RGB radiance
uniform sampler2D u_env_marginal;     // (H + 1) x 1 CDF over rows
uniform sampler2D u_env_conditional;  // (W + 1) x H CDF per row
uniform ivec2 u_env_size;             // W, H
uniform int u_env_peaked;             // a small bright source holds much of the power (EnvironmentMap.peaked)
uniform float u_env_rotation;         // radians about world z

vec3 env_rotate(vec3 d, float a) {
    float c = cos(a), s = sin(a);
    return vec3(c * d.x - s * d.y, s * d.x + c * d.y, d.z);
}

vec2 env_uv(vec3 m) {  // map-frame direction -> (u along phi, v along theta)
    float phi = atan(m.y, m.x);
    if (phi < 0.0) phi += 2.0 * PI;
    return vec2(phi / (2.0 * PI), acos(clamp(m.z, -1.0, 1.0)) / PI);
}

vec3 env_radiance(vec3 d) {
    return texture(u_env, env_uv(env_rotate(d, -u_env_rotation))).rgb;
}

// Largest k in [0, n - 1] with cdf(k) <= u, cdf read along x of row `row`.
int env_find(sampler2D cdf, int row, int n, float u) {
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        if (texelFetch(cdf, ivec2(mid, row), 0).r <= u) lo = mid; else hi = mid - 1;
    }
    return lo;
}

float pdf_env(vec3 d) {
    vec3 m = env_rotate(d, -u_env_rotation);
    vec2 uv = env_uv(m);
    ivec2 t = clamp(ivec2(uv * vec2(u_env_size)), ivec2(0), u_env_size - 1);
    float m0 = texelFetch(u_env_marginal, ivec2(t.y, 0), 0).r, m1 = texelFetch(u_env_marginal, ivec2(t.y + 1, 0), 0).r;
    float c0 = texelFetch(u_env_conditional, ivec2(t.x, t.y), 0).r;
    float c1 = texelFetch(u_env_conditional, ivec2(t.x + 1, t.y), 0).r;
    // probability of the texel over its (du dv) area, then the solid-angle Jacobian
    float p_uv = (m1 - m0) * (c1 - c0) * float(u_env_size.x * u_env_size.y);
    return p_uv / (2.0 * PI * PI * max(sqrt(max(0.0, 1.0 - m.z * m.z)), 1e-6));
}

vec3 sample_env(vec2 u, out float pdf) {
    int h = u_env_size.y, w = u_env_size.x;
    int j = env_find(u_env_marginal, 0, h, u.y);
    float m0 = texelFetch(u_env_marginal, ivec2(j, 0), 0).r, m1 = texelFetch(u_env_marginal, ivec2(j + 1, 0), 0).r;
    int i = env_find(u_env_conditional, j, w, u.x);
    float c0 = texelFetch(u_env_conditional, ivec2(i, j), 0).r, c1 = texelFetch(u_env_conditional, ivec2(i + 1, j), 0).r;
    float fv = clamp((u.y - m0) / max(m1 - m0, 1e-12), 0.0, 1.0);
    float fu = clamp((u.x - c0) / max(c1 - c0, 1e-12), 0.0, 1.0);
    float theta = (float(j) + fv) / float(h) * PI, phi = (float(i) + fu) / float(w) * 2.0 * PI;
    vec3 m = vec3(sin(theta) * cos(phi), sin(theta) * sin(phi), cos(theta));
    pdf = (m1 - m0) * (c1 - c0) * float(w * h) / (2.0 * PI * PI * max(sin(theta), 1e-6));
    return env_rotate(m, u_env_rotation);
}
