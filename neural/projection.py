"""Projection (SPEC section 6): fit latents to BRDF samples with the decoder frozen.

Works on a batch of B single-channel BRDFs at once (B = 3 for one RGB
material), each given as n samples (wi, wo, f). The loss is the training
loss (log(1 + f cos) squared error) for the first steps, then the
prediction-relative squared error (``decoder.unbiased_error``), whose
minimum is the mean of noisy Monte Carlo samples rather than their
geometric mean.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import torch

from nbrdf.neural.coat import COAT_PARAMS, coat_eval, with_coat
from nbrdf.neural.decoder import Decoder, loss_target, predicted_target, unbiased_error
from nbrdf.neural.errors import NbrdfError

Tensor = torch.Tensor


@dataclass(frozen=True)
class ProjectionConfig:
    """How latents are fitted (Adam on the latents, cosine schedule). 400 steps at lr 0.04 rather than
    200 at 0.08: on the look-development set the projection's HDR-FLIP median / worst went 0.072 / 0.319
    -> 0.066 / 0.136 (the faster schedule left some dark bodies in a poor minimum; docs/RESULTS.md)."""

    steps: int = 400
    """optimisation steps"""
    lr: float = 0.04
    """Adam learning rate of the latents (decays to 2 % of it)"""
    latent_reg: float = 1e-4
    """weight of the latents' squared-norm penalty (the training's prior on latents)"""
    unbiased_share: float = 0.5
    """final share of the steps on ``decoder.unbiased_error`` (fits the noisy mean)"""


def check_samples(wi: Tensor, wo: Tensor, f: Tensor) -> None:
    if wi.shape != wo.shape or wi.shape[-1] != 3 or f.shape != wi.shape[:-1]:
        raise NbrdfError(f"samples: wi {tuple(wi.shape)}, wo {tuple(wo.shape)} and f {tuple(f.shape)} "
                         "do not fit together (expected (B, n, 3), (B, n, 3), (B, n))")
    for name, t in (("wi", wi), ("wo", wo), ("f", f)):
        if not torch.isfinite(t).all():
            raise NbrdfError(f"samples: {name} holds NaN or infinite values")
    if (f < 0).any():
        raise NbrdfError("samples: f holds negative values (a BRDF is never negative)")
    if not ((wi[..., 2] > 0) & (wo[..., 2] > 0)).any():
        raise NbrdfError("samples: no pair has both directions above the horizon")


def project(dec: Decoder, wi: Tensor, wo: Tensor, f: Tensor, cfg: ProjectionConfig = ProjectionConfig(),
            z0: Tensor | None = None, weight: Tensor | None = None, coat: Tensor | None = None,
            stop: Callable[[int], bool] | None = None) -> Tensor:
    """Codes (B, 34) for B BRDFs sampled at (B, n) pairs (latents (B, 32)
    for a decoder without the coat split). Under the coat split the latent is
    fitted to the body, the samples minus the closed-form reflection of
    ``coat`` (B, 2) (each BRDF's top interface; None: no coat, e.g. a
    measured table), and the code carries the coat. ``z0`` warm-starts the
    fit (codes or latents); ``stop(step)`` True ends it before that step
    (a cancelled refinement), returning the latents as they are."""
    check_samples(wi, wo, f)
    if coat is not None and not dec.spec.coat:
        raise NbrdfError("projection: this decoder predates the coat split and cannot take a coat")
    if coat is not None:
        coat = torch.as_tensor(coat, dtype=torch.float32).reshape(-1, COAT_PARAMS).expand(wi.shape[0], -1)
        f = (f.float() - coat_eval(coat[:, None, :], wi.float(), wo.float())).clamp_min(0.0)
    up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    feats = dec.encode(wi.float(), wo.float())
    cos_o = wo[..., 2].float().clamp_min(0.0)
    target = loss_target(f.float(), cos_o, dec.spec.loss_scale)
    w = up.float() if weight is None else weight.float() * up.float()
    w = w / w.sum(-1, keepdim=True).clamp_min(1e-12)
    B = wi.shape[0]
    L = dec.spec.latent
    z = (dec.latent_mean.expand(B, -1).clone() if z0 is None else z0[..., :L].clone().float()).requires_grad_(True)
    opt = torch.optim.Adam([z], lr=cfg.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, cfg.steps, eta_min=cfg.lr * 0.02)
    req = [p.requires_grad for p in dec.parameters()]
    for p in dec.parameters():
        p.requires_grad_(False)
    switch = cfg.steps - int(round(cfg.unbiased_share * cfg.steps))
    try:
        for step in range(cfg.steps):
            if stop is not None and stop(step):
                break
            y = dec.log_f(z[:, None, :], feats)
            if step < switch:  # the training loss first (robust far from the solution) ...
                err = (predicted_target(y, cos_o, dec.spec.loss_scale) - target) ** 2
            else:  # ... then the error whose minimum is the samples' mean, not their geometric mean
                err = unbiased_error(y, f.float(), cos_o, dec.spec.loss_scale)
            loss = (err * w).sum() + cfg.latent_reg * (z * z).sum()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
    finally:
        for p, r in zip(dec.parameters(), req):
            p.requires_grad_(r)
    return with_coat(z.detach(), coat) if dec.spec.coat else z.detach()
