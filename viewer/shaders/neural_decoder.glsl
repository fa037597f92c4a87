// The shared neural BRDF decoder (SPEC sections 6 and 7), one pixel, RGB.
//
// Sizes and offsets arrive as #defines generated from the architecture
// (neural/gpu_pack.py), so every loop below has constant bounds and unrolls.
// The three colour channels run together as vec3 lanes: each weight is
// fetched once per pixel and used for R, G and B.
//
// Needs: PI (common.glsl); NB_WIDTH, NB_WIDTH4, NB_DEPTH, NB_FEATS4, NB_ACT,
// NB_ENCODING (and for lobes11 NB_LOBE_IOR, NB_LOBE_A0..2),
// NB_TEX_W, NB_STORAGE, NB_COUNT, NB_OFF_OUT, NB_UNROLLED; the chain of hidden
// layers (snippet nb_layers) or, unrolled, the whole network (snippet nb_net,
// straight-line code from neural/gpu_pack.py); and NB_SHARE(j), the latent's
// share of layer 1 for unit j (default: the uniform array of a uniform material).
// The loop forms also define nb_decode2 (two pairs per call: snippets
// nb_hidden2 and nb_chain2).
//
// Weight storage (NB_STORAGE): 0 a float texture (OpenGL 3.3, per-pixel
// fetches), 1 an SSBO, 2 a uniform buffer (every pixel reads the same weight:
// a broadcast), 3 literals compiled into the unrolled network (no reads at all).

#if NB_STORAGE == 1
layout(std430, binding = 0) readonly buffer NbWeights { vec4 nb_w[]; };
vec4 nb_fetch(int i) { return nb_w[i]; }
#elif NB_STORAGE == 2
layout(std140, binding = 0) uniform NbWeightsU { vec4 nb_u[NB_COUNT]; };
vec4 nb_fetch(int i) { return nb_u[i]; }
#elif NB_STORAGE == 0
uniform sampler2D u_nb_weights;
vec4 nb_fetch(int i) { return texelFetch(u_nb_weights, ivec2(i % NB_TEX_W, i / NB_TEX_W), 0); }
#endif

#ifndef NB_SHARE
uniform vec3 u_nb_share[NB_WIDTH];  // W1[:, :32] z + b1 per unit, channels RGB
#define NB_SHARE(j) u_nb_share[j]
#endif

vec3 nb_act(vec3 v) {
#if NB_ACT == 0
    return max(v, vec3(0.0));
#else
    return v / (1.0 + exp(-v));
#endif
}

// Direction features, as neural/decoder.py encode(): sqrt(2 theta_h / pi),
// 2 theta_d / pi, cos(2 phi_d), cos_i cos_o, (cos_i + cos_o) / 2 (rusink5,
// NB_ENCODING 0); lobes11 (NB_ENCODING 1) adds bumps 1 / (1 + tan^2 / a^2) of
// the half vector and of the half vector of the directions refracted into ior
// NB_LOBE_IOR, for a in NB_LOBE_A0..2.
#if NB_ENCODING == 1
float nb_bump(vec3 h, float a) {
    float c2 = a * a * h.z * h.z;
    return c2 / max(c2 + dot(h.xy, h.xy), 1e-30);
}
vec3 nb_inside(vec3 w) {
    vec2 t = w.xy * (1.0 / NB_LOBE_IOR);
    return vec3(t, sqrt(max(1.0 - dot(t, t), 0.0)));
}
#endif

//@INCLUDE half_diff.glsl

void nb_encode(vec3 wi, vec3 wo, out vec4 e[NB_FEATS4]) {
    vec3 h;
    vec3 a = nb_half_diff(wi, wo, h);  // theta_h, theta_d, cos(2 phi_d)
    e[0] = vec4(sqrt(a.x * (2.0 / PI)), a.y * (2.0 / PI), a.z, wi.z * wo.z);
#if NB_ENCODING == 1
    vec3 hi = nb_inside(wi) + nb_inside(wo);
    hi = hi / max(length(hi), 1e-12);
    e[1] = vec4(0.5 * (wi.z + wo.z), nb_bump(h, NB_LOBE_A0), nb_bump(h, NB_LOBE_A1), nb_bump(h, NB_LOBE_A2));
    e[2] = vec4(nb_bump(hi, NB_LOBE_A0), nb_bump(hi, NB_LOBE_A1), nb_bump(hi, NB_LOBE_A2), 0.0);
#else
    e[1] = vec4(0.5 * (wi.z + wo.z), 0.0, 0.0, 0.0);
#endif
}

