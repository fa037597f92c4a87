// Lit object: world-space position, normal, tangent and uv for the fragment stage.
in vec3 in_position;
in vec3 in_normal;
in vec4 in_tangent;
in vec2 in_uv;

uniform mat4 u_model;
uniform mat4 u_view_proj;

out vec3 v_world;
out vec3 v_normal;
out vec4 v_tangent;
out vec2 v_uv;

void main() {
    vec4 w = u_model * vec4(in_position, 1.0);
    v_world = w.xyz;
    v_normal = mat3(u_model) * in_normal;
    v_tangent = vec4(mat3(u_model) * in_tangent.xyz, in_tangent.w);
    v_uv = in_uv;
    gl_Position = u_view_proj * w;
}
