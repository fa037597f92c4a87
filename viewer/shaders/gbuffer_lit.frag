// G-buffer of the deferred lit view (lit.comp shades it): per pixel the
// shading normal of shading_frame.glsl (world; normal map applied) with the
// coverage in w, the world position with the latent texture's mip level in w
// (what texture() would pick here; the compute pass has no derivatives), and
// the uv with the draw range's (material's) index in z, which lit.comp
// shades with that material, and in w the turn of the mesh's tangent about that normal
// (shading_frame.glsl tangent_turn: an anisotropic material's frame). The shading frame is
// frame_from_normal of that normal in both paths, or tangent_frame under NB_ANISO.
// NB_PLAIN_SURFACE: a program of its own for draws without a normal map or a latent texture.
//@INCLUDE common.glsl
//@INCLUDE shading_frame.glsl
uniform sampler2DArray u_nb_share_tex;  // a textured neural material's share (mip level only)
uniform int u_textured;
uniform int u_material_id;  // the draw range being rasterised (one per material)
layout(location = 0) out vec4 out_normal;
layout(location = 1) out vec4 out_world;
layout(location = 2) out vec4 out_uv;
void main() {
    vec3 view;
    mat3 tbn = shading_frame(view);
#ifdef NB_PLAIN_SURFACE
    float lod = 0.0;
#else
    float lod = u_textured != 0 ? textureQueryLod(u_nb_share_tex, v_uv).x : 0.0;
#endif
    out_normal = vec4(tbn[2], 1.0);
    out_world = vec4(v_world, lod);
    out_uv = vec4(v_uv, float(u_material_id), tangent_turn(tbn[2]));
}
