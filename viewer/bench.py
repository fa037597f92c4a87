"""Previewer benchmarks, run by ``nbrdf bench render`` and ``nbrdf bench app``:
frame times of the GLSL decoder and of full shading, the GLSL decoder's
throughput against the torch CPU decoder's on the same machine, and the
look-development window's frame time and edit latency (one JSON object each)."""
from __future__ import annotations

import time

import numpy as np
import torch

from nbrdf.neural.decoder import DEFAULT_WEIGHTS, Decoder, DecoderSpec, load_decoder


def _time(fn, repeats: int) -> float:
    """Median seconds of fn() over ``repeats`` runs after one warm-up."""
    fn()
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def bench_render(size: tuple[int, int] = (1920, 1080), repeats: int = 3, torch_pairs: int = 1 << 18) -> dict:
    import moderngl

    from nbrdf.neural.material import load_material
    from nbrdf.viewer import shaders
    from nbrdf.viewer.gl import describe, offscreen_context
    from nbrdf.viewer.neural_gpu import GpuDecoder
    from nbrdf.viewer.renderer import Renderer, ViewState
    from nbrdf.viewer.options import DEFAULT_MATERIAL

    dec = load_decoder(DEFAULT_WEIGHTS) if DEFAULT_WEIGHTS.is_file() else Decoder(DecoderSpec()).eval()
    torch.manual_seed(0)
    z = dec.latent_mean.expand(3, -1).clone()
    w, h = size
    n = w * h
    ctx = offscreen_context()
    gdec = GpuDecoder(ctx, dec)

    # Decoder only: one evaluation (RGB) per pixel at random pairs.
    g = np.random.default_rng(0)
    v = g.normal(size=(2, n, 3)).astype(np.float32)
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[..., 2] = np.abs(v[..., 2])
    prog = ctx.program(vertex_shader=shaders.source("fullscreen.vert"),
                       fragment_shader=gdec.source("decoder_probe.frag"))
    tw = 2048
    pairs = np.zeros((2 * n, 4), np.float32)
    pairs[0::2, :3], pairs[1::2, :3] = v[0], v[1]
    rows = -(-2 * n // tw)
    buf = np.zeros((rows * tw, 4), np.float32)
    buf[: 2 * n] = pairs
    ptex = ctx.texture((tw, rows), 4, buf.tobytes(), dtype="f4")
    target = ctx.texture((w, h), 4, dtype="f4")
    fbo = ctx.framebuffer([target])
    vao = ctx.vertex_array(prog, [])

    def decode_frame():
        fbo.use()
        gdec.bind(prog)
        gdec.set_latent(prog, z)
        ptex.use(0)
        prog["u_pairs"].value = 0
        prog["u_pairs_w"].value = tw
        prog["u_target_w"].value = w
        vao.render(moderngl.TRIANGLES, vertices=3)
        ctx.finish()

    t_dec = _time(decode_frame, repeats)

    # Full shading: the lit sphere filling the frame, one directional light, no environment.
    r = Renderer(ctx, load_material(DEFAULT_MATERIAL), neural=gdec, latent=z)
    state = ViewState(env_on=False)
    state.camera.distance = 2.2

    def shade_frame():
        r.accumulate(state, w, h, 0, 1)
        ctx.finish()

    t_full = _time(shade_frame, repeats)

    # The torch decoder on this CPU, same work per evaluation (RGB at one pair).
    wi = torch.from_numpy(v[0, :torch_pairs].copy())
    wo = torch.from_numpy(v[1, :torch_pairs].copy())

    def torch_run():
        with torch.no_grad():
            dec.eval_rgb(z, wi, wo)

    t_torch = _time(torch_run, repeats)
    glsl_rate = n / t_dec
    torch_rate = wi.shape[0] / t_torch
    return {
        "renderer": describe(ctx),
        "size": f"{w}x{h}",
        "decoder": {"width": dec.spec.width, "depth": dec.spec.depth,
                    "macs_per_channel": dec.spec.macs(), "shipped_weights": DEFAULT_WEIGHTS.is_file()},
        "decoder_only_ms": round(1000 * t_dec, 2),
        "full_shading_one_light_ms": round(1000 * t_full, 2),
        "glsl_rgb_evals_per_s": round(glsl_rate),
        "torch_cpu_rgb_evals_per_s": round(torch_rate),
        "torch_threads": torch.get_num_threads(),
        "glsl_over_torch": round(glsl_rate / torch_rate, 3),
    }


def bench_app(size: tuple[int, int] = (1000, 620), edits: int = 8, warmup: int = 6) -> dict:
    """The look-development window (needs a display; Xvfb will do): frame time
    and the latency from a slider edit (a base roughness change, through leaf
    encoders and layering) to the end of the first frame that shows it, with
    the window's adaptive resolution as a user gets it."""
    import statistics

    from nbrdf.viewer.app import App
    from nbrdf.viewer.options import DEFAULT_MATERIAL, ViewOptions

    app = App(ViewOptions(material=DEFAULT_MATERIAL, size=size), size=size)
    ld = app.lookdev
    try:
        for _ in range(warmup):
            app.step()
        frames, latency, latent = [], [], []
        base = len(ld.editor.layers) - 1
        for k in range(edits):
            for _ in range(2):
                t0 = time.perf_counter()
                app.step()
                frames.append((time.perf_counter() - t0) * 1000.0)
            ld.set_param(base, "roughness", 0.2 + 0.05 * (k % 4))
            app.step()
            latency.append(ld.timings.edit_to_frame_ms)
            latent.append(ld.timings.latent_ms)
        return {
            "renderer": app.ctx.info.get("GL_RENDERER", "?"),
            "window": f"{size[0]}x{size[1]}",
            "render_scale": app.scale,
            "frame_ms_median": round(statistics.median(frames), 1),
            "edit_to_frame_ms_median": round(statistics.median(latency), 1),
            "edit_to_frame_ms_max": round(max(latency), 1),
            "latent_update_ms_median": round(statistics.median(latent), 2),
        }
    finally:
        app.close()
