// A pass shaded in bands (viewer/gpu/renderer.py ``Renderer.end_pass``): its
// image, complete, drawn into the accumulation -- added by blending, or
// written over it as the accumulation's first pass -- so the accumulation
// only ever holds whole passes.
uniform sampler2D u_pass;
out vec4 frag;

void main() {
    frag = texelFetch(u_pass, ivec2(gl_FragCoord.xy), 0);
}
