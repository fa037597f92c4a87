"""Runs the compiled walk (``training.walk``) on the CPU or, where Numba finds
one, on a CUDA device (``training.walk_cuda``): the one entry point of
``training.layered.simulate``.

The walk's kernel and its CUDA twin depend on the kernel module only; this
module is the one that knows both, so neither imports the other.
"""
from __future__ import annotations

import os

import numba
import numpy as np

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import BASE_CODES
from nbrdf.training import walk_cuda
from nbrdf.training.walk import kernel, walk_params


def run_walk(wi: np.ndarray, wo: np.ndarray, spp: int, seed: int, rough: np.ndarray, ior: np.ndarray,
             sigma: np.ndarray, alb: np.ndarray, base: str, b_rough: np.ndarray, b_r0: np.ndarray,
             b_f82: np.ndarray, b_ior: np.ndarray, b_alb: np.ndarray, rr_depth: int = 4, max_depth: int = 100_000,
             forced: bool = True, device: str | None = None, rough_y: np.ndarray | None = None,
             b_rough_y: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """Runs the walk for N pairs (float64 arrays, shapes as ``StackParams``
    with explicit channels) on ``device`` ("cpu", "cuda"; None: ``walk_device()``).
    ``rough`` / ``b_rough`` are alpha_x, ``rough_y`` / ``b_rough_y`` alpha_y (None: isotropic); wi and wo
    are in the material's rotated tangent frame (SPEC section 10).
    Returns per pair the sum and sum of squares of the path contributions
    (N, C), the per-block sums (N, n_blocks, C) for batch means, the vertex
    count and the number of dropped paths."""
    if forced:
        # reciprocity (both directions lie above the stack): walk from the
        # more grazing one, whose light refracts nearer the critical angle and
        # feeds the light trapped under the coat; the steeper one's exit lobe
        # is then reached by next-event estimation and the two-bounce
        # connection instead of by rare paths (docs/decisions/003-estimator-v3.md)
        swap = (np.asarray(wo)[:, 2] < np.asarray(wi)[:, 2])[:, None]
        wi, wo = np.where(swap, wo, wi), np.where(swap, wi, wo)
    N = wi.shape[0]
    C = alb.shape[2]
    P = walk_params(wi, wo, spp, seed, rough, ior, sigma, alb, BASE_CODES[base], b_rough, b_r0, b_f82, b_ior, b_alb,
                    rr_depth, max_depth, forced, rough_y, b_rough_y)
    if walk_device(device) == "cuda":
        s1, s2, verts, dropped = walk_cuda.run_items(P)
    else:
        s1, s2, verts, dropped = kernel.run(P)
    nb = s1.shape[0] // max(N, 1)
    blocks = s1.reshape(N, nb, C)
    return blocks.sum(1), s2.reshape(N, nb, C).sum(1), blocks, int(verts.sum()), int(dropped.sum())


def walk_device(requested: str | None = None) -> str:
    """Where the walk runs: ``requested``, else ``NBRDF_WALK_DEVICE``: cpu,
    cuda, or auto (the default): CUDA when Numba finds a device, else the
    CPU. One line (``NbrdfError``) for an unknown value or for cuda without a
    device."""
    source = "device" if requested is not None else "NBRDF_WALK_DEVICE"
    want = requested if requested is not None else os.environ.get("NBRDF_WALK_DEVICE", "auto")
    want = want.strip().lower() or "auto"
    if want not in ("auto", "cpu", "cuda"):
        raise NbrdfError(f"{source} must be auto, cpu or cuda (got {want!r})")
    if want == "cpu":
        return "cpu"
    if walk_cuda.available():
        return "cuda"
    if want == "cuda":
        raise NbrdfError(f"{source}=cuda, but Numba finds no CUDA device "
                         "(install the cuda extra on a machine with one)")
    return "cpu"


def threads() -> int:
    """Threads the walk runs on (``NUMBA_NUM_THREADS`` or every core)."""
    return numba.get_num_threads()


__all__ = ["run_walk", "walk_device", "threads"]
