// A calibrated code's body scale (neural/body_scale.py): the body times g(theta_i) g(theta_o) per channel,
// g linear in the angle between the knots NB_SCALE_KNOTS (degrees, increasing; NB_SCALE_COUNT of them) and
// flat outside them; NB_SCALE(j) is g at knot j: the uniform u_body_scale in the previewer, constants
// (NB_SCALE_VALUES) in an export, the stack in use's in an exported mix. The same function on both sides:
// f stays reciprocal.
#ifndef NB_SCALE
#ifdef NB_SCALE_VALUES
const vec3 nb_scale_values[NB_SCALE_COUNT] = vec3[](NB_SCALE_VALUES);
#define NB_SCALE(j) nb_scale_values[j]
#else
uniform vec3 u_body_scale[NB_SCALE_COUNT];
#define NB_SCALE(j) u_body_scale[j]
#endif
#endif
const float nb_scale_knots[NB_SCALE_COUNT] = float[](NB_SCALE_KNOTS);

vec3 nb_scale_at(float cos_theta) {
    float t = clamp(degrees(acos(clamp(cos_theta, -1.0, 1.0))), nb_scale_knots[0],
                    nb_scale_knots[NB_SCALE_COUNT - 1]);
    vec3 g = NB_SCALE(NB_SCALE_COUNT - 1);
    for (int j = NB_SCALE_COUNT - 1; j >= 1; --j) {
        if (t <= nb_scale_knots[j]) {
            float a = clamp((t - nb_scale_knots[j - 1]) / (nb_scale_knots[j] - nb_scale_knots[j - 1]), 0.0, 1.0);
            g = mix(NB_SCALE(j - 1), NB_SCALE(j), a);
        }
    }
    return g;
}

vec3 nb_scale_pair(vec3 wi, vec3 wo) { return nb_scale_at(wi.z) * nb_scale_at(wo.z); }
