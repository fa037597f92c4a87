"""``nbrdf bench mitsuba``: RGB evaluations per second of the ``nbrdf`` plugin
inside Mitsuba's Dr.Jit kernel (one wavefront of random direction pairs,
compiled once, timed over repeats), next to the torch neural BRDF on the same
pairs in the same process."""
from __future__ import annotations

import os
import time

import drjit as dr
import mitsuba as mi
import numpy as np
import torch

from nbrdf.neural.material_code import load_code
from nbrdf.neural.neural_brdf import latent_brdf


def _pairs(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(2):
        v = rng.normal(size=(n, 3))
        v[:, 2] = np.abs(v[:, 2])
        out.append((v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32))
    return out[0], out[1]


def bench_mitsuba(material: str, n: int = 1 << 20, repeats: int = 5, torch_n: int = 1 << 16) -> dict:
    """Median throughputs of ``repeats`` timed runs (after one that compiles;
    the package's import registered the plugin)."""
    bsdf = mi.load_dict({"type": "nbrdf", "material": material})
    light, view = _pairs(n)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(np.ascontiguousarray(view.T))
    wo = mi.Vector3f(np.ascontiguousarray(light.T))
    ctx = mi.BSDFContext()
    dr.eval(si, wo)

    def timed(fn) -> float:
        fn()  # compile / warm up
        ts = []
        for _ in range(repeats):
            t = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t)
        return float(np.median(ts))

    def run(out) -> None:
        dr.eval(out)
        dr.sync_thread()  # kernels launch asynchronously: wait for the result

    t_eval = timed(lambda: run(bsdf.eval(ctx, si, wo)))
    t_sample = timed(lambda: run(bsdf.sample(ctx, si, mi.Float(0.3), mi.Point2f(0.6, 0.2))))
    model, code = load_code(material)
    brdf = latent_brdf(model.decoder, code, None, model.sampler)
    tl, tv = torch.from_numpy(light[:torch_n]), torch.from_numpy(view[:torch_n])
    t_torch = timed(lambda: brdf.eval(tl, tv))
    return {
        "material": material,
        "variant": mi.variant(),
        "pairs": n,
        "rgb_evals_per_s": n / t_eval,
        "rgb_samples_per_s": n / t_sample,
        "torch_rgb_evals_per_s": torch_n / t_torch,
        "torch_pairs": torch_n,
        "torch_threads": torch.get_num_threads(),
        "cpu_count": os.cpu_count(),
        "llvm": os.environ.get("DRJIT_LIBLLVM_PATH"),
    }
