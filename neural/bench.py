"""``nbrdf bench operations``: CPU latency of the operations a slider drives
(leaf encoders, one layering call, the whole path of a stack), per RGB material."""
from __future__ import annotations

import platform
import time

import numpy as np
import torch

from nbrdf.neural.coat import with_coat
from nbrdf.neural.material import parse_material

THREE_LAYER = {"format": "nbrdf-material/1", "name": "bench three-layer", "layers": [
    {"type": "dielectric", "roughness": 0.05, "ior": 1.5}, {"type": "medium", "albedo": [0.9, 0.6, 0.3], "sigma_t": 0.5},
    {"type": "dielectric", "roughness": 0.2, "ior": 1.3}, {"type": "medium", "albedo": 0.8, "sigma_t": 1.0},
    {"type": "conductor", "roughness": 0.3, "r0": [0.95, 0.7, 0.3]}]}


def _timed(fn, repeats: int) -> dict:
    for _ in range(10):
        fn()
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append((time.perf_counter() - t0) * 1e3)
    return {"p50_ms": float(np.percentile(ts, 50)), "p99_ms": float(np.percentile(ts, 99))}


def bench_operations(model, repeats: int = 1000) -> dict:
    leaf, net = model.require("leaf"), model.require("layering")
    r3 = torch.tensor([0.9, 0.6, 0.3])

    top = torch.tensor([[0.1, 1.5]]).expand(3, 2)  # the interface's (roughness, ior): the code's coat
    z_bot = with_coat(leaf.conductor(0.3, r3), None)
    material = parse_material(THREE_LAYER)
    with torch.no_grad():
        out = {
            "leaf_conductor_rgb": _timed(lambda: leaf.conductor(0.3, r3), repeats),
            "leaf_dielectric": _timed(lambda: leaf.dielectric(torch.tensor([0.1]), torch.tensor([1.5])), repeats),
            "layering_rgb": _timed(lambda: net(top, z_bot, r3, torch.full((3,), 1.0)), repeats),
            "three_layer_material_latent": _timed(lambda: model.material_latent(material), repeats // 4),
        }
    out["machine"] = {"cpu": platform.processor() or platform.machine(), "torch_threads": torch.get_num_threads()}
    return out
