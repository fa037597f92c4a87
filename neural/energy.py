"""Energy conservation of a material code, on the code alone.

The networks are fitted to BRDF values, not to the energy they reflect: a code
of a lossless stack can reflect a few per cent more light than arrives at some
incidences (the white furnace, docs/RESULTS.md section 15), which a path tracer
turns into glowing interreflections. ``conserve`` bounds a code's directional
albedo: it estimates the albedo of the code's whole BRDF (decoded body plus the
closed-form coat) at ``EnergySettings.thetas`` with the code's own importance
sampler (fixed scrambled Sobol points, so a code always gets the same answer),
and where any incidence of any channel exceeds ``bound`` it moves that channel's
body latent by Newton steps on its worst incidence (the smallest move of the
latent that brings it just inside the bound, to first order) until every
incidence is within it. Codes within the bound (most stacks) are returned
unchanged; the coat is closed form and never changed.

``settle`` goes further for the layering network's codes when the bundle carries
an albedo network (``neural.albedo_net``; the shipped one does not, decision
122): the network predicts the walk's albedo from the code and its decoded
albedo, and the body latent takes the smallest move (Levenberg-Marquardt on
every incidence at once) that brings the decoded albedo to that prediction, then
the bound as above.

Every consumer of a uniform material's code -- the window, the Mitsuba plugins,
the GLSL export, the command line -- gets it from ``NeuralModel.material_latent``,
which applies this: one place, the same code everywhere.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from nbrdf.neural.albedo_net import ALBEDO_FLOOR, AlbedoNet
from nbrdf.neural.anisotropy import body_tail, from_tangent_frame, tail_turn, turned_tail
from nbrdf.neural.coat import coat_of, has_coat
from nbrdf.neural.decoder import Decoder
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.geometry import incidence
from nbrdf.neural.sampling import coated_sample

Tensor = torch.Tensor


@dataclass(frozen=True)
class EnergySettings:
    """How a code's albedo is bounded."""

    thetas: tuple[float, ...] = (0.0, 15.0, 30.0, 45.0, 55.0, 65.0, 75.0, 80.0, 85.0)
    """Incidences (degrees) where the albedo is checked: the furnace report's and 80."""
    samples: int = 256
    """Directions per incidence, from the code's own sampler (coat lobe and body proxy)."""
    bound: float = 0.985
    """The largest directional albedo a code keeps: 1 less a margin for this estimate's noise
    (about 0.5 % at 256 samples on the furnace set's lossless stacks), so an independent
    estimate stays at or below 1."""
    screen_samples: int = 32
    """A first look with this many directions per incidence: a code whose estimate stays under
    ``screen_bound`` there is returned at once (every absorbing stack; the window edits at this cost)."""
    screen_bound: float = 0.85
    """The first look's threshold: far enough under ``bound`` that its noise (a few per cent at 32
    directions) cannot hide an albedo above it."""
    steps: int = 8
    """Newton steps of the projection at most (each: the albedo and its gradient once)."""
    seed: int = 11
    """The scramble of the Sobol points (fixed: a code always maps to the same code)."""
    match_steps: int = 2
    """Levenberg-Marquardt steps at most that move a network's code to the albedo network's prediction (``settle``)."""
    match_tolerance: float = 0.01
    """``settle`` stops once every incidence and channel is this close (relative) to the prediction."""
    match_threshold: float = 0.03
    """``settle`` moves a channel only where the prediction differs from the decoded albedo by more than this
    (relative, at some incidence): the network's own error is about 1-2 %, and every move of the latent
    changes the lobe's shape as well as its albedo."""

    walk_threshold: float = 0.004
    """A code's body is scaled to the walk's albedo (``neural.body_scale``) only where the two differ by more than
    this (relative, at some incidence and channel): about the walk estimate's own noise."""

    def check(self) -> "EnergySettings":
        if not (self.thetas and all(0.0 <= t < 90.0 for t in self.thetas) and 16 <= self.samples <= 1 << 16
                and 0.5 <= self.bound <= 1.0 and 0 <= self.steps <= 10_000
                and 1 <= self.screen_samples and 0.0 < self.screen_bound <= self.bound
                and 0 <= self.match_steps <= 100 and self.match_tolerance > 0.0 and self.walk_threshold >= 0.0):
            raise NbrdfError(f"energy: incidences in [0, 90), samples 16..65536, bound 0.5..1, steps >= 0 "
                             f"(got {self.thetas}, {self.samples}, {self.bound}, {self.steps})")
        return self


