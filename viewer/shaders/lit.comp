// Lit object, deferred compute path (OpenGL 4.3): one invocation per pixel of
// the G-buffer (gbuffer_lit.frag) runs u_passes passes of lit_shade.glsl --
// the same BRDF snippet, samplers and random numbers (pixel, pass) as the
// fragment path object.frag -- and adds their sum to the float accumulation
// image (alpha counts the passes, as the fragment path's blending does).
// A mesh of several materials runs it once per material (u_material_id), an
// OpenPBR mix once per component (u_mix_weight).
// A dispatch may cover a band of rows only (u_row0 .. u_row_end - 1): the
// window's still view shades a pass over several frames (viewer/gpu/renderer.py), and
// covers the object's box on screen only (u_col0 .. u_col_end - 1 too): llvmpipe runs
// an invocation's code under a mask whether it returns at once or not.
//@INCLUDE common.glsl
// No derivatives in a compute shader: the latent texture is read at the mip
// level the G-buffer pass found (textureQueryLod), which is what texture()
// picks in the fragment path. Only the BRDF snippet sees this macro.
float nb_px_lod = 0.0;
#define texture(s, p) textureLod(s, p, nb_px_lod)
//@INCLUDE brdf
#undef texture
//@INCLUDE sampling.glsl
//@INCLUDE environment.glsl
//@INCLUDE lit_shade.glsl

layout(local_size_x = 8, local_size_y = 8) in;
layout(rgba32f, binding = 0) uniform image2D u_accum;
uniform sampler2D u_gb_normal;  // shading normal (world), w = coverage
uniform sampler2D u_gb_world;   // world position, w = latent mip level
uniform sampler2D u_gb_uv;      // uv, z = the material (draw range) index
uniform int u_material_id;      // shade only that material's pixels (-1: every covered pixel)
uniform vec3 u_eye;
uniform uint u_first_pass;
uniform int u_passes;
uniform int u_row0;             // the dispatch's first row (invocation y 0)
uniform int u_row_end;          // rows from here on are another dispatch's
uniform int u_col0;             // the dispatch's first column (invocation x 0): the object's screen box
uniform int u_col_end;          // columns from here on are off the object
uniform float u_mix_weight;     // this BRDF's share of its material's OpenPBR mix (1: no mix): each
                                // component's dispatch adds its share, the passes counted once in all

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy) + ivec2(u_col0, u_row0);
    if (any(greaterThanEqual(px, imageSize(u_accum))) || px.y >= u_row_end || px.x >= u_col_end) return;
    vec4 n = texelFetch(u_gb_normal, px, 0);
    if (n.w < 0.5) return;
    if (u_material_id >= 0 && int(texelFetch(u_gb_uv, px, 0).z + 0.5) != u_material_id) return;
    vec4 world = texelFetch(u_gb_world, px, 0);
#ifdef NB_ANISO
    mat3 tbn = tangent_frame(n.xyz, texelFetch(u_gb_uv, px, 0).w);
#else
    mat3 tbn = frame_from_normal(n.xyz);
#endif
    vec3 view = normalize(u_eye - world.xyz);
#ifdef NB_TEXTURED
    nb_px_lod = world.w;
    nb_load_share(texelFetch(u_gb_uv, px, 0).xy);
#endif
    vec3 sum = vec3(0.0);
#if defined(NB_ENV_TABLE)
    for (int k = 0; k < u_passes; ++k) sum += shade_lit_mapped(tbn, view, world.xyz, uvec2(px), u_first_pass + uint(k));
#elif defined(NB_EVERY_CANDIDATE)
    for (int k = 0; k < u_passes; ++k) sum += shade_lit_every(tbn, view, world.xyz, uvec2(px), u_first_pass + uint(k));
#else
    for (int k = 0; k < u_passes; ++k) sum += shade_lit(tbn, view, world.xyz, uvec2(px), u_first_pass + uint(k));
#endif
    imageStore(u_accum, px, imageLoad(u_accum, px) + u_mix_weight * vec4(sum, float(u_passes)));
}
