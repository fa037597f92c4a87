"""MERL measured BRDFs: the standard ``.binary`` layout, read and written.

Layout (Matusik et al. 2003): three int32 dimensions (90, 90, 180) for
(theta_h, theta_d, phi_d), then three blocks (R, G, B) of float64 values,
phi_d varying fastest. theta_h is indexed non-linearly (index = 90
sqrt(theta_h / (pi/2))), theta_d and phi_d linearly; phi_d covers [0, pi)
by reciprocity. Stored values are divided by the per-channel scales below
when read. Negative values mark cells with no measurement.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.geometry import half_diff

Tensor = torch.Tensor

RES = (90, 90, 180)
SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])


def angles(wi: Tensor, wo: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """(theta_h, theta_d, phi_d in [0, pi)) of direction pairs."""
    h, d = half_diff(wi.double(), wo.double())
    theta_h = torch.acos(h[..., 2].clamp(-1, 1))
    theta_d = torch.acos(d[..., 2].clamp(-1, 1))
    phi_d = torch.atan2(d[..., 1], d[..., 0])
    phi_d = torch.where(phi_d < 0, phi_d + math.pi, phi_d)
    return theta_h, theta_d, phi_d.clamp(0, math.pi)


def indices(wi: Tensor, wo: Tensor) -> Tensor:
    """Flat table indices of pairs, the standard MERL lookup (nearest lower cell)."""
    th, td, pd = angles(wi, wo)
    ih = torch.sqrt(th / (math.pi / 2)) * RES[0]
    ih = ih.floor().clamp(0, RES[0] - 1).long()
    id_ = (td / (math.pi / 2) * RES[1]).floor().clamp(0, RES[1] - 1).long()
    ip = (pd / math.pi * RES[2]).floor().clamp(0, RES[2] - 1).long()
    return (ih * RES[1] + id_) * RES[2] + ip


def cell_centres() -> tuple[Tensor, Tensor, Tensor]:
    """theta_h, theta_d, phi_d at the centre of every cell, each (90*90*180,)."""
    ih, id_, ip = torch.meshgrid(*(torch.arange(r, dtype=torch.float64) for r in RES), indexing="ij")
    th = ((ih + 0.5) / RES[0]) ** 2 * (math.pi / 2)
    td = (id_ + 0.5) / RES[1] * (math.pi / 2)
    pd = (ip + 0.5) / RES[2] * math.pi
    return th.reshape(-1), td.reshape(-1), pd.reshape(-1)


def directions(theta_h: Tensor, theta_d: Tensor, phi_d: Tensor) -> tuple[Tensor, Tensor]:
    """(wi, wo) of Rusinkiewicz angles with phi_h = 0."""
    d = torch.stack([theta_d.sin() * phi_d.cos(), theta_d.sin() * phi_d.sin(), theta_d.cos()], -1)
    ct, st = theta_h.cos(), theta_h.sin()
    wi = torch.stack([ct * d[:, 0] + st * d[:, 2], d[:, 1], -st * d[:, 0] + ct * d[:, 2]], -1)
    h = torch.stack([st, torch.zeros_like(st), ct], -1)
    wo = 2 * (wi * h).sum(-1, keepdim=True) * h - wi
    return wi, wo


class MerlBRDF:
    """A measured BRDF: RGB table (3, 90, 90, 180) in 1/sr; NaN = not measured."""

    def __init__(self, table: np.ndarray, name: str = "merl"):
        if table.shape != (3,) + RES:
            raise NbrdfError(f"{name}: a MERL table must have shape (3, 90, 90, 180), got {table.shape}")
        self.table = np.asarray(table, dtype=np.float64)
        self.name = name

    @classmethod
    def load(cls, path: str | Path) -> "MerlBRDF":
        p = Path(path)
        if not p.is_file():
            raise NbrdfError(f"{path}: no such MERL file")
        raw = p.read_bytes()
        if len(raw) < 12:
            raise NbrdfError(f"{path}: too short for a MERL .binary file")
        dims = tuple(int(x) for x in np.frombuffer(raw[:12], dtype="<i4"))
        if dims != RES:
            raise NbrdfError(f"{path}: dimensions {dims} are not the MERL layout {RES}")
        n = int(np.prod(RES))
        if len(raw) != 12 + 3 * n * 8:
            raise NbrdfError(f"{path}: holds {len(raw) - 12} bytes of values, the MERL layout needs {3 * n * 8}")
        vals = np.frombuffer(raw[12:], dtype="<f8").reshape(3, n).copy()
        if not np.isfinite(vals).all():
            raise NbrdfError(f"{path}: holds NaN or infinite values")
        vals = vals * SCALE[:, None]
        vals[vals < 0] = np.nan
        return cls(vals.reshape((3,) + RES), name=p.name)

    def save(self, path: str | Path) -> None:
        vals = self.table.reshape(3, -1) / SCALE[:, None]
        vals = np.where(np.isnan(vals), -1.0, vals)
        with open(path, "wb") as fh:
            fh.write(np.asarray(RES, dtype="<i4").tobytes())
            fh.write(vals.astype("<f8").tobytes())

    @classmethod
    def tabulate(cls, fn: Callable[[Tensor, Tensor], Tensor], name: str = "tabulated") -> "MerlBRDF":
        """Samples an RGB BRDF fn(wi, wo) -> (N, 3) at every cell centre; cells
        with a direction below the horizon are marked unmeasured."""
        th, td, pd = cell_centres()
        wi, wo = directions(th, td, pd)
        vals = torch.zeros(wi.shape[0], 3, dtype=torch.float64)
        for s in range(0, wi.shape[0], 1 << 18):
            vals[s:s + (1 << 18)] = fn(wi[s:s + (1 << 18)], wo[s:s + (1 << 18)]).double()
        below = (wi[:, 2] <= 0) | (wo[:, 2] <= 0)
        vals[below] = float("nan")
        return cls(vals.T.reshape((3,) + RES).numpy(), name=name)

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        """RGB values (N, 3), nearest-cell lookup; unmeasured cells and
        directions below the horizon give 0."""
        idx = indices(wi, wo).numpy()
        v = self.table.reshape(3, -1)[:, idx].T
        v = np.nan_to_num(v, nan=0.0)
        up = ((wi[:, 2] > 0) & (wo[:, 2] > 0)).numpy()
        return torch.from_numpy(np.where(up[:, None], v, 0.0)).to(wi.dtype)

    def samples(self, n: int, seed: int = 0) -> tuple[Tensor, Tensor, Tensor]:
        """n measured cells (wi, wo (n, 3), f (n, 3)) drawn at random, with the
        theta_h rows near the specular peak drawn as often as any other (the
        table's own non-linear spacing)."""
        g = np.random.default_rng(seed)
        flat = self.table.reshape(3, -1)
        valid = np.flatnonzero(np.isfinite(flat).all(0))
        if valid.size == 0:
            raise NbrdfError(f"{self.name}: the table holds no measured cell")
        pick = g.choice(valid, size=min(n, valid.size), replace=False)
        ih, rest = np.divmod(pick, RES[1] * RES[2])
        id_, ip = np.divmod(rest, RES[2])
        th = torch.from_numpy(((ih + 0.5) / RES[0]) ** 2 * (math.pi / 2))
        td = torch.from_numpy((id_ + 0.5) / RES[1] * (math.pi / 2))
        pd = torch.from_numpy((ip + 0.5) / RES[2] * math.pi)
        wi, wo = directions(th, td, pd)
        return wi, wo, torch.from_numpy(flat[:, pick].T.copy())
