"""Training the albedo network (``neural.albedo_net``; issue 40, record 122) on walk albedos of drawn stacks
(``training.albedo_data``): the bundle's codes and decoded albedos of those stacks in, the walk's albedo out."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from nbrdf.neural import energy
from nbrdf.neural.albedo_net import AlbedoNet, albedo_spec, log_ratio_target
from nbrdf.neural.decoder import DEFAULT_WEIGHTS
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material
from nbrdf.neural.model import NeuralModel, load_model, save_model
from nbrdf.training import albedo_data

Tensor = torch.Tensor


@dataclass
class AlbedoTrainConfig:
    """How the albedo network is trained and where it goes."""

    data: str
    """folder of ``training.albedo_data`` (walk albedos of drawn stacks: `nbrdf data --preset albedo`)"""
    out: str
    """the bundle written: ``model`` with the albedo network added (or replaced)"""
    model: str | None = None
    """the bundle whose codes it learns to correct (None: the shipped one)"""
    steps: int = 2000
    """full-batch Adam steps"""
    lr: float = 3e-3
    """Adam's learning rate (cosine decay to 1 % of it)"""
    weight_decay: float = 1e-2
    """AdamW's decoupled weight decay"""
    width: int = 64
    """hidden units per layer"""
    depth: int = 2
    """hidden layers"""
    val_share: float = 0.15
    """share of the stacks held out to choose the step and report the error"""
    seed: int = 0
    """seed of the split and the initialisation"""


def code_table(model: NeuralModel, materials: list[Material], progress: bool = True) -> tuple[Tensor, Tensor]:
    """(codes (N, 3, 34), decoded albedos (N, 3, T)) of the layering network's codes of ``materials``, unsettled,
    at the energy check's incidences."""
    codes, decoded = [], []
    for m in tqdm(materials, desc="codes", unit="stack", disable=not progress):
        z = model.material_latent(m, conserve=False)
        codes.append(z)
        decoded.append(energy.albedo(model.decoder, z, *model.proxy(z), model.energy))
    return torch.stack(codes).float(), torch.stack(decoded).float()


#: Entries whose walk albedo has a relative standard error above this are left out of the held-out figures
#: (a dim channel's walk is noisy; the training weighs it down instead).
MEASURED_SE = 0.01
#: The relative error the loss weights are floored at: 1 / (se^2 + this^2) per entry.
WEIGHT_FLOOR = 0.005


def relative_errors(pred: Tensor, walk: Tensor, se_rel: Tensor) -> np.ndarray:
    """|pred - walk| / walk, flattened, over entries the walk measured to ``MEASURED_SE`` (relative)."""
    keep = (se_rel <= MEASURED_SE) & (walk > 0)
    return ((pred - walk).abs() / walk.clamp_min(1e-6))[keep].numpy()


def _summary(e: np.ndarray) -> dict[str, float]:
    """Median, p90, p99 and max of relative errors (NaN for none: a held-out part without a well-measured walk)."""
    if len(e) == 0:
        return {"median": math.nan, "p90": math.nan, "p99": math.nan, "max": math.nan}
    return {"median": float(np.median(e)), "p90": float(np.percentile(e, 90)), "p99": float(np.percentile(e, 99)),
            "max": float(e.max())}


