// Bakes the body's environment light over the object's normals
// (env_table.glsl, viewer/gpu/env_prefilter.py): per node of the octahedral map,
// the point of the bounding sphere (u_centre, u_radius) with that normal, its view
// toward u_eye, and u_draws draws of the lit pass's own body estimator
// (lit_shade.glsl every_body_samples: the environment's CDF and the body's lobe
// at every candidate, balance heuristic), their mean written to u_table. Only the
// nodes the camera sees, and a margin of u_margin (cosine) behind the silhouette
// shaded at a grazing view so the map interpolates smoothly up to it, are baked;
// the rest stay black. A dispatch covers rows u_row0 .. u_row_end - 1 (the
// window bakes over several frames).
//@INCLUDE common.glsl
//@INCLUDE brdf
//@INCLUDE sampling.glsl
//@INCLUDE environment.glsl
//@INCLUDE lit_shade.glsl
//@INCLUDE env_table.glsl

layout(local_size_x = 8, local_size_y = 8) in;
layout(rgba32f, binding = 1) uniform writeonly image2D u_table;
uniform vec3 u_eye;
uniform vec3 u_centre;
uniform float u_radius;
uniform int u_draws;     // estimator draws per node
uniform float u_margin;  // nodes down to this cosine of the view behind the silhouette are baked
uniform int u_row0;      // the dispatch's first row
uniform int u_row_end;   // rows from here on are another dispatch's

// Cosine of the most grazing view a node is still baked at (rows just behind the silhouette).
const float GRAZING = 0.02;

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy) + ivec2(0, u_row0);
    ivec2 size = imageSize(u_table);
    if (any(greaterThanEqual(t, size)) || t.y >= u_row_end) return;
    vec3 n = env_table_dir((vec2(t) + 0.5) / vec2(size));
    vec3 view = normalize(u_eye - (u_centre + u_radius * n));
#ifdef NB_ANISO  // the sphere's tangent runs along its parallels (viewer/scene/mesh.py uv_sphere): a function of n
    vec3 tz = cross(vec3(0.0, 0.0, 1.0), n);
    mat3 tbn = dot(tz, tz) > 1e-12 ? mat3(normalize(tz), cross(n, normalize(tz)), n) : frame_from_normal(n);
#else
    mat3 tbn = frame_from_normal(n);
#endif
    vec3 wo = transpose(tbn) * view;
    vec3 sum = vec3(0.0);
    // A node the camera does not see draws nothing: a loop's count per invocation, not a branch
    // around the loop (llvmpipe runs a branch's code under a mask; a loop ends for a group of
    // invocations once every one of them is done).
    int draws = wo.z > -u_margin && u_env_on != 0 ? u_draws : 0;
    wo = normalize(vec3(wo.xy, max(wo.z, GRAZING)));
#ifdef NB_SPLIT_COAT
    coat_pass = vec2(0.05, 1.0);  // the coat is not baked: its candidates add nothing
    coat_n = 0;
    coat_counts = vec3(0.0);
#endif
    int m = u_ris_candidates;
    int n_lobe = clamp(u_body_every, 1, m - 1);
    vec3 unused = vec3(0.0);
    for (int k = 0; k < draws; ++k) sum += every_body_samples(tbn, wo, uvec2(t), uint(k), m, n_lobe, unused);
    sum /= float(max(draws, 1));
    imageStore(u_table, t, vec4(sum, 1.0));
}
