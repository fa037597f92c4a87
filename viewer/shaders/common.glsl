// Shared helpers: constants, local shading frame, hashing for per-pixel random numbers.
const float PI = 3.14159265358979;

// Orthonormal basis with n as z (Duff et al. 2017).
mat3 frame_from_normal(vec3 n) {
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    float b = n.x * n.y * a;
    vec3 t = vec3(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    vec3 bt = vec3(b, s + n.y * n.y * a, -n.y);
    return mat3(t, bt, n);  // columns: tangent, bitangent, normal
}

uint pcg_hash(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Per-pixel random numbers for pass ``pass_index``: the R2 low-discrepancy
// sequence (Roberts 2018) over passes, shifted per pixel and dimension by a
// hashed offset (Cranley-Patterson rotation), so the passes of one pixel are
// stratified and neighbouring pixels decorrelated.
vec2 rand2(uvec2 pixel, uint pass_index, uint dim) {
    uint h = pcg_hash(pixel.x + pcg_hash(pixel.y + pcg_hash(dim)));
    uint h2 = pcg_hash(h);
    vec2 offset = vec2(float(h >> 8) / 16777216.0, float(h2 >> 8) / 16777216.0);
    return fract(offset + float(pass_index) * vec2(0.7548776662466927, 0.5698402909980532));
}
