// The body of a uniform neural material from its baked table
// (neural/body_table.py): log f per RGB channel on a grid over
// (sqrt(2 theta_h / pi), 2 theta_d / pi, phi_d folded to [0, pi/2]), one
// trilinear fetch instead of a decoder evaluation. The angles are computed as
// nb_encode computes them (neural_decoder.glsl), so the table and the decoder
// see the same pair. Selected by NB_BODY_TABLE (viewer/pipeline.py BrdfKind.TABLE).
// Needs PI (common.glsl).
uniform sampler3D u_body_table;  // (N theta_h, M theta_d, K phi_d) RGB log f, nodes at texel centres

vec3 nb_table(vec3 wi, vec3 wo) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);
    vec3 h = wi + wo;
    h = h / max(length(h), 1e-12);
    float cos_d = clamp(dot(wi, h), -1.0, 1.0);
    float theta_h = atan(length(h.xy), h.z);
    float theta_d = atan(length(cross(wi, h)), cos_d);
    vec3 t = wi - cos_d * h;
    vec3 b = vec3(-h.y, h.x, 0.0);
    float bn = length(b);
    b = bn > 1e-7 ? b / max(bn, 1e-12) : vec3(0.0, 1.0, 0.0);
    float tn2 = dot(t, t);
    float ty = dot(t, b);
    float cos2 = tn2 > 1e-14 ? 1.0 - 2.0 * ty * ty / max(tn2, 1e-30) : 1.0;
    vec3 g = clamp(vec3(sqrt(theta_h * (2.0 / PI)), theta_d * (2.0 / PI), acos(clamp(cos2, -1.0, 1.0)) / PI),
                   0.0, 1.0);
    vec3 n = vec3(textureSize(u_body_table, 0));
    return exp(textureLod(u_body_table, (g * (n - 1.0) + 0.5) / n, 0.0).rgb);
}
