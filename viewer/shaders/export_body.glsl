#ifdef NB_ANISO
vec3 nb_body(vec3 wi, vec3 wo) {
    vec3 a, b;
    float j = body_warp(wi, wo, NBRDF_BODY_TAIL, coat_params(NBRDF_COAT).y, a, b);
    return j > 0.0 ? nb_decode(a, b) * j : vec3(0.0);
}
#else
#define nb_body(wi, wo) nb_decode(wi, wo)
#endif
