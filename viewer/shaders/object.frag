// Lit object, fragment path (the fallback for OpenGL 3.3-4.2; the deferred
// compute pass lit.comp shades the same way where OpenGL 4.3 exists): the
// shading frame of the fragment (shading_frame.glsl: interpolated normal,
// tangent-space normal map) and one pass of lit_shade.glsl; passes are added
// by blending (progressive). A textured neural material (NB_TEXTURED) fetches
// its texel's latent share once per pixel.
//@INCLUDE common.glsl
//@INCLUDE brdf
//@INCLUDE sampling.glsl
//@INCLUDE environment.glsl
//@INCLUDE shading_frame.glsl
//@INCLUDE lit_shade.glsl

uniform uint u_pass;
uniform float u_mix_weight;  // this BRDF's share of its material's OpenPBR mix (1: no mix; blending adds the shares)

out vec4 frag;

void main() {
    vec3 view;
    mat3 tbn = shading_frame(view);
#ifdef NB_TEXTURED
    nb_load_share(v_uv);
#endif
    frag = u_mix_weight * vec4(shade_lit(tbn, view, v_world, uvec2(gl_FragCoord.xy), u_pass), 1.0);
}
