// A text label (viewer/labels.py): white glyphs (u_text's red = coverage) on a
// translucent black box, alpha-blended over the view.
uniform sampler2D u_text;
in vec2 v_uv;
out vec4 frag;
void main() {
    float t = texture(u_text, v_uv).r;
    frag = vec4(vec3(t), max(0.6, t));
}
