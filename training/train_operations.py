"""Training of the latent operations (``nbrdf train leaf|layering``; the sampler: ``training.train_sampler``).

All three train *through the frozen decoder*, so every network is judged by
the BRDF its latents decode to, not by distances in latent space:

- leaf encoders against the closed-form single layers, drawn fresh every
  step from the legal parameter ranges;
- the layering network against the Monte Carlo tabulated stacks of a data
  set (``nbrdf data --preset layering``): first two-layer and diffuse-base
  stacks, then fine-tuned with three-layer stacks through the recursion
  (the bottom latent is itself the network's output);
- the sampler by minimising the KL divergence from the decoded lobe
  f cos(theta_o) (normalised per incident direction) to the proxy pdf,
  estimated by importance sampling over latents of random stacks.

Each run checkpoints and resumes, and writes the bundle (decoder plus every
operation network it has) to ``<out>/model.safetensors``.
"""
from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import torch
from tqdm import tqdm

from nbrdf.neural.decoder import DEFAULT_WEIGHTS, encode, loss_target, predicted_target, unbiased_error
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import CONDUCTOR, DIELECTRIC
from nbrdf.neural.layering import CODE, MEDIUM_SETS, LayeringNet, layering_spec
from nbrdf.neural.leaf import BARE, BARE_F82, F82, LEAF_PARAMS, LeafEncoders, leaf_spec
from nbrdf.neural.model import NeuralModel, layered_latents, load_model, save_model
from nbrdf.neural.stack import CLASSES, DEEP, THREE_LAYERED, P, params_to_stack
from nbrdf.training.analytic import GGXConductor, Lambertian
from nbrdf.training.bare_conductor import bare_encoders, bare_params
from nbrdf.training.dataset import body_values, data_folders, load_manifest, load_split, pair_pdf, sample_pairs
from nbrdf.training.distributions import mixed_params, random_leaf_params  # noqa: F401 (random_leaf_params re-exported)
from nbrdf.training.plots import save_curves

Tensor = torch.Tensor


@dataclass
class OpsConfig:
    """One operation-training run (``nbrdf train leaf|layering|sampler``); the
    subclasses below hold each operation's defaults."""

    out: str
    """run folder (checkpoint, curves, model.safetensors)"""
    decoder: str = str(DEFAULT_WEIGHTS)
    """bundle to build on (default: the shipped weights); a network of the same shape already in it is fine-tuned"""
    steps: int = 3000
    """optimisation steps (Adam, cosine schedule)"""
    batch: int = 64
    """BRDFs per step"""
    pairs: int = 256
    """direction pairs per BRDF per step"""
    lr: float = 2e-3
    """Adam learning rate"""
    seed: int = 0
    """random seed of initialisation and batches"""
    data: str | None = None
    """layering: a folder made by `nbrdf data --preset layering` (several: comma-separated)"""
    recursion_steps: int = 1500
    """layering: final steps that mix in three-layer stacks (recursive layering)"""
    width: int = 0
    """layering: hidden units per layer of the layering network (0: the default, 256)"""
    depth: int = 0
    """layering: hidden layers of the layering network (0: the default, 3)"""
    medium: str = field(default="basic", metadata={"choices": tuple(MEDIUM_SETS)})
    """layering: the slab features the network takes (``neural.layering.MEDIUM_SETS``): basic, or slab (adds the
    slab's closed-form diffuse transmittance 2 E3(sigma_t) and Kubelka-Munk reflectance and transmittance); a
    bundle network with fewer features is fine-tuned from its weights, the added inputs' weights starting at zero"""
    medium_lr_scale: float = 1.0
    """layering: learning-rate multiplier of the first-layer weights on the features a widened network added
    (a short fine-tune moves every weight by about a percent, too little for weights that start at zero)"""
    loss: str = "log"
    """layering: log (the decoder's training loss) or mean (``neural.decoder.unbiased_error``: fits the
    Monte Carlo mean, where the log loss fits a geometric mean that skewed noise pulls too dark)"""
    loss_scale: float = 0.0
    """layering: s of the loss, below which errors count as absolute (0: the decoder's own); smaller weighs
    dark bodies (black lacquers) more"""
    relative_scale: float = 0.0
    """layering: when > 0, each stack's loss scale is this times the stack's mean body value f cos (an
    exposure-adapted loss, as HDR-FLIP adapts to each image: a dark material's relative errors weigh like a
    bright one's); 0: the fixed loss scale"""
    energy_weight: float = 0.0
    """layering: weight of the energy term (issue 40): the squared error of the decoded body's directional albedo
    in four incidence bands, relative to the stack's whole albedo, both estimated on the batch's own pairs with the
    same quadrature weights (cos_i cos_o / the pairs' density), so the decoded and the Monte Carlo estimates share
    their sampling; 0: off"""
    ema: float = 0.0
    """decay of an exponential moving average of the weights, validated and shipped instead of the last
    step's (0: off; 0.999 averages about the last 1,000 steps, smoothing minibatch and Monte Carlo noise)"""


