// Lit object: one directional light plus a procedural sky, sampled by cosine
// hemisphere and BRDF-lobe sampling with MIS, one sample of each per pass;
// passes are averaged (progressive).
//@INCLUDE common.glsl
//@INCLUDE brdf
//@INCLUDE sampling.glsl

in vec3 v_world;
in vec3 v_normal;
in vec4 v_tangent;
in vec2 v_uv;

uniform vec3 u_eye;
uniform vec3 u_light_dir;       // toward the light, world space
uniform vec3 u_light_radiance;
uniform float u_env_intensity;
uniform int u_env_on;           // 0: the light alone (benchmarks, quick previews)
uniform uint u_pass;

out vec4 frag;

vec3 sky(vec3 d) {
    float t = clamp(d.z, -1.0, 1.0);  // world z is up
    vec3 zenith = vec3(0.35, 0.55, 1.0);
    vec3 horizon = vec3(1.0, 0.95, 0.85);
    vec3 ground = vec3(0.25, 0.22, 0.2);
    return t >= 0.0 ? mix(horizon, zenith, pow(t, 0.6)) : mix(horizon, ground, pow(-t, 0.4));
}

void main() {
    vec3 n = normalize(v_normal);
    vec3 view = normalize(u_eye - v_world);
    if (dot(n, view) < 0.0) n = -n;  // two-sided
    mat3 tbn = frame_from_normal(n);
    mat3 to_local = transpose(tbn);
    vec3 wo = to_local * view;
    vec3 color = vec3(0.0);
    vec3 wl = to_local * normalize(u_light_dir);
    if (wl.z > 0.0) color += brdf(wl, wo) * u_light_radiance * wl.z;
    if (u_env_on == 0) { frag = vec4(color, 1.0); return; }
    // Environment: one cosine sample and one sample of the BRDF's lobe strategy
    // (sample_lobe / pdf_lobe of the BRDF snippet) per pass, balance heuristic.
    float pc;
    vec3 wc = sample_cosine(rand2(uvec2(gl_FragCoord.xy), u_pass, 0u), pc);
    color += brdf(wc, wo) * wc.z / (pc + pdf_lobe(wo, wc)) * sky(tbn * wc) * u_env_intensity;
    vec3 ul = vec3(rand2(uvec2(gl_FragCoord.xy), u_pass, 1u), rand2(uvec2(gl_FragCoord.xy), u_pass, 2u).x);
    vec3 wg = sample_lobe(wo, ul);
    if (wg.z > 0.0) {
        color += brdf(wg, wo) * wg.z / (pdf_lobe(wo, wg) + pdf_cosine(wg)) * sky(tbn * wg) * u_env_intensity;
    }
    frag = vec4(color, 1.0);
}