def _tangent_turn(decoder: Decoder, code: Tensor) -> Tensor | None:
    """The turn rho of a code's tangent (``neural.anisotropy.tail_turn``); None for a code without an
    anisotropic tail (or a decoder without a coat, whose codes have none)."""
    return tail_turn(code, decoder.spec.code) if decoder.spec.coat else None


def incidence_count(decoder: Decoder, code: Tensor, s: EnergySettings) -> int:
    """How many incidences the albedo is taken at: ``s.thetas``; twice as many for a code with an
    anisotropic tail (in the plane of its tangent and across it)."""
    return len(s.thetas) * (1 if _tangent_turn(decoder, code) is None else 2)


def sample_set(code: Tensor, decoder: Decoder, sigma: float, w: float, s: EnergySettings,
                n: int | None = None) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor]:
    """(wi, wo, weight (N,), coat term (N,), features (N, K), body factor (N,)) of the fixed sample set
    (``n`` per incidence, default ``s.samples``): the code's sampler's directions, cos / pdf per pair (0
    where a draw failed), the coat's value there (the same in every channel), and the decoder's
    features and factor of the body at them (``Decoder.body_pair``: 1 for an isotropic code).

    A code with an anisotropic tail is measured in its tangent's frame: the incidences lie in the plane
    of the tangent and across it, and the whole set is drawn for the code turned back to rho = 0 and
    then turned by rho (the proxy is symmetric about the normal, the coat's pdf turns with it), so the
    bound of a turned material is the turned bound, not a different Monte Carlo draw."""
    n = n or s.samples
    rho = _tangent_turn(decoder, code)
    base = torch.stack([incidence(t) for t in s.thetas]).float()
    spec = decoder.spec
    code0 = code
    if rho is not None:
        base = torch.cat([base, from_tangent_frame(base, torch.tensor(0.0), torch.tensor(1.0))])  # across it
        code0 = turned_tail(code, spec.code, -float(rho))
    wi = base.repeat_interleave(n, 0)
    u = torch.quasirandom.SobolEngine(3, scramble=True, seed=s.seed).draw(n).float().repeat(base.shape[0], 1)
    coat = coat_of(code0[:1], spec.latent)[0].float() if has_coat(spec, code0) else None
    with torch.no_grad():
        tail0 = body_tail(code0[:1].float(), spec.code) if spec.coat else None
        wo, pdf = coated_sample(wi, u, coat, torch.tensor(float(sigma)), torch.tensor(float(w)),
                                None if tail0 is None else tail0[0, :2])
        ok = (wo[:, 2] > 0) & (pdf > 0) & torch.isfinite(pdf)
        weight = torch.where(ok, wo[:, 2].clamp_min(0) / torch.where(ok, pdf, torch.ones_like(pdf)),
                             torch.zeros_like(pdf))
        if rho is not None:
            wi, wo = from_tangent_frame(wi, torch.cos(rho), torch.sin(rho)), from_tangent_frame(wo, torch.cos(rho),
                                                                                               torch.sin(rho))
        c = decoder.coat(code[:1], wi, wo)
        coat_f = torch.zeros_like(weight) if c is None else c.float()
        if rho is not None:  # an anisotropic code's glow (per channel, unwarped) joins the closed-form terms
            coat_f = coat_f[None] + decoder.glow(code[:, None, :].float(), wi[None], wo[None]).float()
        bi, bo, jac = decoder.body_pair(code[:1].float(), wi, wo)
        feats = decoder.encode(bi, bo)
    return wi, wo, weight, coat_f, feats, torch.ones_like(weight) if jac is None else jac.float()