@dataclass
class LeafConfig(OpsConfig):
    """``nbrdf train leaf``: leaf encoders, through the frozen decoder against closed-form layers."""

    part: str = field(default="all", metadata={"choices": ("all", "f82", "bare")})
    """all: every leaf encoder from scratch (the layering network and sampler must then be retrained); f82: only
    the conductor's F82-tint correction, added to a bundle's encoders (a tint of 1 keeps their latents exactly,
    so the bundle's layering network and sampler stay valid); bare: a lone conductor's own pair (encoder and F82
    correction), started from the conductor's and fine-tuned, every other network kept (decision 124)"""
    steps: int = 6000
    batch: int = 32
    pairs: int = 128
    lr: float = 2e-3


@dataclass
class LayeringConfig(OpsConfig):
    """``nbrdf train layering``: the layering network, through the decoder against Monte Carlo stacks."""

    steps: int = 5000
    batch: int = 48
    pairs: int = 192
    lr: float = 1e-3
    recursion_steps: int = 2000
    width: int = 256
    loss: str = "mean"


# --- a small resumable loop ---------------------------------------------------------------
def run_loop(name: str, cfg: OpsConfig, modules: dict[str, torch.nn.Module], total: int,
              step: Callable[[int], Tensor], validate: Callable[[], float], progress: bool,
              rng: torch.Generator, scaled: tuple[tuple[Tensor, tuple, float], ...] = ()) -> dict:
    """Adam with a cosine schedule; checkpoints every 250 steps into
    ``<out>/<name>.ckpt.pt`` and resumes from it (with the batches' generator
    ``rng``, so a resumed run equals one that ran through); returns the history. With
    ``cfg.ema`` the modules end with (and are validated at) the moving
    average of their weights. ``scaled``: (parameter, index, k) entries whose
    Adam step is k times the others' (Adam's step is elementwise, so this is a
    learning rate of k lr on those entries alone)."""
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    params = [p for m in modules.values() for p in m.parameters()]
    if not 0.0 <= cfg.ema < 1.0:
        raise NbrdfError(f"--ema: {cfg.ema} must lie in [0, 1)")
    ema = [p.detach().clone() for p in params] if cfg.ema else []
    opt = torch.optim.Adam(params, lr=cfg.lr)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: 0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(s, total) / total)))
    history: dict = {"train": [], "val": [], "val_step": []}
    ck = out / f"{name}.ckpt.pt"
    key = json.dumps(asdict(cfg), sort_keys=True)
    start = 0
    if ck.exists():
        state = torch.load(ck, weights_only=True)
        if state["key"] != key:
            raise NbrdfError(f"{ck}: belongs to a run with other settings; choose another --out")
        for k, m in modules.items():
            m.load_state_dict(state[k])
        opt.load_state_dict(state["opt"])
        sched.load_state_dict(state["sched"])
        history, start = json.loads(state["history"]), int(state["step"])
        torch.set_rng_state(state["rng"])
        for e, v in zip(ema, state["ema"]):  # the key matched: written by this loop
            e.copy_(v)
        rng.set_state(state["batch_rng"])
    bar = tqdm(total=total, initial=start, desc=f"train {name}", unit="step", file=sys.stderr,
               disable=not progress or None)
    run = []
    for s in range(start, total):
        for m in modules.values():
            m.train()
        loss = step(s)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        before = [p.detach()[i].clone() for p, i, _ in scaled]
        opt.step()
        with torch.no_grad():
            for (p, i, k), b in zip(scaled, before):
                p[i] = b + k * (p[i] - b)
        sched.step()
        if ema:  # warm-up: a plain mean of the steps so far while that is shorter than the window
            d = min(cfg.ema, (s + 1) / (s + 2))
            with torch.no_grad():
                for e, p in zip(ema, params):
                    e.lerp_(p, 1.0 - d)
        run.append(loss.item())
        bar.update(1)
        if (s + 1) % 50 == 0:
            history["train"].append(sum(run) / len(run))
            bar.set_postfix(loss=f"{history['train'][-1]:.3e}")
            run = []
        if (s + 1) % 250 == 0 or s + 1 == total:
            for m in modules.values():
                m.eval()
            state = {k: m.state_dict() for k, m in modules.items()}  # the raw weights: training resumes from them
            with torch.no_grad():
                _swap(params, ema)
                history["val"].append(validate())
                _swap(params, ema)
            history["val_step"].append(s + 1)
            state.update(opt=opt.state_dict(), sched=sched.state_dict(), history=json.dumps(history), step=s + 1,
                         rng=torch.get_rng_state(), batch_rng=rng.get_state(), key=key, ema=ema)
            torch.save(state, out / f"{name}.ckpt.tmp")
            (out / f"{name}.ckpt.tmp").replace(ck)
    bar.close()
    with torch.no_grad():
        _swap(params, ema)
    for m in modules.values():
        m.eval()
        for p in m.parameters():
            p.requires_grad_(False)
    return history


