// The standard lobe image (SPEC section 9): pixel centres over the projected
// disk of wo, value f(wi, wo) cos(theta_o), zeros outside. Framebuffer row 0
// (the bottom) is y = -1, as in the SPEC's array.
//@INCLUDE common.glsl
//@INCLUDE brdf
uniform vec3 u_wi;
uniform vec2 u_size;
out vec4 frag;
uniform float u_mix_weight;  // this BRDF's share of its material's OpenPBR mix (1: no mix)
void main() {
    vec2 xy = gl_FragCoord.xy / u_size * 2.0 - 1.0;
    xy *= u_size / min(u_size.x, u_size.y);  // a round disk in a view of any shape (x1 when square)
    float r2 = dot(xy, xy);
    if (r2 >= 1.0) { frag = vec4(0.0, 0.0, 0.0, 1.0); return; }
    vec3 wo = vec3(xy, sqrt(1.0 - r2));
    frag = vec4(u_mix_weight * brdf(u_wi, wo) * wo.z, 1.0);
}
