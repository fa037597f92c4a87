"""A symmetric per-incidence scale of a code's body: the energy a walk measured, on the networks' lobe (issue 40).

The networks get a stack's lobe shape right and its energy to a few per cent (1.8 % median, 29.6 % worst on the
furnace set). A latent cannot carry a per-incidence correction: moving it to the right albedo at every incidence
reshapes the lobe (decision 125: the validation set's render-space error 0.068 -> 0.091). A scale of the body does
not: f = coat + g(theta_i) g(theta_o) body, g piecewise linear in the angle on knots (the energy incidences), the
same function on both sides, so f stays reciprocal, and the body's shape at each incidence is kept. ``fit`` finds
g from a target albedo at the knots (the walk's: ``training.calibration``) by Gauss-Newton in log g, each
incidence weighted by the target's noise and log g held near 0 by a weak prior: a body that is already right, or
that reflects too little of the light for its error to be seen under the coat's, keeps g = 1.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from nbrdf.neural.decoder import Decoder
from nbrdf.neural.energy import EnergySettings, sample_set
from nbrdf.neural.errors import NbrdfError

Tensor = torch.Tensor
#: The relative noise of the fit's own albedo estimate (4,096 directions per incidence: at most about 0.3 %); a
#: residual is weighed by it and the target's standard error together.
NOISE = 0.003
#: The prior's width in log g: a weak pull toward 1 (a deep lossless stack needs g about 1.3).
PRIOR = 0.5
#: The prior's width on log g's second differences across the knots: the networks' energy error is smooth in the
#: angle, so an incidence whose target is noisy (a dim channel of a deep stack) follows its neighbours.
CURVATURE = 0.05
#: g's range: a body more than this far off is not the networks' lobe with the wrong energy.
G_RANGE = (0.5, 2.0)
#: Directions per incidence of the fit's albedo (the code's own sampler, fixed Sobol points; 60-150 ms a fit here).
FIT_SAMPLES = 4096


@dataclass(frozen=True)
class BodyScale:
    """g (3, T) per channel at ``knots`` (degrees, increasing): the body's factor is g(theta_i) g(theta_o),
    linear in the angle between knots and flat outside them."""

    knots: tuple[float, ...]
    g: Tensor

    def __post_init__(self):
        k = torch.tensor(self.knots)
        if (self.g.dim() != 2 or self.g.shape != (3, len(self.knots)) or len(self.knots) < 2
                or not bool((k[1:] > k[:-1]).all()) or not bool(torch.isfinite(self.g).all())
                or not bool((self.g > 0).all())):
            raise NbrdfError(f"body scale: positive finite factors (3, T) on T >= 2 increasing knots are needed, "
                             f"got {tuple(self.g.shape)} on {self.knots}")

    def weights(self, cos_theta: Tensor) -> Tensor:
        """(N, T) hat weights of directions' angles (from their cosines (N,)) on the knots."""
        knots = torch.tensor(self.knots, dtype=cos_theta.dtype, device=cos_theta.device)
        t = torch.rad2deg(torch.acos(cos_theta.clamp(-1.0, 1.0))).clamp(float(knots[0]), float(knots[-1]))
        j = torch.searchsorted(knots, t.contiguous(), right=True).clamp(1, len(self.knots) - 1)
        lo, hi = knots[j - 1], knots[j]
        a = ((t - lo) / (hi - lo)).clamp(0.0, 1.0)
        w = torch.zeros(t.shape[0], len(self.knots), dtype=cos_theta.dtype, device=cos_theta.device)
        w.scatter_(1, (j - 1)[:, None], (1.0 - a)[:, None])
        w.scatter_add_(1, j[:, None], a[:, None])
        return w

    def at(self, cos_theta: Tensor) -> Tensor:
        """g (N, 3) at directions' cosines (N,)."""
        return self.weights(cos_theta) @ self.g.to(cos_theta.dtype).T

    def __call__(self, wi: Tensor, wo: Tensor) -> Tensor:
        """The body's factor (N, 3) at pairs (N, 3)."""
        return self.at(wi[:, 2]) * self.at(wo[:, 2])


