"""Monte Carlo ground truth for layered BRDFs (SPEC section 5).

Position-free Monte Carlo (Guo, Hasan, Zhao 2018): a random walk starts at
the top interface by refracting ``wi`` into the stack, free-flies through
homogeneous slabs (thickness 1, extinction sigma_t, albedo A, isotropic
phase), scatters at media, internal interfaces and the base, and is ended by
Russian roulette. Every vertex that can see the top interface from below
(inside the top slab or on its bottom boundary) connects to ``wo`` by
next-event estimation: the top interface is sampled from ``wo`` (forced
transmission) and the connection is weighted by MIS against the walk itself
reaching the top and being evaluated there. Both MIS weights use the
*consistent* pdf: the density with which sampling the top interface from
``wo`` produces the direction in question. The single reflection off the top
interface is added in closed form.

The walk carries photon weights (energy) with the radiance-convention BSDFs of
``training.analytic``; along any path that enters and leaves through the top
the eta^2 factors of the two refractions cancel, so the estimate is the
stack's reciprocal BRDF. Sampling decisions do not depend on the colour
channel, so the channels share paths and only the weights differ.

Lanes are (pair, sample) paths; dead lanes are dropped every bounce so the
cost follows the live paths.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from training.analytic import GGXConductor, GGXDielectric, Lambertian
from training.microfacet import fresnel_dielectric, refract, sample_vndf, smith_g1, vndf_pdf

Tensor = torch.Tensor

BASES = ("conductor", "diffuse", "dielectric")
INV_4PI = 1.0 / (4.0 * math.pi)


@dataclass
class StackParams:
    """N stacks (one per (wi, wo) pair or per lane group), top to bottom.

    L interfaces, each a GGX dielectric followed by a medium slab (sigma_t 0 =
    no medium); then the base. Shapes: ``roughness``, ``ior``, ``sigma_t``
    (N, L); ``albedo`` (N, L, C) or (N, L); ``base_r0`` / ``base_albedo``
    (N, C) or (N,); ``base_roughness`` / ``base_ior`` (N,). C is the number of
    colour channels carried together (they share paths)."""

    roughness: Tensor
    ior: Tensor
    albedo: Tensor
    sigma_t: Tensor
    base: str
    base_roughness: Tensor
    base_r0: Tensor = field(default=None)  # type: ignore[assignment]
    base_ior: Tensor = field(default=None)  # type: ignore[assignment]
    base_albedo: Tensor = field(default=None)  # type: ignore[assignment]

    def normalized(self, dtype: torch.dtype) -> tuple["StackParams", bool]:
        """Copy with every tensor in ``dtype`` and channel dims made explicit;
        also says whether the input was single-channel without a channel dim."""
        if self.base not in BASES:
            raise ValueError(f"unknown base {self.base!r}")
        n, L = self.roughness.shape
        squeeze = self.albedo.dim() == 2
        alb = self.albedo[..., None] if squeeze else self.albedo
        C = alb.shape[-1]

        def chan(t: Tensor | None, default: float) -> Tensor:
            if t is None:
                return torch.full((n, C), default, dtype=dtype)
            t = torch.as_tensor(t, dtype=dtype)
            t = t[:, None] if t.dim() == 1 else t
            return t.expand(n, C).to(dtype)

        def scal(t: Tensor | None, default: float) -> Tensor:
            return torch.full((n,), default, dtype=dtype) if t is None else torch.as_tensor(t, dtype=dtype).expand(n)

        p = StackParams(
            roughness=self.roughness.to(dtype), ior=self.ior.to(dtype), albedo=alb.to(dtype),
            sigma_t=self.sigma_t.to(dtype), base=self.base,
            base_roughness=scal(self.base_roughness, 0.5), base_r0=chan(self.base_r0, 0.0),
            base_ior=scal(self.base_ior, 1.5), base_albedo=chan(self.base_albedo, 0.0))
        return p, squeeze


@dataclass
class SimStats:
    """What a simulation cost: paths traced, vertices processed, seconds."""

    paths: int = 0
    vertices: int = 0
    seconds: float = 0.0


def _forced_transmission_pdf(a: Tensor, eta_rel: Tensor, w: Tensor, wt: Tensor) -> Tensor:
    """Density of drawing wt by refracting w through a VNDF-sampled facet
    (no Fresnel choice); eta_rel = index on wt's side / index on w's side."""
    h = -(w + eta_rel[..., None] * wt)
    h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-30)
    h = torch.where(h[..., 2:3] < 0, -h, h)
    wh, th = (w * h).sum(-1), (wt * h).sum(-1)
    denom = wh + eta_rel * th
    ok = (wh * th < 0) & (w[..., 2] * wt[..., 2] < 0) & (denom.abs() > 1e-12)
    p = vndf_pdf(w, h, a) * eta_rel * eta_rel * th.abs() / torch.where(ok, denom * denom, torch.ones_like(denom))
    return torch.where(ok, p, torch.zeros_like(p))


def _forced_transmission_sample(a: Tensor, eta_rel: Tensor, w: Tensor, u: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Refracts w through a VNDF-sampled facet. Returns (wt, weight, pdf):
    weight = f_t |cos wt| / pdf = (1 - F) G1(wt); 0 under TIR or a bad side."""
    m = sample_vndf(w, a, u[..., 0], u[..., 1])
    wt, ok = refract(w, m, 1.0 / eta_rel)
    F = fresnel_dielectric((w * m).sum(-1), eta_rel)
    ok = ok & (w[..., 2] * wt[..., 2] < 0)
    weight = (1.0 - F) * smith_g1(wt, m, a)
    weight = torch.where(ok, weight, torch.zeros_like(weight))
    pdf = torch.where(ok, _forced_transmission_pdf(a, eta_rel, w, wt), torch.zeros_like(weight))
    return wt, weight, pdf


