"""Statistical tests that never flake: fixed seeds and stated significance.

``chi2_sphere`` follows Mitsuba 3's chi-square sampler tests: bin sampled
directions on a grid uniform in (cos theta, phi), integrate the claimed pdf
over each bin on a fine sub-grid, pool bins with small expected counts, and
reject at significance ``alpha``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from scipy import stats


@dataclass
class Chi2Result:
    p_value: float
    statistic: float
    dof: int
    pdf_integral: float  # integral of the pdf over the sphere
    valid_fraction: float  # fraction of samples returned with pdf > 0
    n_samples: int

    def __str__(self) -> str:
        return (f"p={self.p_value:.3g} chi2={self.statistic:.1f} dof={self.dof} "
                f"int pdf={self.pdf_integral:.4f} valid={self.valid_fraction:.4f}")


def chi2_sphere(sample_fn, pdf_fn, n_samples: int = 400_000, n_theta: int = 40, n_phi: int = 80,
                sub: int = 10, min_expected: float = 5.0) -> Chi2Result:
    """``sample_fn(n) -> (dirs (n, 3), pdf (n,))``; ``pdf_fn(dirs (m, 3)) -> (m,)``.
    Directions over the whole sphere; invalid samples carry pdf 0."""
    dirs, pdf = sample_fn(n_samples)
    valid = pdf > 0
    d = dirs[valid].double()
    ct = d[:, 2].clamp(-1, 1 - 1e-15)
    ph = torch.atan2(d[:, 1], d[:, 0]) % (2 * math.pi)
    it = ((ct + 1) / 2 * n_theta).long().clamp(0, n_theta - 1)
    ip = (ph / (2 * math.pi) * n_phi).long().clamp(0, n_phi - 1)
    observed = torch.bincount(it * n_phi + ip, minlength=n_theta * n_phi).double()

    # Expected counts: midpoint rule on a sub x sub grid inside every bin.
    ic = (torch.arange(n_theta * sub, dtype=torch.float64) + 0.5) / (n_theta * sub) * 2 - 1
    pc = (torch.arange(n_phi * sub, dtype=torch.float64) + 0.5) / (n_phi * sub) * 2 * math.pi
    C, P = torch.meshgrid(ic, pc, indexing="ij")
    S = torch.sqrt((1 - C * C).clamp_min(0))
    grid = torch.stack([S * torch.cos(P), S * torch.sin(P), C], -1).reshape(-1, 3)
    vals = torch.cat([pdf_fn(chunk).double() for chunk in grid.split(200_000)])
    cell = (2.0 / (n_theta * sub)) * (2 * math.pi / (n_phi * sub))
    dens = vals.view(n_theta, sub, n_phi, sub).sum((1, 3)) * cell
    integral = float(dens.sum())
    expected = (dens * n_samples).flatten()

    # Pool small bins into one, as usual for chi-square.
    order = torch.argsort(expected)
    e_sorted, o_sorted = expected[order], observed[order]
    small = e_sorted < min_expected
    e_bins = list(e_sorted[~small])
    o_bins = list(o_sorted[~small])
    if small.any():
        e_bins.append(e_sorted[small].sum())
        o_bins.append(o_sorted[small].sum())
    e = torch.stack(e_bins)
    o = torch.stack(o_bins)
    keep = e > 0
    bad_empty = float(o[~keep].sum())
    chi2 = float(((o[keep] - e[keep]) ** 2 / e[keep]).sum())
    dof = int(keep.sum()) - 1
    p = float(stats.chi2.sf(chi2, dof)) if bad_empty == 0 else 0.0
    return Chi2Result(p, chi2, dof, integral, float(valid.double().mean()), n_samples)


def z_threshold(alpha: float, n_tests: int) -> float:
    """Two-sided |z| limit at family-wise significance alpha over n_tests (Bonferroni)."""
    return float(stats.norm.isf(alpha / (2 * n_tests)))