def _swap(params: list[Tensor], ema: list[Tensor]) -> None:
    """Exchanges the weights with their moving average in place (no-op without one)."""
    for e, p in zip(ema, params):
        t = p.detach().clone()
        p.copy_(e)
        e.copy_(t)


def finish_run(name: str, cfg: OpsConfig, model: NeuralModel, history: dict, extra: dict) -> Path:
    out = Path(cfg.out)
    save_curves({"train": history["train"]}, out / f"{name}_curves.png", xlabel="step / 50")
    model.trained_on[name] = {"config": asdict(cfg), **extra}
    bundle = out / "model.safetensors"
    save_model(model, bundle, like=cfg.decoder)
    (out / f"{name}_metrics.json").write_text(json.dumps({"history": history, **extra}, indent=1))
    return bundle


def _decoder_loss(model: NeuralModel, z: Tensor, feats: Tensor, cos_o: Tensor, target: Tensor, s: float | Tensor,
                  f: Tensor | None = None) -> Tensor:
    """The decoder's training loss with scale ``s`` (a number or per BRDF (B, 1); ``target`` made with the same s)
    for latents z (B, 32) at pairs (B, P, .); with the values ``f`` themselves,
    ``neural.decoder.unbiased_error`` instead."""
    return _pair_loss(model.decoder.log_f(z[:, None, :], feats), cos_o, target, s, f)


def _pair_loss(y: Tensor, cos_o: Tensor, target: Tensor, s: float | Tensor, f: Tensor | None) -> Tensor:
    """``_decoder_loss`` of decoded log values y (B, P)."""
    if f is not None:
        return unbiased_error(y, f, cos_o, s).mean()
    return ((predicted_target(y, cos_o, s) - target) ** 2).mean()


# --- leaf encoders --------------------------------------------------------------------------
def leaf_values(kind: str, params: Tensor, wi: Tensor, wo: Tensor) -> Tensor:
    """Closed-form values (B, P) of B leaves' bodies at pairs (B, P, 3): a
    bare dielectric is all coat (``neural.coat``), so its body is black."""
    if kind == CONDUCTOR:
        return GGXConductor(params[:, 0:1], params[:, 1:2], params[:, 2:3]).eval(wi, wo)
    if kind == DIELECTRIC:
        return torch.zeros(wi.shape[:-1], dtype=wi.dtype)
    return Lambertian(params[:, 0:1]).eval(wi, wo)


class _PairPool:
    """A large fixed pool of direction pairs (the data set's distribution),
    with their decoder features, drawn from at random each step."""

    def __init__(self, n: int, g: torch.Generator, encoding: str):
        wi, wo = sample_pairs(n, g)
        self.wi, self.wo = wi.float(), wo.float()
        self.feats = encode(self.wi, self.wo, encoding)

    def draw(self, b: int, p: int, g: torch.Generator):
        idx = torch.randint(0, self.wi.shape[0], (b, p), generator=g)
        return self.wi[idx], self.wo[idx], self.feats[idx]