def albedo(decoder: Decoder, code: Tensor, sigma: float, w: float,
           settings: EnergySettings | None = None) -> Tensor:
    """The directional albedo (3, T) of a code (3, code) at ``settings.thetas`` (its own sampler)."""
    s = (settings or EnergySettings()).check()
    wi, wo, weight, coat_f, feats, jac = sample_set(code, decoder, sigma, w, s)
    with torch.no_grad():
        return _estimate(decoder, code[:, : decoder.spec.latent].float(), feats, wi, wo, weight, coat_f, jac,
                         incidence_count(decoder, code, s))


def _estimate(decoder: Decoder, latent: Tensor, feats: Tensor, wi: Tensor, wo: Tensor, weight: Tensor,
              coat_f: Tensor, jac: Tensor, incidences: int) -> Tensor:
    """The albedo (3, T) of body latents (3, L) plus the coat over a sample set of ``sample_set``: the
    decoded body (zero below the horizon, times its factor ``jac``) and the coat's value, times cos / pdf,
    averaged per incidence."""
    y = decoder.log_f_from_share(decoder.latent_share(latent)[:, None, :], feats[None])
    up = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    body = torch.where(up[None], torch.exp(y.clamp(max=80.0)) * jac[None], torch.zeros_like(y))
    return ((body + coat_f) * weight).reshape(3, incidences, -1).mean(-1)


def conserve(decoder: Decoder, code: Tensor, sigma: float, w: float,
             settings: EnergySettings | None = None) -> Tensor:
    """``code`` (3, code) with its albedo at most ``settings.bound`` at every incidence and channel
    (module docstring); unchanged when it already is."""
    s = (settings or EnergySettings()).check()
    if code.dim() != 2 or code.shape[0] != 3 or not torch.isfinite(code).all():
        raise NbrdfError(f"energy: a finite material code (3, {decoder.spec.code}) is needed, "
                         f"got {tuple(code.shape)}")
    L, T = decoder.spec.latent, incidence_count(decoder, code, s)
    z = code[:, :L].float()
    if s.screen_samples < s.samples:
        wi, wo, weight, coat_f, feats, jac = sample_set(code, decoder, sigma, w, s, s.screen_samples)
        with torch.no_grad():
            if float(_estimate(decoder, z, feats, wi, wo, weight, coat_f, jac, T).max()) < s.screen_bound:
                return code
    return _bounded(decoder, code, sample_set(code, decoder, sigma, w, s), s)


def _bounded(decoder: Decoder, code: Tensor, dirs: tuple[Tensor, ...], s: EnergySettings) -> Tensor:
    """``conserve`` on the sample set ``dirs`` of ``sample_set``."""
    wi, wo, weight, coat_f, feats, jac = dirs
    L, T = decoder.spec.latent, incidence_count(decoder, code, s)
    z = code[:, :L].float()
    # Newton steps on each channel's worst incidence: the smallest move of the latent (its norm) that brings
    # that incidence's albedo, to first order, to just inside the bound; again from there while any incidence
    # is above it (the albedo is smooth in the latent: two or three steps). Channels within it never move.
    goal = s.bound - 0.002
    moved = False
    for _ in range(s.steps):
        with torch.enable_grad():  # callers may hold no_grad (the window's plots): the gradient is this step's own
            zz = z.clone().requires_grad_(True)
            worst, _ = _estimate(decoder, zz, feats, wi, wo, weight, coat_f, jac, T).max(-1)  # (3,)
            move = worst > s.bound
            if not bool(move.any()):
                break
            (g,) = torch.autograd.grad(worst[move].sum(), zz)  # the rows are independent: each channel's gradient
        with torch.no_grad():
            step = (worst - goal).clamp_min(0.0) / g.pow(2).sum(-1).clamp_min(1e-12)
            z = torch.where(move[:, None], z - step[:, None] * g, z)
        moved = True
    if not moved:
        return code
    out = code.clone()
    out[:, :L] = z.to(code.dtype)
    return out


