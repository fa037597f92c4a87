"""Previewer benchmarks, run by ``nbrdf bench render`` and ``nbrdf bench app``:
frame times of the GLSL decoder and of full shading, the GLSL decoder's
throughput against the torch CPU decoder's on the same machine, and the
look-development window's frame time and edit latency (one JSON object each)."""
from __future__ import annotations

import math
import os
import time
from dataclasses import replace
from pathlib import Path

import moderngl
import numpy as np
import torch

from nbrdf.imaging.flip import flip
from nbrdf.neural.body_table import TableSize
from nbrdf.neural.decoder import DEFAULT_WEIGHTS, Decoder, DecoderSpec, load_decoder
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material
from nbrdf.viewer.gpu import shaders
from nbrdf.viewer.gpu.body_table_gpu import BodyTables
from nbrdf.viewer.gpu.gl import COMPUTE_VERSION, describe, half_float_extensions, offscreen_context
from nbrdf.viewer.gpu.neural_gpu import ComputeDecoderPass, GpuDecoder, WeightStorage
from nbrdf.viewer.gpu.noise import render_seeds
from nbrdf.viewer.gpu.pipeline import MaterialPipeline, gpu_brdf
from nbrdf.viewer.gpu.renderer import Renderer
from nbrdf.viewer.options import DEFAULT_MATERIAL
from nbrdf.viewer.view_settings import ViewState


def _time(fn, repeats: int) -> float:
    """Median seconds of fn() over ``repeats`` runs after one warm-up."""
    fn()
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def _time_interleaved(fns: dict[str, object], repeats: int) -> dict[str, float]:
    """Median seconds of each fn() over ``repeats`` rounds that run every fn once
    in turn (after one warm-up each): on a machine shared with other work, a
    change of load then hits every path alike and their ratios stay fair."""
    for fn in fns.values():
        fn()
    ts: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            ts[k].append(time.perf_counter() - t0)
    return {k: float(np.median(v)) for k, v in ts.items()}


#: FP32 peaks of GPUs in GFMA/s (half the vendor's FP32 TFLOPS at boost clock), by a
#: fragment of the GL renderer string; the first match wins, so specific names come first.
GPU_PEAK_GFMA = {
    "H100 PCIe": 25_600,  # 51.2 TFLOPS
    "H100 NVL": 30_000,   # 60 TFLOPS
    "GH200": 33_450, "H100": 33_450, "H200": 33_450,  # SXM: 66.9 TFLOPS
    "A100": 9_750, "A40": 18_700, "A30": 5_150, "A10": 15_600,  # A10 / A10G: 31.2 TFLOPS
    "L40S": 45_800, "L40": 45_250, "L4": 15_150, "T4": 4_050, "V100": 7_850,
    "RTX 6000 Ada": 45_500, "RTX A6000": 19_350, "RTX 4090": 41_300, "RTX 4080": 24_350,
    "RTX 3090": 17_800, "RTX 3080": 14_900,
}
#: The reference frame size of the per-frame figures (a 1080p frame).
FRAME_1080P = 1920 * 1080


def cpu_peak(cpuinfo: str | None = None, cores: int | None = None) -> dict:
    """The CPU's FP32 fused multiply-add peak from its own report (/proc/cpuinfo):
    cores x SIMD lanes x 2 FMA units x clock. Lanes: 16 with AVX-512 on Intel,
    8 with AVX2 (and with AVX-512 on AMD Zen 4, which runs 512-bit FMAs as two
    256-bit halves), 4 otherwise; no FMA flag halves the figure (a multiply and
    an add pipe)."""
    text = cpuinfo if cpuinfo is not None else (Path("/proc/cpuinfo").read_text()
                                                 if Path("/proc/cpuinfo").is_file() else "")
    field = lambda key: next((ln.split(":", 1)[1].strip() for ln in text.splitlines()
                              if ln.split(":", 1)[0].strip() == key), "")
    flags = set(field("flags").split())
    amd = field("vendor_id") == "AuthenticAMD"
    lanes = 16 if "avx512f" in flags and not amd else 8 if {"avx2", "avx512f"} & flags else 4
    units = 2 if "fma" in flags else 1
    mhz = float(field("cpu MHz") or 0.0)
    n = cores or os.cpu_count() or 1
    return {"kind": "cpu", "model": field("model name") or "unknown", "cores": n, "fp32_lanes": lanes,
            "fma_units": units, "clock_mhz": round(mhz), "peak_gfma_per_s": round(n * lanes * units * mhz / 1000, 1)}