def train_leaf(cfg: OpsConfig, progress: bool = True) -> Path:
    model = load_model(cfg.decoder)
    torch.manual_seed(cfg.seed)
    g = torch.Generator().manual_seed(cfg.seed)
    pool = _PairPool(1 << 18, g, model.decoder.spec.encoding)
    part = getattr(cfg, "part", "all")
    if part == "f82":
        return _train_leaf_f82(cfg, model, pool, g, progress)
    if part == "bare":
        return _train_leaf_bare(cfg, model, pool, g, progress)
    leaf = LeafEncoders()
    with torch.no_grad():  # start every encoder at the training latents' mean
        for name, net in leaf.nets.items():
            if name == F82:  # a correction: it starts at zero (the plain conductor's latent)
                net.net[-1].weight.zero_()
                net.net[-1].bias.zero_()
            else:
                net.net[-1].bias.copy_(model.decoder.latent_mean)
    s_ = model.decoder.spec.loss_scale
    gv = torch.Generator().manual_seed(cfg.seed + 1)
    val = {k: (random_leaf_params(k, 64, gv), *pool.draw(64, 512, gv)) for k in LEAF_PARAMS}

    def loss_of(kind: str, params: Tensor, wi: Tensor, wo: Tensor, feats: Tensor) -> Tensor:
        cos_o = wo[..., 2]
        target = loss_target(leaf_values(kind, params, wi, wo), cos_o, s_)
        return _decoder_loss(model, leaf.encode(kind, params), feats, cos_o, target, s_)

    def step(_s: int) -> Tensor:
        return sum(loss_of(k, random_leaf_params(k, cfg.batch, g), *pool.draw(cfg.batch, cfg.pairs, g))
                   for k in LEAF_PARAMS) / len(LEAF_PARAMS)

    def validate() -> dict:
        return {k: loss_of(k, *val[k]).item() for k in LEAF_PARAMS}

    t0 = time.perf_counter()
    history = run_loop("leaf", cfg, {"leaf": leaf}, cfg.steps, step, validate, progress, rng=g)
    model.leaf = leaf
    model.layering = model.layering_deep = model.sampler = None  # trained on the old leaf latents: retrain them
    for stale in ("layering", "layering_deep", "sampler"):
        model.trained_on.pop(stale, None)
    return finish_run("leaf", cfg, model, history, {"seconds_this_run": round(time.perf_counter() - t0, 1),
                                                 "val_loss": history["val"][-1]})


def _train_leaf_f82(cfg: OpsConfig, model: NeuralModel, pool: "_PairPool", g: torch.Generator,
                    progress: bool) -> Path:
    """Adds the conductor's F82-tint correction to a bundle's leaf encoders and trains it alone: the
    other encoders, the layering network and the sampler are kept (a tint of 1 leaves every latent as
    it was)."""
    old = model.require("leaf")
    specs = {**old.specs, F82: old.specs.get(F82, leaf_spec(F82))}
    leaf = LeafEncoders(specs)
    for name in old.nets:  # the bundle's encoders, frozen; its own F82 correction, if any, fine-tuned
        leaf.nets[name].load_state_dict(old.nets[name].state_dict())
        leaf.nets[name].requires_grad_(name == F82)
    net = leaf.nets[F82]
    if F82 not in old.nets:  # a new correction starts at zero: the plain conductor's latent
        with torch.no_grad():
            net.net[-1].weight.zero_()
            net.net[-1].bias.zero_()

    def tinted(n: int, gen: torch.Generator) -> Tensor:
        p = random_leaf_params(CONDUCTOR, n, gen)
        p[:, 2] = torch.rand(n, generator=gen)  # the correction only matters away from tint 1
        return p

    return _conductor_run("leaf_f82", cfg, model, leaf, net, tinted, False, 64, pool, g, progress)


def _train_leaf_bare(cfg: OpsConfig, model: NeuralModel, pool: "_PairPool", g: torch.Generator,
                     progress: bool) -> Path:
    """Fine-tunes a lone conductor's pair (``training.bare_conductor``) through the frozen decoder against the
    closed form; every other network of the bundle is kept, so no layered code moves."""
    leaf = bare_encoders(model)
    nets = torch.nn.ModuleDict({BARE: leaf.nets[BARE], BARE_F82: leaf.nets[BARE_F82]})
    return _conductor_run("leaf_bare", cfg, model, leaf, nets, bare_params, True, 256, pool, g, progress)


