"""The walk's tuning constants and its one parameter record, ``WalkParams``,
which the CPU entry point (``kernel.run``) and the CUDA kernel
(``training.walk_cuda``) both take: the stack's arrays, the pairs and every
setting, built once by ``walk_params``."""
from __future__ import annotations

from collections import namedtuple

import numpy as np

#: Russian roulette weight window: paths whose largest channel weight is below
#: this survive with probability weight / RR_WEIGHT (and are divided by it).
RR_WEIGHT = 0.2
#: Top interface seen from below, below the critical angle (the vertices
#: that feed total internal reflection): the reflected facet comes from VNDF(a)
#: with probability WIDE_LAM, else from VNDF(WIDE_ROUGHNESS) (one-sample
#: mixture, weighted by the mixture pdf).
WIDE_ROUGHNESS = 0.4
WIDE_LAM = 0.5
#: Beyond the critical angle (trapped light, only without a medium in the top
#: slab): VNDF(a) with probability GUIDE_LAM, else the mirror guide toward wo.
GUIDE_LAM = 0.8
#: Roughness of the wide guide (strategy D of the two-bounce connection): the
#: exit lobe toward wo of a rougher copy of the coat, mirrored. It covers the
#: ring around the narrow guide's lobe, where a near-mirror base's GGX tail
#: bridges to the exit lobe (next-event estimation at the base).
WIDE_GUIDE_ROUGHNESS = 0.5
#: Splitting by exit importance (empty top slab over a conductor): at the top
#: seen from below a path's importance is its weight times I(w), the coat's
#: reflection density from its state w toward the centre of the mirrored exit
#: lobe. Each time it doubles against the level the path started at, the path
#: is split (copies of weight beta / k), at most SPLIT_STEP ways per vertex and
#: SPLIT_MAX copies per path in all (1: off).
SPLIT_MAX = 8
SPLIT_STEP = 2
#: Floor of I(w) as a fraction of its peak (a state's future value is never
#: only its immediate connection value: trapped light drifts).
SPLIT_FLOOR = 1e-3
#: Next-event estimation by way of the base, and the two-bounce connection
#: through a medium, for one interface over a medium and a conductor base
#: sharper than this roughness (rougher bases: the walk's own sampling of the
#: base lobe suffices).
MIRROR_CHAIN_ROUGHNESS = 0.1
#: Probability that a scattering draws the chain by way of the base (its
#: contribution divided by it, its density times it in the MIS weights).
MIRROR_CHAIN_P = 0.5
#: Paths per work item (a block of one pair's paths run by one thread).
BLOCK = 32

#: Compiler flags of every kernel: fastmath without "nnan" / "ninf" (the
#: non-finite checks stay valid); contraction into FMAs and reassociation
#: change results only by rounding, identically on every thread.
JIT = dict(cache=True, fastmath={"contract", "arcp", "nsz", "reassoc"}, nogil=True)
#: The same, inlined by Numba into the caller (the vertex, strategy and
#: record functions, called once per vertex: as calls they pass their
#: records and arrays through memory and cost a quarter of the throughput,
#: docs/decisions/061-walk-as-parts.md).
JIT_INLINE = dict(JIT, inline="always")

#: The walk's input, one record for the CPU and the CUDA entry points (a
#: namedtuple: Numba passes it to ``@njit`` and ``@cuda.jit`` code alike).
#: Arrays (float64): wi, wo (N, 3) the pairs, in the material's rotated
#: tangent frame (SPEC section 10); rough, rough_y (alpha_x, alpha_y: equal
#: for an isotropic interface), ior, sigma (N, L) per interface / slab; alb
#: (N, L, C) the slabs' albedo; b_rough, b_rough_y, b_ior (N,) and
#: b_r0, b_f82 (the F82-tint coefficient b, 0: Schlick), b_alb (N, C) the base's. Scalars: spp, seed; base (0 conductor,
#: 1 diffuse, 2 dielectric); rr_depth, max_depth; forced (the forced top
#: reflection and every strategy; False: the plain walk); rr_weight;
#: a_wide, lam, lam_w, agw (WIDE_ROUGHNESS, GUIDE_LAM, WIDE_LAM,
#: WIDE_GUIDE_ROUGHNESS); kmax, kstep, ifloor (SPLIT_MAX, SPLIT_STEP,
#: SPLIT_FLOOR); block (paths per work item).
WalkParams = namedtuple("WalkParams", [
    "wi", "wo", "rough", "ior", "sigma", "alb", "b_rough", "b_r0", "b_f82", "b_ior", "b_alb", "rough_y", "b_rough_y",
    "spp", "seed", "base", "rr_depth", "max_depth", "forced", "rr_weight", "a_wide", "lam", "lam_w", "agw",
    "kmax", "kstep", "ifloor", "block"])


def walk_params(wi: np.ndarray, wo: np.ndarray, spp: int, seed: int, rough: np.ndarray, ior: np.ndarray,
                sigma: np.ndarray, alb: np.ndarray, base: int, b_rough: np.ndarray, b_r0: np.ndarray,
                b_f82: np.ndarray, b_ior: np.ndarray, b_alb: np.ndarray, rr_depth: int, max_depth: int, forced: bool,
                rough_y: np.ndarray | None = None, b_rough_y: np.ndarray | None = None) -> WalkParams:
    """The record for N pairs (arrays made contiguous float64, the seed
    folded to 63 bits) with this module's tuning constants, read when called;
    ``rough_y`` / ``b_rough_y`` None: isotropic (alpha_y = alpha_x)."""
    f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)
    rough_y = rough if rough_y is None else rough_y
    b_rough_y = b_rough if b_rough_y is None else b_rough_y
    return WalkParams(f64(wi), f64(wo), f64(rough), f64(ior), f64(sigma), f64(alb), f64(b_rough), f64(b_r0),
                      f64(b_f82), f64(b_ior), f64(b_alb), f64(rough_y), f64(b_rough_y), int(spp), int(seed) & 0x7FFFFFFFFFFFFFFF, int(base), int(rr_depth),
                      int(max_depth), bool(forced), float(RR_WEIGHT), float(WIDE_ROUGHNESS), float(GUIDE_LAM),
                      float(WIDE_LAM), float(WIDE_GUIDE_ROUGHNESS), int(SPLIT_MAX), int(SPLIT_STEP),
                      float(SPLIT_FLOOR), int(BLOCK))