def train_albedo(cfg: AlbedoTrainConfig, log=print) -> dict:
    """Trains the network, writes ``cfg.out`` and returns the held-out figures (decoded and predicted against
    the walk, relative: median, p90, p99, max)."""
    model = load_model(cfg.model)
    if model.layering is None or model.sampler is None or model.energy is None:
        raise NbrdfError(f"{cfg.model or 'the shipped bundle'}: the albedo network needs the layering and "
                         "sampler networks")
    mats, walk, se = albedo_data.load(cfg.data)
    T = len(model.energy.thetas)
    if walk.shape[1] != T:
        raise NbrdfError(f"{cfg.data}: albedos at {walk.shape[1]} incidences, the bundle checks {T}")
    codes, decoded = code_table(model, mats)
    walk_t = torch.from_numpy(walk).permute(0, 2, 1).float()  # (N, 3, T)
    se_rel = torch.from_numpy(se).permute(0, 2, 1).float() / walk_t.clamp_min(1e-6)
    g = torch.Generator().manual_seed(cfg.seed)
    order = torch.randperm(len(mats), generator=g)
    n_val = max(1, int(round(cfg.val_share * len(mats))))
    val, train = order[:n_val], order[n_val:]

    def rows(idx: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        return (codes[idx].reshape(-1, codes.shape[-1]), decoded[idx].reshape(-1, T), walk_t[idx].reshape(-1, T),
                se_rel[idx].reshape(-1, T))

    c_tr, d_tr, w_tr, s_tr = rows(train)
    c_va, d_va, w_va, s_va = rows(val)
    y_tr = log_ratio_target(w_tr, d_tr)
    weight = 1.0 / (s_tr.pow(2) + WEIGHT_FLOOR ** 2)  # inverse variance: a noisy walk counts less
    weight = weight / weight.mean()
    torch.manual_seed(cfg.seed)
    net = AlbedoNet(albedo_spec(T, cfg.width, cfg.depth))
    opt = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, cfg.steps, eta_min=cfg.lr * 0.01)
    best, best_state = float("inf"), None
    bar = tqdm(range(cfg.steps), desc="albedo net", unit="step")
    for step in bar:
        loss = (weight * (net.log_ratio(c_tr, d_tr) - y_tr).pow(2)).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if step % 50 == 0 or step == cfg.steps - 1:
            with torch.no_grad():
                e = relative_errors(net(c_va, d_va), w_va, s_va)
                v = float(e.mean()) if len(e) else float(loss)  # no well-measured entry held out: the loss
            if best_state is None or v < best:
                best, best_state = v, {k: t.clone() for k, t in net.state_dict().items()}
            bar.set_postfix(loss=f"{loss.item():.2e}", val=f"{v:.4f}")
    net.load_state_dict(best_state)
    net.eval()
    for p in net.parameters():
        p.requires_grad_(False)
    model.albedo = net
    rows = []  # the held-out codes settled, their albedo on the sample set settling used (the input's proxy)
    for i in tqdm(val.tolist(), desc="settled codes", unit="stack"):
        sigma, w = model.proxy(codes[i])
        rows.append(energy.albedo(model.decoder, model.settled(codes[i]), sigma, w, model.energy))
    settled = torch.stack(rows).reshape(-1, T)
    with torch.no_grad():
        figures = {"stacks": {"train": len(train), "val": len(val)},
                   "decoded": _summary(relative_errors(d_va, w_va, s_va)),
                   "predicted": _summary(relative_errors(net(c_va, d_va), w_va, s_va)),
                   "settled": _summary(relative_errors(settled, w_va, s_va)),
                   "walk_se": _summary(s_va[s_va <= MEASURED_SE].numpy())}
    model.trained_on["albedo"] = {"data": Path(cfg.data).name, "stacks": len(mats), "steps": cfg.steps,
                                  "val": figures["predicted"]}
    Path(cfg.out).parent.mkdir(parents=True, exist_ok=True)
    save_model(model, cfg.out, like=cfg.model or DEFAULT_WEIGHTS)
    log(f"albedo network -> {cfg.out}: held-out relative error median / p99 / max "
        f"{figures['predicted']['median']:.4f} / {figures['predicted']['p99']:.4f} / {figures['predicted']['max']:.4f}"
        f" (decoded {figures['decoded']['median']:.4f} / {figures['decoded']['p99']:.4f} / "
        f"{figures['decoded']['max']:.4f}; settled codes {figures['settled']['median']:.4f} / "
        f"{figures['settled']['p99']:.4f} / {figures['settled']['max']:.4f}; the walk's own standard error median "
        f"{figures['walk_se']['median']:.4f})")
    return figures
