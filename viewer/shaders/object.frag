// Lit object: a directional light, an optional point light and an HDR environment. Per pass and pixel,
// one sample each of three strategies -- the environment's luminance CDF, the
// BRDF's lobe (sample_lobe / pdf_lobe of the BRDF snippet: the learned proxy pdf
// for neural materials, GGX visible normals for closed-form ones) and the cosine
// lobe -- combined by the balance heuristic; passes are averaged (progressive).
// No shadowing: one object under a distant environment. A tangent-space normal
// map (OpenGL convention, +y = green up) bends the shading normal; a textured
// neural material (NB_TEXTURED) fetches its texel's latent share once per pixel.
//@INCLUDE common.glsl
//@INCLUDE brdf
//@INCLUDE sampling.glsl
//@INCLUDE environment.glsl
//@INCLUDE shading_frame.glsl

uniform vec3 u_light_dir;       // toward the light, world space
uniform vec3 u_light_radiance;
uniform int u_point_on;         // 1: a point light too
uniform vec3 u_point_pos;       // world space
uniform vec3 u_point_intensity; // radiant intensity: irradiance I cos / d^2
uniform float u_env_intensity;
uniform int u_env_on;           // 0: the light alone (benchmarks, quick previews)
uniform uint u_pass;

out vec4 frag;

uniform int u_strategies;  // 4: the light and three environment strategies (a uniform, so the loop
                           // is not unrolled: one call site of the BRDF keeps the shader small)

void main() {
    vec3 view;
    mat3 tbn = shading_frame(view);
#ifdef NB_TEXTURED
    nb_load_share(v_uv);
#endif
    mat3 to_local = transpose(tbn);
    vec3 wo = to_local * view;
    uvec2 px = uvec2(gl_FragCoord.xy);
    vec3 color = vec3(0.0);
    int count = u_env_on == 0 ? 1 : u_strategies;
    for (int k = u_point_on != 0 ? -1 : 0; k < count; ++k) {
        vec3 l;
        float unused;
        vec3 to_point = u_point_pos - v_world;
        if (k == -1) l = to_local * normalize(to_point);
        else if (k == 0) l = to_local * normalize(u_light_dir);
        else if (k == 1) l = to_local * sample_env(rand2(px, u_pass, 0u), unused);
        else if (k == 2) l = sample_lobe(wo, vec3(rand2(px, u_pass, 1u), rand2(px, u_pass, 2u).x));
        else l = sample_cosine(rand2(px, u_pass, 3u), unused);
        if (l.z <= 0.0) continue;
        vec3 weight;  // radiance over (MIS-weighted) pdf
        if (k == -1) {
            weight = u_point_intensity / max(dot(to_point, to_point), 1e-8);
        } else if (k == 0) {
            weight = u_light_radiance;
        } else {
            vec3 lw = tbn * l;
            float p = pdf_env(lw) + pdf_lobe(wo, l) + pdf_cosine(l);
            if (p <= 0.0) continue;
            weight = env_radiance(lw) * u_env_intensity / p;
        }
        color += brdf(l, wo) * l.z * weight;
    }
    frag = vec4(color, 1.0);
}
