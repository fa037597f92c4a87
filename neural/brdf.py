"""The one BRDF interface shared by analytic, Monte Carlo and neural BRDFs.

Conventions (SPEC section 3): local frame with z the normal; ``wi`` points to
the light, ``wo`` to the viewer, both unit and away from the surface; values
are in 1/sr and exclude every cosine. Every tensor is batched over its leading
dimension: directions are (N, 3); values and pdfs are (N,) for a
single-channel BRDF.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import torch


@dataclass
class Sample:
    """A sampled direction ``w`` (N, 3) with the BRDF value ``f`` (N,) for the
    pair (given, w) and the solid-angle ``pdf`` (N,) of drawing it. ``pdf`` is
    0 where sampling failed (then ``f`` is 0 too)."""

    w: torch.Tensor
    f: torch.Tensor
    pdf: torch.Tensor

    @property
    def weight(self) -> torch.Tensor:
        """f |cos theta_w| / pdf, 0 where the pdf is 0."""
        ok = self.pdf > 0
        return torch.where(ok, self.f * self.w[..., 2].abs() / torch.where(ok, self.pdf, 1.0), 0.0)


@runtime_checkable
class BRDF(Protocol):
    """eval, sample and pdf of one channel, batched over N (wi, wo) pairs."""

    def eval(self, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
        """f(wi, wo), shape (N,)."""
        ...

    def sample(self, w: torch.Tensor, u: torch.Tensor) -> Sample:
        """Draws the other direction given ``w`` from uniforms ``u`` (N, 3)."""
        ...

    def pdf(self, w: torch.Tensor, w_other: torch.Tensor) -> torch.Tensor:
        """Solid-angle density with which ``sample(w, .)`` returns ``w_other``."""
        ...
