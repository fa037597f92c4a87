// Decoder probe, compute version: weights from an SSBO (OpenGL 4.3).
//@INCLUDE common.glsl
//@INCLUDE neural_decoder.glsl
layout(local_size_x = 64) in;
layout(std430, binding = 1) readonly buffer Pairs { vec4 pairs[]; };  // wi, wo as xyz_
layout(std430, binding = 2) writeonly buffer Values { vec4 values[]; };
uniform int u_count;
void main() {
    int k = int(gl_GlobalInvocationID.x);
    if (k >= u_count) return;
    values[k] = vec4(nb_decode(pairs[2 * k].xyz, pairs[2 * k + 1].xyz), 1.0);
}
