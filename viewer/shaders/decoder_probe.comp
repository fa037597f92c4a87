// Decoder probe, compute version: weights from a buffer or compiled in (OpenGL
// 4.3). NB_PAIRS 2: each invocation decodes two consecutive pairs with
// nb_decode2 (one weight fetch feeds both); 1: one pair with nb_decode.
//@INCLUDE common.glsl
//@INCLUDE neural_decoder.glsl
#ifndef NB_PAIRS
#define NB_PAIRS 1
#endif
layout(local_size_x = 64) in;
layout(std430, binding = 1) readonly buffer Pairs { vec4 pairs[]; };  // wi, wo as xyz_
layout(std430, binding = 2) writeonly buffer Values { vec4 values[]; };
uniform int u_count;
void main() {
    int k = NB_PAIRS * int(gl_GlobalInvocationID.x);
    if (k >= u_count) return;
#if NB_PAIRS == 2
    int k1 = min(k + 1, u_count - 1);
    vec3 f0, f1;
    nb_decode2(pairs[2 * k].xyz, pairs[2 * k + 1].xyz, pairs[2 * k1].xyz, pairs[2 * k1 + 1].xyz, f0, f1);
    values[k] = vec4(f0, 1.0);
    if (k + 1 < u_count) values[k + 1] = vec4(f1, 1.0);
#else
    values[k] = vec4(nb_decode(pairs[2 * k].xyz, pairs[2 * k + 1].xyz), 1.0);
#endif
}
