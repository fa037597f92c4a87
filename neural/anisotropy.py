"""Anisotropic interfaces (SPEC section 10), the conventions in one place.

A ``dielectric`` or ``conductor`` layer's ``anisotropy`` a turns its GGX
alpha (``roughness``) into OpenPBR's pair alpha_x = alpha sqrt(2 / (1 + (1 -
a)^2)), alpha_y = (1 - a) alpha_x, along the tangent frame that the
material's ``anisotropy_rotation`` (degrees) turns about the normal,
counter-clockwise seen from above; every interface of a stack shares it.
Here: the alphas, the change of frame, and the one-line refusal of the paths
that cannot take anisotropy yet (``require_isotropic``).
"""
from __future__ import annotations

import math

import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material, TextureRef

Tensor = torch.Tensor


def alphas(alpha, a):
    """(alpha_x, alpha_y) of GGX alpha ``alpha`` and anisotropy ``a`` (floats, arrays or tensors). a = 0
    gives (alpha, alpha) bit for bit: sqrt(2 / 2) is 1 exactly."""
    one_minus = 1.0 - a
    scale = (2.0 / (1.0 + one_minus * one_minus)) ** 0.5
    ax = alpha * scale
    return ax, one_minus * ax


def to_frame(w: Tensor, rotation_deg) -> Tensor:
    """Directions (..., 3) in the material's rotated frame: their coordinates along the tangent turned by
    ``rotation_deg`` (broadcast to the batch) counter-clockwise about z, the bitangent and z."""
    t = torch.as_tensor(rotation_deg, dtype=w.dtype, device=w.device) * (math.pi / 180.0)
    c, s = torch.cos(t), torch.sin(t)
    x, y = w[..., 0], w[..., 1]
    return torch.stack([c * x + s * y, c * y - s * x, w[..., 2]], -1)


def from_frame(w: Tensor, rotation_deg) -> Tensor:
    """The inverse of ``to_frame``: directions given in the rotated frame, back in the shading frame."""
    return to_frame(w, -torch.as_tensor(rotation_deg, dtype=w.dtype, device=w.device))


def anisotropic_layers(material: Material) -> list[int]:
    """Indices of the layers with a non-zero (or texture-mapped) anisotropy."""
    out = []
    for i, layer in enumerate(material.layers):
        a = getattr(layer, "anisotropy", 0.0)
        if isinstance(a, TextureRef) or a != 0:
            out.append(i)
    return out


def require_isotropic(material: Material, path: str) -> None:
    """One line (``NbrdfError``) naming the first anisotropic layer when ``path`` (e.g. "the neural
    leaf encoders and layering") cannot take anisotropy yet: never a silent drop."""
    found = anisotropic_layers(material)
    if found:
        raise NbrdfError(f"layers[{found[0]}].anisotropy: anisotropy is not yet supported by {path}")
