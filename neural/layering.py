"""Layering network (SPEC section 6): per channel (top interface, bottom
code, albedo, sigma_t) -> the code of the stack "top interface over a medium
slab over bottom". Three or more layers apply it recursively from the bottom
up, the bottom code then being itself a layered code.

Under the coat split (``neural.coat``) every code is a body latent plus a
clear coat. The top of a layering is always a dielectric interface, so it
enters by its two parameters (they are the new code's coat, exact); the
network predicts the new body, the light that entered through that
interface, from the bottom's body latent and coat and the slab.

sigma_t enters as the slab's normal transmittance exp(-sigma_t) and its
square as well as linearly, so thin and thick slabs are both well resolved
over the whole legal range [0, 5]. The ``slab`` feature set (``LayeringSpec.medium``)
adds the slab's closed-form response to diffuse light: its hemispherical
transmittance without scattering, 2 E3(sigma_t), and its Kubelka-Munk
reflectance and transmittance, which couple albedo and thickness the way the
body under a dark, thick slab does.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import torch
from torch import nn

from nbrdf.neural.coat import COAT_PARAMS, coat_features, with_coat
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.nets import MLP, MLPSpec

Tensor = torch.Tensor
LATENT = 32
CODE = LATENT + COAT_PARAMS
COAT_FEATURES = 3
#: Slab descriptions the layering network can take, by name, with their
#: feature counts; each set starts with the one before it, so a network is
#: widened to a larger set by appending input columns.
MEDIUM_SETS = {"basic": 5, "slab": 8}

# Abramowitz & Stegun 5.1.53 (0 < x <= 1, |error| < 2e-7) and 5.1.56 (x >= 1, relative error < 5e-8) for E1.
_E1_SMALL = (-0.57721566, 0.99999193, -0.24991055, 0.05519968, -0.00976004, 0.00107857)
_E1_NUM = (8.5733287401, 18.0590169730, 8.6347608925, 0.2677737343)
_E1_DEN = (9.5733223454, 25.6329561486, 21.0996530827, 3.9584969228)


def exp_integral_e1(x: Tensor) -> Tensor:
    """E1(x) for x > 0 (float64 inside; x = 0 gives a large finite value)."""
    x = x.double().clamp_min(1e-30)
    small = -torch.log(x) + sum(c * x ** k for k, c in enumerate(_E1_SMALL))
    y = x.clamp_min(1.0)
    num = y ** 4 + _E1_NUM[0] * y ** 3 + _E1_NUM[1] * y ** 2 + _E1_NUM[2] * y + _E1_NUM[3]
    den = y ** 4 + _E1_DEN[0] * y ** 3 + _E1_DEN[1] * y ** 2 + _E1_DEN[2] * y + _E1_DEN[3]
    return torch.where(x <= 1, small, num / den * torch.exp(-y) / y)


def diffuse_transmittance(tau: Tensor) -> Tensor:
    """2 E3(tau): the share of cosine-weighted (diffuse) light that crosses a
    non-scattering slab of optical depth tau unscattered (1 at tau = 0)."""
    t = tau.double().clamp_min(0)
    e3 = ((1 - t) * torch.exp(-t) + t * t * exp_integral_e1(t)) / 2
    return (2 * e3).to(tau.dtype)


def kubelka_munk(albedo: Tensor, tau: Tensor) -> tuple[Tensor, Tensor]:
    """Diffuse reflectance and transmittance of a slab of single-scattering
    albedo a and optical depth tau (Kubelka-Munk, K = 2 (1 - a) tau and
    S = a tau per slab): R = S sinh(x) / D, T = x / D with x = 2 tau sqrt(1 - a)
    and D = (S + K) sinh(x) + x cosh(x), written through sinh(x) / x so a = 1
    (R = tau / (1 + tau)) and tau = 0 (R = 0, T = 1) are exact."""
    a, t = albedo.double().clamp(0, 1), tau.double().clamp_min(0)
    x = 2 * t * (1 - a).sqrt()
    sinhc = torch.where(x < 1e-4, 1 + x * x / 6, torch.sinh(x) / x.clamp_min(1e-4))
    d = (a * t + 2 * (1 - a) * t) * sinhc + torch.cosh(x)
    return (a * t * sinhc / d).to(albedo.dtype), (1 / d).to(albedo.dtype)


def medium_features(albedo: Tensor, sigma_t: Tensor, medium: str = "basic") -> Tensor:
    """(N, MEDIUM_SETS[medium]) inputs describing the slab of unit thickness."""
    feats = [albedo, 1 - (1 - albedo).clamp_min(0).sqrt(), sigma_t / 5, torch.exp(-sigma_t), torch.exp(-2 * sigma_t)]
    if medium == "slab":
        feats += [diffuse_transmittance(sigma_t), *kubelka_munk(albedo, sigma_t)]
    elif medium != "basic":
        raise NbrdfError(f"layering: medium features {medium!r} are unknown ({', '.join(MEDIUM_SETS)})")
    return torch.stack(feats, -1)


def _inputs(medium: str) -> int:
    return COAT_FEATURES + LATENT + COAT_FEATURES + MEDIUM_SETS[medium]


@dataclass(frozen=True)
class LayeringSpec(MLPSpec):
    """The layering network's MLP and the slab description it takes."""

    medium: str = "basic"
    """slab features: basic (albedo, sqrt form, sigma_t / 5, exp(-sigma_t), exp(-2 sigma_t)); slab (those and
    the closed-form diffuse transmittance 2 E3(sigma_t) and Kubelka-Munk reflectance and transmittance).
    Files written before this field existed hold basic networks."""

    def __post_init__(self):
        super().__post_init__()
        if self.medium not in MEDIUM_SETS:
            raise NbrdfError(f"layering: medium features {self.medium!r} are unknown ({', '.join(MEDIUM_SETS)})")
        if self.inputs != _inputs(self.medium) or self.outputs != LATENT:
            raise NbrdfError(f"layering: a network of {self.inputs} inputs and {self.outputs} outputs does not fit "
                             f"medium features {self.medium!r} ({_inputs(self.medium)} inputs, {LATENT} outputs)")


