#ifdef NB_BODY_SCALE
//@INCLUDE body_scale.glsl
#define NB_SCALED(v, wi, wo) ((v) * nb_scale_pair(wi, wo))
#else
#define NB_SCALED(v, wi, wo) (v)
#endif
#ifdef NB_ANISO
vec3 nb_body(vec3 wi, vec3 wo) {
    vec3 a, b;
    float c_ior = coat_params(NBRDF_COAT).y;
    float j = body_warp(wi, wo, NBRDF_BODY_TAIL, c_ior, a, b);
    return NB_SCALED((j > 0.0 ? nb_decode(a, b) * j : vec3(0.0)) + NBRDF_BODY_GLOW * glow_basis(wi, wo, c_ior), wi, wo);
}
#else
#define nb_body(wi, wo) NB_SCALED(nb_decode(wi, wo), wi, wo)
#endif
