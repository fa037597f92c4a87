// The half vector of a direction pair and its isotropic angles, shared by the
// decoder's input encoding (neural_decoder.glsl) and the baked body table
// (body_table.glsl), so both see the same pair: returns (theta_h, theta_d,
// cos(2 phi_d)), with the half vector in ``h``.
vec3 nb_half_diff(vec3 wi, vec3 wo, out vec3 h) {
    h = wi + wo;
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
    return vec3(theta_h, theta_d, cos2);
}