def machine_peak(renderer: str) -> dict | None:
    """The FP32 FMA peak of what runs the shaders: the CPU for software OpenGL
    (llvmpipe), a known GPU by name, or None when the name is not in the table."""
    low = renderer.lower()
    if any(k in low for k in ("llvmpipe", "softpipe", "swrast")):
        return cpu_peak()
    for name, peak in GPU_PEAK_GFMA.items():
        if name.lower() in low:
            return {"kind": "gpu", "model": name, "peak_gfma_per_s": peak}
    return None


def bench_render(size: tuple[int, int] = (1920, 1080), repeats: int = 3, torch_pairs: int = 1 << 18,
                 storages: tuple[str, ...] = ("texture", "ssbo", "ubo", "const"), frames: bool = True) -> dict:
    """Per decoder path -- the fragment shader (weights in a texture) and the
    compute shader with each weight storage of ``storages``, one pair per
    invocation and (the loop forms) two (``_x2``: nb_decode2) -- one RGB decoder
    evaluation per pixel of a (w, h) frame at random directions: evaluations
    and effective multiply-adds per second, the share of the machine's FP32
    FMA peak and the ratio to the torch CPU decoder's throughput in the same
    run; and (``frames``) the lit sphere filling the frame per lit path
    (deferred compute with its default storage, fragment fallback): ms per frame with one directional light and ms per
    environment pass (the default resampled estimator; the balance heuristic
    over three environment strategies and over two, ``LitSampling.strategies``
    3), the first frame's seconds (shader
    compilation included), and the same per 1080p frame (scaled by pixel
    count when ``size`` is another). Also which half-precision arithmetic
    extensions the context offers. The decoder paths and torch are timed in
    interleaved rounds (fair ratios on a shared machine). Never needs a display; the GPU's name picks
    its peak (``GPU_PEAK_GFMA``), software OpenGL the CPU's."""
    try:
        chosen = [WeightStorage(x) for x in storages]
    except ValueError:
        raise NbrdfError(f"--storages: each one of {', '.join(s.value for s in WeightStorage)}") from None
    dec = load_decoder(DEFAULT_WEIGHTS) if DEFAULT_WEIGHTS.is_file() else Decoder(DecoderSpec()).eval()
    torch.manual_seed(0)
    z = dec.latent_mean.expand(3, -1).clone()
    w, h = size
    n = w * h
    ctx = offscreen_context()
    gdec = GpuDecoder(ctx, dec)
    compute = ctx.version_code >= COMPUTE_VERSION
    times, t_torch, torch_n = _decoder_paths(ctx, gdec, dec, z, size, chosen if compute else [], repeats,
                                             torch_pairs)
    frame_ms = _lit_frames(ctx, gdec, z, size, repeats, compute) if frames else {}
    torch_rate = torch_n / t_torch
    macs_rgb = 3 * dec.spec.macs()  # one RGB evaluation, latent share cached
    info = describe(ctx)
    peak = machine_peak(info)
    gfma = lambda rate: round(rate * macs_rgb / 1e9, 3)  # noqa: E731
    paths = {k: {"decoder_ms": round(1000 * t, 2), "rgb_evals_per_s": round(n / t), "gfma_per_s": gfma(n / t)}
             for k, t in times.items()}
    paths["torch_cpu"] = {"rgb_evals_per_s": round(torch_rate), "gfma_per_s": gfma(torch_rate)}
    for entry in paths.values():
        entry["over_torch"] = round(entry["rgb_evals_per_s"] / torch_rate, 3)
        if peak is not None:
            entry["fraction_of_peak"] = round(entry["gfma_per_s"] / peak["peak_gfma_per_s"], 4)
    best = max((k for k in paths if k != "torch_cpu"), key=lambda k: paths[k]["rgb_evals_per_s"])
    glsl_rate = n / times["fragment_texture"]
    lit = frame_ms.get("compute", frame_ms.get("fragment", {}))
    return {
        "renderer": info,
        "size": f"{w}x{h}",
        "decoder": {"width": dec.spec.width, "depth": dec.spec.depth,
                    "macs_per_channel": dec.spec.macs(), "shipped_weights": DEFAULT_WEIGHTS.is_file()},
        "decoder_only_ms": round(1000 * times["fragment_texture"], 2),
        "full_shading_one_light_ms": lit.get("one_light_ms"),
        "lit_frames": frame_ms,
        "glsl_rgb_evals_per_s": round(glsl_rate),
        "torch_cpu_rgb_evals_per_s": round(torch_rate),
        "torch_threads": torch.get_num_threads(),
        "glsl_over_torch": round(glsl_rate / torch_rate, 3),
        "macs_per_rgb_eval": macs_rgb,
        "paths": paths,
        "best_glsl_path": best,
        "best_glsl_over_torch": round(paths[best]["rgb_evals_per_s"] / torch_rate, 3),
        "peak": peak,
        "f16_arithmetic_extensions": half_float_extensions(ctx),
    }