def layering_spec(width: int = 256, depth: int = 3, medium: str = "basic") -> LayeringSpec:
    if medium not in MEDIUM_SETS:
        raise NbrdfError(f"layering: medium features {medium!r} are unknown ({', '.join(MEDIUM_SETS)})")
    return LayeringSpec(inputs=_inputs(medium), outputs=LATENT, width=width, depth=depth, medium=medium)


class LayeringNet(nn.Module):
    """body = bottom body + MLP(top, bottom, medium), coat = top: the residual
    form starts from "the medium hides nothing", right for a clear coat."""

    def __init__(self, spec: MLPSpec | None = None):
        """``spec``: a ``LayeringSpec``; a plain ``MLPSpec`` (a file's record
        without the medium field) is the basic feature set."""
        super().__init__()
        spec = spec or layering_spec()
        self.spec = spec if isinstance(spec, LayeringSpec) else LayeringSpec(**asdict(spec))
        self.mlp = MLP(self.spec)

    def widened(self, medium: str) -> "LayeringNet":
        """A copy taking the larger feature set ``medium`` whose first-layer
        weights on the added features are zero: it computes exactly what this
        network does until training teaches it to use them."""
        old, new = MEDIUM_SETS[self.spec.medium], MEDIUM_SETS.get(medium, -1)
        if new < old:
            raise NbrdfError(f"layering: cannot widen medium features {self.spec.medium!r} to {medium!r}")
        net = LayeringNet(replace(self.spec, inputs=_inputs(medium), medium=medium))
        state = {k: v.detach().clone() for k, v in self.state_dict().items()}
        w = state["mlp.net.0.weight"]
        state["mlp.net.0.weight"] = torch.cat([w, w.new_zeros(w.shape[0], new - old)], 1)
        net.load_state_dict(state)
        return net

    def forward(self, top: Tensor, bottom: Tensor, albedo: Tensor, sigma_t: Tensor) -> Tensor:
        """Codes (N, 34) of N stacks from the top interfaces' (roughness, ior)
        (N, 2), the bottom codes (N, 34), albedo and sigma_t (N,) or scalars."""
        n = bottom.shape[0]
        if top.shape != (n, COAT_PARAMS) or bottom.shape != (n, CODE):
            raise NbrdfError(f"layering: expected top interfaces (N, {COAT_PARAMS}) and bottom codes (N, {CODE}), "
                             f"got {tuple(top.shape)} and {tuple(bottom.shape)}")
        albedo = torch.as_tensor(albedo, dtype=bottom.dtype).expand(n)
        sigma_t = torch.as_tensor(sigma_t, dtype=bottom.dtype).expand(n)
        for name, v, hi in (("albedo", albedo, 1.0), ("sigma_t", sigma_t, 5.0)):
            if not torch.isfinite(v).all() or (v < 0).any() or (v > hi).any():
                raise NbrdfError(f"layering: {name} must lie in [0, {hi:g}]")
        z_b, c_b = bottom[:, :LATENT], bottom[:, LATENT:]
        x = torch.cat([coat_features(top), z_b, coat_features(c_b),
                       medium_features(albedo, sigma_t, self.spec.medium)], -1)
        return with_coat(z_b + self.mlp(x), top)
