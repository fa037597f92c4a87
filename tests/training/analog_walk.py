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

import torch

from nbrdf.training.analytic import GGXConductor, GGXDielectric, Lambertian


def analog_bins(layers: list[tuple[float, float, float, float]], base: tuple, wi: torch.Tensor,
                n_photons: int, n_theta: int, n_phi: int, seed: int,
                skip_top_reflection: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """Bin estimates (n_theta, n_phi) of the integral of f cos over each bin
    and their standard errors. ``layers``: (roughness, ior, albedo, sigma_t)
    top to bottom; ``base``: ("conductor", roughness, r0) | ("diffuse", albedo)
    | ("dielectric", roughness, ior). Bins are uniform in cos(theta_o) and
    phi_o in [0, 2 pi)."""
    g = torch.Generator().manual_seed(seed)
    dt = torch.float64
    L = len(layers)
    n = n_photons
    pid = torch.arange(n)
    w = wi.to(dt).expand(n, 3).clone()
    top = GGXDielectric(layers[0][0], layers[0][1])
    s = top.sample(w, torch.rand(n, 3, generator=g, dtype=dt))
    beta = s.weight
    exit_w = torch.zeros(n, 3, dtype=dt)
    exit_b = torch.zeros(n, dtype=dt)
    refl = (s.pdf > 0) & (s.w[:, 2] > 0)
    if not skip_top_reflection:
        exit_w[refl], exit_b[refl] = s.w[refl], beta[refl]
    inside = (s.pdf > 0) & (s.w[:, 2] < 0)
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
                ss = GGXDielectric(layers[kk][0], layers[kk][1]).sample(win, u3[sel])
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
                    ss = GGXConductor(base[1], base[2]).sample(win, u3[sel])
                elif kind == "diffuse":
                    ss = Lambertian(base[1]).sample(win, u3[sel])
                else:
                    ss = GGXDielectric(base[1], base[2]).sample(win, u3[sel])
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
    # bin exits
    ct = exit_w[:, 2].clamp(0, 1 - 1e-12)
    ph = torch.atan2(exit_w[:, 1], exit_w[:, 0]) % (2 * math.pi)
    it = (ct * n_theta).long().clamp(max=n_theta - 1)
    ip = (ph / (2 * math.pi) * n_phi).long().clamp(max=n_phi - 1)
    b = it * n_phi + ip
    vals = torch.zeros(n_photons, n_theta * n_phi, dtype=dt)
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
