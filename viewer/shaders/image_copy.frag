// A kept image drawn over the viewport texel for texel (viewer/jobs/view_frames.py: the
// still view's composite, drawn again while a pass is shaded in bands and nothing it
// shows has changed).
uniform sampler2D u_image;
in vec2 v_uv;
out vec4 frag;

void main() {
    frag = texelFetch(u_image, ivec2(v_uv * vec2(textureSize(u_image, 0))), 0);
}
