// The lit object's reference (viewer/compare.py): the clear coat's environment
// light, accumulated on the GPU in closed form (u_coat: the sum of
// u_coat_passes passes, alpha = coverage x passes), plus the Monte Carlo image
// of everything else (u_body, at its own resolution: rgb = radiance x
// coverage, a = coverage; the ratio of the two filtered reads keeps the
// silhouette from darkening where the coarse image is upsampled), added where
// the object covers the pixel. One image out (passes 1), alpha = coverage, as
// the backdrop pass reads it. A material with no coat pass (a lone interface
// the closed form on the GPU does not draw: a brushed metal) is the Monte
// Carlo image alone, its coverage the image's own.
uniform sampler2D u_coat;
uniform float u_coat_passes;
uniform int u_coat_on;   // 0: no coat pass (u_coat is not read)
uniform sampler2D u_body;
uniform int u_has_body;  // 0: the worker has sent nothing yet (the coat alone)
in vec2 v_uv;
out vec4 frag;
void main() {
    vec4 b = texture(u_body, v_uv);
    vec3 body = u_has_body != 0 && b.a > 1e-4 ? b.rgb / b.a : vec3(0.0);
    if (u_coat_on == 0) {
        float cover = u_has_body != 0 ? clamp(b.a, 0.0, 1.0) : 0.0;
        frag = vec4(body * cover, cover);
        return;
    }
    vec4 c = texture(u_coat, v_uv) / max(u_coat_passes, 1.0);
    frag = vec4(c.rgb + body * c.a, c.a);
}
