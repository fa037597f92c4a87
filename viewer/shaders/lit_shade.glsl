// The lit object's radiance toward the viewer at one surface point for one
// pass: a directional light, an optional point light and an HDR environment.
// Per pass and pixel, one sample each of three strategies -- the environment's
// luminance CDF, the BRDF's lobe (sample_lobe / pdf_lobe of the BRDF snippet:
// the learned proxy pdf for neural materials, GGX visible normals for
// closed-form ones) and the cosine lobe -- combined by the balance heuristic.
// u_strategies = 3 drops the cosine lobe (issue 12 measured the same noise for
// one BRDF evaluation less per pass); u_one_sample draws a single sample from
// the three strategies' mixture (one-sample MIS: more noise per unit time).
// No shadowing: one object under a distant environment. Both lit paths call
// it -- object.frag (fragment fallback) and lit.comp (deferred compute pass) --
// with the same pixel and pass, hence the same random numbers and image.
// Needs common.glsl, the BRDF snippet, sampling.glsl and environment.glsl.

uniform vec3 u_light_dir;       // toward the light, world space
uniform vec3 u_light_radiance;
uniform int u_point_on;         // 1: a point light too
uniform vec3 u_point_pos;       // world space
uniform vec3 u_point_intensity; // radiant intensity: irradiance I cos / d^2
uniform float u_env_intensity;
uniform int u_env_on;           // 0: the light alone (benchmarks, quick previews)
uniform int u_strategies;  // 4: the light and three environment strategies, 3: without the cosine lobe
                           // (a uniform, so the loop is not unrolled: one call site of the BRDF keeps
                           // the shader small)
uniform int u_one_sample;  // 1: one environment sample per pass from the mixture of the three strategies
                           // (one-sample MIS, balance heuristic): two BRDF evaluations per pass, not four

// ``tbn``: the shading frame (columns tangent, bitangent, normal; world);
// ``view``: unit vector to the eye; ``world``: the surface point.
vec3 shade_lit(mat3 tbn, vec3 view, vec3 world, uvec2 px, uint pass_index) {
    mat3 to_local = transpose(tbn);
    vec3 wo = to_local * view;
    vec3 color = vec3(0.0);
    int count = u_env_on == 0 ? 1 : u_one_sample != 0 ? 2 : u_strategies;
    // One-sample MIS: the strategy of the single environment sample, chosen uniformly.
    float pick = u_one_sample != 0 ? rand2(px, pass_index, 4u).x * 3.0 : 0.0;
    for (int k = u_point_on != 0 ? -1 : 0; k < count; ++k) {
        vec3 l;
        float unused;
        vec3 to_point = u_point_pos - world;
        int s = k == 1 && u_one_sample != 0 ? 1 + min(int(pick), 2) : k;
        if (s == -1) l = to_local * normalize(to_point);
        else if (s == 0) l = to_local * normalize(u_light_dir);
        else if (s == 1) l = to_local * sample_env(rand2(px, pass_index, 0u), unused);
        else if (s == 2) l = sample_lobe(wo, vec3(rand2(px, pass_index, 1u), rand2(px, pass_index, 2u).x));
        else l = sample_cosine(rand2(px, pass_index, 3u), unused);
        if (l.z <= 0.0) continue;
        vec3 weight;  // radiance over (MIS-weighted) pdf
        if (k == -1) {
            weight = u_point_intensity / max(dot(to_point, to_point), 1e-8);
        } else if (k == 0) {
            weight = u_light_radiance;
        } else {
            vec3 lw = tbn * l;
            float p = pdf_env(lw) + pdf_lobe(wo, l) + (u_strategies > 3 || u_one_sample != 0 ? pdf_cosine(l) : 0.0);
            if (u_one_sample != 0) p *= 1.0 / 3.0;  // the mixture's pdf
            if (p <= 0.0) continue;
            weight = env_radiance(lw) * u_env_intensity / p;
        }
        color += brdf(l, wo) * l.z * weight;
    }
    return color;
}
