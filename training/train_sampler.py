"""Training of the sampler (``nbrdf train sampler``): the proxy pdf's network (``neural.sampling.SamplerNet``),
by minimising the KL divergence from the decoded lobe f cos(theta_o) (normalised per incident direction) to the
proxy pdf, estimated by importance sampling over latents of random stacks; through the frozen decoder, with the
resumable loop of ``training.train_operations``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import torch

from nbrdf.neural.geometry import cosine_hemisphere
from nbrdf.neural.layering import LATENT
from nbrdf.neural.model import NeuralModel, load_model
from nbrdf.neural.sampling import SamplerNet, lambert_pdf, proxy_pdf, proxy_sample
from nbrdf.training.distributions import mixed_params
from nbrdf.training.train_operations import OpsConfig, finish_run, run_loop, stack_latents

Tensor = torch.Tensor


@dataclass
class SamplerConfig(OpsConfig):
    """``nbrdf train sampler``: the proxy-pdf network, by KL divergence to decoded lobes."""

    steps: int = 3000
    batch: int = 64
    pairs: int = 256
    lr: float = 3e-3


PROPOSAL_SIGMAS = (0.03, 0.12, 0.5)


def _proposal(wi: Tensor, g: torch.Generator) -> tuple[Tensor, Tensor]:
    """wo from an even mixture of a cosine lobe and three half-vector
    Gaussians (narrow to wide), with the mixture's pdf."""
    n = wi.shape[0]
    k = torch.randint(0, 1 + len(PROPOSAL_SIGMAS), (n,), generator=g)
    sig = torch.tensor((1.0,) + PROPOSAL_SIGMAS)[k]
    wo, _ = proxy_sample(wi, torch.rand(n, 3, generator=g), sig, (k == 0).float())
    pdf = lambert_pdf(wo) + sum(proxy_pdf(wi, wo, torch.tensor(s), torch.tensor(0.0)) for s in PROPOSAL_SIGMAS)
    return wo, pdf / (1 + len(PROPOSAL_SIGMAS))


def random_material_params(n: int, g: torch.Generator) -> Tensor:
    """Data-set parameter vectors over every class, as the paper's distributions."""
    return mixed_params(n, g).float()


def sampler_targets(model: NeuralModel, z: Tensor, n_wi: int, n_wo: int, g: torch.Generator):
    """Importance-sampled body lobes of codes z (M, 34): wi (M, n_wi, 3), wo
    (M, n_wi, n_wo, 3), normalised weights f cos / proposal per wi (the
    proxy serves the body; the coat is sampled exactly)."""
    z = z[:, :LATENT]
    M = z.shape[0]
    a, b = torch.rand(M, n_wi, generator=g), torch.rand(M, n_wi, generator=g)
    wi = cosine_hemisphere(a.clamp(max=1 - 1e-4), b)  # never exactly at the horizon
    wi_r = wi[:, :, None, :].expand(M, n_wi, n_wo, 3).reshape(-1, 3)
    wo, pdf = _proposal(wi_r, g)
    with torch.no_grad():
        f = model.decoder(z[:, None, :].expand(M, n_wi * n_wo, LATENT).reshape(-1, LATENT), wi_r, wo)
    w = torch.where(wo[:, 2] > 0, f * wo[:, 2].clamp_min(0) / pdf.clamp_min(1e-12), torch.zeros_like(f))
    w = w.view(M, n_wi, n_wo)
    w = w / w.sum(-1, keepdim=True).clamp_min(1e-20)
    return wi_r.view(M, n_wi, n_wo, 3), wo.view(M, n_wi, n_wo, 3), w


def train_sampler(cfg: OpsConfig, progress: bool = True) -> Path:
    model = load_model(cfg.decoder)
    torch.manual_seed(cfg.seed)
    g = torch.Generator().manual_seed(cfg.seed)
    n_mat = max(cfg.batch * 16, 512)
    with torch.no_grad():
        z = stack_latents(model, random_material_params(n_mat, g))
        z_val = stack_latents(model, random_material_params(256, g))
    wi, wo, w = sampler_targets(model, z, 8, cfg.pairs, g)
    vwi, vwo, vw = sampler_targets(model, z_val, 8, cfg.pairs, g)
    net = SamplerNet()

    def cross_entropy(zz: Tensor, a: Tensor, b: Tensor, ww: Tensor) -> Tensor:
        sigma, lam = net(zz)
        q = proxy_pdf(a, b, sigma[:, None, None], lam[:, None, None])
        return -(ww * torch.log(q.clamp_min(1e-30))).sum(-1).mean()

    def step(_s: int) -> Tensor:
        idx = torch.randint(0, n_mat, (cfg.batch,), generator=g)
        return cross_entropy(z[idx], wi[idx], wo[idx], w[idx])

    def validate() -> float:
        return cross_entropy(z_val, vwi, vwo, vw).item()

    t0 = time.perf_counter()
    history = run_loop("sampler", cfg, {"sampler": net}, cfg.steps, step, validate, progress, rng=g)
    model.sampler = net
    return finish_run("sampler", cfg, model, history, {"seconds_this_run": round(time.perf_counter() - t0, 1),
                                                    "val_cross_entropy": history["val"][-1]})