#if !NB_UNROLLED
// One hidden layer after the first: y = act(W x + b).
void nb_hidden(in vec3 x[NB_WIDTH], out vec3 y[NB_WIDTH], int off) {
    for (int o = 0; o < NB_WIDTH; ++o) {
        vec3 s = vec3(nb_fetch(off + NB_WIDTH * NB_WIDTH4 + o / 4)[o % 4]);
        for (int k = 0; k < NB_WIDTH4; ++k) {
            vec4 w = nb_fetch(off + o * NB_WIDTH4 + k);
            s += w.x * x[4 * k] + w.y * x[4 * k + 1] + w.z * x[4 * k + 2] + w.w * x[4 * k + 3];
        }
        y[o] = nb_act(s);
    }
}
#endif

#if !NB_UNROLLED
//@INCLUDE nb_hidden2
// f at two (wi, wo) pairs in one call (f0, f1: as nb_decode gives them): every
// weight fetched once feeds both pairs (register blocking; issue 12). Compute
// passes that evaluate several pairs per invocation call this.
void nb_decode2(vec3 wi0, vec3 wo0, vec3 wi1, vec3 wo1, out vec3 f0, out vec3 f1) {
    vec4 e0[NB_FEATS4];
    vec4 e1[NB_FEATS4];
    nb_encode(wi0, wo0, e0);
    nb_encode(wi1, wo1, e1);
    vec3 a0[NB_WIDTH];
    vec3 a1[NB_WIDTH];
    vec3 b0[NB_WIDTH];
    vec3 b1[NB_WIDTH];
    for (int o = 0; o < NB_WIDTH; ++o) {
        float d0 = 0.0, d1 = 0.0;
        for (int k = 0; k < NB_FEATS4; ++k) {
            vec4 w = nb_fetch(o * NB_FEATS4 + k);
            d0 += dot(w, e0[k]);
            d1 += dot(w, e1[k]);
        }
        a0[o] = nb_act(NB_SHARE(o) + d0);
        a1[o] = nb_act(NB_SHARE(o) + d1);
    }
//@INCLUDE nb_chain2
    vec3 y0 = vec3(nb_fetch(NB_OFF_OUT + NB_WIDTH4).x);
    vec3 y1 = y0;
    for (int k = 0; k < NB_WIDTH4; ++k) {
        vec4 w = nb_fetch(NB_OFF_OUT + k);
        y0 += w.x * a0[4 * k] + w.y * a0[4 * k + 1] + w.z * a0[4 * k + 2] + w.w * a0[4 * k + 3];
        y1 += w.x * a1[4 * k] + w.y * a1[4 * k + 1] + w.z * a1[4 * k + 2] + w.w * a1[4 * k + 3];
    }
    // a select, not a product: directions below the horizon may encode to NaN
    f0 = wi0.z > 0.0 && wo0.z > 0.0 ? exp(min(y0, vec3(80.0))) : vec3(0.0);
    f1 = wi1.z > 0.0 && wo1.z > 0.0 ? exp(min(y1, vec3(80.0))) : vec3(0.0);
}
#endif

// f(wi, wo) for R, G, B (no cosine); 0 when a direction is below the horizon.
vec3 nb_decode(vec3 wi, vec3 wo) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);
    vec4 e[NB_FEATS4];
    nb_encode(wi, wo, e);
#if NB_UNROLLED
//@INCLUDE nb_net
#else
    vec3 a[NB_WIDTH];
    vec3 b[NB_WIDTH];
    // Layer 1: the direction part is the same for all channels; the latent
    // part (and the bias) is the precomputed share.
    for (int o = 0; o < NB_WIDTH; ++o) {
        float d = 0.0;
        for (int k = 0; k < NB_FEATS4; ++k) d += dot(nb_fetch(o * NB_FEATS4 + k), e[k]);
        a[o] = nb_act(NB_SHARE(o) + d);
    }
//@INCLUDE nb_layers
    vec3 y = vec3(nb_fetch(NB_OFF_OUT + NB_WIDTH4).x);
    for (int k = 0; k < NB_WIDTH4; ++k) {
        vec4 w = nb_fetch(NB_OFF_OUT + k);
        y += w.x * a[4 * k] + w.y * a[4 * k + 1] + w.z * a[4 * k + 2] + w.w * a[4 * k + 3];
    }
#endif
    return exp(min(y, vec3(80.0)));
}
