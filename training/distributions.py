"""The paper's parameter distributions (SPEC section 9), written once.

Each parameter is a fixed transform of a uniform number u in [0, 1):

- roughness ~ U(0.216, 1)^3 (the cube root is uniform: dense at glossy values),
- ior ~ U(1.05, 2),
- r0 ~ U(0, 1) (conductor colour) and a diffuse base's albedo ~ U(0, 1),
- a medium's albedo ~ 1 - U(0, 1)^2 (mostly bright, as real coatings),
- sigma_t ~ U(0, 5).

Every transform maps [0, 1] into the legal range of ``neural.material.RANGES``
(tests check it). The data sets (``sample_params``), the held-out set
(``training.evaluate``) and the operation training (``random_leaf_params``)
draw their uniforms from their own seeded generators and turn them into
parameters here, so each keeps its own deterministic stream.
"""
from __future__ import annotations

from typing import Callable, TypeVar

import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import CONDUCTOR, DIELECTRIC
from nbrdf.neural.stack import (
    CLASSES,
    COATS,
    DIFFUSE_BASED,
    INTERFACE_COLUMNS,
    PAPER_CLASSES,
    PARAM_NAMES,
    THREE_LAYERED,
    P,
)

Tensor = torch.Tensor
U = TypeVar("U")  # a float, a numpy array or a torch tensor of uniforms


def roughness(u: U) -> U:
    """GGX roughness from a uniform: U(0.216, 1)^3, in [0.0101, 1]."""
    return (0.216 + 0.784 * u) ** 3


def ior(u: U) -> U:
    """Relative index of refraction: U(1.05, 2)."""
    return 1.05 + 0.95 * u


def colour(u: U) -> U:
    """A conductor's r0 or a diffuse base's albedo: U(0, 1)."""
    return u


def medium_albedo(u: U) -> U:
    """A medium's single-scattering albedo: 1 - U(0, 1)^2."""
    return 1.0 - u * u


def sigma_t(u: U) -> U:
    """A slab's extinction (thickness 1): U(0, 5)."""
    return 5.0 * u


#: parameter -> (legal-range key in ``neural.material.RANGES``, transform).
DISTRIBUTIONS: dict[str, tuple[str, Callable]] = {
    "roughness": ("roughness", roughness),
    "ior": ("ior", ior),
    "r0": ("r0", colour),
    "base_albedo": ("albedo", colour),
    "medium_albedo": ("albedo", medium_albedo),
    "sigma_t": ("sigma_t", sigma_t),
}


def _u(g: torch.Generator, n: int) -> Tensor:
    return torch.rand(n, generator=g, dtype=torch.float64)


def sample_params(cls: str, n: int, g: torch.Generator) -> Tensor:
    """n single-channel stacks of a class as data-set parameter vectors
    (n, len(PARAM_NAMES)), float64 (``neural.stack.params_to_stack`` decodes
    them). The draw order is fixed: data-set shards depend on it."""
    if cls not in CLASSES:
        raise NbrdfError(f"unknown BRDF class {cls!r} (one of {', '.join(CLASSES)})")
    p = torch.zeros(n, len(PARAM_NAMES), dtype=torch.float64)
    p[:, P["class"]] = CLASSES.index(cls)
    if cls == "conductor":
        p[:, P["base_roughness"]], p[:, P["base_value"]] = roughness(_u(g, n)), colour(_u(g, n))
    elif cls == "dielectric":
        p[:, P["top_roughness"]], p[:, P["top_ior"]] = roughness(_u(g, n)), ior(_u(g, n))
    else:
        for rough, eta, alb, sig in INTERFACE_COLUMNS[: COATS[cls]]:  # top down, each coat's four in turn
            p[:, P[rough]], p[:, P[eta]] = roughness(_u(g, n)), ior(_u(g, n))
            p[:, P[alb]], p[:, P[sig]] = medium_albedo(_u(g, n)), sigma_t(_u(g, n))
        if cls in DIFFUSE_BASED:
            p[:, P["base_value"]] = colour(_u(g, n))
        else:
            p[:, P["base_roughness"]], p[:, P["base_value"]] = roughness(_u(g, n)), colour(_u(g, n))
    return p


def _pick_stacks(p: Tensor, share: float, g: torch.Generator) -> tuple[Tensor, Tensor]:
    """Three uniforms per row of ``p`` (drawn for every row, so the stream does
    not depend on the classes) and the mask of the stacks (not single
    interfaces) whose first uniform falls below ``share``."""
    u = torch.rand(p.shape[0], 3, generator=g, dtype=torch.float64)
    cls = p[:, P["class"]].round().long()
    stacks = (cls != CLASSES.index("conductor")) & (cls != CLASSES.index("dielectric"))
    return u, stacks & (u[:, 0] < share)


def sharpen_coats(p: Tensor, share: float, g: torch.Generator, bright: float = 1.0) -> Tensor:
    """Redraws a ``share`` of the stacks in ``p`` (in place; returned) in the
    look-development range the paper's distributions rarely reach: a top coat
    of roughness U(0.01, 0.06), over a bright base (r0 or albedo
    1 - U(0, 1)^2) for a ``bright`` share of them (the rest keep their base:
    lacquers over dark bases). Single interfaces are left alone. Draws a fixed
    number of uniforms per row (one more when ``bright`` < 1), so the result
    depends only on ``g``'s state and ``p``."""
    u, pick = _pick_stacks(p, share, g)
    p[pick, P["top_roughness"]] = 0.01 + 0.05 * u[pick, 1]
    lit = pick
    if bright < 1.0:
        lit = pick & (torch.rand(p.shape[0], generator=g, dtype=torch.float64) < bright)
    p[lit, P["base_value"]] = 1.0 - u[lit, 2] ** 2
    return p


