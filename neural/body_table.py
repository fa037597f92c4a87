"""A decoded body baked into a small table over isotropic half/difference angles.

The decoder's features (``decoder.rusink5`` and ``lobes11``) are functions of
the Rusinkiewicz angles theta_h, theta_d and phi_d alone, and they are unchanged
by phi_d -> pi - phi_d (swapping and mirroring the directions). So a material's
body is a function of (theta_h, theta_d, phi_d) over [0, pi/2]^3, and one
batched decoder pass over a grid of those angles after each edit turns every
later per-pixel decoder evaluation into one filtered 3D-texture fetch.

Layout (what viewer/shaders/body_table.glsl reads): ``values`` (K, M, N, 3)
float32, the decoder's log f per RGB channel, index [k, j, i] at the grid nodes

- theta_h = (i / (N - 1))^2 * pi / 2   (sqrt mapping: nodes dense at the specular peak)
- theta_d = j / (M - 1) * pi / 2
- phi_d   = k / (K - 1) * pi / 2       (folded: 0.5 acos(cos 2 phi_d))

A body that is not reciprocal (Belcour's model, viewer/gpu/belcour_gpu.py) needs
the swap of wi and wo apart: an ``ordered`` table keeps phi_d over [0, pi],
measured from the half vector's tilt away from the normal (``cos_phi_d``).

Log space keeps trilinear interpolation of a peaked lobe accurate. Nodes whose
directions fall below the horizon keep the network's value (a smooth
continuation); the shader zeroes f there as the decoder does. The clear coat
is not in the table: it stays exact (closed form).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from nbrdf.neural.decoder import Decoder, rusink5
from nbrdf.neural.errors import NbrdfError


@dataclass(frozen=True)
class TableSize:
    """Grid nodes per angle of a body table."""

    theta_h: int = 64
    """Nodes over theta_h (sqrt-mapped)."""
    theta_d: int = 32
    """Nodes over theta_d (linear)."""
    phi_d: int = 16
    """Nodes over the folded phi_d in [0, pi/2] (linear; [0, pi] when ``ordered``)."""
    ordered: bool = False
    """phi_d over [0, pi] with wi's side kept: a body that is not reciprocal (Belcour's
    model, viewer/gpu/belcour_gpu.py); False: folded by the swap of wi and wo as well."""

    def check(self) -> "TableSize":
        if min(self.theta_h, self.theta_d, self.phi_d) < 2 or max(self.theta_h, self.theta_d, self.phi_d) > 512:
            raise NbrdfError(f"body table size {self.theta_h}x{self.theta_d}x{self.phi_d}: each 2..512")
        return self

    @property
    def shape(self) -> tuple[int, int, int]:
        """(phi_d, theta_d, theta_h): the array's (depth, height, width)."""
        return self.phi_d, self.theta_d, self.theta_h


def table_directions(size: TableSize) -> tuple[torch.Tensor, torch.Tensor]:
    """(wi, wo), each (K, M, N, 3) float32, of the grid nodes: the half vector
    at (theta_h, azimuth 0), the difference vector at (theta_d, phi_d) around it."""
    size.check()
    k, m, n = size.shape
    th = (torch.linspace(0.0, 1.0, n, dtype=torch.float64) ** 2) * (math.pi / 2)
    td = torch.linspace(0.0, 1.0, m, dtype=torch.float64) * (math.pi / 2)
    pd = torch.linspace(0.0, 1.0, k, dtype=torch.float64) * (math.pi if size.ordered else math.pi / 2)
    pd, td, th = torch.meshgrid(pd, td, th, indexing="ij")
    # The difference vector in the half vector's frame, then rotated by theta_h about y.
    dx, dy, dz = torch.sin(td) * torch.cos(pd), torch.sin(td) * torch.sin(pd), torch.cos(td)
    c, s = torch.cos(th), torch.sin(th)

    def rot(x, y, z):
        return torch.stack([c * x + s * z, y, -s * x + c * z], -1)

    return rot(dx, dy, dz).float(), rot(-dx, -dy, dz).float()


@torch.no_grad()
def bake_body(decoder: Decoder, z: torch.Tensor, size: TableSize = TableSize()) -> torch.Tensor:
    """The body of the material code (or latent) ``z`` (3, >= 32) as log f at the
    grid nodes of ``size``: (K, M, N, 3) float32 (module docstring). One batched
    decoder pass; the coat (if any in ``z``) is not included."""
    if z.ndim != 2 or z.shape[0] != 3 or z.shape[1] < decoder.spec.latent:
        raise NbrdfError(f"bake_body: a (3, >= {decoder.spec.latent}) latent, got {tuple(z.shape)}")
    if not torch.isfinite(z).all():
        raise NbrdfError("bake_body: the latent has non-finite values")
    wi, wo = table_directions(size)
    feats = decoder.encode(wi.reshape(-1, 3), wo.reshape(-1, 3))
    share = decoder.latent_share(z.float())  # (3, W)
    y = decoder.log_f_from_share(share[None, :, :], feats[:, None, :])  # (P, 3)
    return y.clamp(-80.0, 80.0).reshape(*size.shape, 3).contiguous()


def cos_phi_d(wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
    """cos(phi_d) (P,) of wi about the pair's half vector, from the half vector's tilt away
    from the normal: the third angle of an ``ordered`` table (body_table.glsl nb_cos_phi_d)."""
    h = wi + wo
    h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    t = wi - (wi * h).sum(-1, keepdim=True) * h
    ex = h[..., 2:3] * h - torch.tensor([0.0, 0.0, 1.0], dtype=wi.dtype)
    en = ex.norm(dim=-1, keepdim=True)
    ex = torch.where(en > 1e-7, ex / en.clamp_min(1e-12), torch.tensor([1.0, 0.0, 0.0], dtype=wi.dtype))
    tn = t.norm(dim=-1)
    return torch.where(tn > 1e-7, (t * ex).sum(-1) / tn.clamp_min(1e-12), torch.ones_like(tn))


def table_lookup(values: torch.Tensor, wi: torch.Tensor, wo: torch.Tensor, ordered: bool = False) -> torch.Tensor:
    """f (P, 3) of a baked table at pairs (P, 3) each, trilinear in log space as
    the shader's filtered fetch (a CPU twin for tests and error measurements);
    0 where a direction is below the horizon. ``ordered``: the table's phi_d spans [0, pi]."""
    k, m, n = values.shape[:3]
    r = rusink5(wi, wo)  # sqrt(2 theta_h / pi), 2 theta_d / pi, cos 2 phi_d, ...
    u = r[:, 0].clamp(0, 1) * (n - 1)
    v = r[:, 1].clamp(0, 1) * (m - 1)
    c = cos_phi_d(wi, wo) if ordered else r[:, 2]
    w = torch.acos(c.clamp(-1, 1)) / math.pi * (k - 1)
    out = torch.zeros(wi.shape[0], 3, dtype=values.dtype)
    i0, j0, k0 = (t.floor().long().clamp(0, s - 2) for t, s in ((u, n), (v, m), (w, k)))
    fu, fv, fw = u - i0, v - j0, w - k0
    for dk in (0, 1):
        for dj in (0, 1):
            for di in (0, 1):
                wt = ((fu if di else 1 - fu) * (fv if dj else 1 - fv) * (fw if dk else 1 - fw))[:, None]
                out = out + wt * values[k0 + dk, j0 + dj, i0 + di]
    f = torch.exp(out)
    up = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
    return torch.where(up, f, torch.zeros_like(f))


__all__ = ["TableSize", "bake_body", "cos_phi_d", "table_directions", "table_lookup"]
