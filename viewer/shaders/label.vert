// A screen-aligned rectangle u_rect = (x0, y0, x1, y1) in normalised device
// coordinates (y0 at the bottom), drawn as a four-vertex triangle strip; v_uv
// has v = 0 at the top row (images uploaded top row first).
uniform vec4 u_rect;
out vec2 v_uv;
void main() {
    vec2 c = vec2(float(gl_VertexID & 1), float((gl_VertexID >> 1) & 1));
    v_uv = vec2(c.x, 1.0 - c.y);
    gl_Position = vec4(mix(u_rect.xy, u_rect.zw, c), 0.0, 1.0);
}
