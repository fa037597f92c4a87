"""The albedo network: what a layered code's directional albedo should be (issue 40, record 122).

The decoder is fitted to BRDF values, not to the energy they carry, and the layering network's codes of bright,
deep stacks reflect several per cent too little (or too much) light: the furnace report's errors are the
networks'. This network reads a code (its body latent and the coat's roughness and ior) together with the
albedo the decoder gives it at the energy check's incidences (``neural.energy.EnergySettings.thetas``), and
predicts the walk's albedo there as a log ratio to the decoded one. ``neural.energy.settle`` then moves the
body latent the least it can so the decoded albedo matches the prediction (bounded below 1): the code stays a
code, so every consumer -- the window, the Mitsuba plugins, the GLSL export -- gets the corrected one.

It is trained on walk albedos of drawn stacks (``training.albedo_data``, ``training.train_albedo``) and applies to
the layering network's codes of isotropic stacks; refined and projected codes are fitted to the walk already and
are only bounded.
"""
from __future__ import annotations

import torch
from torch import nn

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.nets import MLP, MLPSpec

Tensor = torch.Tensor
#: The code's floats the network reads: the body latent (32) and the coat's roughness and ior.
CODE_INPUTS = 34
#: The largest correction it may predict, as a log ratio (a factor of e^0.5 = 1.65 either way): a guard
#: against a code far from its training data, not a limit the data reaches (its largest is about 0.4).
MAX_LOG_RATIO = 0.5
#: Decoded albedos below this are treated as this (the log of a black channel's albedo carries no signal).
ALBEDO_FLOOR = 1e-3


def albedo_spec(incidences: int, width: int = 64, depth: int = 2) -> MLPSpec:
    """The network's shape for ``incidences`` incidences: code and log albedos in, one log ratio each out."""
    return MLPSpec(inputs=CODE_INPUTS + incidences, outputs=incidences, width=width, depth=depth)


def features(code: Tensor, decoded: Tensor) -> Tensor:
    """(N, 34 + T) inputs: codes (N, >= 34) with their decoded albedos (N, T), the albedos as logs. A code
    without a coat has coat roughness and ior 0 (``neural.coat``), as in training."""
    return torch.cat([code[:, :CODE_INPUTS].float(), decoded.float().clamp_min(ALBEDO_FLOOR).log()], -1)


class AlbedoNet(nn.Module):
    """(code, decoded albedo at T incidences) per channel -> the predicted albedo at those incidences."""

    def __init__(self, spec: MLPSpec):
        super().__init__()
        if spec.inputs <= CODE_INPUTS or spec.outputs != spec.inputs - CODE_INPUTS:
            raise NbrdfError(f"albedo network: {spec.inputs} inputs and {spec.outputs} outputs do not fit "
                             f"{CODE_INPUTS} code floats and one albedo per incidence")
        self.spec = spec
        self.mlp = MLP(spec)

    @property
    def incidences(self) -> int:
        return self.spec.outputs

    def log_ratio(self, code: Tensor, decoded: Tensor) -> Tensor:
        """(N, T) predicted log(walk albedo / decoded albedo), within +-``MAX_LOG_RATIO``."""
        if decoded.shape[-1] != self.incidences:
            raise NbrdfError(f"albedo network: trained for {self.incidences} incidences, given {decoded.shape[-1]}")
        return MAX_LOG_RATIO * torch.tanh(self.mlp(features(code, decoded)) / MAX_LOG_RATIO)

    def forward(self, code: Tensor, decoded: Tensor) -> Tensor:
        """(N, T) the predicted albedo: the decoded one times the predicted ratio."""
        return decoded.clamp_min(0.0) * torch.exp(self.log_ratio(code, decoded))


def log_ratio_target(walk: Tensor, decoded: Tensor) -> Tensor:
    """The training target log(walk / decoded), both floored at ``ALBEDO_FLOOR`` (a black channel: 0)."""
    return walk.clamp_min(ALBEDO_FLOOR).log() - decoded.clamp_min(ALBEDO_FLOOR).log()

