// The backdrop behind the lit object, composited after the object's passes
// (viewer/backdrop.py): where the object does not cover a pixel (coverage =
// the accumulation's alpha / passes), the background -- the environment, its
// pre-filtered copy, or a flat colour -- seen along the pixel's view ray,
// darkened on the ground plane under the object by the contact shadow (a
// shadow catcher: the ground is the background itself, so it never changes
// how the object is lit). Linear radiance out, one image (passes = 1).
// Two programs: NB_BACKGROUND_ONLY draws the background alone (kept while the camera,
// environment and settings stay: viewer/gpu/backdrop.py), and the default one puts the
// object's accumulation over that image (u_background) -- the same values as one pass.
//@INCLUDE common.glsl

in vec2 v_uv;
uniform sampler2D u_accum;      // the object's accumulation (rgb sum, alpha = passes where covered)
uniform float u_passes;
uniform int u_mode;             // a BACKGROUND_* constant
uniform sampler2D u_bg_env;     // equirectangular radiance: the environment or its blurred copy
uniform float u_bg_rotation;    // radians about world z
uniform float u_bg_intensity;
uniform vec3 u_flat;            // the flat colour, linear
uniform int u_ground;           // 1: the contact shadow on the ground plane
uniform sampler2D u_shadow;     // top-down shadow strength over [-u_extent, u_extent]^2
uniform float u_extent;
uniform float u_ground_z;
uniform mat4 u_inv_view_proj;
uniform vec3 u_eye;
out vec4 frag;

vec3 background(vec3 d) {
    if (u_mode == BACKGROUND_FLAT) return u_flat;
    if (u_mode == BACKGROUND_NONE) return vec3(0.0);
    float c = cos(-u_bg_rotation), s = sin(-u_bg_rotation);
    vec3 m = vec3(c * d.x - s * d.y, s * d.x + c * d.y, d.z);
    float phi = atan(m.y, m.x);
    if (phi < 0.0) phi += 2.0 * PI;
    vec2 uv = vec2(phi / (2.0 * PI), acos(clamp(m.z, -1.0, 1.0)) / PI);
    return texture(u_bg_env, uv).rgb * u_bg_intensity;
}

#ifndef NB_BACKGROUND_ONLY
uniform sampler2D u_background;  // NB_BACKGROUND_ONLY's image, the target's size
void main() {
    vec4 acc = texture(u_accum, v_uv);
    float passes = max(u_passes, 1.0);
    float cover = clamp(acc.a / passes, 0.0, 1.0);
    frag = vec4(acc.rgb / passes + (1.0 - cover) * texelFetch(u_background, ivec2(gl_FragCoord.xy), 0).rgb, 1.0);
}
#else
void main() {
    vec4 far = u_inv_view_proj * vec4(v_uv * 2.0 - 1.0, 1.0, 1.0);
    vec3 d = normalize(far.xyz / far.w - u_eye);
    vec3 bg = background(d);
    if (u_ground == 1 && d.z < 0.0 && u_eye.z > u_ground_z) {
        vec3 p = u_eye + d * ((u_ground_z - u_eye.z) / d.z);
        vec2 st = p.xy / (2.0 * u_extent) + 0.5;
        if (all(greaterThanEqual(st, vec2(0.0))) && all(lessThanEqual(st, vec2(1.0))))
            bg *= 1.0 - texture(u_shadow, st).r;
    }
    frag = vec4(bg, 1.0);
}
#endif
