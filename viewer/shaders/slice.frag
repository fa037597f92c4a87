// Image slice (Disney BRDF Explorer): theta_h along x, theta_d along y (both
// 0..90 degrees, pixel centres), phi_d = 90 degrees; value f(wi, wo).
//@INCLUDE common.glsl
//@INCLUDE brdf
uniform vec2 u_size;
out vec4 frag;
uniform float u_mix_weight;  // this BRDF's share of its material's OpenPBR mix (1: no mix)
void main() {
    vec2 t = gl_FragCoord.xy / u_size * (0.5 * PI);
    float th = t.x, td = t.y;
    vec3 h = vec3(sin(th), 0.0, cos(th));
    vec3 d = vec3(0.0, sin(td), cos(td));  // phi_d = 90 deg in the half-vector frame
    // Rotate d from the frame where h is the pole back to the local frame (about y by theta_h).
    vec3 wi = vec3(cos(th) * d.x + sin(th) * d.z, d.y, -sin(th) * d.x + cos(th) * d.z);
    vec3 wo = 2.0 * dot(wi, h) * h - wi;
    frag = vec4(u_mix_weight * brdf(wi, wo), 1.0);
}
