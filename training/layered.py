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

from nbrdf.training.analytic import GGXConductor, GGXDielectric, Lambertian
from nbrdf.training.microfacet import fresnel_dielectric, refract, sample_vndf, smith_g1, vndf_pdf

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
    dropped: int = 0  # contributions lost to float round-off (non-finite), about one in 10^8 paths


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


def _compile(fn):
    """torch.compile(dynamic=True) on request (``NBRDF_COMPILE=1`` or
    ``simulate(..., compile=True)``): the kernels below are pure elementwise
    functions, which inductor fuses into one loop each."""
    state = {"compiled": None}

    def call(*args, compiled: bool = False):
        if not compiled:
            return fn(*args)
        if state["compiled"] is None:
            state["compiled"] = torch.compile(fn, dynamic=True)
        return state["compiled"](*args)

    call.__wrapped__ = fn
    call.__doc__ = fn.__doc__
    return call


def _isotropic(u: Tensor) -> Tensor:
    z = 1.0 - 2.0 * u[:, 0]
    r = torch.sqrt((1.0 - z * z).clamp_min(0.0))
    ph = 2.0 * math.pi * u[:, 1]
    return torch.stack([r * torch.cos(ph), r * torch.sin(ph), z], -1)


def _nee_to_top(z: Tensor, wo: Tensor, a0: Tensor, e0: Tensor, tau0: Tensor, u: Tensor):
    """Samples the top interface from wo (forced transmission). Returns the
    direction v leaving the vertex toward the top, the factor
    Tr * f_top(-v, wo) / pdf (0 when the sample failed) and that pdf."""
    wt, _, pdf_nee = _forced_transmission_sample(a0, e0, wo, u)
    v = -wt
    ok = pdf_nee > 0
    tr = torch.exp(-tau0 * z / v[:, 2].clamp_min(1e-12))
    f_t = GGXDielectric(a0, e0).eval(wt, wo)
    scale = torch.where(ok, tr * f_t / torch.where(ok, pdf_nee, torch.ones_like(pdf_nee)), torch.zeros_like(tr))
    return v, scale, pdf_nee


@_compile
def _k_flight(depth: Tensor, uz: Tensor, slab_top: Tensor, tau: Tensor, u: Tensor):
    """Free flight in the current slab: (scatters, new depth)."""
    down = uz < 0
    dist_b = torch.where(down, (slab_top + 1.0 - depth) / (-uz).clamp_min(1e-12), (depth - slab_top) / uz.clamp_min(1e-12))
    t = -torch.log1p(-u) / tau.clamp_min(1e-30)
    scatter = (tau > 0) & (t < dist_b)
    new_depth = torch.where(scatter, depth - t * uz, torch.where(down, slab_top + 1.0, slab_top))
    return scatter, new_depth


@_compile
def _k_medium(beta: Tensor, depth: Tensor, alb: Tensor, nee_on: Tensor, wo: Tensor, a0: Tensor, e0: Tensor,
              tau0: Tensor, u: Tensor):
    """Scattering in a medium: NEE (in the top slab) and phase sampling."""
    v, scale, pdf_nee = _nee_to_top(depth, wo, a0, e0, tau0, u[:, 0:2])
    mis = pdf_nee / (pdf_nee + INV_4PI)
    contrib = beta * alb * (INV_4PI * scale * mis * nee_on)[:, None]
    return contrib, beta * alb, _isotropic(u[:, 2:4])


@_compile
def _k_top(beta: Tensor, pdir: Tensor, pdf_last: Tensor, wo: Tensor, a0: Tensor, e0: Tensor, u: Tensor):
    """The walk reaches the top from below: evaluate the exit toward wo (MIS
    against NEE with the consistent pdf), then sample the interface."""
    top = GGXDielectric(a0, e0)
    w_in = -pdir
    f_t = top.eval(w_in, wo)
    pdf_nee = _forced_transmission_pdf(a0, e0, wo, w_in)
    mis = pdf_last / (pdf_last + pdf_nee)
    contrib = beta * (f_t * mis)[:, None]
    s = top.sample(w_in, u)
    stays = (s.pdf > 0) & (s.w[:, 2] < 0)
    return contrib, beta * s.weight[:, None], s.w, s.pdf, stays


