"""An independent check of the layered simulator: a plain analog random walk.

Photons carry energy (no NEE, no MIS, no eta^2 radiance scaling): they enter
through the top interface, scatter by sampling each interaction's physical
kernel, and their exit directions are binned. For a bin B the mean photon
weight landing in B estimates the integral over B of f(wi, wo) cos(theta_o).
Written separately from training/layered.py on purpose: it shares only the
single-interface BSDF samplers, which have their own chi-square tests.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from nbrdf.training.analytic import GGXConductor, GGXDielectric, Lambertian


def analog_exits(layers: list[tuple[float, float, float, float]], base: tuple, wi: torch.Tensor,
                 n_photons: int, seed: int, skip_top_reflection: bool = True, top_only: bool = False,
                 anisotropy: tuple[float, ...] | None = None, base_anisotropy: float = 0.0, rotation: float = 0.0
                 ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Every photon's exit direction (n, 3) and energy (n,) (0: absorbed, or
    its single reflection off the top left out with ``skip_top_reflection``).
    ``layers``: (roughness, ior, albedo, sigma_t) top to bottom; ``base``:
    ("conductor", roughness, r0[, f82 tint]) | ("diffuse", albedo) | ("dielectric",
    roughness, ior). The mean of energy x [exit in B] over photons estimates
    the integral over B of f(wi, wo) cos(theta_o). Third: which photons left
    by the single reflection off the top. ``top_only``: photons that enter
    the stack are dropped at once (a cheap run of the top's reflection alone). ``anisotropy`` (per layer,
    None: 0), ``base_anisotropy`` (a conductor or dielectric base) and ``rotation`` (degrees): SPEC section
    10, through the closed forms' own anisotropic sampling."""
    aniso = anisotropy or (0.0,) * len(layers)
    g = torch.Generator().manual_seed(seed)
    dt = torch.float64
    L = len(layers)
    n = n_photons
    pid = torch.arange(n)
    w = wi.to(dt).expand(n, 3).clone()
    top = GGXDielectric(layers[0][0], layers[0][1], aniso[0], rotation)
    s = top.sample(w, torch.rand(n, 3, generator=g, dtype=dt))
    beta = s.weight
    exit_w = torch.zeros(n, 3, dtype=dt)
    exit_b = torch.zeros(n, dtype=dt)
    refl = (s.pdf > 0) & (s.w[:, 2] > 0)
    if not skip_top_reflection:
        exit_w[refl], exit_b[refl] = s.w[refl], beta[refl]
    inside = (s.pdf > 0) & (s.w[:, 2] < 0) & (not top_only)
    pid, d, beta = pid[inside], s.w[inside], beta[inside]
    depth = torch.zeros(pid.numel(), dtype=dt)
    slab = torch.zeros(pid.numel(), dtype=torch.long)
    bounce = 0
    while pid.numel():
        bounce += 1
        m = pid.numel()
        tau = torch.tensor([l[3] for l in layers], dtype=dt)[slab]
        alb = torch.tensor([l[2] for l in layers], dtype=dt)[slab]
        down = d[:, 2] < 0
        lo = slab.to(dt)
        dist = torch.where(down, (lo + 1 - depth) / (-d[:, 2]).clamp_min(1e-15), (depth - lo) / d[:, 2].clamp_min(1e-15))
        t = -torch.log(1 - torch.rand(m, generator=g, dtype=dt)) / tau.clamp_min(1e-300)
        sc = (tau > 0) & (t < dist)
        depth = torch.where(sc, depth - t * d[:, 2], torch.where(down, lo + 1, lo))
        alive = torch.ones(m, dtype=torch.bool)
        nd = d.clone()
        # medium
        u = torch.rand(m, 2, generator=g, dtype=dt)
        z = 1 - 2 * u[:, 0]
        r = torch.sqrt(1 - z * z)
        iso = torch.stack([r * torch.cos(2 * math.pi * u[:, 1]), r * torch.sin(2 * math.pi * u[:, 1]), z], -1)
        nd = torch.where(sc[:, None], iso, nd)
        beta = torch.where(sc, beta * alb, beta)
        # surfaces, one lane at a time type by type
        k = torch.where(down, slab + 1, slab)
        u3 = torch.rand(m, 3, generator=g, dtype=dt)
        for kk in range(L + 1):
            sel = (~sc) & (k == kk)
            if not sel.any():
                continue
            win = -d[sel]
            if kk < L:
                ss = GGXDielectric(layers[kk][0], layers[kk][1], aniso[kk], rotation).sample(win, u3[sel])
                ok = ss.pdf > 0
                crossed = ok & (win[:, 2] * ss.w[:, 2] < 0)
                if kk == 0:
                    out = crossed  # left through the top
                    idx = pid[sel][out]
                    exit_w[idx] = ss.w[out]
                    exit_b[idx] = beta[sel][out] * ss.weight[out]
                    ok = ok & ~crossed
                else:
                    slab[sel] = torch.where(crossed, torch.where(win[:, 2] > 0, kk, kk - 1), slab[sel])
            else:
                kind = base[0]
                if kind == "conductor":
                    ss = GGXConductor(base[1], base[2], base[3] if len(base) > 3 else 1.0, base_anisotropy,
                                      rotation).sample(win, u3[sel])
                elif kind == "diffuse":
                    ss = Lambertian(base[1]).sample(win, u3[sel])
                else:
                    ss = GGXDielectric(base[1], base[2], base_anisotropy, rotation).sample(win, u3[sel])
                ok = (ss.pdf > 0) & (ss.w[:, 2] > 0)
            beta[sel] = beta[sel] * torch.where(ok, ss.weight, torch.zeros_like(ss.weight))
            nd[sel] = ss.w
            alive[sel] = ok
        d = nd
        if bounce >= 4:
            q = beta.clamp(max=0.95)
            surv = torch.rand(m, generator=g, dtype=dt) < q
            beta = beta / torch.where(surv, q, torch.ones_like(q))
            alive &= surv
        alive &= beta > 0
        pid, d, beta, depth, slab = pid[alive], d[alive], beta[alive], depth[alive], slab[alive]
    return exit_w, exit_b, refl