def _conductor_run(name: str, cfg: OpsConfig, model: NeuralModel, leaf: LeafEncoders, trained: torch.nn.Module,
                   draw: Callable[[int, torch.Generator], Tensor], bare: bool, n_val: int, pool: "_PairPool",
                   g: torch.Generator, progress: bool) -> Path:
    """Trains ``trained`` (a part of ``leaf``) on conductors ``draw`` makes, through the frozen decoder against the
    closed form (``bare``: as lone conductors are encoded), validated on ``n_val`` of them; writes the bundle."""
    s_ = model.decoder.spec.loss_scale
    gv = torch.Generator().manual_seed(cfg.seed + 1)
    val = (draw(n_val, gv), *pool.draw(n_val, 512, gv))

    def loss_of(params: Tensor, wi: Tensor, wo: Tensor, feats: Tensor) -> Tensor:
        cos_o = wo[..., 2]
        target = loss_target(leaf_values(CONDUCTOR, params, wi, wo), cos_o, s_)
        return _decoder_loss(model, leaf.encode(CONDUCTOR, params, bare=bare), feats, cos_o, target, s_)

    t0 = time.perf_counter()
    history = run_loop(name, cfg, {name: trained}, cfg.steps,
                       lambda _s: loss_of(draw(cfg.batch, g), *pool.draw(cfg.batch, cfg.pairs, g)),
                       lambda: loss_of(*val).item(), progress, rng=g)
    model.leaf = leaf
    return finish_run(name, cfg, model, history, {"seconds_this_run": round(time.perf_counter() - t0, 1),
                                               "val_loss": history["val"][-1]})


# --- layering -------------------------------------------------------------------------------
def stack_latents(model: NeuralModel, params: Tensor, layering: LayeringNet | None = None) -> Tensor:
    """Codes (K, 34) of single-channel data-set BRDFs (``neural.stack``
    parameter vectors) through ``neural.model.layered_latents``, class by
    class; differentiable in the layering network."""
    leaf = model.require("leaf")
    net = layering if layering is not None else model.require("layering")
    cls = params[:, P["class"]].round().long()
    out = torch.zeros(params.shape[0], CODE)
    for c in range(len(CLASSES)):
        sel = (cls == c).nonzero().squeeze(-1)
        if sel.numel():
            out = out.index_put((sel,), layered_latents(leaf, net, params_to_stack(params[sel].float()))[:, 0])
    return out


class _StackData:
    """A data set's stacks in memory with decoder features and loss targets
    (of the bodies: the codes' coats are exact, ``neural.coat``)."""

    def __init__(self, folders: str, split: str, scale: float, encoding: str, relative: float = 0.0):
        """``folders``: one data set, or several joined by commas (same pairs per
        stack); ``encoding``: the decoder's direction features; ``relative`` > 0:
        per-stack loss scales (``OpsConfig.relative_scale``)."""
        parts = [load_split(f, split) for f in data_folders(folders)]
        if len({p.wi.shape[1] for p in parts}) != 1:
            raise NbrdfError(f"--data: {folders}: the data sets have different numbers of pairs per stack")
        self.params = torch.cat([d.params for d in parts])
        self.feats = torch.cat([encode(d.wi, d.wo, encoding) for d in parts])
        self.cos_o = torch.cat([d.wo[..., 2] for d in parts])
        self.body = torch.cat([body_values(d) for d in parts])
        self.total = torch.cat([d.f for d in parts]).clamp_min(0.0)
        wi = torch.cat([d.wi for d in parts])
        self.weight, self.band = energy_quadrature(wi, torch.cat([d.wo for d in parts]))
        level = (self.body * self.cos_o).mean(1)
        self.scale = ((relative * level).clamp_min(1e-6) if relative > 0 else torch.full_like(level, scale))[:, None]
        self.target = loss_target(self.body, self.cos_o, self.scale)
        self.cls = torch.tensor([CLASSES.index(c) for d in parts for c in d.classes])

    def index_of(self, *names: str) -> Tensor:
        return torch.isin(self.cls, torch.tensor([CLASSES.index(n) for n in names])).nonzero().squeeze(-1)

    def batch(self, idx: Tensor, pairs: int, g: torch.Generator):
        n = self.feats.shape[1]
        cols = torch.randint(0, n, (idx.numel(), pairs), generator=g) if pairs < n else \
            torch.arange(n).expand(idx.numel(), n)
        rows = idx[:, None].expand_as(cols)
        return (self.params[idx], self.feats[rows, cols], self.cos_o[rows, cols], self.target[rows, cols],
                self.body[rows, cols], self.scale[idx],
                (self.weight[rows, cols], self.band[rows, cols], self.total[rows, cols]))


