"""``nbrdf export --glsl``: the exported include compiles in a bare moderngl
program (nothing of the previewer around it) and equals the torch neural
BRDF within SPEC section 7's tolerance, its sampler and pdf too."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from gpu_brdfs import run_pairs

from nbrdf.neural.material import load_material
from nbrdf.neural.material_code import load_code
from nbrdf.training.brdfs import brdf_for
from nbrdf.viewer.glsl_export import export_glsl

ASSETS = Path(__file__).resolve().parents[2] / "viewer" / "assets" / "materials"
N = 2048

VERT = """#version 330 core
void main() { vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2)); gl_Position = vec4(2.0 * p - 1.0, 0.0, 1.0); }
"""
FRAG = """#version 330 core
{export}
uniform sampler2D u_in;   // texel 2k: a, texel 2k + 1: b (xyz)
uniform int u_mode;       // 0: nbrdf_eval(a, b); 1: nbrdf_sample(a = wo, b = u) and its nbrdf_pdf
out vec4 frag;
void main() {{
    int k = int(gl_FragCoord.y) * 64 + int(gl_FragCoord.x);
    vec3 a = texelFetch(u_in, ivec2((2 * k) % 128, (2 * k) / 128), 0).xyz;
    vec3 b = texelFetch(u_in, ivec2((2 * k + 1) % 128, (2 * k + 1) / 128), 0).xyz;
    if (u_mode == 0) {{ frag = vec4(nbrdf_eval(a, b), 1.0); return; }}
    vec3 wi = nbrdf_sample(a, b);
    frag = vec4(wi, nbrdf_pdf(a, wi));
}}
"""


def _run(prog, ctx, a: np.ndarray, b: np.ndarray, mode: int) -> np.ndarray:
    """(n, 4) outputs of the program at the n pairs (a, b)."""
    return run_pairs(prog, ctx, a, b, mode, 128, 64)


def _dirs(rng) -> np.ndarray:
    v = rng.normal(size=(N, 3))
    v[:, 2] = np.abs(v[:, 2])
    return (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)


@pytest.mark.gl
@pytest.mark.slow
@pytest.mark.ci_slow
@pytest.mark.parametrize("name", ["car_paint.json", "rough_gold.json", "brushed_steel_lacquer.json"])
def test_exported_glsl_equals_torch(name):
    import moderngl

    model, code = load_code(ASSETS / name)
    text = export_glsl(model, code, name)
    ctx = moderngl.create_context(standalone=True, backend="egl")
    try:
        prog = ctx.program(vertex_shader=VERT, fragment_shader=FRAG.format(export=text))
        assert {n for n in prog if not n.startswith("gl_")} == {"u_in", "u_mode"}  # self-contained: the export adds no uniforms
        rng = np.random.default_rng(3)
        wi, wo = _dirs(rng), _dirs(rng)
        brdf = brdf_for(load_material(ASSETS / name), "neural")
        got = _run(prog, ctx, wi, wo, 0)[:, :3]
        ref = brdf.eval(torch.from_numpy(wi), torch.from_numpy(wo)).numpy()
        assert ref.max() > 0.5
        assert (np.abs(got - ref) / (1e-4 * (1 + np.abs(ref)))).max() <= 1.0
        u = rng.random((N, 3)).astype(np.float32) * 0.999
        out = _run(prog, ctx, wo, u, 1)
        s = brdf.sample(torch.from_numpy(wo), torch.from_numpy(u))
        ok = s.pdf.numpy() > 0
        assert ok.mean() > 0.5
        np.testing.assert_allclose(out[ok, :3], s.w.numpy()[ok], atol=2e-4)
        np.testing.assert_allclose(out[ok, 3], s.pdf.numpy()[ok], rtol=2e-3, atol=1e-5)
        prog.release()
    finally:
        ctx.release()
