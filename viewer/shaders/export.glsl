// An nbrdf material as one self-contained GLSL include (nbrdf export --glsl).
// Local shading frame, z = the normal; wi toward the light, wo toward the viewer,
// both unit and pointing away from the surface.
//
//   vec3  nbrdf_eval(vec3 wi, vec3 wo)   RGB BRDF in 1/sr, no cosine (0 below the horizon)
//   vec3  nbrdf_sample(vec3 wo, vec3 u)  a light direction wi drawn for the viewer direction wo
//                                        from uniforms u in [0, 1)^3 (may fall below the horizon:
//                                        a failed sample)
//   float nbrdf_pdf(vec3 wo, vec3 wi)    the solid-angle density of nbrdf_sample returning wi
//
// f = the clear coat in closed form (GGX, exact Fresnel) + the shared neural decoder's
// body at this material's latents; every weight is a constant below. Sampling: the coat's
// visible normals mixed with the body's proxy pdf (docs/NEURAL.md). GLSL 3.30 / ES 3.00
// or newer. Helper names start with nb_, coat_, sample_, pdf_, aniso_ (one material per program).
// An anisotropic material (NB_ANISO below): the frame's x must be the surface's tangent (SPEC
// section 10: y = z x x); the brushing direction is the material's anisotropy_rotation about z.
#ifndef PI
#define PI 3.14159265358979
#endif
//@INCLUDE nb_constants
#define NB_SHARE(j) nb_share[j]
//@INCLUDE neural_decoder.glsl
//@INCLUDE coat.glsl

//@INCLUDE export_body.glsl

vec3 nbrdf_eval(vec3 wi, vec3 wo) { return nb_body(wi, wo) + vec3(coat_eval(wi, wo, NBRDF_COAT)); }

vec3 nbrdf_sample(vec3 wo, vec3 u) { return coated_sample(wo, u, NBRDF_COAT, NBRDF_PROXY_SIGMA, NBRDF_PROXY_W); }

float nbrdf_pdf(vec3 wo, vec3 wi) {
    if (wi.z <= 0.0 || wo.z <= 0.0) return 0.0;
    return coated_pdf(wo, wi, NBRDF_COAT, NBRDF_PROXY_SIGMA, NBRDF_PROXY_W);
}