#: cos(theta_i) edges of the energy term's incidence bands (normal to grazing)
ENERGY_BANDS = (1.0, 0.85, 0.6, 0.3, 0.0)


def energy_quadrature(wi: Tensor, wo: Tensor) -> tuple[Tensor, Tensor]:
    """Per pair (K, n): the weight w with E[w f 1(band)] = the band's cosine-weighted mean directional
    albedo (the pairs' density from ``training.dataset.pair_pdf``, each band's projected solid angle
    pi (b^2 - a^2) divided out), and the pair's band index."""
    ci = wi[..., 2].clamp(0.0, 1.0)
    edges = torch.tensor(ENERGY_BANDS, dtype=ci.dtype)
    band = (ci[..., None] < edges[1:-1]).sum(-1)  # 0: near normal ... 3: grazing
    area = math.pi * (edges[:-1] ** 2 - edges[1:] ** 2)
    w = ci * wo[..., 2].clamp_min(0.0) / pair_pdf(wi.double(), wo.double()).to(ci.dtype).clamp_min(1e-12)
    return (w / area[band]).float(), band


def energy_error(f_dec: Tensor, f_ref: Tensor, total: Tensor, weight: Tensor, band: Tensor) -> Tensor:
    """Mean over stacks and bands of ((A_dec - A_ref) / (A_total + 0.01))^2: the bodies' band albedos
    (B, P) values -> (B, bands) sums, relative to the whole stack's (coat included) albedo in the band
    (a band with no pair of a stack in the batch counts 0)."""
    n = len(ENERGY_BANDS) - 1
    one_hot = torch.nn.functional.one_hot(band, n).to(weight.dtype)  # (B, P, bands)
    per = lambda f: torch.einsum("bp,bpk->bk", weight * f, one_hot) / f.shape[1]
    return ((per(f_dec) - per(f_ref)) / (per(total).detach() + 0.01)).pow(2).mean()