def _conductor_rgb(a: Tensor, r0: Tensor, wi: Tensor, wo: Tensor) -> Tensor:
    """GGX conductor values (n, C) for per-channel r0 (n, C): Schlick is
    linear in r0, so one geometric evaluation serves every channel."""
    geo = GGXConductor(a, 1.0).eval(wi, wo)  # F = 1
    h = wi + wo
    h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-30)
    x = (1.0 - (wi * h).sum(-1).abs().clamp(max=1.0)) ** 5
    return geo[:, None] * (x[:, None] + r0 * (1.0 - x[:, None]))


def simulate(stack: StackParams, wi: Tensor, wo: Tensor, spp: int = 64, seed: int = 0, *,
             dtype: torch.dtype = torch.float32, rr_depth: int = 4, max_depth: int = 10_000,
             include_top_reflection: bool = True, stats: SimStats | None = None,
             progress=None) -> tuple[Tensor, Tensor]:
    """Mean and standard error of the stack's BRDF f(wi, wo) per pair.

    ``wi``, ``wo``: (N, 3) upper-hemisphere unit vectors; ``spp`` paths per
    pair; ``include_top_reflection=False`` leaves out the closed-form single
    reflection off the top (to test the walk alone). Returns tensors (N, C) (or (N,) for single-channel input without a
    channel dim) in ``dtype``. Deterministic for a given seed and batch."""
    import time

    t0 = time.perf_counter()
    p, squeeze = stack.normalized(dtype)
    wi = wi.to(dtype)
    wo = wo.to(dtype)
    N, L = p.roughness.shape
    C = p.albedo.shape[-1]
    gen = torch.Generator().manual_seed(int(seed))

    def rand(n: int, k: int) -> Tensor:
        return torch.rand(n, k, generator=gen, dtype=dtype)

    # Closed-form single reflection off the top interface.
    top_all = GGXDielectric(p.roughness[:, 0], p.ior[:, 0])
    f_top_refl = top_all.eval(wi, wo) if include_top_reflection else torch.zeros(N, dtype=dtype)

    # Lanes: spp paths per pair, laid out pair-major.
    n_lanes = N * spp
    pid = torch.arange(N).repeat_interleave(spp)
    acc = torch.zeros(n_lanes, C, dtype=dtype)
    lane = torch.arange(n_lanes)

    # Entry: forced refraction of wi through the top interface (stratified over spp).
    u = rand(n_lanes, 2)
    if spp > 1:
        j = torch.arange(n_lanes) % spp
        u[:, 0] = (j + u[:, 0]) / spp
    a0, e0 = p.roughness[pid, 0], p.ior[pid, 0]
    d_in, w_entry, _ = _forced_transmission_sample(a0, e0, wi[pid], u)
    beta = w_entry[:, None].expand(n_lanes, C).clone()
    pdir = d_in  # photon travel direction (down into slab 0)
    depth = torch.zeros(n_lanes, dtype=dtype)
    slab = torch.zeros(n_lanes, dtype=torch.long)
    pdf_last = torch.zeros(n_lanes, dtype=dtype)  # sampling pdf of the current direction at its vertex
    bounces = 0
    alive = beta.amax(-1) > 0
    pid, lane, beta, pdir, depth, slab, pdf_last = (t[alive] for t in (pid, lane, beta, pdir, depth, slab, pdf_last))
    vertices = 0

    def nee(idx: Tensor, z: Tensor, kernel_and_pdf):
        """NEE from vertices ``idx`` at depth z in slab 0 toward wo."""
        q = pid[idx]
        w_o = wo[q]
        uu = rand(idx.numel(), 2)
        a, e = p.roughness[q, 0], p.ior[q, 0]
        wt, _, pdf_nee = _forced_transmission_sample(a, e, w_o, uu)
        v = -wt  # direction leaving the vertex, upward
        ok = pdf_nee > 0
        kern, pdf_x = kernel_and_pdf(idx, v)  # (n, C), (n,)
        tau = p.sigma_t[q, 0]
        tr = torch.exp(-tau * z / v[:, 2].clamp_min(1e-12))
        f_t = GGXDielectric(a, e).eval(wt, w_o)
        mis = pdf_nee / (pdf_nee + pdf_x)
        scale = torch.where(ok, tr * f_t * mis / torch.where(ok, pdf_nee, torch.ones_like(pdf_nee)), torch.zeros_like(tr))
        acc.index_add_(0, lane[idx], beta[idx] * kern * scale[:, None])

    while pid.numel() > 0 and bounces < max_depth:
        n = pid.numel()
        vertices += n
        bounces += 1
        # Free flight inside the current slab.
        tau = p.sigma_t[pid, slab]
        uz = pdir[:, 2]
        going_down = uz < 0
        top_of_slab = slab.to(dtype)
        dist_b = torch.where(going_down, (top_of_slab + 1.0 - depth) / (-uz).clamp_min(1e-12),
                             (depth - top_of_slab) / uz.clamp_min(1e-12))
        t = -torch.log1p(-rand(n, 1)[:, 0]) / tau.clamp_min(1e-30)
        scatter = (tau > 0) & (t < dist_b)
        depth = torch.where(scatter, depth - t * uz,
                            torch.where(going_down, top_of_slab + 1.0, top_of_slab))
        new_dir = pdir.clone()
        new_pdf = pdf_last.clone()
        kill = torch.zeros(n, dtype=torch.bool)
        # Classify every lane's event before any state changes.
        hit_lower = ~scatter & going_down
        k_if = torch.where(hit_lower, slab + 1, slab)  # index of the interface hit (L = base)
        itop = (~scatter & (k_if == 0)).nonzero().squeeze(-1)
        iint = (~scatter & (k_if >= 1) & (k_if < L)).nonzero().squeeze(-1)
        ibase = (~scatter & (k_if == L)).nonzero().squeeze(-1)

        # --- medium scattering --------------------------------------------
        im = scatter.nonzero().squeeze(-1)
        if im.numel():
            alb = p.albedo[pid[im], slab[im]]
            in0 = im[slab[im] == 0]
            if in0.numel():
                alb0 = p.albedo[pid[in0], 0]
                nee(in0, depth[in0], lambda idx, v, alb0=alb0: (alb0 * INV_4PI, torch.full((idx.numel(),), INV_4PI, dtype=dtype)))
            beta[im] = beta[im] * alb
            uu = rand(im.numel(), 2)
            zc = 1.0 - 2.0 * uu[:, 0]
            r = torch.sqrt((1.0 - zc * zc).clamp_min(0.0))
            ph = 2.0 * math.pi * uu[:, 1]
            new_dir[im] = torch.stack([r * torch.cos(ph), r * torch.sin(ph), zc], -1)
            new_pdf[im] = INV_4PI

        # --- top interface from below -----------------------------------------
        if itop.numel():
            q = pid[itop]
            a, e = p.roughness[q, 0], p.ior[q, 0]
            top = GGXDielectric(a, e)
            w_in = -pdir[itop]  # points down, away from the interface
            f_t = top.eval(w_in, wo[q])
            pdf_nee = _forced_transmission_pdf(a, e, wo[q], w_in)
            mis = pdf_last[itop] / (pdf_last[itop] + pdf_nee)
            acc.index_add_(0, lane[itop], beta[itop] * (f_t * mis)[:, None])
            s = top.sample(w_in, rand(itop.numel(), 3))
            refl = (s.pdf > 0) & (s.w[:, 2] < 0)  # stays inside
            wgt = s.weight
            beta[itop] = beta[itop] * wgt[:, None]
            new_dir[itop] = s.w
            new_pdf[itop] = s.pdf
            kill[itop] = ~refl

        # --- internal interfaces (k >= 1), from above or below ---------------
        if iint.numel():
            q, k = pid[iint], k_if[iint]
            itf = GGXDielectric(p.roughness[q, k], p.ior[q, k])
            w_in = -pdir[iint]
            at1 = k == 1
            if at1.any():
                sel = iint[at1]
                itf1 = GGXDielectric(p.roughness[pid[sel], 1], p.ior[pid[sel], 1])
                w1 = -pdir[sel]
                nee(sel, torch.ones(sel.numel(), dtype=dtype),
                    lambda idx, v, itf1=itf1, w1=w1: (itf1.eval(w1, v)[:, None] * v[:, 2:3].abs(), itf1.pdf(w1, v)))
            s = itf.sample(w_in, rand(iint.numel(), 3))
            ok = s.pdf > 0
            beta[iint] = beta[iint] * s.weight[:, None]
            new_dir[iint] = s.w
            new_pdf[iint] = s.pdf
            crossed = ok & (w_in[:, 2] * s.w[:, 2] < 0)
            # crossing downward enters slab k, crossing upward enters slab k-1
            slab_new = torch.where(crossed, torch.where(w_in[:, 2] > 0, k, k - 1), slab[iint])
            slab[iint] = slab_new
            kill[iint] = ~ok

        # --- base -------------------------------------------------------------
        if ibase.numel():
            q = pid[ibase]
            w_in = -pdir[ibase]
            if L == 1:
                def kern(idx, v, w_in=w_in, q=q):
                    if p.base == "conductor":
                        f = _conductor_rgb(p.base_roughness[q], p.base_r0[q], w_in, v)
                        pdf = GGXConductor(p.base_roughness[q], 0.0).pdf(w_in, v)
                    elif p.base == "diffuse":
                        f = p.base_albedo[q] / math.pi * (v[:, 2:3] > 0)
                        pdf = Lambertian(1.0).pdf(w_in, v)
                    else:
                        d = GGXDielectric(p.base_roughness[q], p.base_ior[q])
                        f = d.eval(w_in, v)[:, None].expand(-1, C)
                        pdf = d.pdf(w_in, v)
                    return f * v[:, 2:3].abs(), pdf
                nee(ibase, torch.ones(ibase.numel(), dtype=dtype), kern)
            uu = rand(ibase.numel(), 3)
            if p.base == "conductor":
                geo = GGXConductor(p.base_roughness[q], 1.0)  # direction sampling is channel-free
                s = geo.sample(w_in, uu)
                ok = s.pdf > 0
                h = w_in + s.w
                h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-30)
                cos_h = (w_in * h).sum(-1, keepdim=True).abs()
                fres = p.base_r0[q] + (1.0 - p.base_r0[q]) * (1.0 - cos_h.clamp(max=1.0)) ** 5
                wgt = s.weight[:, None] * fres
            elif p.base == "diffuse":
                s = Lambertian(1.0).sample(w_in, uu)
                ok = s.pdf > 0
                wgt = torch.where(ok[:, None], p.base_albedo[q], torch.zeros_like(p.base_albedo[q]))
            else:
                s = GGXDielectric(p.base_roughness[q], p.base_ior[q]).sample(w_in, uu)
                ok = (s.pdf > 0) & (s.w[:, 2] > 0)  # transmission leaves the stack
                wgt = torch.where(ok, s.weight, torch.zeros_like(s.weight))[:, None]
            beta[ibase] = beta[ibase] * wgt
            new_dir[ibase] = s.w
            new_pdf[ibase] = s.pdf
            kill[ibase] = ~ok

        pdir, pdf_last = new_dir, new_pdf
        # Russian roulette.
        if bounces >= rr_depth:
            qsurv = beta.amax(-1).clamp(max=0.95)
            survive = rand(n, 1)[:, 0] < qsurv
            beta = beta / torch.where(survive, qsurv, torch.ones_like(qsurv))[:, None]
            kill = kill | ~survive
        kill = kill | ~(beta.amax(-1) > 0)
        keep = ~kill
        pid, lane, beta, pdir, depth, slab, pdf_last = (t[keep] for t in (pid, lane, beta, pdir, depth, slab, pdf_last))
        if progress is not None:
            progress(bounces, pid.numel())

    per = acc.view(N, spp, C)
    mean = per.mean(1) + f_top_refl[:, None]
    if spp > 1:
        stderr = per.std(1, unbiased=True) / math.sqrt(spp)
    else:
        stderr = torch.full_like(mean, float("inf"))
    if stats is not None:
        stats.paths += n_lanes
        stats.vertices += vertices
        stats.seconds += time.perf_counter() - t0
    if squeeze:
        return mean[:, 0], stderr[:, 0]
    return mean, stderr
