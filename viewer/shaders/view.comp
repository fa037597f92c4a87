// Lobe and slice views, compute path (OpenGL 4.3): the pixels and values of
// lobe.frag / slice.frag (pixel centres; VIEW_IS_LOBE picks the lobe) written
// into the float target with imageStore, one pixel per invocation. (Two pixels
// per invocation through nb_decode2 decode faster on llvmpipe but compile
// several times slower, and a GPU would spill the doubled activations: issue 12.)
//@INCLUDE common.glsl
//@INCLUDE brdf
layout(local_size_x = 8, local_size_y = 8) in;
layout(rgba32f, binding = 0) uniform image2D u_target;
uniform vec3 u_wi;    // the lobe's incidence
uniform vec2 u_size;  // the target's size, pixels
uniform float u_mix_weight;  // this BRDF's share of its material's OpenPBR mix (1: no mix)
uniform int u_mix_add;       // 1: add to what the mix's earlier components wrote

// The pair of pixel ``px`` and the factor of its value; ``inside`` false: zero.
void view_pair(ivec2 px, out vec3 wi, out vec3 wo, out float scale, out bool inside) {
    vec2 fc = vec2(px) + 0.5;
#ifdef VIEW_IS_LOBE
    // lobe.frag: wo over the projected disk, value f(wi, wo) cos(theta_o)
    vec2 xy = fc / u_size * 2.0 - 1.0;
    xy *= u_size / min(u_size.x, u_size.y);  // a round disk in a view of any shape (x1 when square)
    float r2 = dot(xy, xy);
    inside = r2 < 1.0;
    wi = u_wi;
    wo = vec3(xy, sqrt(max(1.0 - r2, 0.0)));
    scale = wo.z;
#else
    // slice.frag: theta_h along x, theta_d along y, phi_d = 90 degrees
    vec2 t = fc / u_size * (0.5 * PI);
    float th = t.x, td = t.y;
    vec3 h = vec3(sin(th), 0.0, cos(th));
    vec3 d = vec3(0.0, sin(td), cos(td));
    wi = vec3(cos(th) * d.x + sin(th) * d.z, d.y, -sin(th) * d.x + cos(th) * d.z);
    wo = 2.0 * dot(wi, h) * h - wi;
    scale = 1.0;
    inside = true;
#endif
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(u_target)))) return;
    vec3 wi, wo;
    float scale;
    bool inside;
    view_pair(px, wi, wo, scale, inside);
    vec3 f = brdf(wi, wo);
    vec3 v = u_mix_weight * (inside ? f * scale : vec3(0.0));
    if (u_mix_add != 0) v += imageLoad(u_target, px).rgb;
    imageStore(u_target, px, vec4(v, 1.0));
}
