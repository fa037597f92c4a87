// The body's environment light pre-integrated over the object's normals
// (viewer/gpu/env_prefilter.py): one RGB value per node of an octahedral map
// of world normals (its pole toward the camera, u_env_table_basis), each node the
// body's reflection of the environment toward the eye at the point of the
// object's bounding sphere with that normal -- the whole integral, baked by
// env_prefilter.comp from the lit pass's own body estimator. Exact on the sphere
// up to the map's interpolation; the lit pass reads it instead of its body
// samples (lit_shade.glsl NB_ENV_TABLE).
uniform mat3 u_env_table_basis;  // columns: the map's x, y and pole (toward the camera), world

// World direction -> octahedral map coordinates in [0, 1]^2.
vec2 env_table_uv(vec3 n) {
    vec3 d = transpose(u_env_table_basis) * n;
    d /= abs(d.x) + abs(d.y) + abs(d.z);
    vec2 p = d.xy;
    if (d.z < 0.0) p = (1.0 - abs(d.yx)) * vec2(p.x >= 0.0 ? 1.0 : -1.0, p.y >= 0.0 ? 1.0 : -1.0);
    return p * 0.5 + 0.5;
}

// Octahedral map coordinates -> world direction (unit).
vec3 env_table_dir(vec2 uv) {
    vec2 f = uv * 2.0 - 1.0;
    vec3 d = vec3(f, 1.0 - abs(f.x) - abs(f.y));
    float t = max(-d.z, 0.0);
    d.x += d.x >= 0.0 ? -t : t;
    d.y += d.y >= 0.0 ? -t : t;
    return u_env_table_basis * normalize(d);
}
