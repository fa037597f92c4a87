"""A lone conductor's own encoders: what ``nbrdf train leaf --part bare`` trains (``training.train_operations``;
decision 124).

The conductor encoder and its F82 correction make latents for two uses: the
layering network's input under interfaces, and what a lone (bare) metal shows.
The layering network was trained on the first, so that encoder cannot move; the
frozen decoder fits a lone conductor 4 dB closer than it does (projection on the
held-out brushed conductors' isotropic equivalents: 53.8 against 49.7 dB lobe
PSNR). So a lone conductor gets a copy of the pair, fine-tuned through the frozen
decoder against the closed form; every stack with an interface keeps its codes.

The roughness it is trained on is the paper's distribution for half the draws
and, for the other half, the geometric-mean alpha of an anisotropic draw
(anisotropy U(0, 0.9), SPEC section 10), which is what the encoder sees of a
brushed metal (``neural.anisotropy``).
"""
from __future__ import annotations

import torch

from nbrdf.neural.anisotropy import geometric_alpha
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import CONDUCTOR
from nbrdf.neural.leaf import BARE, BARE_F82, F82, LeafEncoders
from nbrdf.neural.model import NeuralModel
from nbrdf.training.distributions import random_leaf_params

Tensor = torch.Tensor


def bare_params(n: int, g: torch.Generator) -> Tensor:
    """n lone-conductor parameters (roughness, r0, f82_tint): the paper's draws, half of them with the roughness
    replaced by the geometric-mean alpha of the same roughness at an anisotropy U(0, 0.9)."""
    p = random_leaf_params(CONDUCTOR, n, g)
    u = torch.rand(n, 2, generator=g)
    brushed = geometric_alpha(p[:, 0].double(), 0.9 * u[:, 0].double()).float()
    p[:, 0] = torch.where(u[:, 1] < 0.5, brushed, p[:, 0])
    return p


def bare_encoders(model: NeuralModel) -> LeafEncoders:
    """The bundle's leaf encoders, frozen, with a bare pair to train: the bundle's own bare pair when it has one
    (fine-tuned further), else a copy of the conductor's pair (the start is exactly today's lone-conductor latent)."""
    old = model.require("leaf")
    if not old.has_f82:
        raise NbrdfError("a bare pair needs encoders with the F82 correction (`nbrdf train leaf --part f82` first)")
    specs = {**old.specs, BARE: old.specs.get(BARE, old.specs[CONDUCTOR]),
             BARE_F82: old.specs.get(BARE_F82, old.specs[F82])}
    leaf = LeafEncoders(specs)
    for name, net in leaf.nets.items():
        src = name if name in old.nets else {BARE: CONDUCTOR, BARE_F82: F82}[name]
        net.load_state_dict(old.nets[src].state_dict())
        net.requires_grad_(name in (BARE, BARE_F82))
    return leaf
