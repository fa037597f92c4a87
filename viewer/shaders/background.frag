// The environment behind the object: radiance along each pixel's view ray.
// Drawn at the far plane (depth 1) after the object's depth pre-pass, so it
// fills exactly the pixels the object leaves empty.
//@INCLUDE common.glsl
//@INCLUDE environment.glsl

in vec2 v_uv;
uniform mat4 u_inv_view_proj;
uniform vec3 u_eye;
uniform float u_env_intensity;
out vec4 frag;

void main() {
    vec4 far = u_inv_view_proj * vec4(v_uv * 2.0 - 1.0, 1.0, 1.0);
    vec3 d = normalize(far.xyz / far.w - u_eye);
    frag = vec4(env_radiance(d) * u_env_intensity, 1.0);
    gl_FragDepth = 1.0;
}