@_compile
def _k_interface(beta: Tensor, pdir: Tensor, a: Tensor, e: Tensor, nee_on: Tensor, wo: Tensor, a0: Tensor,
                 e0: Tensor, tau0: Tensor, u: Tensor):
    """An internal interface hit from either side; NEE when it bounds the top slab."""
    itf = GGXDielectric(a, e)
    w_in = -pdir
    v, scale, pdf_nee = _nee_to_top(torch.ones_like(a), wo, a0, e0, tau0, u[:, 0:2])
    kern = itf.eval(w_in, v) * v[:, 2].abs()
    mis = pdf_nee / (pdf_nee + itf.pdf(w_in, v))
    contrib = beta * (kern * scale * mis * nee_on)[:, None]
    s = itf.sample(w_in, u[:, 2:5])
    ok = s.pdf > 0
    crossed = ok & (w_in[:, 2] * s.w[:, 2] < 0)
    return contrib, beta * s.weight[:, None], s.w, s.pdf, ok, crossed


@_compile
def _k_base_conductor(beta: Tensor, pdir: Tensor, a: Tensor, r0: Tensor, nee_on: Tensor, wo: Tensor, a0: Tensor,
                      e0: Tensor, tau0: Tensor, u: Tensor):
    geo = GGXConductor(a, 1.0)  # directions do not depend on r0
    w_in = -pdir
    v, scale, pdf_nee = _nee_to_top(torch.ones_like(a), wo, a0, e0, tau0, u[:, 0:2])
    kern = _conductor_rgb(a, r0, w_in, v) * v[:, 2:3].abs()
    mis = pdf_nee / (pdf_nee + geo.pdf(w_in, v))
    contrib = beta * kern * (scale * mis * nee_on)[:, None]
    s = geo.sample(w_in, u[:, 2:5])
    ok = s.pdf > 0
    h = w_in + s.w
    h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-30)
    x = (1.0 - (w_in * h).sum(-1).abs().clamp(max=1.0)) ** 5
    fres = x[:, None] + r0 * (1.0 - x[:, None])
    return contrib, beta * s.weight[:, None] * fres, s.w, s.pdf, ok


@_compile
def _k_base_diffuse(beta: Tensor, pdir: Tensor, alb: Tensor, nee_on: Tensor, wo: Tensor, a0: Tensor, e0: Tensor,
                    tau0: Tensor, u: Tensor):
    lam = Lambertian(1.0)
    w_in = -pdir
    v, scale, pdf_nee = _nee_to_top(torch.ones_like(a0), wo, a0, e0, tau0, u[:, 0:2])
    pdf_x = lam.pdf(w_in, v)
    mis = pdf_nee / (pdf_nee + pdf_x)
    contrib = beta * alb * (v[:, 2].clamp_min(0.0) / math.pi * scale * mis * nee_on)[:, None]
    s = lam.sample(w_in, u[:, 2:5])
    ok = s.pdf > 0
    return contrib, beta * alb, s.w, s.pdf, ok


@_compile
def _k_base_dielectric(beta: Tensor, pdir: Tensor, a: Tensor, e: Tensor, nee_on: Tensor, wo: Tensor, a0: Tensor,
                       e0: Tensor, tau0: Tensor, u: Tensor):
    d = GGXDielectric(a, e)
    w_in = -pdir
    v, scale, pdf_nee = _nee_to_top(torch.ones_like(a), wo, a0, e0, tau0, u[:, 0:2])
    kern = d.eval(w_in, v) * v[:, 2].abs()
    mis = pdf_nee / (pdf_nee + d.pdf(w_in, v))
    contrib = beta * (kern * scale * mis * nee_on)[:, None]
    s = d.sample(w_in, u[:, 2:5])
    ok = (s.pdf > 0) & (s.w[:, 2] > 0)  # what is transmitted leaves the stack
    return contrib, beta * torch.where(ok, s.weight, torch.zeros_like(s.weight))[:, None], s.w, s.pdf, ok


