// The body of a uniform neural material from its baked table
// (neural/body_table.py): log f per RGB channel on a grid over
// (sqrt(2 theta_h / pi), 2 theta_d / pi, phi_d folded to [0, pi/2]), one
// trilinear fetch instead of a decoder evaluation. The angles come from
// nb_half_diff (half_diff.glsl), as the decoder's, so the table and the decoder
// see the same pair. Selected by NB_BODY_TABLE (viewer/pipeline.py BrdfKind.TABLE).
// u_body_table_ordered 1: a non-reciprocal body (Belcour's model), phi_d over
// [0, pi] measured from the half vector's tilt away from the normal, so
// swapping wi and wo (phi_d + pi) reads another node. Needs PI (common.glsl).
//@INCLUDE half_diff.glsl
uniform sampler3D u_body_table;  // (N theta_h, M theta_d, K phi_d) RGB log f, nodes at texel centres
uniform int u_body_table_ordered;  // 1: phi_d over [0, pi] (wi's side kept), 0: folded to [0, pi/2]

// cos(phi_d) of wi about the half vector h, from the tilt of h away from the
// normal (neural/body_table.py table_directions' x axis; any axis at h = z).
float nb_cos_phi_d(vec3 wi, vec3 h) {
    vec3 t = wi - dot(wi, h) * h;
    vec3 ex = h.z * h - vec3(0.0, 0.0, 1.0);
    float en = length(ex);
    ex = en > 1e-7 ? ex / en : vec3(1.0, 0.0, 0.0);
    float tn = length(t);
    return tn > 1e-7 ? dot(t, ex) / tn : 1.0;
}

vec3 nb_table(vec3 wi, vec3 wo) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);
    vec3 h;
    vec3 a = nb_half_diff(wi, wo, h);  // theta_h, theta_d, cos(2 phi_d)
    float c = u_body_table_ordered != 0 ? nb_cos_phi_d(wi, h) : a.z;
    vec3 g = clamp(vec3(sqrt(a.x * (2.0 / PI)), a.y * (2.0 / PI), acos(clamp(c, -1.0, 1.0)) / PI), 0.0, 1.0);
    vec3 n = vec3(textureSize(u_body_table, 0));
    return exp(textureLod(u_body_table, (g * (n - 1.0) + 0.5) / n, 0.0).rgb);
}
