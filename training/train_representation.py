"""Auto-decoder training (``nbrdf train representation``).

The decoder and one latent per training BRDF are optimised together (the
paper's auto-decoder); validation BRDFs are projected with the decoder
frozen, which is how every new BRDF will be met later. Runs on the CPU or on
CUDA; checkpoints every epoch and resumes from the last one.

A run folder holds: ``checkpoint.pt`` (resume state), ``decoder.safetensors``
(the bundle, with metadata), ``latents.safetensors`` (training latents and
their parameters, for the leaf encoders and the layering network),
``curves.png`` and ``metrics.json``.
"""
from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import torch
from safetensors.torch import save_file
from tqdm import tqdm

from nbrdf.neural.decoder import Decoder, DecoderSpec, encode, loss_target, predicted_target, save_decoder
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.projection import ProjectionConfig, project
from nbrdf.training.dataset import CLASSES, BRDFSet, body_values, data_folders, load_manifest, load_split
from nbrdf.training.plots import _plt

Tensor = torch.Tensor


@dataclass
class TrainConfig:
    """One representation-training run (``nbrdf train representation``): the
    decoder and one latent per training BRDF, optimised together."""

    data: str
    """a folder made by `nbrdf data`, or several joined by commas (trained on together; the first one's
    validation split is used)"""
    out: str
    """run folder (checkpoint, decoder.safetensors, curves.png)"""
    spec: DecoderSpec = field(default_factory=DecoderSpec)
    """the decoder's architecture (on the command line: --width, --depth, --activation, --loss-scale); by
    default a coat-split decoder, trained on bodies (the values minus the top interface's reflection)"""
    epochs: int = 40
    """passes over the training samples"""
    batch: int = 8192
    """samples (BRDF, direction pair) per step"""
    lr: float = 2e-3
    """Adam learning rate of the decoder (cosine schedule)"""
    latent_lr: float = 1e-2
    """Adam learning rate of the training latents"""
    latent_reg: float = 1e-4
    """weight of the latents' squared-norm penalty"""
    val_every: int = 5
    """epochs between validations (validation BRDFs projected with the decoder frozen)"""
    seed: int = 0
    """random seed of initialisation and batches"""
    device: str = field(default="auto", metadata={"choices": ("auto", "cpu", "cuda")})
    """auto (CUDA when available), cpu or cuda"""


def _device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise NbrdfError("--device cuda: no CUDA device is available")
    return torch.device(name)


@dataclass
class _Flat:
    """A split flattened to samples: features, cos(theta_o), target, owner index."""

    feats: Tensor
    cos_o: Tensor
    target: Tensor
    owner: Tensor


def flatten(data: BRDFSet, scale: float, encoding: str) -> _Flat:
    K, n = data.f.shape
    feats = encode(data.wi.reshape(-1, 3), data.wo.reshape(-1, 3), encoding)
    cos_o = data.wo[..., 2].reshape(-1)
    return _Flat(feats, cos_o, loss_target(data.f.reshape(-1), cos_o, scale), torch.arange(K).repeat_interleave(n))


def _join(parts: list[_Flat], sizes: list[int]) -> _Flat:
    """Several flattened sets as one (owners renumbered after each other)."""
    offsets = [sum(sizes[:i]) for i in range(len(sizes))]
    return _Flat(*(torch.cat([getattr(p, k) for p in parts]) for k in ("feats", "cos_o", "target")),
                 torch.cat([p.owner + o for p, o in zip(parts, offsets)]))


def validate(dec: Decoder, val: BRDFSet, steps: int = 150, fit_pairs: int | None = None) -> dict:
    """Projects the validation BRDFs on half their pairs and reports the loss
    on the other half, per class and overall."""
    n = val.f.shape[1]
    half = fit_pairs or n // 2
    with torch.enable_grad():
        z = project(dec, val.wi[:, :half], val.wo[:, :half], val.f[:, :half], ProjectionConfig(steps=steps))
    wi, wo, f = val.wi[:, half:], val.wo[:, half:], val.f[:, half:]
    with torch.no_grad():
        y = dec.log_f(z[:, None, :], dec.encode(wi, wo))
        cos_o = wo[..., 2]
        s = dec.spec.loss_scale
        err = ((predicted_target(y, cos_o, s) - loss_target(f, cos_o, s)) ** 2).mean(-1)
    out = {"all": float(err.mean())}
    for _i, cls in enumerate(CLASSES):
        sel = [k for k, c in enumerate(val.classes) if c == cls]
        if sel:
            out[cls] = float(err[sel].mean())
    return out