def fit(decoder: Decoder, code: Tensor, sigma: float, w: float, target: Tensor, target_se: Tensor | None = None,
        settings: EnergySettings | None = None) -> BodyScale | None:
    """The body scale that brings a code's albedo (its decoded body times g g, plus the coat) to ``target``
    (3, T) at ``settings.thetas`` (capped at the bound), each incidence weighed by its standard error
    ``target_se`` (3, T) (default 0); None when every channel is already within ``settings.walk_threshold``
    of it (the code needs none)."""
    s = settings or EnergySettings()
    T = len(s.thetas)
    se = torch.zeros(3, T) if target_se is None else target_se.float()
    if (tuple(target.shape) != (3, T) or tuple(se.shape) != (3, T) or not bool(torch.isfinite(target).all())
            or not bool(torch.isfinite(se).all())):
        raise NbrdfError(f"body scale: a finite target albedo (3, {T}) at {s.thetas} is needed, "
                         f"got {tuple(target.shape)}")
    fit_settings = EnergySettings(thetas=s.thetas, samples=FIT_SAMPLES, seed=s.seed)
    wi, wo, weight, coat_f, feats, jac = sample_set(code, decoder, sigma, w, fit_settings)
    if wi.shape[0] != T * FIT_SAMPLES:
        return None  # a code with an anisotropic tail: its albedo depends on azimuth (not scaled)
    scale = BodyScale(tuple(s.thetas), torch.ones(3, T))
    with torch.no_grad():
        y = decoder.log_f_from_share(decoder.latent_share(code[:, : decoder.spec.latent].float())[:, None, :],
                                     feats[None])
        up = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        body = torch.where(up[None], torch.exp(y.clamp(max=80.0)) * jac[None], torch.zeros_like(y))  # (3, N)
        P = scale.weights(wo[:, 2].float())  # (N, T): where each sample's wo falls on the knots
        M = ((body * weight)[..., None] * P[None]).reshape(3, T, FIT_SAMPLES, T).mean(2)  # body_t = g_t (M g)_t
        C = (coat_f * weight).reshape(-1, T, FIT_SAMPLES).mean(-1).expand(3, T)
        goal = target.float().clamp(max=s.bound - 0.002)
        if float(((C + M.sum(-1) - goal).abs() / goal.clamp_min(1e-6)).amax()) <= s.walk_threshold:
            return None
        sd = (se.pow(2) + (NOISE * goal).pow(2)).sqrt().clamp_min(1e-6)
        x = torch.zeros(3, T)  # log g
        eye = torch.eye(T)
        d2 = (eye[:-2] - 2.0 * eye[1:-1] + eye[2:]) / CURVATURE  # second differences across the knots
        prior = torch.cat([eye / PRIOR, d2]).expand(3, 2 * T - 2, T)
        for _ in range(30):  # Gauss-Newton on the noise-weighted residuals and the priors (T unknowns per channel)
            g = x.exp()
            Mg = (M @ g[..., None])[..., 0]
            r = torch.cat([(C + g * Mg - goal) / sd, (prior @ x[..., None])[..., 0]], -1)
            dA = (eye * Mg[:, None, :] + g[:, :, None] * M) * g[:, None, :]  # dA_t / dx_j
            J = torch.cat([dA / sd[..., None], prior], 1)
            step = torch.linalg.solve(J.transpose(1, 2) @ J + 1e-9 * eye, -(J.transpose(1, 2) @ r[..., None]))
            x = (x + step[..., 0]).clamp(*(torch.log(torch.tensor(G_RANGE)).tolist()))
            if float(step.abs().max()) < 1e-5:
                break
    return BodyScale(tuple(s.thetas), x.exp())