def _with_jacobian(decoder: Decoder, z: Tensor, feats: Tensor, wi: Tensor, wo: Tensor, weight: Tensor,
                   coat_f: Tensor, jac: Tensor, incidences: int) -> tuple[Tensor, Tensor]:
    """``_estimate``'s albedo (3, T) and its Jacobian in the body latent (3, T, L), from one backward pass: the
    latent enters the decoder only through its first layer's share (affine in it), so each sample gets a copy
    of the share, one backward gives every sample's gradient, and a sum per incidence times the share's matrix
    gives the Jacobian (instead of one backward per incidence)."""
    L = decoder.spec.latent
    share = decoder.latent_share(z.detach())
    up = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    with torch.enable_grad():  # callers may hold no_grad (the window's plots): the gradient is this call's own
        copies = share[:, None, :].expand(share.shape[0], feats.shape[0], share.shape[-1]).clone().requires_grad_(True)
        y = decoder.log_f_from_share(copies, feats[None])
        body = torch.where(up[None], torch.exp(y.clamp(max=80.0)) * jac[None], torch.zeros_like(y))
        (g,) = torch.autograd.grad((body * weight).sum(), copies)  # (3, N, width)
    with torch.no_grad():
        a = ((body + coat_f) * weight).reshape(3, incidences, -1).mean(-1)
        per_t = g.reshape(3, incidences, -1, g.shape[-1]).mean(2)  # (3, T, width)
        return a, per_t @ decoder.first_layer.weight[:, :L]


def settle(decoder: Decoder, code: Tensor, sigma: float, w: float, net: AlbedoNet | None,
           settings: EnergySettings | None = None) -> Tensor:
    """A layering network's ``code`` (3, code) with its decoded albedo moved to what ``net`` predicts for it
    (at most the bound), then bounded (``conserve``). A code with an anisotropic tail, or without a network
    (or one trained for other incidences), is only bounded.

    Levenberg-Marquardt on the relative residuals of all incidences at once, each step the least move of the
    latent (its norm) that meets them to first order, halved until it lowers their sum of squares; channels
    apart (their rows are independent)."""
    s = (settings or EnergySettings()).check()
    T = len(s.thetas)
    if (net is None or code.dim() != 2 or code.shape[0] != 3 or not torch.isfinite(code).all()
            or _tangent_turn(decoder, code) is not None or net.incidences != T):
        return conserve(decoder, code, sigma, w, s)
    L = decoder.spec.latent
    dirs = sample_set(code, decoder, sigma, w, s)
    wi, wo, weight, coat_f, feats, jac = dirs
    z = code[:, :L].float()
    a, J = _with_jacobian(decoder, z, feats, wi, wo, weight, coat_f, jac, T)
    with torch.no_grad():
        target = net(code.float(), a).clamp(max=s.bound - 0.002)
        scale = target.clamp_min(ALBEDO_FLOOR)
        live = target.min(-1).values > 10 * ALBEDO_FLOOR  # a near-black channel has nothing to match
        live &= ((target - a) / scale).abs().amax(-1) > s.match_threshold  # a small correction is not worth a move
        sq = lambda a_: ((target - a_) / scale).pow(2).sum(-1)  # noqa: E731  (per channel)
        for _ in range(s.match_steps):
            r = (target - a) / scale
            now = sq(a)
            todo = live & (r.abs().amax(-1) > s.match_tolerance)
            if not bool(todo.any()):
                break
            Jr = J / scale[..., None]
            jjt = Jr @ Jr.transpose(1, 2)
            damp = (1e-3 * jjt.diagonal(dim1=1, dim2=2).mean(-1) + 1e-12)[:, None, None] * torch.eye(T)
            step = (Jr.transpose(1, 2) @ torch.linalg.solve(jjt + damp, r[..., None]))[..., 0]
            step = torch.where(todo[:, None], step, torch.zeros_like(step))
            for _half in range(4):  # backtracking: a step that does not lower the residuals' squares is halved
                a_new, J_new = _with_jacobian(decoder, z + step, feats, wi, wo, weight, coat_f, jac, T)
                better = sq(a_new) < now
                if bool(better[todo].all()):
                    break
                step = torch.where(better[:, None], step, 0.5 * step)
            keep = (todo & better)[:, None]
            z = torch.where(keep, z + step, z)
            a = torch.where(keep, a_new, a)
            J = torch.where(keep[..., None], J_new, J)
            if not bool(keep.any()):
                break
    out = code.clone()
    out[:, :L] = z.to(code.dtype)
    return _bounded(decoder, out, dirs, s)  # the prediction is capped at the bound: a guard, rarely a step
