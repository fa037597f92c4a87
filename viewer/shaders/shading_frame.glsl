// The shading frame of a lit-object fragment: the interpolated normal (flipped
// toward the viewer: meshes are two-sided), bent by the material's tangent-space
// normal map (OpenGL convention, +y = green up) when there is one.
in vec3 v_world;
in vec3 v_normal;
in vec4 v_tangent;
in vec2 v_uv;

uniform vec3 u_eye;
uniform sampler2D u_normal_map;
uniform int u_has_normal_map;

// The turn psi of the mesh's tangent (projected on the plane of n) from frame_from_normal(n)'s x axis:
// the deferred pass keeps one float per pixel (gbuffer_lit.frag) and rebuilds the frame (tangent_frame).
float tangent_turn(vec3 n) {
    mat3 f = frame_from_normal(n);
    vec3 t = v_tangent.xyz - n * dot(n, v_tangent.xyz);
    return dot(t, t) > 1e-12 ? atan(dot(t, f[1]), dot(t, f[0])) : 0.0;
}

// Columns tangent, bitangent, normal (world); ``view`` = unit vector to the eye. An anisotropic
// material (NB_ANISO) is shaded in the frame of the mesh's tangent; others in any frame of the normal.
mat3 shading_frame(out vec3 view) {
    vec3 n = normalize(v_normal);
    view = normalize(u_eye - v_world);
    if (dot(n, view) < 0.0) n = -n;  // two-sided
#ifndef NB_PLAIN_SURFACE  // (a program without a normal map: its code compiled out, not masked)
    if (u_has_normal_map != 0) {
        vec3 t = v_tangent.xyz - n * dot(n, v_tangent.xyz);
        t = dot(t, t) > 1e-12 ? normalize(t) : frame_from_normal(n)[0];
        vec3 b = cross(n, t) * (v_tangent.w < 0.0 ? -1.0 : 1.0);
        vec3 m = texture(u_normal_map, v_uv).xyz * 2.0 - 1.0;
        n = normalize(t * m.x + b * m.y + n * max(m.z, 1e-3));
        float nv = dot(n, view);  // a bent normal facing away: pull it back to the silhouette
        if (nv < 1e-3) n = normalize(n + view * (1e-3 - nv));
    }
#endif
#ifdef NB_ANISO
    return tangent_frame(n, tangent_turn(n));
#else
    return frame_from_normal(n);
#endif
}
