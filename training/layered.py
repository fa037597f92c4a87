"""Monte Carlo ground truth for layered BRDFs (SPEC section 5).

Position-free Monte Carlo (Guo, Hasan, Zhao 2018): a random walk starts at
the top interface by refracting ``wi`` into the stack, free-flies through
homogeneous slabs (thickness 1, extinction sigma_t, albedo A, isotropic
phase), scatters at media, internal interfaces and the base, and is ended by
Russian roulette. Every vertex that can see the top interface from below
(inside the top slab or on its bottom boundary) connects to ``wo`` by
next-event estimation: the top interface is sampled from ``wo`` (forced
transmission) and the connection is weighted by MIS against the walk itself
reaching the top and being evaluated there. Both MIS weights use the
*consistent* pdf: the density with which sampling the top interface from
``wo`` produces the direction in question. The single reflection off the top
interface is added in closed form.

The walk carries photon weights (energy) with the radiance-convention BSDFs of
``training.analytic``; along any path that enters and leaves through the top
the eta^2 factors of the two refractions cancel, so the estimate is the
stack's reciprocal BRDF. Sampling decisions do not depend on the colour
channel, so the channels share paths and only the weights differ.

The walk itself is compiled per lane by Numba (``training.walk``), with the
v2 estimator changes described there and in docs/RESULTS.md ("Ground truth
v2"); this module keeps the parameter types, the input checks and the
statistics.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import torch

from nbrdf.neural.anisotropy import alphas, to_frame
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import DIFFUSE, PARAMETRIC_BASES
from nbrdf.neural.microfacet import f82_coefficient
from nbrdf.training.analytic import GGXDielectric
from nbrdf.training.walk import BLOCK

Tensor = torch.Tensor

#: The bases the walk simulates (their codes are ``layer_kinds.BASE_CODES``).
BASES = PARAMETRIC_BASES
INV_4PI = 1.0 / (4.0 * math.pi)


@dataclass
class StackParams:
    """N stacks (one per (wi, wo) pair or per lane group), top to bottom.

    L interfaces, each a GGX dielectric followed by a medium slab (sigma_t 0 =
    no medium); then the base. Shapes: ``roughness``, ``ior`` (N, L);
    ``albedo`` (N, L, C) or (N, L); ``sigma_t`` (N, L) shared by the channels
    or (N, L, C) per channel (a coloured absorbing coat); ``base_r0`` / ``base_f82`` (a conductor's
    F82 tint, None: 1) / ``base_albedo`` (N, C) or (N,); ``base_roughness`` / ``base_ior`` (N,). C is the number of
    colour channels carried together (they share paths). Anisotropy (SPEC section 10; None: 0):
    ``anisotropy`` (N, L), ``base_anisotropy`` (N,), ``rotation`` (N,) in degrees."""

    roughness: Tensor
    ior: Tensor
    albedo: Tensor
    sigma_t: Tensor
    base: str
    base_roughness: Tensor
    base_r0: Tensor = field(default=None)  # type: ignore[assignment]
    base_f82: Tensor = field(default=None)  # type: ignore[assignment]
    base_ior: Tensor = field(default=None)  # type: ignore[assignment]
    base_albedo: Tensor = field(default=None)  # type: ignore[assignment]
    anisotropy: Tensor = field(default=None)  # type: ignore[assignment]
    base_anisotropy: Tensor = field(default=None)  # type: ignore[assignment]
    rotation: Tensor = field(default=None)  # type: ignore[assignment]

    def normalized(self, dtype: torch.dtype) -> tuple["StackParams", bool]:
        """Copy with every tensor in ``dtype`` and channel dims made explicit;
        also says whether the input was single-channel without a channel dim."""
        if self.base not in BASES:
            raise ValueError(f"unknown base {self.base!r}")
        n, L = self.roughness.shape
        squeeze = self.albedo.dim() == 2
        alb = self.albedo[..., None] if squeeze else self.albedo
        C = alb.shape[-1]

        def chan(t: Tensor | None, default: float) -> Tensor:
            if t is None:
                return torch.full((n, C), default, dtype=dtype)
            t = torch.as_tensor(t, dtype=dtype)
            t = t[:, None] if t.dim() == 1 else t
            return t.expand(n, C).to(dtype)

        def scal(t: Tensor | None, default: float) -> Tensor:
            return torch.full((n,), default, dtype=dtype) if t is None else torch.as_tensor(t, dtype=dtype).expand(n)

        sig = self.sigma_t.to(dtype)
        sig = (sig[..., None] if sig.dim() == 2 else sig).expand(n, L, C)
        p = StackParams(
            roughness=self.roughness.to(dtype), ior=self.ior.to(dtype), albedo=alb.to(dtype),
            sigma_t=sig, base=self.base,
            base_roughness=scal(self.base_roughness, 0.5), base_r0=chan(self.base_r0, 0.0),
            base_f82=chan(self.base_f82, 1.0), base_ior=scal(self.base_ior, 1.5), base_albedo=chan(self.base_albedo, 0.0),
            anisotropy=(torch.zeros(n, L, dtype=dtype) if self.anisotropy is None
                        else torch.as_tensor(self.anisotropy, dtype=dtype).expand(n, L)),
            base_anisotropy=scal(self.base_anisotropy, 0.0), rotation=scal(self.rotation, 0.0))
        return p, squeeze


@dataclass
class SimStats:
    """What a simulation cost: paths traced, vertices processed, seconds."""

    paths: int = 0
    vertices: int = 0
    seconds: float = 0.0
    dropped: int = 0  # contributions lost to float round-off (non-finite), about one in 10^8 paths


def _check(p: StackParams, wi: Tensor, wo: Tensor, spp: int) -> None:
    """One clear line (``NbrdfError``) for a stack or pair set that cannot be simulated."""
    if int(spp) < 1:
        raise NbrdfError(f"spp must be at least 1 (got {spp})")
    n = p.roughness.shape[0]
    if wi.dim() != 2 or wi.shape != wo.shape or wi.shape != (n, 3):
        raise NbrdfError(f"wi and wo must be ({n}, 3) like the stack (got {tuple(wi.shape)} and {tuple(wo.shape)})")
    for name in ("roughness", "ior", "albedo", "sigma_t", "base_roughness", "base_r0", "base_f82", "base_ior",
                 "base_albedo", "anisotropy", "base_anisotropy", "rotation"):
        t = getattr(p, name)
        if not bool(torch.isfinite(t).all()):
            raise NbrdfError(f"stack parameter {name} holds NaN or infinite values")
    if not (bool(torch.isfinite(wi).all()) and bool(torch.isfinite(wo).all())):
        raise NbrdfError("a direction holds NaN or infinite values")
    if bool((wi[:, 2] < 0).any()) or bool((wo[:, 2] < 0).any()):
        raise NbrdfError("a direction lies below the horizon (z < 0); the stack's BRDF is 0 there")
    if bool((p.ior <= 0).any()) or bool((p.base_ior <= 0).any()):
        raise NbrdfError("an index of refraction is not positive")
    if bool((p.roughness <= 0).any()) or (p.base != DIFFUSE and bool((p.base_roughness <= 0).any())):
        raise NbrdfError("a roughness is not positive")
    if bool((p.sigma_t < 0).any()):
        raise NbrdfError("sigma_t is negative")
    if bool((p.anisotropy < 0).any()) or bool((p.anisotropy >= 1).any()) or bool((p.base_anisotropy < 0).any()) \
            or bool((p.base_anisotropy >= 1).any()):
        raise NbrdfError("an anisotropy lies outside [0, 1)")
    if bool((p.base_f82 < 0).any()) or bool((p.base_f82 > 1).any()):
        raise NbrdfError("an F82 tint lies outside [0, 1]")
    if bool((p.albedo < 0).any()) or bool((p.albedo > 1).any()) or bool((p.base_albedo < 0).any()):
        raise NbrdfError("an albedo lies outside [0, 1]")


def simulate(stack: StackParams, wi: Tensor, wo: Tensor, spp: int = 64, seed: int = 0, *,
             dtype: torch.dtype = torch.float32, rr_depth: int = 4, max_depth: int = 100_000,
             include_top_reflection: bool = True, stats: SimStats | None = None, error: str = "paths",
             forced_top_reflection: bool = True, device: str | None = None) -> tuple[Tensor, Tensor]:
    """Mean and standard error of the stack's BRDF f(wi, wo) per pair.

    ``wi``, ``wo``: (N, 3) upper-hemisphere unit vectors; ``spp`` paths per
    pair; ``include_top_reflection=False`` leaves out the closed-form single
    reflection off the top (to test the walk alone). ``error``: "paths"
    (default) takes the standard error from the per-path spread; "batch"
    from independent batch means over blocks of ``training.walk.BLOCK``
    paths (at least 8 blocks, else the per-path spread). Paths are
    independent, so both estimate the same quantity; neither can see a tail
    the paths missed (docs/RESULTS.md, "Ground truth v2"). ``forced_top_reflection=False`` restores v1's sampled exit at the
    top (kept for the analysis and its test only). ``device``:
    "cpu" or "cuda" (the same paths, up to rounding: ``training.walk_cuda``);
    None follows ``NBRDF_WALK_DEVICE`` (default auto: CUDA when present). Returns
    tensors (N, C) (or (N,) for single-channel input without a channel dim)
    in ``dtype``, computed in float64. Deterministic for a given seed and
    batch, whatever the number of threads. Raises ``NbrdfError`` (one line)
    on input that cannot be simulated."""
    from nbrdf.training.walk_dispatch import run_walk  # late: numba costs ~0.4 s; most importers never walk

    t0 = time.perf_counter()
    p, squeeze = stack.normalized(torch.float64)
    wi = torch.as_tensor(wi).to(torch.float64)
    wo = torch.as_tensor(wo).to(torch.float64)
    _check(p, wi, wo, spp)
    N, L = p.roughness.shape
    npy = lambda t: t.detach().cpu().numpy()
    torch_threads = torch.get_num_threads()
    b_f82 = f82_coefficient(p.base_r0, p.base_f82)
    ax, ay, b_ax, b_ay, wi_w, wo_w = _walk_frame(p, wi, wo)
    # the walk's paths carry every channel through one medium; where the extinction differs per channel
    # (a coloured absorbing coat), each channel walks on its own, from the same seed
    shared = bool((p.sigma_t == p.sigma_t[..., :1]).all())
    parts = [slice(None)] if shared else [slice(c, c + 1) for c in range(p.albedo.shape[-1])]
    try:
        runs = [run_walk(
            npy(wi_w), npy(wo_w), spp, seed, npy(ax), npy(p.ior), npy(p.sigma_t[..., ch][..., 0]),
            npy(p.albedo[..., ch]), p.base, npy(b_ax), npy(p.base_r0[:, ch]), npy(b_f82[:, ch]),
            npy(p.base_ior), npy(p.base_albedo[:, ch]), rr_depth=rr_depth, max_depth=max_depth,
            forced=forced_top_reflection, device=device, rough_y=npy(ay), b_rough_y=npy(b_ay)) for ch in parts]
    finally:
        # Numba's OpenMP layer sets the OpenMP runtime's thread count it shares with torch: put torch's
        # back, or every torch operation after a walk (a projection's fit) runs on the walk's threads,
        # up to 15 times slower on a loaded machine (docs/decisions/056-refinement-on-idle.md).
        torch.set_num_threads(torch_threads)
    s1, s2, blocks = (np.concatenate([r[i] for r in runs], -1) for i in range(3))
    verts, dropped = sum(r[3] for r in runs), sum(r[4] for r in runs)
    mean = s1 / spp
    if spp > 1:
        var_paths = np.maximum(s2 / spp - mean * mean, 0.0) * spp / (spp - 1)
        se = np.sqrt(var_paths / spp)
        if error == "batch":
            se = _batch_error(blocks, spp, se)
        elif error != "paths":
            raise ValueError(f"unknown error mode {error!r}")
    else:
        se = np.full_like(mean, np.inf)
    if include_top_reflection:
        top = GGXDielectric(p.roughness[:, 0], p.ior[:, 0], p.anisotropy[:, 0], p.rotation)
        mean = mean + top.eval(wi, wo).numpy()[:, None]
    if stats is not None:
        stats.paths += N * spp
        stats.vertices += verts
        stats.dropped += dropped
        stats.seconds += time.perf_counter() - t0
    mean_t = torch.from_numpy(mean).to(dtype)
    se_t = torch.from_numpy(se).to(dtype)
    if squeeze:
        return mean_t[:, 0], se_t[:, 0]
    return mean_t, se_t


def _walk_frame(p: StackParams, wi: Tensor, wo: Tensor) -> tuple[Tensor, ...]:
    """(alpha_x, alpha_y of the interfaces (N, L), of the base (N,), wi and wo in the material's rotated
    tangent frame): the walk's inputs (SPEC section 10). Isotropic stacks get their roughness and the
    directions themselves, bit for bit (the walk's estimates then equal those before anisotropy to
    rounding: docs/RESULTS.md section 1)."""
    ax, ay = alphas(p.roughness, p.anisotropy)
    b_ax, b_ay = alphas(p.base_roughness, p.base_anisotropy)
    if not bool((p.rotation != 0).any()):
        return ax, ay, b_ax, b_ay, wi, wo
    return ax, ay, b_ax, b_ay, to_frame(wi, p.rotation), to_frame(wo, p.rotation)


def _batch_error(blocks, spp: int, se_paths):
    """Standard error from the batch means of the full path blocks; the
    per-path error where there are fewer than 8 of them."""
    nb = spp // BLOCK
    if nb < 8:
        return se_paths
    full = blocks[:, :nb] / BLOCK
    return full.std(1, ddof=1) / np.sqrt(nb)
