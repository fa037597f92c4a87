// The lit object's geometry per pixel, for the Monte Carlo reference of the
// compare mode: target 0 = the light direction and target 1 = the view
// direction, both in the shading frame object.frag uses (w = 1 on the object).
//@INCLUDE common.glsl
//@INCLUDE shading_frame.glsl
uniform vec3 u_light_dir;  // toward the light, world space
layout(location = 0) out vec4 out_wi;
layout(location = 1) out vec4 out_wo;
void main() {
    vec3 view;
    mat3 to_local = transpose(shading_frame(view));
    out_wi = vec4(to_local * normalize(u_light_dir), 1.0);
    out_wo = vec4(to_local * view, 1.0);
}
