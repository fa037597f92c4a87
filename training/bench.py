"""``nbrdf bench reference``: Monte Carlo throughput and time to a converged
standard lobe, on the standard two-layer stack."""
from __future__ import annotations

import os
import platform
import time

import torch

from nbrdf.neural.material import parse_material
from nbrdf.neural.metrics import noise_psnr
from nbrdf.training.layered import SimStats, simulate
from nbrdf.training.reference import converged_lobe, stack_params
from nbrdf.training.walk_dispatch import threads, walk_device

#: The standard stack of the benchmark (issue: ground truth).
STANDARD_STACK = {
    "format": "nbrdf-material/1",
    "name": "bench standard two-layer",
    "layers": [
        {"type": "dielectric", "roughness": 0.1, "ior": 1.5},
        {"type": "medium", "albedo": 0.9, "sigma_t": 1.0},
        {"type": "conductor", "roughness": 0.3, "r0": 0.9},
    ],
}
#: A reference lobe counts as converged when its noise PSNR reaches this:
#: 10 dB below the strictest error the project measures (40 dB lobe PSNR).
CONVERGED_NOISE_PSNR = 50.0
#: The ground-truth v2 target (issue 14): a standard lobe at 60 dB of noise PSNR.
V2_NOISE_PSNR = 60.0


def machine() -> dict:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    return {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
            "torch_threads": torch.get_num_threads(), "torch": torch.__version__, "walk": f"numba-{walk_device()}",
            "walk_threads": threads(), "load_average_1min": load}


def bench_reference(quick: bool = False) -> dict:
    """Paths per second (one path = one sample of one pair, RGB together)
    of the compiled walk after warm-up (reported under both historical keys
    ``paths_per_second_eager`` and ``paths_per_second_compiled``: there is one
    walk now), the same per CPU-second of this process (``paths_per_cpu_second``:
    the figure to compare on a shared machine, where wall time depends on the
    load), and seconds to converged 64 x 64 lobes at theta_i = 30
    degrees (as ``nbrdf lobe`` computes them): to 50 dB of noise PSNR
    (``lobe_*``) and, unless ``quick``, to 60 dB (``lobe60_*``)."""
    mat = parse_material(STANDARD_STACK)
    n_pairs, spp = (256, 64) if quick else (4096, 256)
    g = torch.Generator().manual_seed(0)
    u = torch.rand(2, n_pairs, 2, generator=g)
    z = torch.sqrt(1 - u[..., 0])
    r = torch.sqrt(u[..., 0])
    d = torch.stack([r * torch.cos(6.2832 * u[..., 1]), r * torch.sin(6.2832 * u[..., 1]), z], -1)
    sp = stack_params(mat, n_pairs)
    out = {"stack": "dielectric a=0.1 ior=1.5 / medium albedo=0.9 sigma_t=1 / conductor a=0.3 r0=0.9",
           "paths": n_pairs * spp}
    simulate(stack_params(mat, 64), d[0, :64], d[1, :64], spp=16, seed=0)  # warm-up: loads the compiled walk
    st = SimStats()
    cpu0 = time.process_time()
    simulate(sp, d[0], d[1], spp=spp, seed=1, stats=st)
    cpu = time.process_time() - cpu0
    out["paths_per_second_eager"] = out["paths_per_second_compiled"] = round(st.paths / st.seconds)
    out["paths_per_cpu_second"] = round(st.paths / max(cpu, 1e-9))
    out["vertices_per_path"] = round(st.vertices / st.paths, 2)
    t0 = time.perf_counter()
    img, se, spp_used = converged_lobe(mat, 30.0, target_noise_psnr=20.0 if quick else CONVERGED_NOISE_PSNR)
    out.update({
        "lobe_theta_i": 30.0,
        "lobe_target_noise_psnr_db": 20.0 if quick else CONVERGED_NOISE_PSNR,
        "lobe_noise_psnr_db": round(noise_psnr(img, se), 2),
        "lobe_spp": spp_used,
        "lobe_seconds": round(time.perf_counter() - t0, 2),
    })
    if not quick:
        t0 = time.perf_counter()
        img, se, spp_used = converged_lobe(mat, 30.0, target_noise_psnr=V2_NOISE_PSNR)
        out.update({"lobe60_target_noise_psnr_db": V2_NOISE_PSNR, "lobe60_noise_psnr_db": round(noise_psnr(img, se), 2),
                    "lobe60_spp": spp_used, "lobe60_seconds": round(time.perf_counter() - t0, 2)})
    out["machine"] = machine()
    return out
