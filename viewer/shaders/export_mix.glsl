// An nbrdf material that is OpenPBR's linear mix of pure stacks (a fractional base_metalness or
// coat_weight) as one self-contained GLSL include (nbrdf export --glsl). Local shading frame,
// z = the normal; wi toward the light, wo toward the viewer, both unit and pointing away from
// the surface.
//
//   vec3  nbrdf_eval(vec3 wi, vec3 wo)   RGB BRDF in 1/sr, no cosine (0 below the horizon): the
//                                        stacks' BRDFs summed with their weights
//   vec3  nbrdf_sample(vec3 wo, vec3 u)  a light direction wi drawn for the viewer direction wo
//                                        from uniforms u in [0, 1)^3 (may fall below the horizon:
//                                        a failed sample): u.x picks a stack by weight and is
//                                        rescaled to stay uniform for that stack's sampler
//   float nbrdf_pdf(vec3 wo, vec3 wi)    the solid-angle density of nbrdf_sample returning wi: the
//                                        stacks' densities summed with their weights
//
// Each stack is what a single material's export holds (the clear coat in closed form plus the
// shared neural decoder's body at its latents, sampled by the coat's visible normals mixed with
// the body's proxy pdf; docs/NEURAL.md), all evaluated by the same functions: nb_use(k) makes
// stack k the current one. Every weight is a constant below. GLSL 3.30 / ES 3.00 or newer.
// Helper names start with nb_, coat_, sample_, pdf_, aniso_ (one material per program).
// An anisotropic mix (NB_ANISO below): the frame's x must be the surface's tangent (SPEC
// section 10: y = z x x); the brushing direction is the material's anisotropy_rotation about z.
#ifndef PI
#define PI 3.14159265358979
#endif
//@INCLUDE nb_constants

// The stack in use (nb_use): its latents' share of the decoder's first layer (what NB_SHARE reads),
// its coat, its proxy (sigma, w) and, when anisotropic, its tail (zero vectors: an isotropic stack).
vec3 nb_share[NB_WIDTH];
vec2 nb_coat;
vec2 nb_proxy;
#ifdef NB_ANISO
vec2 nb_coat_aniso;
vec2 nb_body_aniso;
vec3 nb_body_tail;
vec3 nb_body_glow;
#define NB_COAT_ANISO nb_coat_aniso
#define NB_BODY_ANISO nb_body_aniso
#define NBRDF_BODY_TAIL nb_body_tail
#define NBRDF_BODY_GLOW nb_body_glow
#endif
#ifdef NB_BODY_SCALE
vec3 nb_scale[NB_SCALE_COUNT];  // the stack in use's body scale (ones: a stack that needs none)
#define NB_SCALE(j) nb_scale[j]
#endif
#define NBRDF_COAT nb_coat
#define NB_SHARE(j) nb_share[j]
//@INCLUDE neural_decoder.glsl
//@INCLUDE coat.glsl

//@INCLUDE export_body.glsl

// The share is copied into nb_share, which the unrolled decoder reads at constant indices (read in
// place, at k * NB_WIDTH + j, it takes Mesa's llvmpipe several times as long to compile).
void nb_use(int k) {
    for (int j = 0; j < NB_WIDTH; ++j) nb_share[j] = nb_part_share[k * NB_WIDTH + j];
    nb_coat = nb_part_coat[k];
    nb_proxy = nb_part_proxy[k];
#ifdef NB_BODY_SCALE
    for (int j = 0; j < NB_SCALE_COUNT; ++j) nb_scale[j] = nb_part_scale[k * NB_SCALE_COUNT + j];
#endif
#ifdef NB_ANISO
    nb_coat_aniso = nb_part_aniso[k].xy;
    nb_body_aniso = nb_part_aniso[k].zw;
    nb_body_tail = vec3(nb_body_aniso, nb_part_body_alpha[k]);
    nb_body_glow = nb_part_body_glow[k];
#endif
}

// Stack k's BRDF, as a single material's export computes it (export.glsl's nbrdf_eval).
vec3 nb_part_eval(int k, vec3 wi, vec3 wo) {
    nb_use(k);
    return nb_body(wi, wo) + vec3(coat_eval(wi, wo, NBRDF_COAT));
}

// Stack k's sampler and density (export.glsl's nbrdf_sample and nbrdf_pdf).
vec3 nb_part_sample(int k, vec3 wo, vec3 u) {
    nb_use(k);
    return coated_sample(wo, u, NBRDF_COAT, nb_proxy.x, nb_proxy.y);
}

float nb_part_pdf(int k, vec3 wo, vec3 wi) {
    nb_use(k);
    return coated_pdf(wo, wi, NBRDF_COAT, nb_proxy.x, nb_proxy.y);
}

// A loop, so the program holds one copy of the unrolled decoder (written out stack by stack, the
// copies take Mesa's llvmpipe far longer than the loop to compile).
vec3 nbrdf_eval(vec3 wi, vec3 wo) {
    vec3 f = vec3(0.0);
    for (int k = 0; k < NB_PARTS; ++k) f += nb_part_weight[k] * nb_part_eval(k, wi, wo);
    return f;
}

// Stack k takes u.x in [nb_part_edge[k], nb_part_edge[k + 1]) (the running sums of the weights), and
// u.x rescaled to [0, 1) for its sampler.
vec3 nbrdf_sample(vec3 wo, vec3 u) {
    int k = NB_PARTS - 1;
    for (int j = NB_PARTS - 1; j >= 1; --j) {
        if (u.x < nb_part_edge[j]) k = j - 1;
    }
    u.x = clamp((u.x - nb_part_edge[k]) / nb_part_weight[k], 0.0, 1.0 - 1e-7);
    return nb_part_sample(k, wo, u);
}

float nbrdf_pdf(vec3 wo, vec3 wi) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return 0.0;
    float p = 0.0;
    for (int k = 0; k < NB_PARTS; ++k) p += nb_part_weight[k] * nb_part_pdf(k, wo, wi);
    return p;
}