def clear_top_slabs(p: Tensor, share: float, g: torch.Generator) -> Tensor:
    """Redraws the top slab of a ``share`` of the stacks in ``p`` (in place;
    returned) as a clear coat's: no medium at all (sigma_t 0) for half of
    them, a thin one (sigma_t U(0, 0.3)) for the rest -- a coat laid straight
    on its base (coated metals, glazes, the clear coat over a car paint's
    base coat), which U(0, 5) almost never draws. Single interfaces are left
    alone; a fixed number of uniforms per row."""
    u, pick = _pick_stacks(p, share, g)
    p[pick, P["sigma_t_1"]] = torch.where(u[pick, 1] < 0.5, 0.0, 0.3 * u[pick, 2])
    return p


def darken_top_slabs(p: Tensor, share: float, g: torch.Generator) -> Tensor:
    """Redraws the top slab of a ``share`` of the stacks in ``p`` (in place;
    returned) as a dark, thick coloured coating: albedo U(0, 0.3), sigma_t
    U(2, 5) -- black and tinted lacquers, whose bodies are a few per cent of
    a bright one's; the paper's mostly bright media (albedo 1 - U^2) give
    such a slab to one stack in ten, a black one (albedo <= 0.1, sigma_t >= 3)
    to one in fifty. Single interfaces are left alone; a fixed number of
    uniforms per row."""
    u, pick = _pick_stacks(p, share, g)
    p[pick, P["albedo_1"]] = 0.3 * u[pick, 1]
    p[pick, P["sigma_t_1"]] = 2.0 + 3.0 * u[pick, 2]
    return p


def paint_base_coats(p: Tensor, share: float, g: torch.Generator) -> Tensor:
    """Redraws the lower half of a ``share`` of the three-layered stacks in
    ``p`` (in place; returned) as a car paint's base coat: a rough, low-index
    inner interface (roughness U(0.1, 0.4), ior U(1.25, 1.6)) over a coloured,
    thick slab (albedo U(0, 1)^2, so half of them below 0.25; sigma_t U(1, 5)).
    The paper's distributions give such a slab (dark and thick) under a clear
    coat to about one three-layer stack in a hundred. Other classes are left
    alone; a fixed number of uniforms per row."""
    u, pick = _pick_stacks(p, share, g)
    v = torch.rand(p.shape[0], 2, generator=g, dtype=torch.float64)
    pick = pick & torch.isin(p[:, P["class"]].round().long(),
                             torch.tensor([CLASSES.index(c) for c in THREE_LAYERED]))
    p[pick, P["mid_roughness"]] = 0.1 + 0.3 * u[pick, 1]
    p[pick, P["mid_ior"]] = 1.25 + 0.35 * u[pick, 2]
    p[pick, P["albedo_2"]] = v[pick, 0] ** 2
    p[pick, P["sigma_t_2"]] = 1.0 + 4.0 * v[pick, 1]
    return p


def lossless_stacks(p: Tensor, share: float, g: torch.Generator) -> Tensor:
    """Makes a ``share`` of the stacks in ``p`` (in place; returned) lossless: every medium's albedo, the
    conductor's r0 or the diffuse base's albedo set to 1, so the stack loses light only at its rough
    interfaces (the white-furnace stacks: their light bounces longest, and the paper's distributions,
    albedo 1 - U^2, never draw exactly 1). Single interfaces are left alone; a fixed number of uniforms per row."""
    _u3, pick = _pick_stacks(p, share, g)
    coats = torch.tensor([COATS.get(c, 0) for c in CLASSES])[p[:, P["class"]].round().long()]
    for j, (_r, _i, alb, _s) in enumerate(INTERFACE_COLUMNS):
        p[pick & (coats > j), P[alb]] = 1.0  # the class's own slabs: unused columns stay 0
    p[pick, P["base_value"]] = 1.0
    return p


def mixed_params(n: int, g: torch.Generator) -> Tensor:
    """n parameter vectors over the paper's classes (even shares, the rest two-layer)."""
    per = [n // len(PAPER_CLASSES)] * len(PAPER_CLASSES)
    per[PAPER_CLASSES.index("two_layer")] += n - sum(per)
    return torch.cat([sample_params(c, k, g) for c, k in zip(PAPER_CLASSES, per)])


def f82_tint(u: U) -> U:
    """A conductor's F82 tint (OpenPBR's specular_color on a metal): 1 (Schlick) for u < 1/4, else
    U(0, 1) (the paper's distributions have no tint; a quarter of plain conductors keeps the
    correction network honest at its anchor)."""
    return torch.where(u < 0.25, torch.ones_like(u), (u - 0.25) / 0.75) if isinstance(u, torch.Tensor) else (
        1.0 if u < 0.25 else (u - 0.25) / 0.75)


def random_leaf_params(kind: str, n: int, g: torch.Generator) -> Tensor:
    """n single-channel leaf parameters (float32) in ``neural.leaf.LEAF_PARAMS``
    order: conductor (roughness, r0, f82_tint), dielectric (roughness, ior), diffuse (albedo)."""
    u = torch.rand(n, 3, generator=g)
    rough = roughness(u[:, 0])
    if kind == CONDUCTOR:
        return torch.stack([rough, colour(u[:, 1]), f82_tint(u[:, 2])], -1)
    if kind == DIELECTRIC:
        return torch.stack([rough, ior(u[:, 1])], -1)
    return colour(u[:, :1])
