"""Leaf encoders (SPEC section 6): a single layer's parameters -> its latent.

One small network per leaf type maps the parameters of one colour channel to
the latent the decoder turns into that layer's BRDF. They are trained through
the frozen decoder against the closed-form BRDFs (``training.train_operations``),
so a slider moves a latent in microseconds instead of a projection's seconds.
Inputs are reparametrised so the paper's distributions are near uniform:
roughness enters as its cube root, ior linearly over its legal range.

A conductor's F82 tint (OpenPBR's edge colour, SPEC section 11) enters through
a second network whose output is added times (1 - tint): a tint of 1 gives
exactly the latent of the paper's Schlick conductor, so every stack built on
it (the layering network was trained on those latents) is unchanged.

A lone conductor (no interface above it) may have encoders of its own, the
conductor's pair fine-tuned on their own (decision 124): its latent is what is
shown, not a layering input, so it can fit the closed form closer than the
layering network's inputs may move.
"""
from __future__ import annotations

import torch
from torch import nn

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import ANISOTROPY, CONDUCTOR, DIELECTRIC, DIFFUSE, KINDS
from nbrdf.neural.nets import MLP, MLPSpec

Tensor = torch.Tensor

#: Leaf type -> parameter names, in input order (anisotropy, SPEC section 10, has no input yet: an
#: anisotropic material is refused before it reaches the encoders, ``neural.model``).
LEAF_PARAMS: dict[str, tuple[str, ...]] = {k: tuple(p.name for p in KINDS[k].params if p.name != ANISOTROPY)
                                           for k in (CONDUCTOR, DIELECTRIC, DIFFUSE)}
#: The conductor's F82-tint correction network (its output times 1 - tint is added to the conductor's latent).
F82 = "conductor_f82"
#: A lone conductor's encoder and F82 correction (decision 124): the conductor's pair fine-tuned for latents that are
#: shown as they are, never layered.
BARE, BARE_F82 = "conductor_bare", "conductor_bare_f82"
#: Every network of the leaf encoders; a bundle from before the F82 tint lacks F82, one from before decision 124
#: the bare pair.
LEAF_NETS: tuple[str, ...] = (*LEAF_PARAMS, F82, BARE, BARE_F82)


def leaf_features(kind: str, params: Tensor) -> Tensor:
    """Network inputs (N, k) from raw parameters (N, k) in LEAF_PARAMS order (the conductor's
    third feature, its F82 tint, feeds the correction network only)."""
    if kind == CONDUCTOR:
        return torch.stack([params[:, 0].clamp(1e-4, 1).pow(1 / 3), params[:, 1], params[:, 2]], -1)
    if kind == DIELECTRIC:
        return torch.stack([params[:, 0].clamp(1e-4, 1).pow(1 / 3), (params[:, 1] - 1.05) / 0.95], -1)
    if kind == DIFFUSE:
        return torch.stack([params[:, 0], params[:, 0].clamp_min(0).sqrt()], -1)
    raise NbrdfError(f"no leaf encoder for {kind!r} (one of {', '.join(LEAF_PARAMS)})")


def leaf_spec(kind: str, width: int = 64, depth: int = 3) -> MLPSpec:
    """Every leaf has two input features (``leaf_features``); the F82 corrections three."""
    if kind not in LEAF_NETS:
        raise NbrdfError(f"no leaf encoder for {kind!r} (one of {', '.join(LEAF_PARAMS)})")
    return MLPSpec(inputs=3 if kind in (F82, BARE_F82) else 2, outputs=32, width=width, depth=depth)


class LeafEncoders(nn.Module):
    """The three leaf encoders (and the conductor's F82 correction); ``encode(kind, params)``
    -> latents (N, 32)."""

    def __init__(self, specs: dict[str, MLPSpec] | None = None):
        super().__init__()
        specs = specs or {k: leaf_spec(k) for k in (*LEAF_PARAMS, F82)}
        missing = [k for k in LEAF_PARAMS if k not in specs]
        if missing:
            raise NbrdfError(f"leaf encoders: no network for {', '.join(missing)}")
        self.specs = specs
        self.nets = nn.ModuleDict({k: MLP(specs[k]) for k in LEAF_NETS if k in specs})

    @property
    def has_f82(self) -> bool:
        """Whether these encoders take a conductor's F82 tint (bundles from before it do not)."""
        return F82 in self.nets

    @property
    def has_bare(self) -> bool:
        """Whether a lone conductor has encoders of its own (decision 124)."""
        return BARE in self.nets and BARE_F82 in self.nets

    def encode(self, kind: str, params: Tensor, bare: bool = False) -> Tensor:
        """Latents (N, 32) of N leaves; ``bare``: the leaves are lone conductors, shown as they are (their own
        encoders where these encoders have them, decision 124)."""
        if kind not in self.nets:
            raise NbrdfError(f"no leaf encoder for {kind!r} (one of {', '.join(LEAF_PARAMS)})")
        params = torch.as_tensor(params, dtype=torch.float32)
        if params.dim() != 2 or params.shape[1] != len(LEAF_PARAMS[kind]):
            raise NbrdfError(f"{kind} leaf: parameters must be (N, {len(LEAF_PARAMS[kind])}) "
                             f"({', '.join(LEAF_PARAMS[kind])}), got {tuple(params.shape)}")
        if not torch.isfinite(params).all():
            raise NbrdfError(f"{kind} leaf: parameters hold NaN or infinite values")
        x = leaf_features(kind, params)
        if kind != CONDUCTOR:
            return self.nets[kind](x)
        own = bare and self.has_bare
        z = self.nets[BARE if own else kind](x[:, :2])
        edge = 1.0 - params[:, 2:3]
        if self.has_f82:
            return z + edge * self.nets[BARE_F82 if own else F82](x)
        if bool((edge != 0).any()):
            raise NbrdfError("these leaf encoders predate the F82 tint (a conductor with f82_tint 1 only); "
                             "use the shipped weights or `nbrdf train leaf --part f82`")
        return z

    def conductor(self, roughness: Tensor, r0: Tensor, f82_tint: Tensor | float = 1.0, bare: bool = False) -> Tensor:
        return self.encode(CONDUCTOR, torch.stack(torch.broadcast_tensors(_t(roughness), _t(r0), _t(f82_tint)), -1),
                           bare)

    def dielectric(self, roughness: Tensor, ior: Tensor) -> Tensor:
        return self.encode(DIELECTRIC, torch.stack(torch.broadcast_tensors(_t(roughness), _t(ior)), -1))

    def diffuse(self, albedo: Tensor) -> Tensor:
        return self.encode(DIFFUSE, _t(albedo)[:, None])


def _t(x) -> Tensor:
    return torch.as_tensor(x, dtype=torch.float32).reshape(-1)