class _Tables:
    """Per-lane parameter lookup: a gather by pair index, or a broadcast of
    the one row when every stack shares the parameter."""

    def __init__(self, p: StackParams):
        self.p = p
        names = ("roughness", "ior", "sigma_t", "albedo", "base_roughness", "base_r0", "base_ior", "base_albedo")
        self.shared = {k: bool((getattr(p, k) == getattr(p, k)[:1]).all()) for k in names}

    def layer(self, name: str, q: Tensor, k: Tensor) -> Tensor:
        t = getattr(self.p, name)
        return t[0][k] if self.shared[name] else t[q, k]

    def top(self, name: str, q: Tensor) -> Tensor:
        t = getattr(self.p, name)[:, 0]
        return t[:1].expand(q.shape[0]) if self.shared[name] else t[q]

    def base(self, name: str, q: Tensor) -> Tensor:
        t = getattr(self.p, name)
        return t[:1].expand(q.shape[0], *t.shape[1:]) if self.shared[name] else t[q]


def simulate(stack: StackParams, wi: Tensor, wo: Tensor, spp: int = 64, seed: int = 0, *,
             dtype: torch.dtype = torch.float32, rr_depth: int = 4, max_depth: int = 100_000,
             include_top_reflection: bool = True, compile: bool | None = None,
             stats: SimStats | None = None) -> tuple[Tensor, Tensor]:
    """Mean and standard error of the stack's BRDF f(wi, wo) per pair.

    ``wi``, ``wo``: (N, 3) upper-hemisphere unit vectors; ``spp`` paths per
    pair; ``include_top_reflection=False`` leaves out the closed-form single
    reflection off the top (to test the walk alone); ``compile`` fuses the
    kernels with torch.compile (default: env ``NBRDF_COMPILE=1``). Returns
    tensors (N, C) (or (N,) for single-channel input without a channel dim)
    in ``dtype``. Deterministic for a given seed, batch and ``compile``."""
    import os
    import time

    t0 = time.perf_counter()
    if compile is None:
        compile = os.environ.get("NBRDF_COMPILE", "0") == "1"
    kw = {"compiled": bool(compile)}
    p, squeeze = stack.normalized(dtype)
    wi = wi.to(dtype)
    wo = wo.to(dtype)
    N, L = p.roughness.shape
    C = p.albedo.shape[-1]
    gen = torch.Generator().manual_seed(int(seed))

    def rand(n: int, k: int) -> Tensor:
        return torch.rand(n, k, generator=gen, dtype=dtype)

    # Closed-form single reflection off the top interface.
    f_top_refl = (GGXDielectric(p.roughness[:, 0], p.ior[:, 0]).eval(wi, wo) if include_top_reflection
                  else torch.zeros(N, dtype=dtype))

    # Lanes: spp paths per pair, laid out pair-major.
    n_lanes = N * spp
    pid = torch.arange(N).repeat_interleave(spp)
    acc = torch.zeros(n_lanes, C, dtype=dtype)
    lane = torch.arange(n_lanes)

    # Entry: forced refraction of wi through the top interface, stratified over spp.
    u = rand(n_lanes, 2)
    if spp > 1:
        u[:, 0] = (torch.arange(n_lanes) % spp + u[:, 0]) / spp
    d_in, w_entry, _ = _forced_transmission_sample(p.roughness[pid, 0], p.ior[pid, 0], wi[pid], u)
    beta = w_entry[:, None].expand(n_lanes, C).clone()
    pdir = d_in  # photon travel direction
    depth = torch.zeros(n_lanes, dtype=dtype)
    slab = torch.zeros(n_lanes, dtype=torch.long)
    pdf_last = torch.zeros(n_lanes, dtype=dtype)  # density of pdir at the vertex that chose it
    keep = w_entry > 0
    pid, lane, beta, pdir, depth, slab, pdf_last = (t[keep] for t in (pid, lane, beta, pdir, depth, slab, pdf_last))
    # Parameters shared by every stack (one material's lobe, say) are
    # broadcast instead of gathered per lane.
    tab = _Tables(p)
    bounces = vertices = 0

    while pid.numel() > 0 and bounces < max_depth:
        n = pid.numel()
        vertices += n
        bounces += 1
        u = rand(n, 7)
        scatter, depth = _k_flight(depth, pdir[:, 2], slab.to(dtype), tab.layer("sigma_t", pid, slab), u[:, 0], **kw)
        going_down = pdir[:, 2] < 0
        k_if = torch.where(going_down, slab + 1, slab)  # the interface reached (L = base)
        alive = torch.ones(n, dtype=torch.bool)
        new_dir, new_pdf = pdir.clone(), pdf_last.clone()

        def common(idx: Tensor):
            q = pid[idx]
            return wo[q], tab.top("roughness", q), tab.top("ior", q), tab.top("sigma_t", q)

        def absorb(idx: Tensor, contrib: Tensor, b: Tensor, d: Tensor, pdf: Tensor, ok: Tensor) -> None:
            finite = torch.isfinite(contrib)
            if not bool(finite.all()):  # a degenerate float32 configuration: drop it, never poison the mean
                contrib = torch.where(finite, contrib, torch.zeros_like(contrib))
                if stats is not None:
                    stats.dropped += int((~finite).any(-1).sum())
            acc.index_add_(0, lane[idx], contrib)
            beta[idx], new_dir[idx], new_pdf[idx] = b, d, pdf
            alive[idx] = ok

        idx = scatter.nonzero().squeeze(-1)
        if idx.numel():
            q, s_ = pid[idx], slab[idx]
            contrib, b, d = _k_medium(beta[idx], depth[idx], tab.layer("albedo", q, s_), (s_ == 0).to(dtype), *common(idx),
                                      torch.cat([u[idx, 1:3], u[idx, 3:5]], 1), **kw)
            absorb(idx, contrib, b, d, torch.full_like(depth[idx], INV_4PI), torch.ones_like(s_, dtype=torch.bool))

        idx = (~scatter & (k_if == 0)).nonzero().squeeze(-1)
        if idx.numel():
            w_o, a0, e0, _ = common(idx)
            absorb(idx, *_k_top(beta[idx], pdir[idx], pdf_last[idx], w_o, a0, e0, u[idx, 3:6], **kw))

        idx = (~scatter & (k_if >= 1) & (k_if < L)).nonzero().squeeze(-1)
        if idx.numel():
            q, k = pid[idx], k_if[idx]
            contrib, b, d, pdf, ok, crossed = _k_interface(
                beta[idx], pdir[idx], tab.layer("roughness", q, k), tab.layer("ior", q, k), (k == 1).to(dtype), *common(idx),
                u[idx, 1:6], **kw)
            absorb(idx, contrib, b, d, pdf, ok)
            # Crossing downward enters slab k, upward slab k - 1.
            slab[idx] = torch.where(crossed, torch.where(pdir[idx, 2] < 0, k, k - 1), slab[idx])

        idx = (~scatter & (k_if == L)).nonzero().squeeze(-1)
        if idx.numel():
            q = pid[idx]
            nee_on = torch.full((idx.numel(),), 1.0 if L == 1 else 0.0, dtype=dtype)
            args = (beta[idx], pdir[idx])
            if p.base == "conductor":
                out = _k_base_conductor(*args, tab.base("base_roughness", q), tab.base("base_r0", q), nee_on, *common(idx),
                                        u[idx, 1:6], **kw)
            elif p.base == "diffuse":
                out = _k_base_diffuse(*args, tab.base("base_albedo", q), nee_on, *common(idx), u[idx, 1:6], **kw)
            else:
                out = _k_base_dielectric(*args, tab.base("base_roughness", q), tab.base("base_ior", q), nee_on,
                                         *common(idx), u[idx, 1:6], **kw)
            absorb(idx, *out)

        pdir, pdf_last = new_dir, new_pdf
        if bounces >= rr_depth:  # Russian roulette on the largest channel weight
            q_s = beta.amax(-1).clamp(max=0.95)
            survive = u[:, 6] < q_s
            beta = beta / torch.where(survive, q_s, torch.ones_like(q_s))[:, None]
            alive &= survive
        alive &= beta.amax(-1) > 0
        pid, lane, beta, pdir, depth, slab, pdf_last = (t[alive] for t in (pid, lane, beta, pdir, depth, slab, pdf_last))

    per = acc.view(N, spp, C)
    mean = per.mean(1) + f_top_refl[:, None]
    stderr = per.std(1) / math.sqrt(spp) if spp > 1 else torch.full_like(mean, float("inf"))
    if stats is not None:
        stats.paths += n_lanes
        stats.vertices += vertices
        stats.seconds += time.perf_counter() - t0
    if squeeze:
        return mean[:, 0], stderr[:, 0]
    return mean, stderr