def _decoder_paths(ctx, gdec, dec, z, size: tuple[int, int], storages: list, repeats: int,
                   torch_pairs: int) -> tuple[dict[str, float], float, int]:
    """Seconds of one RGB decoder evaluation per pixel at random pairs per decoder
    path (the fragment shader, the compute shader per weight ``storages``, one
    and two pairs per invocation), and of the torch CPU decoder on its share of
    the pairs, timed in interleaved rounds: (path times, torch time, torch pairs)."""
    w, h = size
    n = w * h
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

    runs = {"fragment_texture": decode_frame}
    cpasses = []
    for st in storages:
        for k in (1,) if st.unrolled else (1, 2):
            cpasses.append(ComputeDecoderPass(ctx, gdec, z, v[0], v[1], st, k))
            runs[f"compute_{st.value}" + ("_x2" if k == 2 else "")] = cpasses[-1].run
    wi = torch.from_numpy(v[0, :torch_pairs].copy())
    wo = torch.from_numpy(v[1, :torch_pairs].copy())

    def torch_run():
        with torch.no_grad():
            dec.eval_rgb(z, wi, wo)

    runs["torch_cpu"] = torch_run
    times = _time_interleaved(runs, repeats)
    for cpass in cpasses:
        cpass.release()
    return times, times.pop("torch_cpu"), wi.shape[0]


def _lit_frames(ctx, gdec, z, size: tuple[int, int], repeats: int, compute: bool) -> dict[str, dict]:
    """The lit sphere filling the frame per lit path (deferred compute, fragment):
    ms per frame with one directional light and per environment pass (the default
    resampled estimator, the balance heuristic over three strategies and over
    two), the first frame's seconds, and the same per 1080p frame."""
    w, h = size
    mat = load_material(DEFAULT_MATERIAL)
    frame_ms: dict[str, dict] = {}
    for name, comp in (("compute", True), ("fragment", False)) if compute else (("fragment", False),):
        r = Renderer(ctx, gpu_brdf(ctx, mat, gdec, z), compute=comp)
        out: dict[str, object] = {}
        for key, state in (("one_light_ms", ViewState(env_on=False)),
                           ("env_pass_ms", ViewState(env_on=True, background=False))):
            state.camera.distance = 2.2

            def shade_frame(state=state):
                r.accumulate(state, w, h, 0, 1)
                ctx.finish()

            if key == "one_light_ms":  # the first frame builds the programs
                t0 = time.perf_counter()
                shade_frame()
                out["first_frame_s"] = round(time.perf_counter() - t0, 2)
            out[key] = round(1000 * _time(shade_frame, repeats), 2)
            if key == "env_pass_ms":  # the balance heuristic instead of resampling: three and two strategies
                default = r.sampling
                r.sampling = replace(default, ris_samples=0)
                out["env_pass_balance_ms"] = round(1000 * _time(shade_frame, repeats), 2)
                r.sampling = replace(default, ris_samples=0, strategies=3)
                out["env_pass_two_strategies_ms"] = round(1000 * _time(shade_frame, repeats), 2)
                r.sampling = default
        out["storage"] = gdec.compute_storage.value if comp else "texture"
        scale = FRAME_1080P / (w * h)
        out["per_1080p_frame"] = {k: round(val * scale, 1) for k, val in out.items() if k.endswith("_ms")}
        frame_ms[name] = out
    return frame_ms