def train(cfg: TrainConfig, progress: bool = True, stop_after: int | None = None) -> Path | None:
    """Trains (or resumes) into ``cfg.out``; returns the decoder bundle path.
    ``stop_after`` ends this run after that many epochs (a time-boxed
    session); the next call resumes, and returns None until training ends."""
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    folders = data_folders(cfg.data)
    manifests = [load_manifest(f) for f in folders]
    data_config = manifests[0]["config"] if len(manifests) == 1 else [m["config"] for m in manifests]
    dev = _device(cfg.device)
    torch.manual_seed(cfg.seed)
    train_sets = [load_split(f, "train") for f in folders]
    val_set = load_split(folders[0], "val")
    if cfg.spec.coat:  # the decoder learns bodies; the coat is closed form (neural.coat)
        train_sets = [replace(t, f=body_values(t)) for t in train_sets]
        val_set = replace(val_set, f=body_values(val_set))
    flat = _join([flatten(t, cfg.spec.loss_scale, cfg.spec.encoding) for t in train_sets], [len(t) for t in train_sets])
    params = torch.cat([t.params for t in train_sets])  # (K, 11): the training BRDFs, in latent order
    K = params.shape[0]
    dec = Decoder(cfg.spec).to(dev)
    latents = torch.nn.Parameter(torch.randn(K, cfg.spec.latent, device=dev) * 0.01)
    opt = torch.optim.Adam([{"params": dec.parameters(), "lr": cfg.lr},
                            {"params": [latents], "lr": cfg.latent_lr}])
    steps_per_epoch = math.ceil(flat.target.numel() / cfg.batch)
    total = steps_per_epoch * cfg.epochs
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: 0.03 + 0.97 * 0.5 * (1 + math.cos(math.pi * min(s, total) / total)))
    history: dict[str, list] = {"train": [], "val": [], "val_epoch": []}
    start = 0
    ck = out / "checkpoint.pt"
    run_key = {"config": json.loads(json.dumps(asdict(cfg), default=str)), "data": data_config}
    if ck.exists():
        state = torch.load(ck, map_location=dev, weights_only=True)
        if json.loads(state["run_key"]) != run_key:
            raise NbrdfError(f"{ck}: belongs to a run with other settings or data; choose another --out")
        dec.load_state_dict(state["decoder"])
        with torch.no_grad():
            latents.copy_(state["latents"])
        opt.load_state_dict(state["opt"])
        sched.load_state_dict(state["sched"])
        history = json.loads(state["history"])
        start = int(state["epoch"])
        torch.set_rng_state(state["rng"])
    f_dev = _Flat(flat.feats.to(dev), flat.cos_o.to(dev), flat.target.to(dev), flat.owner.to(dev))
    t0 = time.perf_counter()
    bar = tqdm(total=total, initial=start * steps_per_epoch, desc="train", unit="step", file=sys.stderr,
               disable=not progress or None)
    for epoch in range(start, cfg.epochs):
        if stop_after is not None and epoch - start >= stop_after:
            bar.close()
            return None
        dec.train()
        perm = torch.randperm(flat.target.numel(), device=dev)
        run, count = 0.0, 0
        for s in range(steps_per_epoch):
            idx = perm[s * cfg.batch:(s + 1) * cfg.batch]
            z = latents[f_dev.owner[idx]]
            y = dec.log_f(z, f_dev.feats[idx])
            loss = ((predicted_target(y, f_dev.cos_o[idx], cfg.spec.loss_scale) - f_dev.target[idx]) ** 2).mean()
            reg = cfg.latent_reg * (z * z).sum(-1).mean()
            opt.zero_grad(set_to_none=True)
            (loss + reg).backward()
            opt.step()
            sched.step()
            run += loss.item()
            count += 1
            bar.update(1)
            if s % 20 == 0:
                bar.set_postfix(epoch=epoch + 1, loss=f"{run / count:.2e}")
        history["train"].append(run / count)
        dec.eval()
        with torch.no_grad():
            dec.latent_mean.copy_(latents.mean(0))
        if (epoch + 1) % cfg.val_every == 0 or epoch + 1 == cfg.epochs:
            history["val"].append(validate(dec.cpu(), val_set))
            history["val_epoch"].append(epoch + 1)
            dec.to(dev)
            bar.write(f"epoch {epoch + 1}: train {history['train'][-1]:.3e}  val {history['val'][-1]['all']:.3e}")
        state = {"decoder": dec.state_dict(), "latents": latents.detach(), "opt": opt.state_dict(),
                 "sched": sched.state_dict(), "history": json.dumps(history), "epoch": epoch + 1,
                 "rng": torch.get_rng_state(), "run_key": json.dumps(run_key)}
        torch.save(state, out / "checkpoint.tmp")
        (out / "checkpoint.tmp").replace(ck)
        _save_val_curves(history, out / "curves.png")
    bar.close()
    dec = dec.cpu().eval()
    trained_on = {"data": str(cfg.data), "preset": ",".join(str(m.get("preset")) for m in manifests),
                  "data_config": data_config,
                  "train_brdfs": K, "epochs": cfg.epochs, "seconds_this_run": round(time.perf_counter() - t0, 1),
                  "device": str(dev)}
    metrics = {"train_loss": history["train"][-1] if history["train"] else None,
               "val_loss": history["val"][-1] if history["val"] else None}
    bundle = out / "decoder.safetensors"
    save_decoder(dec, bundle, trained_on=trained_on, accuracy=metrics)
    _save_latents(out / "latents.safetensors", latents.detach().cpu(), params, dec.weights_id())
    (out / "metrics.json").write_text(json.dumps({"trained_on": trained_on, "history": history,
                                                   "macs_per_eval": dec.spec.macs(),
                                                   "parameters": dec.spec.parameters()}, indent=1))
    return bundle


def _save_val_curves(history: dict, path: Path) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
    ep = range(1, len(history["train"]) + 1)
    ax.plot(list(ep), history["train"], label="train (auto-decoded)")
    if history["val"]:
        for cls in ["all"] + list(CLASSES):
            ys = [v.get(cls) for v in history["val"]]
            if all(y is not None for y in ys):
                ax.plot(history["val_epoch"], ys, marker="o", ms=3, lw=1 if cls != "all" else 2,
                        label=f"val {cls} (projected)")
    ax.set_yscale("log")
    ax.set_xlabel("epoch")
    ax.set_ylabel("mean (log(1 + f cos / s) error)^2")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _save_latents(path: Path, latents: Tensor, params: Tensor, decoder_id: str) -> None:
    save_file({"latents": latents.contiguous(), "params": params.contiguous()}, str(path),
              metadata={"format": "nbrdf-latent-table/1", "decoder_id": decoder_id})
