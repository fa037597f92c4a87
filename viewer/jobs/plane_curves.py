"""The lobe plot's curves: f cos(theta_o) in the plane of incidence, of the
neural image, its reference and up to two saved materials (the View panel's
polar plot)."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Callable

import numpy as np
import torch

from nbrdf.training.reference import single_layer_eval
from nbrdf.viewer.gpu.pipeline import analytic_capable

if TYPE_CHECKING:
    from nbrdf.neural.decoder import Decoder
    from nbrdf.neural.material import Material
    from nbrdf.viewer.reference.compare import Compare

#: Rec. 709 luminance weights.
LUMINANCE = (0.2126, 0.7152, 0.0722)


class PlaneCurves:
    """A session's plane-of-incidence curves and the saved ones; the Monte Carlo
    reference's curve comes from ``compare`` (the worker's, when ready)."""

    def __init__(self, compare: "Compare"):
        self.compare = compare
        self.saved: list[tuple[str, torch.Tensor]] = []
        """(name, latent) of the kept curves, two at most."""

    def save(self, name: str, latent: torch.Tensor) -> None:
        """Keeps a material's latent for the polar plot (two at most)."""
        self.saved = (self.saved + [(name, latent)])[-2:]

    def curves(self, material: "Material", latent: Callable[[], torch.Tensor], decoder: "Decoder",
               theta_i: float, n: int = 181) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """f cos(theta_o) in the plane of incidence at ``theta_i``, luminance,
        for theta_o in [-90, 90] degrees (negative: the side of the specular peak):
        neural (``latent()``, asked for an untextured material only), reference
        (closed form, or the Monte Carlo worker's when ready), saved."""
        th = np.linspace(-89.5, 89.5, n)
        t = np.radians(th)
        wo = torch.tensor(np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], -1), dtype=torch.float32)
        ti = math.radians(theta_i)
        wi = torch.tensor([[math.sin(-ti), 0.0, math.cos(ti)]], dtype=torch.float32).expand(n, 3).contiguous()
        lum = torch.tensor(LUMINANCE)
        out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        cos = wo[:, 2]
        m = material
        if not m.is_textured:
            with torch.no_grad():
                out["neural"] = (th, ((decoder.eval_rgb(latent(), wi, wo) @ lum) * cos).numpy())
            if analytic_capable(m):
                out["reference"] = (th, ((single_layer_eval(m.base, wi, wo) @ lum) * cos).numpy())
            else:
                curve = self.compare.plane_curve(m, theta_i, wi, wo, n)
                if curve is not None:
                    out["reference"] = (th, curve @ lum.numpy())
        for name, z in self.saved:
            with torch.no_grad():
                out[name] = (th, ((decoder.eval_rgb(z, wi, wo) @ lum) * cos).numpy())
        return out