def passes_to_target(noise, spp0: int, target: float, rounds: int = 4) -> tuple[int, float]:
    """The fewest passes whose accumulated image has relative noise under ``target``,
    and the noise's measured rate (noise ~ passes^-rate). ``noise(passes)`` measures
    the noise of that many passes. The rate is fitted from ``spp0`` and 4 ``spp0``
    passes, the count predicted from it is measured, and the prediction is refined
    from the nearest measurements (at most ``rounds`` more) until the count is
    bracketed: a measured count under the target and (where it is above 4 ``spp0``)
    one pass fewer by the local rate over it."""
    measured = {spp0: noise(spp0), 4 * spp0: noise(4 * spp0)}
    rate = max(0.25, math.log(measured[spp0] / measured[4 * spp0]) / math.log(4.0))

    def predict(n: int) -> int:
        return max(1, math.ceil(n * (measured[n] / target) ** (1.0 / rate)))

    n = predict(4 * spp0)
    for _ in range(rounds):
        if n not in measured:
            measured[n] = noise(n)
        below = [k for k, v in measured.items() if v < target]
        above = [k for k, v in measured.items() if v >= target]
        lo, hi = (max(above) if above else 0), (min(below) if below else None)
        if hi is not None and hi - lo <= max(2, hi // 16):  # bracketed to within 1/16 of the count
            return hi, rate
        ref = hi if hi is not None else max(measured)
        if lo and hi:  # the local rate between the bracket's ends
            rate = max(0.25, math.log(measured[lo] / measured[hi]) / math.log(hi / lo))
        n = min(max(predict(ref), lo + 1), hi - 1) if hi is not None else max(predict(ref), ref + 1)
    hi = min((k for k, v in measured.items() if v < target), default=None)
    return (hi if hi is not None else predict(max(measured))), rate


def lit_seeds(renderer, state, vw: int, vh: int, spp: int, renders: int, brdf) -> tuple:
    """``noise.render_seeds`` with ``brdf`` as the renderer's default BRDF (the still view's
    table) and the sampling the window uses for it (render_seeds varies ``sampling``'s seed)."""
    old = renderer.brdf, renderer.sampling, renderer.table_sampling
    renderer.brdf = brdf
    if renderer.table_sampling is not None:
        renderer.sampling, renderer.table_sampling = renderer.table_sampling, None
    try:
        return render_seeds(renderer, state, (max(8, vw // 2), max(8, vh // 2)), spp, range(1, renders + 1))
    finally:
        renderer.brdf, renderer.sampling, renderer.table_sampling = old


def bench_body_table(sizes: tuple[str, ...] = ("32x16x8", "48x24x12"), size: int = 128, spp: int = 4,
                     materials: str | Path | None = None) -> dict:
    """The baked body table's render-space error against the per-pixel decoder
    (viewer/gpu/body_table_gpu.py): the lit sphere (default environment, no background)
    of each uniform material of the look-development set (training/sets/lookdev)
    rendered ``size`` x ``size`` with ``spp`` passes both ways, with the same random
    numbers (the difference is the table's alone), scored with HDR-FLIP; per table
    size the mean and worst FLIP and the median bake time (decoder pass and upload)."""
    root = Path(materials) if materials else Path(__file__).resolve().parents[1] / "training" / "sets" / "lookdev"
    tables = [TableSize(*(int(x) for x in s.split("x"))) for s in sizes]
    ctx = offscreen_context()
    pipe, r, bt = MaterialPipeline(ctx), Renderer(ctx, mesh="sphere"), BodyTables(ctx)
    state = ViewState(background=False)
    state.camera.distance = 2.2
    scores: dict[str, dict[str, float]] = {s: {} for s in sizes}
    bake: dict[str, list[float]] = {s: [] for s in sizes}
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        for path in sorted(root.glob("*.json")):
            m = load_material(path)
            if m.is_textured:
                continue
            brdf = pipe.build(m, "neural")
            ref = r.render_linear(state, (size, size), spp, brdf)
            for name, t in zip(sizes, tables):
                img = r.render_linear(state, (size, size), spp, bt.brdf(brdf, t))
                bake[name].append(bt.bake_ms)
                scores[name][path.stem] = round(flip(ref, img)[0], 4)
    finally:
        torch.set_num_threads(threads)
    return {name: {"flip_mean": round(float(np.mean(list(v.values()))), 4),
                   "flip_worst": max(v.values()), "worst": max(v, key=v.get),
                   "bake_ms_median": round(float(np.median(bake[name])), 1), "per_material": v}
            for name, v in scores.items()}


if __name__ == "__main__":
    import json
    import sys

    # python -m nbrdf.viewer.bench table [SIZE ...]: bench_body_table as JSON.
    if sys.argv[1:2] != ["table"]:
        sys.exit("usage: python -m nbrdf.viewer.bench table [NxMxK ...]")
    print(json.dumps(bench_body_table(tuple(sys.argv[2:]) or ("32x16x8", "48x24x12")), indent=2))
