"""The one BRDF interface shared by analytic, Monte Carlo and neural BRDFs.

Conventions (SPEC section 3): local frame with z the normal; ``wi`` points to
the light, ``wo`` to the viewer, both unit and away from the surface; values
are in 1/sr and exclude every cosine. Every tensor is batched over its leading
dimension: directions are (N, 3); values are (N,) for a single-channel BRDF
(``BRDF``) and (N, 3) for a material's RGB BRDF (``RGBBRDF``); pdfs are (N,):
the colour channels share one sampler.

``RGBBRDF`` is what every evaluation method of a material returns (the
factory is ``training.brdfs.brdf_for``): closed form, the Monte Carlo
reference (which also reports its standard error), a measured table, the
analytic layering baseline, or a neural latent.
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
        """f |cos theta_w| / pdf, 0 where the pdf is 0; (N,) or (N, 3) as f."""
        ok = self.pdf > 0
        if self.f.dim() == self.pdf.dim():
            return torch.where(ok, self.f * self.w[..., 2].abs() / torch.where(ok, self.pdf, 1.0), 0.0)
        scale = torch.where(ok, self.w[..., 2].abs() / torch.where(ok, self.pdf, 1.0), 0.0)
        return self.f * scale[..., None]


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


@runtime_checkable
class RGBBRDF(Protocol):
    """A material's BRDF in three colour channels, batched over N pairs:
    ``eval`` (N, 3); ``sample`` (f (N, 3), one pdf (N,) for all channels);
    ``pdf`` (N,); ``eval_with_error`` also gives the standard error (N, 3)
    of a Monte Carlo estimate, or None for an exact value."""

    def eval(self, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
        """f(wi, wo), shape (N, 3)."""
        ...

    def eval_with_error(self, wi: torch.Tensor, wo: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        """(f (N, 3), standard error (N, 3) or None when f is exact)."""
        ...

    def sample(self, w: torch.Tensor, u: torch.Tensor) -> Sample:
        """Draws the other direction given ``w`` from uniforms ``u`` (N, 3)."""
        ...

    def pdf(self, w: torch.Tensor, w_other: torch.Tensor) -> torch.Tensor:
        """Solid-angle density with which ``sample(w, .)`` returns ``w_other``."""
        ...


class ExactRGB:
    """Mixin: ``eval_with_error`` of a BRDF whose values are exact."""

    def eval_with_error(self, wi: torch.Tensor, wo: torch.Tensor) -> tuple[torch.Tensor, None]:
        return self.eval(wi, wo), None  # type: ignore[attr-defined]
