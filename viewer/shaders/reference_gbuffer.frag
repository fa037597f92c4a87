// The lit object's surface per pixel for the Monte Carlo reference of the
// compare mode (viewer/compare.py): target 0 = the shading normal (world,
// normal map applied, facing the viewer, as object.frag shades with), target 1
// = the world position, w the turn of the mesh's tangent about that normal
// (shading_frame.glsl tangent_turn: an anisotropic material's frame); target 0's w = 1 on the object.
//@INCLUDE common.glsl
//@INCLUDE shading_frame.glsl
layout(location = 0) out vec4 out_normal;
layout(location = 1) out vec4 out_world;
void main() {
    vec3 view;
    mat3 tbn = shading_frame(view);
    out_normal = vec4(tbn[2], 1.0);
    out_world = vec4(v_world, tangent_turn(tbn[2]));
}
