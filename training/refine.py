"""Refinement (``--method refined``): the layering network's code of a
uniform material, its body latent fitted further to the material's own
Monte Carlo simulation within a time budget.

The coat is exact in closed form (``neural.coat``), so only the body is
simulated (the walk without the top interface's single reflection) and
fitted; the code keeps the material's coat. Direction pairs are placed where
a rendered view needs them: the view direction cosine-distributed (the pixels
of an object seen from the camera), the light direction from the body's lobe
around the view's mirror direction, from the cosine lobe, or from the
training distribution (the whole domain, which keeps the fit from drifting
where nothing else looks). Each round simulates new pairs, adds them to the
fitted pool and continues the projection (``neural.projection.project``, the
one fitting loop) from the best code so far; a held-out set of pairs scores
every code, the network's included. Rounds stop when the held-out error
stops falling, or when the next round would overrun the budget.

Refined codes are cached per user (``$XDG_CACHE_HOME/nbrdf/refined``) by the
material's content and the decoder, so reopening a material costs nothing.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import torch

from nbrdf.neural.coat import coat_eval, with_coat
from nbrdf.neural.decoder import Decoder
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Conductor, Dielectric, LatentBase, Material, Measured, material_to_dict
from nbrdf.neural.projection import ProjectionConfig, project

Tensor = torch.Tensor

#: The cache file format's name and version.
CACHE_FORMAT = "nbrdf-refined-1"
#: The default time budget of a refinement (seconds).
DEFAULT_BUDGET = 10.0


@dataclass(frozen=True)
class RefineConfig:
    """How a code is refined (module docstring)."""

    budget: float = DEFAULT_BUDGET
    """Seconds of wall-clock time the refinement may spend, simulation and fitting together."""
    round_pairs: int = 1024
    """New direction pairs simulated per round."""
    heldout_pairs: int = 1024
    """Direction pairs of the held-out set that scores every code (never fitted)."""
    spp: int = 64
    """Monte Carlo paths per pair."""
    steps: int = 120
    """Projection steps per round."""
    fit_pairs: int = 3072
    """Pairs a round fits at most: the new round's and a random draw of the earlier ones (a round's cost stays flat)."""
    lr: float = 0.02
    """Adam learning rate of the rounds (a warm start: half the projection's from the latent mean)."""
    min_gain: float = 0.02
    """A round must lower the held-out error by this share of it to count as falling."""
    patience: int = 1
    """Rounds in a row that may fail to fall before the refinement stops."""
    max_rounds: int = 24
    """Rounds at most (the pool then holds ``round_pairs * max_rounds`` pairs)."""
    seed: int = 0
    """Seed of the pairs and of the simulation."""

    def check(self) -> None:
        """One line for a setting out of range."""
        if not (math.isfinite(self.budget) and self.budget > 0):
            raise NbrdfError(f"--budget: {self.budget} seconds must be a positive number")
        for name in ("round_pairs", "heldout_pairs", "spp", "steps", "fit_pairs", "max_rounds"):
            if getattr(self, name) < 1:
                raise NbrdfError(f"refinement: {name} {getattr(self, name)} must be at least 1")


@dataclass
class RefineState:
    """Where a refinement stands (one per material; ``Refiner.state``)."""

    code: Tensor
    """The best code (3, 34) so far: the network's until a round beats it."""
    network_error: float
    """The held-out error of the network's code."""
    error: float
    """The held-out error of ``code``."""
    rounds: int = 0
    """Rounds finished."""
    pairs: int = 0
    """Pairs simulated (held-out set included)."""
    seconds: float = 0.0
    """Wall-clock seconds spent."""
    cpu_seconds: float = 0.0
    """Processor seconds this process spent on it (on a shared machine, less than ``seconds``)."""
    done: bool = False
    """No round follows."""
    converged: bool = False
    """It stopped because the held-out error stopped falling (not for the budget)."""
    history: list[float] = field(default_factory=list)
    """The held-out error after each round."""

    @property
    def improved(self) -> bool:
        """The refined code beats the network's on the held-out pairs."""
        return self.error < self.network_error


# --- pairs -------------------------------------------------------------------------------
def body_roughness(material: Material) -> float | None:
    """The GGX roughness that shapes the body's lobe: the roughest interface
    under the top one or a glossy base (None: a diffuse body)."""
    under = material.layers[1:] if material.interfaces else material.layers
    rough = [float(layer.roughness) for layer in under if isinstance(layer, (Conductor, Dielectric))]
    return max(rough) if rough else None


def placed_pairs(n: int, g: torch.Generator, roughness: float | None) -> tuple[Tensor, Tensor]:
    """n (wi, wo) float32 pairs above the horizon: wo cosine-distributed (the
    view), wi a third each from the body's GGX lobe around wo's mirror (half
    at ``roughness``, half at twice it), the cosine lobe and the training
    distribution (all of the lobe's share cosine for a diffuse body)."""
    from nbrdf.neural.geometry import cosine_hemisphere
    from nbrdf.neural.microfacet import reflect, sample_vndf
    from nbrdf.training.dataset import sample_pairs

    out_i, out_o, have = [], [], 0
    while have < n:
        m = 2 * (n - have) + 16
        u = torch.rand(m, 5, generator=g, dtype=torch.float64)
        wo = cosine_hemisphere(u[:, 0], u[:, 1])
        wi = cosine_hemisphere(u[:, 2], u[:, 3])
        if roughness is not None:
            alpha = torch.where(u[:, 4] < 1 / 6, roughness, min(1.0, 2 * roughness)).clamp_min(0.02)
            lobe = reflect(wo, sample_vndf(wo, alpha, u[:, 2], u[:, 3]))
            wi = torch.where((u[:, 4] < 1 / 3)[:, None], lobe, wi)
        tr_i, tr_o = sample_pairs(m, g)
        train = (u[:, 4] >= 2 / 3)[:, None]
        wi, wo = torch.where(train, tr_i, wi), torch.where(train, tr_o, wo)
        ok = (wi[:, 2] > 1e-4) & (wo[:, 2] > 1e-4)
        out_i.append(wi[ok])
        out_o.append(wo[ok])
        have += int(ok.sum())
    wi = torch.nn.functional.normalize(torch.cat(out_i)[:n], dim=-1)
    wo = torch.nn.functional.normalize(torch.cat(out_o)[:n], dim=-1)
    return wi.float(), wo.float()


def body_values(material: Material, wi: Tensor, wo: Tensor, spp: int, seed: int) -> Tensor:
    """The reference (N, 3) of the light that entered the stack: the walk
    without the top interface's closed-form reflection (a single layer: its
    whole closed form, which the code decodes with no coat)."""
    from nbrdf.training.reference import reference_eval

    return reference_eval(material, wi, wo, spp=spp, seed=seed, top_reflection=False)[0].float()


# --- scores ---------------------------------------------------------------------------------
@dataclass
class HeldOut:
    """The held-out pairs and their whole reference (coat plus body)."""

    wi: Tensor
    wo: Tensor
    f: Tensor
    """(N, 3) the material's value: the code's coat plus the simulated body."""


def heldout_error(dec: Decoder, code: Tensor, h: HeldOut) -> float:
    """The mean over pairs and channels of ((p - f) cos_i / (s + p cos_i))^2, p the
    code's value (coat included, so body errors under a bright highlight count
    less, as they show less), f the simulated one, s the decoder's loss scale:
    the error the fit minimises (``decoder.unbiased_error``) on what a render shows."""
    with torch.no_grad():
        p = dec.eval_rgb(code, h.wi, h.wo).double()
    cos = h.wi[:, 2:3].double().clamp_min(0.0)
    s = dec.spec.loss_scale
    return float((((p - h.f.double()) * cos / (s + p * cos)) ** 2).mean())


# --- the refinement ------------------------------------------------------------------------
class Refiner:
    """One material's refinement in rounds: ``start`` simulates the held-out
    set and scores the network's code; each ``step`` is one round. ``stop``
    (checked between the projection's steps) ends a round early without
    using it, so a caller can cancel at once."""

    def __init__(self, dec: Decoder, material: Material, network_code: Tensor,
                 cfg: RefineConfig = RefineConfig()):
        cfg.check()
        check_refinable(material)
        if not dec.spec.coat:
            raise NbrdfError("refinement: the decoder predates the coat split (retrain, docs/RESULTS.md)")
        code = torch.as_tensor(network_code, dtype=torch.float32).reshape(3, -1)
        if code.shape[1] != dec.spec.code:
            raise NbrdfError(f"refinement: a code has {dec.spec.code} floats per channel, got {code.shape[1]}")
        self.dec, self.material, self.cfg = dec, material, cfg
        self.coat = code[:1, dec.spec.latent:]  # (1, 2): the material's coat, as the network's code has it
        self.roughness = body_roughness(material)
        self.g = torch.Generator().manual_seed(cfg.seed)
        self._network_code = code
        self._pool: list[tuple[Tensor, Tensor, Tensor]] = []
        self._heldout: HeldOut | None = None
        self._spent = (0.0, 0.0)  # (wall, processor) seconds inside start and step: a set-aside run is not charged
        self._round_seconds = 0.0
        self._stale = 0
        self.state: RefineState | None = None

    def _simulate(self, n: int, seed: int) -> tuple[Tensor, Tensor, Tensor]:
        wi, wo = placed_pairs(n, self.g, self.roughness)
        return wi, wo, body_values(self.material, wi, wo, self.cfg.spp, seed)

    def _tick(self, t0: float, c0: float) -> None:
        """Charges the time since (t0, c0) (``perf_counter``, ``process_time``) to the refinement."""
        w, c = self._spent
        self._spent = (w + time.perf_counter() - t0, c + time.process_time() - c0)
        if self.state is not None:
            self.state.seconds, self.state.cpu_seconds = self._spent

    def start(self) -> RefineState:
        """Simulates the held-out set and scores the network's code."""
        if self.state is None:
            t0, c0 = time.perf_counter(), time.process_time()
            wi, wo, body = self._simulate(self.cfg.heldout_pairs, self.cfg.seed * 7919 + 1)
            coat = coat_eval(self.coat.expand(3, -1)[:, None, :], wi[None].expand(3, -1, -1),
                             wo[None].expand(3, -1, -1)).T
            self._heldout = HeldOut(wi, wo, body + coat.float())
            e = heldout_error(self.dec, self._network_code, self._heldout)
            self.state = RefineState(self._network_code, e, e, pairs=self.cfg.heldout_pairs, history=[e])
            self._tick(t0, c0)
        return self.state

    def step(self, stop: Callable[[], bool] | None = None) -> RefineState:
        """One round (module docstring); a round cut short by ``stop`` changes nothing."""
        st = self.start()
        if st.seconds >= self.cfg.budget:  # the held-out set alone spent it
            st.done = True
        if st.done:
            return st
        c, t0, c0 = self.cfg, time.perf_counter(), time.process_time()
        k = st.rounds
        self._pool.append(self._simulate(c.round_pairs, c.seed * 7919 + 2 + k))
        wi, wo, f = (torch.cat(x) for x in zip(*self._pool))
        if wi.shape[0] > c.fit_pairs:  # the newest round whole, the rest drawn from the earlier ones
            old = wi.shape[0] - c.round_pairs
            keep = torch.randperm(old, generator=self.g)[:max(0, c.fit_pairs - c.round_pairs)]
            keep = torch.cat([keep, torch.arange(old, wi.shape[0])])
            wi, wo, f = wi[keep], wo[keep], f[keep]
        wi, wo, f = wi[None].expand(3, -1, -1), wo[None].expand(3, -1, -1), f.T.contiguous()
        cut = [False]

        def hook(_step: int) -> bool:
            cut[0] = cut[0] or (stop is not None and stop())
            return cut[0]

        z = project(self.dec, wi, wo, f, ProjectionConfig(steps=c.steps, lr=c.lr), z0=st.code, stop=hook)
        if cut[0]:
            self._tick(t0, c0)
            return st
        code = with_coat(z[:, :self.dec.spec.latent], self.coat.expand(3, -1))
        e = heldout_error(self.dec, code, self._heldout)
        st.rounds, st.pairs = k + 1, st.pairs + c.round_pairs
        st.history.append(e)
        if e < st.error * (1 - c.min_gain):
            self._stale = 0
        else:
            self._stale += 1
        if e < st.error:
            st.code, st.error = code, e
        self._round_seconds = max(self._round_seconds, time.perf_counter() - t0)
        self._tick(t0, c0)
        if self._stale >= c.patience:
            st.done = st.converged = True
        elif st.rounds >= c.max_rounds or st.seconds + self._round_seconds * (1 + 0.1 * st.rounds) > c.budget:
            st.done = True  # the next round (a growing pool: a little longer) would overrun the budget
        return st

    def run(self, stop: Callable[[], bool] | None = None) -> RefineState:
        """Rounds until done (or ``stop``)."""
        st = self.start()
        while not st.done and not (stop is not None and stop()):
            st = self.step(stop)
        return st


def check_refinable(material: Material) -> None:
    """One line for a material refinement cannot take (it needs a reference)."""
    from nbrdf.training.reference import check_uniform

    check_uniform(material)
    if isinstance(material.base, LatentBase) and not material.interfaces:
        raise NbrdfError("layers[0]: a latent base has no reference to refine against; use --method neural")


# --- the per-user cache ---------------------------------------------------------------------
def cache_dir() -> Path:
    """$XDG_CACHE_HOME/nbrdf/refined (default ~/.cache)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "nbrdf" / "refined"


def material_hash(material: Material) -> str:
    """A content hash of what the material's BRDF depends on (its name aside;
    the folder too when a layer names a file)."""
    d = material_to_dict(material)
    d.pop("name", None)
    blob = {"m": d}
    if any(isinstance(layer, (LatentBase, Measured)) for layer in material.layers):
        blob["dir"] = str(Path(material.base_dir).resolve())
    return hashlib.sha256(json.dumps(blob, sort_keys=True).encode()).hexdigest()[:24]


def cache_path(material: Material, decoder_id: str) -> Path:
    return cache_dir() / f"{material_hash(material)}-{decoder_id[:12]}.json"


@dataclass
class CachedCode:
    """A refined code read from the cache."""

    code: Tensor
    budget: float
    converged: bool
    seconds: float
    error: float
    network_error: float


def load_cached(material: Material, decoder_id: str) -> CachedCode | None:
    """The cached refined code of a material under a decoder (None: none, or an unreadable file)."""
    p = cache_path(material, decoder_id)
    try:
        d = json.loads(p.read_text())
        if d.get("format") != CACHE_FORMAT or d.get("decoder") != decoder_id:
            return None
        code = torch.tensor(d["code"], dtype=torch.float32)
        if code.dim() != 2 or code.shape[0] != 3 or not torch.isfinite(code).all():
            return None
        return CachedCode(code, float(d["budget"]), bool(d["converged"]), float(d["seconds"]), float(d["error"]),
                          float(d["network_error"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def save_cached(material: Material, decoder_id: str, st: RefineState, budget: float) -> None:
    """Writes a finished refinement (atomic; a failure to write only loses the cache entry)."""
    from nbrdf.neural.files import write_atomic

    p = cache_path(material, decoder_id)
    doc = {"format": CACHE_FORMAT, "decoder": decoder_id, "material": material.name, "budget": budget,
           "converged": st.converged, "seconds": round(st.seconds, 3), "rounds": st.rounds,
           "error": st.error, "network_error": st.network_error, "code": st.code.tolist()}
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(p, json.dumps(doc))
    except OSError:
        pass


def serves(c: CachedCode | None, budget: float) -> bool:
    """A cached code answers a request of ``budget`` seconds when it converged or had at least as long."""
    return c is not None and (c.converged or c.budget >= budget - 1e-9)


def refined_code(dec: Decoder, material: Material, network_code: Tensor, cfg: RefineConfig = RefineConfig(),
                 cache: bool = True) -> tuple[Tensor, RefineState | CachedCode]:
    """The refined code (3, 34) of a uniform material (the network's when no
    round beats it on the held-out pairs) and how it was made; from the cache
    when an entry serves the budget."""
    cfg.check()
    did = dec.weights_id()
    if cache:
        hit = load_cached(material, did)
        if serves(hit, cfg.budget):
            return hit.code, hit
    st = Refiner(dec, material, network_code, cfg).run()
    if cache:
        save_cached(material, did, st, cfg.budget)
    return st.code, st


def refined_brdf(material: Material, model=None, budget: float | None = None, seed: int = 0, cache: bool = True):
    """``brdf_for(material, "refined")``: the decoder at the refined code plus
    its coat, sampled like the full neural path; ``.refinement`` tells how the
    code was made (a ``RefineState``, or the ``CachedCode`` it came from)."""
    from nbrdf.neural.model import default_model
    from nbrdf.neural.neural_brdf import latent_brdf

    cfg = RefineConfig(budget=DEFAULT_BUDGET if budget is None else float(budget), seed=seed)
    cfg.check()
    check_refinable(material)
    model = model or default_model()
    code, how = refined_code(model.decoder, material, model.material_latent(material), cfg, cache=cache)
    brdf = latent_brdf(model.decoder, code, material, model.sampler)
    brdf.refinement = how
    return brdf


__all__ = ["CachedCode", "RefineConfig", "RefineState", "Refiner", "cache_dir", "load_cached", "material_hash",
           "placed_pairs", "refined_brdf", "refined_code", "save_cached"]