def analog_bins(layers: list[tuple[float, float, float, float]], base: tuple, wi: torch.Tensor,
                n_photons: int, n_theta: int, n_phi: int, seed: int,
                skip_top_reflection: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """Bin estimates (n_theta, n_phi) of the integral of f cos over each bin
    and their standard errors (``analog_exits``' photons). Bins are uniform
    in cos(theta_o) and phi_o in [0, 2 pi)."""
    exit_w, exit_b, _ = analog_exits(layers, base, wi, n_photons, seed, skip_top_reflection)
    ct = exit_w[:, 2].clamp(0, 1 - 1e-12)
    ph = torch.atan2(exit_w[:, 1], exit_w[:, 0]) % (2 * math.pi)
    it = (ct * n_theta).long().clamp(max=n_theta - 1)
    ip = (ph / (2 * math.pi) * n_phi).long().clamp(max=n_phi - 1)
    b = it * n_phi + ip
    vals = torch.zeros(n_photons, n_theta * n_phi, dtype=torch.float64)
    has = exit_b > 0
    vals[torch.arange(n_photons)[has], b[has]] = exit_b[has]
    return vals.mean(0).view(n_theta, n_phi), (vals.std(0) / math.sqrt(n_photons)).view(n_theta, n_phi)


def uniform_in_bins(n_theta: int, n_phi: int, k: int, seed: int) -> torch.Tensor:
    """k directions uniform (in solid angle) inside each bin: (n_theta*n_phi*k, 3)."""
    g = torch.Generator().manual_seed(seed)
    it = torch.arange(n_theta).repeat_interleave(n_phi * k)
    ip = torch.arange(n_phi).repeat_interleave(k).repeat(n_theta)
    u = torch.rand(it.numel(), 2, generator=g, dtype=torch.float64)
    ct = (it + u[:, 0]) / n_theta
    ph = (ip + u[:, 1]) / n_phi * 2 * math.pi
    st = torch.sqrt(1 - ct * ct)
    return torch.stack([st * torch.cos(ph), st * torch.sin(ph), ct], -1)


# --- bins that resolve the lobes --------------------------------------------------------------
# Exit directions are binned in the projected disk (x, y) = (wo_x, wo_y), where the area element is
# cos(theta_o) d(omega): a bin's integral of f cos over solid angle is the integral of f over its area.
# Bins are ring sectors around the mirror direction of wi (where the specular and the unscattered
# transmitted lobes peak), with ring radii at quantiles of the exiting energy of a separate pilot run, so
# every ring holds about the same energy however sharp the lobe.

@dataclass
class DiskBins:
    """Ring sectors around ``center`` in the projected disk: ring i spans
    radii [edges[i], edges[i + 1]), sector j the angles [2 pi j / n_sectors,
    2 pi (j + 1) / n_sectors) around the center. Index = ring * n_sectors + sector."""

    center: tuple[float, float]  # the mirror direction of wi, projected
    edges: torch.Tensor  # (n_rings + 1,) radii, 0 first, the last beyond the disk
    n_sectors: int  # angular sectors per ring

    @property
    def n_bins(self) -> int:
        return (self.edges.numel() - 1) * self.n_sectors

    def index(self, w: torch.Tensor) -> torch.Tensor:
        """Bin of each upper-hemisphere direction (n, 3)."""
        dx, dy = w[:, 0] - self.center[0], w[:, 1] - self.center[1]
        r = torch.sqrt(dx * dx + dy * dy)
        ring = (torch.searchsorted(self.edges, r, right=True) - 1).clamp(0, self.edges.numel() - 2)
        sec = ((torch.atan2(dy, dx) % (2 * math.pi)) / (2 * math.pi) * self.n_sectors).long()
        return ring * self.n_sectors + sec.clamp(max=self.n_sectors - 1)

    def areas(self) -> torch.Tensor:
        """Area of every bin's sector (the part beyond the unit disk included)."""
        ring = (self.edges[1:] ** 2 - self.edges[:-1] ** 2) * math.pi / self.n_sectors
        return ring.repeat_interleave(self.n_sectors)

    def points(self, k: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
        """k points uniform in each bin's sector: (directions (n_bins k, 3) with
        z = 0 where the point lies beyond the unit disk, inside (n_bins k,))."""
        g = torch.Generator().manual_seed(seed)
        nb = self.n_bins
        b = torch.arange(nb).repeat_interleave(k)
        ring, sec = b // self.n_sectors, b % self.n_sectors
        u = torch.rand(b.numel(), 2, generator=g, dtype=torch.float64)
        r0, r1 = self.edges[ring], self.edges[ring + 1]
        r = torch.sqrt(r0 * r0 + u[:, 0] * (r1 * r1 - r0 * r0))
        ph = (sec + u[:, 1]) / self.n_sectors * 2 * math.pi
        x = self.center[0] + r * torch.cos(ph)
        y = self.center[1] + r * torch.sin(ph)
        rho2 = x * x + y * y
        inside = rho2 < 1.0
        z = torch.sqrt((1.0 - rho2).clamp_min(0.0))
        return torch.stack([x, y, z], -1), inside


def disk_bins(exit_w: torch.Tensor, exit_b: torch.Tensor, top: torch.Tensor, wi: torch.Tensor, n_rings_top: int,
              n_rings_body: int, n_sectors: int) -> DiskBins:
    """Bins around wi's mirror direction from a pilot run (``analog_exits``
    output, the top's reflection included): the ring radii are quantiles of
    the energy of the top's single reflection (``n_rings_top`` rings' worth,
    a narrow peak for a smooth top) and of the light that entered the stack
    (``n_rings_body``), merged, so that both lobes are resolved however sharp."""
    c = (-float(wi[0]), -float(wi[1]))
    r_all = torch.sqrt((exit_w[:, 0] - c[0]) ** 2 + (exit_w[:, 1] - c[1]) ** 2)

    def quantiles(sel: torch.Tensor, k: int) -> torch.Tensor:
        r, e = r_all[sel], exit_b[sel]
        order = torch.argsort(r)
        cum = torch.cumsum(e[order], 0)
        q = torch.arange(1, k, dtype=torch.float64) / k * cum[-1]
        return r[order][torch.searchsorted(cum, q).clamp(max=r.numel() - 1)]

    has = exit_b > 0
    inner = torch.cat([quantiles(has & top, n_rings_top), quantiles(has & ~top, n_rings_body)])
    outer = 1.0 + math.hypot(*c) + 1e-9  # every point of the unit disk lies within it
    edges = torch.unique(torch.cat([torch.zeros(1, dtype=torch.float64), inner,
                                    torch.tensor([outer], dtype=torch.float64)]))
    return DiskBins(c, edges, n_sectors)


def analog_disk_estimate(exit_w: torch.Tensor, exit_b: torch.Tensor, bins: DiskBins
                         ) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-bin mean photon energy (the integral of f over the bin's area in
    the projected disk) and its covariance matrix: a photon lands in at most
    one bin, so bins are (slightly) anti-correlated."""
    n = exit_b.numel()
    has = exit_b > 0
    b = bins.index(exit_w[has])
    e = exit_b[has]
    s1 = torch.zeros(bins.n_bins, dtype=torch.float64).index_add_(0, b, e)
    s2 = torch.zeros(bins.n_bins, dtype=torch.float64).index_add_(0, b, e * e)
    m = s1 / n
    cov = (torch.diag(s2 / n) - torch.outer(m, m)) / (n - 1)
    return m, cov


def walk_disk_estimate(f: torch.Tensor, inside: torch.Tensor, bins: DiskBins, k: int
                       ) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-bin estimate area x mean of f over the bin's k uniform points (f
    counted 0 beyond the unit disk) and its variance, from the points' spread
    (each point's f an independent estimate of its own, so the spread holds
    both the variation of f over the bin and the paths' noise)."""
    v = torch.where(inside, f, torch.zeros_like(f)).view(bins.n_bins, k) * bins.areas()[:, None]
    return v.mean(-1), v.var(-1) / k


def well_populated(exit_w: torch.Tensor, exit_b: torch.Tensor, bins: DiskBins, scale: float,
                   min_photons: float = 40.0) -> torch.Tensor:
    """Bins where a run ``scale`` times the size of this (pilot) run expects
    at least ``min_photons`` photons: the only bins a chi-square may use, as
    an analog bin with a handful of photons (or none, where a sample
    variance is 0) is far from normal. Chosen from the pilot, never from
    the photons being compared."""
    has = exit_b > 0
    counts = torch.zeros(bins.n_bins, dtype=torch.float64).index_add_(
        0, bins.index(exit_w[has]), torch.ones(int(has.sum()), dtype=torch.float64))
    return counts * scale >= min_photons


def chi_square(a: torch.Tensor, a_cov: torch.Tensor, w: torch.Tensor, w_var: torch.Tensor, keep: torch.Tensor
               ) -> tuple[float, int]:
    """(d^T (C_a + diag(var_w))^-1 d, degrees of freedom) for d = w - a over
    the bins in ``keep``."""
    d = (w - a)[keep]
    c = a_cov[keep][:, keep] + torch.diag(w_var[keep])
    return float(d @ torch.linalg.solve(c, d)), int(keep.sum())
