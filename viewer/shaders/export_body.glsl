#ifdef NB_ANISO
vec3 nb_body(vec3 wi, vec3 wo) {
    vec3 a, b;
    float c_ior = coat_params(NBRDF_COAT).y;
    float j = body_warp(wi, wo, NBRDF_BODY_TAIL, c_ior, a, b);
    return (j > 0.0 ? nb_decode(a, b) * j : vec3(0.0)) + NBRDF_BODY_GLOW * glow_basis(wi, wo, c_ior);
}
#else
#define nb_body(wi, wo) nb_decode(wi, wo)
#endif
