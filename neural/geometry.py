"""Direction geometry shared by every part: the standard incidence, cosine
sampling, the half/difference parameterisation, and the standard lobe grid (SPEC section 9)."""
from __future__ import annotations

import math

import torch


def incidence(theta_i_deg: float, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """The standard incident direction (3,) at theta_i degrees, phi_i = 0."""
    t = math.radians(theta_i_deg)
    return torch.tensor([math.sin(t), 0.0, math.cos(t)], dtype=dtype)


def cosine_hemisphere(u1: torch.Tensor, u2: torch.Tensor) -> torch.Tensor:
    """Cosine-distributed unit vectors (..., 3) about +z from uniforms u1, u2
    (pdf cos(theta) / pi)."""
    r, phi = u1.sqrt(), 2 * math.pi * u2
    return torch.stack([r * torch.cos(phi), r * torch.sin(phi), (1 - u1).clamp_min(0).sqrt()], -1)


def normalize(v: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    return v / v.norm(dim=-1, keepdim=True).clamp_min(eps)


def half_vector(wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
    """Reflection half vector, flipped into the upper hemisphere."""
    h = normalize(wi + wo)
    return torch.where(h[..., 2:3] < 0, -h, h)


def half_diff(wi: torch.Tensor, wo: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Rusinkiewicz coordinates: the half vector h and the difference vector d
    (wi expressed in the frame where h is the pole), both (..., 3)."""
    h = half_vector(wi, wo)
    # Rotate wi by -phi_h about z, then by -theta_h about y.
    phi_h = torch.atan2(h[..., 1], h[..., 0])
    theta_h = torch.acos(h[..., 2].clamp(-1.0, 1.0))
    cp, sp = torch.cos(phi_h), torch.sin(phi_h)
    x = cp * wi[..., 0] + sp * wi[..., 1]
    y = -sp * wi[..., 0] + cp * wi[..., 1]
    z = wi[..., 2]
    ct, st = torch.cos(theta_h), torch.sin(theta_h)
    d = torch.stack([ct * x - st * z, y, st * x + ct * z], dim=-1)
    return h, d


def lobe_grid(n: int = 64, dtype: torch.dtype = torch.float32) -> tuple[torch.Tensor, torch.Tensor]:
    """Outgoing directions for the standard lobe image: pixel centres of an
    n x n grid over the projected unit disk. Row index runs along y from -1 to
    1, column index along x. Returns wo (n, n, 3) (zeros outside the disk)
    and the disk mask (n, n)."""
    c = (torch.arange(n, dtype=torch.float64) + 0.5) / n * 2.0 - 1.0
    y, x = torch.meshgrid(c, c, indexing="ij")
    r2 = x * x + y * y
    mask = r2 < 1.0
    z = torch.sqrt((1.0 - r2).clamp_min(0.0))
    wo = torch.stack([x, y, z], dim=-1) * mask[..., None]
    return wo.to(dtype), mask
