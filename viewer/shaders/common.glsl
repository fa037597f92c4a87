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

// The frame of n whose tangent is turned by psi from frame_from_normal(n)'s: columns tangent,
// bitangent = normal x tangent (SPEC section 10), normal (an anisotropic material's shading frame).
mat3 tangent_frame(vec3 n, float psi) {
    mat3 f = frame_from_normal(n);
    vec3 t = cos(psi) * f[0] + sin(psi) * f[1];
    return mat3(t, cross(n, t), n);
}

uint pcg_hash(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Per-pixel random numbers of the lit pass: Owen-scrambled Sobol points per
// pixel (Burley 2020, "Practical Hash-based Owen Scrambling"), sample ``index``
// = the pass (or pass x samples + j). Each ``dim_set`` (one sampling strategy)
// gets its own 2-D Sobol point with the index shuffled and both dimensions
// scrambled by hashes of (pixel, dim_set, seed): the first 2^m samples of one
// strategy form a (0, m, 2)-net (every 2^a x 2^b stratum of area 2^-m holds one
// point), independently randomised per strategy, pixel and seed; a third number
// pads from a separately shuffled, scrambled van der Corput sequence. Stratified
// passes converge faster than 1/sqrt(N) on the smooth parts of the integrand
// (the old per-pixel R2 sequence drew every dimension with the same generator,
// so a strategy's dimensions were correlated across passes). No loops: llvmpipe
// stops a shader's loops after 65535 iterations in all (Mesa's loop limiter).
uint reverse_bits(uint x) {  // bitfieldReverse needs GLSL 4.00; the fragment path is 3.30
    x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
    x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
    x = ((x >> 4) & 0x0F0F0F0Fu) | ((x & 0x0F0F0F0Fu) << 4);
    x = ((x >> 8) & 0x00FF00FFu) | ((x & 0x00FF00FFu) << 8);
    return (x >> 16) | (x << 16);
}

// Laine-Karras style hash (constants of N. Vegdahl's "better LK hash"): each
// output bit depends on the input bits below it only, so applied to bit-
// reversed values it is a nested uniform (Owen) scramble.
uint lk_hash(uint x, uint seed) {
    x ^= x * 0x3d20adeau;
    x += seed;
    x *= (seed >> 16) | 1u;
    x ^= x * 0x05526c56u;
    x ^= x * 0x53a22864u;
    return x;
}

uint owen_scramble(uint x, uint seed) { return reverse_bits(lk_hash(reverse_bits(x), seed)); }

// Sobol dimensions 0 (van der Corput) and 1 (the Pascal matrix mod 2) of ``i``:
// digit d of dimension 1 is the XOR of the index's digits k whose bits contain
// d's (Lucas), a superset transform done in five shift-mask steps.
uvec2 sobol2(uint i) {
    uint x = reverse_bits(i), y = x;
    y ^= (y << 1) & 0xAAAAAAAAu;
    y ^= (y << 2) & 0xCCCCCCCCu;
    y ^= (y << 4) & 0xF0F0F0F0u;
    y ^= (y << 8) & 0xFF00FF00u;
    y ^= (y << 16) & 0xFFFF0000u;
    return uvec2(x, y);
}

// Three uniforms in [0, 1) for sample ``index`` of strategy ``dim_set`` at ``pixel``;
// ``seed`` 0 is the default image, other seeds independent renders (viewer/noise.py).
vec3 rand3(uvec2 pixel, uint index, uint dim_set, uint seed) {
    uint h = pcg_hash(pixel.x + pcg_hash(pixel.y + pcg_hash(dim_set + pcg_hash(seed))));
    uvec2 x = sobol2(owen_scramble(index, h));
    uint z = reverse_bits(owen_scramble(index, pcg_hash(h + 4u)));
    uvec3 r = uvec3(owen_scramble(x.x, pcg_hash(h + 1u)), owen_scramble(x.y, pcg_hash(h + 2u)),
                    owen_scramble(z, pcg_hash(h + 3u)));
    return vec3(r >> 8u) * (1.0 / 16777216.0);
}
