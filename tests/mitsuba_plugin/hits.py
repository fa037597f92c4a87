"""Random directions and surface interactions for the plugin tests (local shading frame, z up)."""
from __future__ import annotations

import numpy as np


def directions(rng: np.random.Generator, n: int, lift: float = 0.0) -> np.ndarray:
    """``n`` unit vectors (n, 3) float32 in the upper hemisphere; ``lift`` is added to z
    before normalising, keeping them away from grazing angles."""
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + lift
    return (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)


def interactions(mi, wi: np.ndarray):
    """A batch of ``mi.SurfaceInteraction3f`` with local incident directions ``wi`` (n, 3)."""
    import drjit as dr

    si = dr.zeros(mi.SurfaceInteraction3f, wi.shape[0])
    si.wi = mi.Vector3f(np.ascontiguousarray(wi.T))
    return si