def train_layering(cfg: OpsConfig, progress: bool = True) -> Path:
    if not cfg.data:
        raise NbrdfError("--data: the layering network trains on a stack data set (nbrdf data --preset layering)")
    model = load_model(cfg.decoder)
    model.require("leaf")
    manifests = [load_manifest(f) for f in data_folders(cfg.data)]
    torch.manual_seed(cfg.seed)
    g = torch.Generator().manual_seed(cfg.seed)
    for flag, v in (("--loss-scale", cfg.loss_scale), ("--relative-scale", cfg.relative_scale)):
        if not v >= 0:
            raise NbrdfError(f"{flag}: {v} is negative")
    s_ = cfg.loss_scale or model.decoder.spec.loss_scale
    enc = model.decoder.spec.encoding
    train = _StackData(cfg.data, "train", s_, enc, cfg.relative_scale)
    val = _StackData(cfg.data, "val", s_, enc, cfg.relative_scale)
    two = train.index_of("two_layer", "diffuse_base")
    three = train.index_of(*THREE_LAYERED)
    deep = train.index_of(*DEEP)
    if two.numel() == 0:
        raise NbrdfError(f"{cfg.data}: no two-layer or diffuse-base stacks to train the layering network on")
    net = LayeringNet(layering_spec(width=cfg.width or 256, depth=cfg.depth or 3, medium=cfg.medium))
    old, added = model.layering, None
    if old is not None and old.spec == net.spec:
        net.load_state_dict(old.state_dict())  # fine-tune the bundle's network
    elif old is not None and replace(old.spec, inputs=net.spec.inputs, medium=net.spec.medium) == net.spec \
            and MEDIUM_SETS[old.spec.medium] < MEDIUM_SETS[net.spec.medium]:
        net = old.widened(net.spec.medium)  # fine-tune it, starting exactly where it is
        added = (slice(None), slice(old.spec.inputs, None))
    else:
        with torch.no_grad():  # start as the identity "the top hides nothing"
            net.mlp.net[-1].weight.mul_(0.1)
            net.mlp.net[-1].bias.zero_()
    if not cfg.medium_lr_scale > 0:
        raise NbrdfError(f"--medium-lr-scale: {cfg.medium_lr_scale} must be positive")
    scaled = ((net.mlp.net[0].weight, added, cfg.medium_lr_scale),) if added and cfg.medium_lr_scale != 1 else ()

    if cfg.loss not in ("log", "mean"):
        raise NbrdfError(f"--loss: {cfg.loss!r} is not one of log, mean")

    if not cfg.energy_weight >= 0:
        raise NbrdfError(f"--energy-weight: {cfg.energy_weight} is negative")

    def losses(data: _StackData, idx: Tensor, pairs: int, fit_mean: bool,
               energy: bool) -> tuple[Tensor, Tensor | None]:
        """The pairs' loss and (``energy``) the energy error of one batch, from one decoding."""
        params, feats, cos_o, target, body, scale, (weight, band, total) = data.batch(idx, pairs, g)
        y = model.decoder.log_f(stack_latents(model, params, net)[:, None, :], feats)
        pair = _pair_loss(y, cos_o, target, scale, body if fit_mean else None)
        return pair, energy_error(torch.exp(y.clamp(max=30.0)), body, total, weight, band) if energy else None

    def loss_on(data: _StackData, idx: Tensor, pairs: int) -> Tensor:
        pair, e = losses(data, idx, pairs, cfg.loss == "mean", cfg.energy_weight > 0)
        return pair if e is None else pair + cfg.energy_weight * e

    def pick(rows: Tensor, k: int) -> Tensor:
        return rows[torch.randint(0, rows.numel(), (k,), generator=g)]

    def step(s: int) -> Tensor:
        if s >= cfg.steps - cfg.recursion_steps and three.numel():
            # half two-layer, the rest three-layer; with deep stacks in the data, a quarter of those
            n_deep = cfg.batch // 4 if deep.numel() else 0
            n_three = cfg.batch // 2 - n_deep
            parts = [pick(two, cfg.batch - n_three - n_deep), pick(three, n_three)]
            return loss_on(train, torch.cat(parts + ([pick(deep, n_deep)] if n_deep else [])), cfg.pairs)
        return loss_on(train, pick(two, cfg.batch), cfg.pairs)

    def validate() -> dict:
        out = {}
        for name in ("two_layer", "diffuse_base") + THREE_LAYERED + DEEP:
            idx = val.index_of(name)
            if idx.numel():
                # the log loss, comparable across runs; with the energy term, its error alone beside it
                pair, e = losses(val, idx, val.feats.shape[1], False, cfg.energy_weight > 0)
                out[name] = pair.item()
                if e is not None:
                    out[f"{name}_energy"] = e.item()
        return out

    t0 = time.perf_counter()
    history = run_loop("layering", cfg, {"layering": net}, cfg.steps, step, validate, progress, rng=g,
                        scaled=scaled)
    model.layering = net
    model.layering_deep = None  # the new network layers every depth until a bundle routes them (route_depth)
    model.sampler = None  # trained on the old layered latents: retrain it on these
    for stale in ("layering_deep", "sampler"):
        model.trained_on.pop(stale, None)
    return finish_run("layering", cfg, model, history, {
        "seconds_this_run": round(time.perf_counter() - t0, 1), "val_loss": history["val"][-1],
        "data_preset": ",".join(str(m.get("preset")) for m in manifests), "train_stacks": int(two.numel() + three.numel())})


def route_depth(base: str | Path, deep: str | Path, out: str | Path) -> str:
    """The bundle ``base`` with the layering network of ``deep`` for stacks of
    ``DEEP_INTERFACES`` interfaces or more (``NeuralModel.layering_deep``): both bundles
    must share the decoder and the leaf encoders (a layering fine-tune of the other), so
    their codes are one space; the shallow stacks keep ``base``'s network, its sampler
    included. Returns the path written."""
    b, d = load_model(base), load_model(deep)
    if b.decoder_id != d.decoder_id:
        raise NbrdfError(f"{deep}: another decoder ({d.decoder_id}) than {base}'s ({b.decoder_id})")
    lb, ld_ = b.require("leaf").state_dict(), d.require("leaf").state_dict()
    if lb.keys() != ld_.keys() or any(not torch.equal(lb[k], ld_[k]) for k in lb):
        raise NbrdfError(f"{deep}: its leaf encoders differ from {base}'s: its codes are another space")
    b.require("layering")
    b.layering_deep = d.require("layering")
    b.trained_on["layering_deep"] = {**d.trained_on.get("layering", {}), "bundle": str(deep)}
    save_model(b, out, like=base)
    return str(out)
