"""The compiled walk on a CUDA device: the same per-path code, one GPU thread
per ``PATHS_PER_THREAD`` paths of a pair.

``training.walk.kernel.path`` is ordinary ``@njit`` code; Numba's CUDA target
compiles a CPU dispatcher called from a kernel into a device function from
the same Python source, so the GPU walk has no second copy of the physics.
The threads' sums are added back into the CPU walk's work items (pair, block
of ``walk.BLOCK`` paths), and each path's random numbers depend only on
(seed, pair, path), so the CPU and the GPU trace the same paths: per-pair results differ only by floating-point
rounding (FMA contraction, the device's libm), never by the launch shape.

Chosen by ``training.walk_dispatch.walk_device``: ``NBRDF_WALK_DEVICE`` = auto (the
default: CUDA when Numba finds a device), cpu or cuda. The test suite never
needs a device: it runs this kernel in Numba's CUDA simulator
(tests/training/test_walk_cuda.py) and compiles it to PTX where NVVM is
installed.
"""
from __future__ import annotations

import functools

import numpy as np
from numba import cuda, float64

from nbrdf.training.walk.kernel import add_path, path
from nbrdf.training.walk.params import SPLIT_MAX, WalkParams

#: Colour channels a GPU path can carry (per-thread scratch is a fixed-size
#: local array); stacks with more channels run on the CPU walk.
MAX_CHANNELS = 4
#: Threads per CUDA block.
THREADS_PER_BLOCK = 128
#: Paths per GPU thread: a CPU work item's ``BLOCK`` paths are split over
#: ``BLOCK / PATHS_PER_THREAD`` threads (more threads in flight: a 4096-pair,
#: 64-path lobe is 32k threads instead of 8k) and summed back into the CPU's
#: blocks on the host, so batch means see the same blocks.
PATHS_PER_THREAD = 8
_STK_ROWS = max(SPLIT_MAX - 1, 1)
_STK_COLS = 7 + MAX_CHANNELS


@functools.lru_cache(maxsize=1)
def available() -> bool:
    """Whether Numba finds a usable CUDA device (False, never an error, on a
    machine without a driver)."""
    try:
        return bool(cuda.is_available())
    except Exception:  # noqa: BLE001 - a broken driver install means "no device"
        return False


@cuda.jit(cache=True)
def _run_kernel(P, s1, s2, verts, dropped):
    """One thread per (pair, ``P.block`` paths): ``training.walk.kernel.run``'s
    loop body with per-thread scratch in local memory."""
    it = cuda.grid(1)
    C = P.alb.shape[2]
    nb = (P.spp + P.block - 1) // P.block
    if it >= P.wi.shape[0] * nb:
        return
    q = it // nb
    b = it - q * nb
    out_l = cuda.local.array(MAX_CHANNELS, float64)
    beta_l = cuda.local.array(MAX_CHANNELS, float64)
    stk = cuda.local.array((_STK_ROWS, _STK_COLS), float64)
    out = out_l[:C]
    beta = beta_l[:C]
    n_verts = 0
    n_dropped = 0
    for c in range(C):
        s1[it, c] = 0.0
        s2[it, c] = 0.0
    for s in range(b * P.block, min(P.spp, (b + 1) * P.block)):
        n_verts += path(q, s, P, out, beta, stk)
        n_dropped += add_path(out, s1, s2, it)
    verts[it] = n_verts
    dropped[it] = n_dropped


#: The record's array fields (copied to the device).
_ARRAYS = ("wi", "wo", "rough", "ior", "sigma", "alb", "b_rough", "b_r0", "b_f82", "b_ior", "b_alb", "rough_y",
           "b_rough_y")


def run_items(P: WalkParams) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``training.walk.kernel.run`` on the CUDA device: per work item (pair,
    ``P.block`` paths) the sum and the sum of squares of the path contributions
    per channel, the vertex count and the dropped paths (arrays on the host)."""
    N, C = P.wi.shape[0], P.alb.shape[2]
    if C > MAX_CHANNELS:
        raise ValueError(f"the CUDA walk carries at most {MAX_CHANNELS} channels (got {C})")
    if P.kmax - 1 > _STK_ROWS:
        raise ValueError(f"the CUDA walk keeps at most {_STK_ROWS + 1} copies of a split path (got {P.kmax})")
    if P.block % PATHS_PER_THREAD:
        raise ValueError(f"the walk's block ({P.block}) must be a multiple of {PATHS_PER_THREAD}")
    nb = (P.spp + P.block - 1) // P.block
    if N * nb == 0:
        z = np.zeros((0, C))
        return z, z.copy(), np.zeros(0, np.int64), np.zeros(0, np.int64)
    fine = PATHS_PER_THREAD
    nf = (P.spp + fine - 1) // fine
    items = N * nf
    dev = P._replace(block=fine, **{k: cuda.to_device(np.ascontiguousarray(getattr(P, k))) for k in _ARRAYS})
    s1 = cuda.device_array((items, C), np.float64)
    s2 = cuda.device_array((items, C), np.float64)
    verts = cuda.device_array(items, np.int64)
    dropped = cuda.device_array(items, np.int64)
    grid = (items + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK
    _run_kernel[grid, THREADS_PER_BLOCK](dev, s1, s2, verts, dropped)
    cuda.synchronize()
    # the CPU's items: block // fine consecutive threads of a pair make one block
    first = (np.arange(N)[:, None] * nf + np.arange(0, nf, P.block // fine)[None, :]).ravel()
    return tuple(np.add.reduceat(a.copy_to_host(), first, axis=0) for a in (s1, s2, verts, dropped))


__all__ = ["available", "run_items", "MAX_CHANNELS"]
