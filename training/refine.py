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
stops falling, or when the budget is spent.

The budget is a bound, not a hope: the work comes in small units (a chunk of
``chunk_pairs`` simulated pairs, one fitting step), each unit's cost is
measured on the refinement's own clock as it runs (a material's paths may
be 20 times longer than another's, and a shared machine's speed changes by
the minute), and a unit starts only when its measured cost fits in the time
left. A round is sized to the time left (fewer new pairs and steps near the
end), and a slow material gets a smaller held-out set. The overrun is at
most the misestimate of one unit; the first chunk, which has no estimate,
is kept small.

Refined codes are cached per user (``training.refined_cache``) by the material's
content, the decoder and the warm start, so reopening a material costs nothing.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import torch

from nbrdf.neural.anisotropy import FRAME_PARAMS, body_pair, body_tail
from nbrdf.neural.coat import coat_eval, with_coat
from nbrdf.neural.decoder import Decoder
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.geometry import cosine_hemisphere
from nbrdf.neural.material import Conductor, Dielectric, LatentBase, Material
from nbrdf.neural.microfacet import reflect, sample_vndf
from nbrdf.neural.model import default_model
from nbrdf.neural.neural_brdf import latent_brdf
from nbrdf.neural.projection import ProjectionConfig, project
from nbrdf.training.dataset import sample_pairs
from nbrdf.training.reference import check_uniform, reference_eval
from nbrdf.training.refined_cache import CachedCode, load_cached, save_cached, serves

Tensor = torch.Tensor

#: The default time budget of a refinement (seconds).
DEFAULT_BUDGET = 10.0


@dataclass(frozen=True)
class RefineConfig:
    """How a code is refined (module docstring)."""

    budget: float = DEFAULT_BUDGET
    """Seconds of wall-clock time the refinement may spend, simulation and fitting together."""
    round_pairs: int = 512
    """New direction pairs simulated per round."""
    heldout_pairs: int = 1024
    """Direction pairs of the held-out set that scores every code (never fitted)."""
    spp: int = 256
    """Monte Carlo paths per pair (at 64 the held-out error is mostly the references' own noise and rounds stop early)."""
    steps: int = 120
    """Projection steps per round."""
    fit_pairs: int = 3072
    """Pairs a round fits at most: the new round's and a random draw of the earlier ones (a round's cost stays flat)."""
    lr: float = 0.02
    """Adam learning rate of the rounds (a warm start: half the projection's from the latent mean)."""
    min_gain: float = 0.02
    """A round must lower the held-out error by this share of it to count as falling."""
    patience: int = 3
    """Rounds in a row that may fail to fall before the refinement stops."""
    max_rounds: int = 24
    """Rounds at most (the pool then holds ``round_pairs * max_rounds`` pairs)."""
    seed: int = 0
    """Seed of the pairs and of the simulation."""
    chunk_pairs: int = 64
    """Pairs per walk call: the least unit of simulation (the budget and a cancel are checked between chunks)."""
    probe_pairs: int = 8
    """Pairs of the very first chunk, whose cost nothing measured yet bounds (it sets the overrun's worst case)."""
    heldout_share: float = 0.3
    """Share of the budget the held-out set may take once it holds ``min_heldout_pairs`` (a slow material gets
    fewer held-out pairs, so that rounds remain)."""
    min_heldout_pairs: int = 128
    """Held-out pairs the refinement simulates whatever their cost (fewer score codes too noisily to choose)."""
    min_round_pairs: int = 64
    """New pairs a round needs to start (a round sized smaller than this by the time left is not run)."""
    min_steps: int = 20
    """Fitting steps a round needs to start."""

    def check(self) -> None:
        """One line for a setting out of range."""
        if not (math.isfinite(self.budget) and self.budget > 0):
            raise NbrdfError(f"--budget: {self.budget} seconds must be a positive number")
        for name in ("round_pairs", "heldout_pairs", "spp", "steps", "fit_pairs", "max_rounds", "chunk_pairs",
                     "probe_pairs", "min_heldout_pairs", "min_round_pairs", "min_steps"):
            if getattr(self, name) < 1:
                raise NbrdfError(f"refinement: {name} {getattr(self, name)} must be at least 1")
        if not 0.0 < self.heldout_share <= 1.0:
            raise NbrdfError(f"refinement: heldout_share {self.heldout_share} must lie in (0, 1]")


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
@dataclass
class WorkCosts:
    """Wall-clock costs of a refinement's units, measured on its own clock as it runs."""

    pair: float | None = None
    """Seconds per simulated pair (``spp`` paths): the latest chunk's rate or the mean so far, the larger."""
    fit: float | None = None
    """Seconds per fitting step and fitted pair (the latest fit's)."""
    score: float = 0.0
    """Seconds to score one code on the held-out set."""
    pairs_done: int = 0
    """Pairs simulated so far."""
    pair_seconds: float = 0.0
    """Seconds their simulation took."""

    def add_chunk(self, n: int, seconds: float) -> None:
        """Records a walk call of n pairs that took ``seconds``."""
        self.pairs_done += n
        self.pair_seconds += seconds
        self.pair = max(seconds / n, self.pair_seconds / self.pairs_done)


class Refiner:
    """One material's refinement in rounds: ``start`` simulates the held-out
    set and scores the network's code; each ``step`` is one round sized to
    the time left (module docstring). ``stop`` (checked between chunks of
    the simulation and between the projection's steps) ends a round early
    without using it, so a caller can cancel at once. ``clock`` (seconds,
    monotonic) measures the budget and the units' costs."""

    def __init__(self, dec: Decoder, material: Material, network_code: Tensor,
                 cfg: RefineConfig = RefineConfig(), clock: Callable[[], float] = time.perf_counter):
        cfg.check()
        check_refinable(material)
        if not dec.spec.coat:
            raise NbrdfError("refinement: the decoder predates the coat split (retrain, docs/RESULTS.md)")
        code = torch.as_tensor(network_code, dtype=torch.float32).reshape(3, -1)
        if code.shape[1] not in (dec.spec.code, dec.spec.code + FRAME_PARAMS):
            raise NbrdfError(f"refinement: a code has {dec.spec.code} floats per channel (or "
                             f"{dec.spec.code + FRAME_PARAMS} with anisotropy), got {code.shape[1]}")
        self.dec, self.material, self.cfg, self.clock = dec, material, cfg, clock
        self.coat = code[:1, dec.spec.latent:dec.spec.code]  # (1, 2): the material's coat, as the network's code has it
        self.tail = code[:, dec.spec.code:]
        """(3, 0) or (3, FRAME_PARAMS): an anisotropic code's tail, kept (its glow per channel); its body is
        fitted at the warped pairs, where the decoder reads it (``neural.anisotropy.body_pair``: the values less
        the glow, divided by J)."""
        self.coat_only = not material.interfaces and float(self.coat[0, 1]) > 1.0
        """A single layer that the code holds as its coat (a lone dielectric): exact in closed form, no body to fit."""
        self.roughness = body_roughness(material)
        self.g = torch.Generator().manual_seed(cfg.seed)
        self.costs = WorkCosts()
        self._network_code = code
        self._pool: list[tuple[Tensor, Tensor, Tensor]] = []
        self._held: list[tuple[Tensor, Tensor, Tensor]] = []  # held-out chunks simulated so far
        self._heldout: HeldOut | None = None
        self._chunks = 0  # walk calls so far (each its own seed)
        self._largest = 0  # pairs of the largest walk call so far
        self._spent = (0.0, 0.0)  # (wall, processor) seconds inside start and step: a set-aside run is not charged
        self._call = (0.0, 0.0)  # (clock, process_time) at the start of the current call
        self._stale = 0
        self.state: RefineState | None = None

    # --- time ---------------------------------------------------------------------------------
    def _begin(self) -> None:
        self._call = (self.clock(), time.process_time())

    def _end(self) -> None:
        """Charges the current call's time to the refinement."""
        w, c = self._spent
        self._spent = (w + self.clock() - self._call[0], c + time.process_time() - self._call[1])
        self._call = (self.clock(), time.process_time())
        if self.state is not None:
            self.state.seconds, self.state.cpu_seconds = self._spent

    def _left(self) -> float:
        """Seconds of the budget left now."""
        return self.cfg.budget - self._spent[0] - (self.clock() - self._call[0])

    # --- work units ---------------------------------------------------------------------------
    def _chunk(self, n: int) -> tuple[Tensor, Tensor, Tensor]:
        """n newly simulated pairs (one walk call), its cost measured."""
        t = self.clock()
        wi, wo = placed_pairs(n, self.g, self.roughness)
        f = body_values(self.material, wi, wo, self.cfg.spp, self.cfg.seed * 7919 + 1 + self._chunks)
        self._chunks += 1
        self._largest = max(self._largest, n)
        self.costs.add_chunk(n, self.clock() - t)
        return wi, wo, f

    def _next_chunk(self, want: int) -> int:
        """Pairs in the next chunk: the first one is a small probe, and a chunk is at most twice the largest so far
        (a cost measured on few pairs is checked on a few more before it is trusted with ``chunk_pairs``)."""
        if self.costs.pair is None:
            return min(want, self.cfg.probe_pairs)
        return min(want, self.cfg.chunk_pairs, 2 * self._largest)

    def _score(self, code: Tensor) -> float:
        t = self.clock()
        e = heldout_error(self.dec, code, self._heldout)
        self.costs.score = self.clock() - t
        return e

    def _measure_fit(self) -> None:
        """The fit's cost per step and pair, from two steps on the held-out pairs (before any round)."""
        h, t = self._heldout, self.clock()
        wi, wo = h.wi[None].expand(3, -1, -1), h.wo[None].expand(3, -1, -1)
        project(self.dec, wi, wo, h.f.T.contiguous(), ProjectionConfig(steps=2, lr=0.0), z0=self._network_code)
        self.costs.fit = (self.clock() - t) / (2 * h.wi.shape[0])

    def _pooled(self) -> int:
        return sum(p[0].shape[0] for p in self._pool)

    def _round_cost(self, n: int, steps: int) -> float:
        """Estimated seconds of a round of n new pairs and ``steps`` steps."""
        fitted = min(n + self._pooled(), self.cfg.fit_pairs)
        return n * self.costs.pair + steps * fitted * self.costs.fit + self.costs.score

    def _plan(self) -> tuple[int, int] | None:
        """(new pairs, steps) of the next round that fit in the time left, or None: none does."""
        c, left = self.cfg, self._left()
        scale = 1.0
        while True:
            n, steps = int(c.round_pairs * scale), int(c.steps * scale)
            if n < min(c.min_round_pairs, c.round_pairs) or steps < min(c.min_steps, c.steps):
                return None
            if self._round_cost(n, steps) <= left:
                return n, steps
            scale *= 0.8

    # --- the refinement -----------------------------------------------------------------------
    def start(self, stop: Callable[[], bool] | None = None) -> RefineState:
        """Simulates the held-out set (all of ``heldout_pairs``, or fewer when
        the walk is slow: at least ``min_heldout_pairs`` while the budget
        lasts) and scores the network's code. ``stop`` pauses it (what was
        simulated is kept); until it is scored, the state holds the network's
        code with infinite errors."""
        if self.state is not None and (self._heldout is not None or self.state.done):
            return self.state
        if self.coat_only:  # nothing below the coat: the network's code is already exact
            self.state = RefineState(self._network_code, 0.0, 0.0, done=True, converged=True, history=[0.0])
            return self.state
        c = self.cfg
        if self.state is None:
            self.state = RefineState(self._network_code, math.inf, math.inf)
        st = self.state
        self._begin()
        have = sum(h[0].shape[0] for h in self._held)
        while have < c.heldout_pairs:
            if stop is not None and stop():
                self._end()
                return st
            k = self._next_chunk(c.heldout_pairs - have)
            if self.costs.pair is not None:
                cost = k * self.costs.pair
                spent = self._spent[0] + self.clock() - self._call[0]
                if have >= c.min_heldout_pairs and spent + cost > c.heldout_share * c.budget:
                    break  # a slow walk: fewer held-out pairs, so that rounds remain
                if cost > self._left():
                    break  # the budget ends here
            self._held.append(self._chunk(k))
            have += k
        wi, wo, body = (torch.cat(x) for x in zip(*self._held))
        coat = coat_eval(self.coat.expand(3, -1)[:, None, :], wi[None].expand(3, -1, -1),
                         wo[None].expand(3, -1, -1)).T
        self._heldout = HeldOut(wi, wo, body + coat.float())
        e = self._score(self._network_code)
        st.network_error = st.error = e
        st.pairs, st.history = have, [e]
        self._measure_fit()
        if self._plan() is None:
            st.done = True  # the held-out set took the budget
        self._end()
        return st

    def step(self, stop: Callable[[], bool] | None = None) -> RefineState:
        """One round (module docstring) sized to the time left; a round cut
        short by ``stop`` changes nothing."""
        st = self.start(stop)
        if st.done or self._heldout is None:
            return st
        c = self.cfg
        self._begin()
        plan = self._plan()
        if plan is None or st.rounds >= c.max_rounds:
            st.done = True
            self._end()
            return st
        n, steps = plan
        # Simulation, chunk by chunk, while the time left keeps room for the fit's least share and the score.
        new: list[tuple[Tensor, Tensor, Tensor]] = []
        have = 0
        while have < n:
            if stop is not None and stop():
                self._end()
                return st
            k = self._next_chunk(n - have)
            fit_least = min(c.min_steps, c.steps) * min(have + k + self._pooled(), c.fit_pairs) * self.costs.fit
            if have > 0 and k * self.costs.pair + fit_least + self.costs.score > self._left():
                break  # slower than measured: fit what there is
            new.append(self._chunk(k))
            have += k
        self._pool.append(tuple(torch.cat(x) for x in zip(*new)))
        wi, wo, f = (torch.cat(x) for x in zip(*self._pool))
        if wi.shape[0] > c.fit_pairs:  # the newest round whole, the rest drawn from the earlier ones
            old = wi.shape[0] - have
            keep = torch.randperm(old, generator=self.g)[:max(0, c.fit_pairs - have)]
            keep = torch.cat([keep, torch.arange(old, wi.shape[0])])
            wi, wo, f = wi[keep], wo[keep], f[keep]
        fitted = wi.shape[0]
        steps = max(1, min(steps, int((self._left() - self.costs.score) / (fitted * self.costs.fit))))
        if self.tail.shape[1]:
            wi, wo, f = self._warped(wi, wo, f)
        wi, wo, f = wi[None].expand(3, -1, -1), wo[None].expand(3, -1, -1), f.T.contiguous()
        cancelled, ran = [False], [0]
        t_fit = self.clock()

        def hook(_step: int) -> bool:
            if stop is not None and stop():
                cancelled[0] = True
                return True
            if _step > 0 and fitted * self.costs.fit + self.costs.score > self._left():
                return True  # the time is up: keep the fit as it is
            ran[0] += 1
            return False

        z = project(self.dec, wi, wo, f, ProjectionConfig(steps=steps, lr=c.lr), z0=st.code, stop=hook)
        if cancelled[0]:
            self._pool.pop()
            self._end()
            return st
        self.costs.fit = (self.clock() - t_fit) / (max(ran[0], 1) * fitted)
        code = torch.cat([with_coat(z[:, :self.dec.spec.latent], self.coat.expand(3, -1)),
                          self.tail], -1)
        e = self._score(code)
        st.rounds, st.pairs = st.rounds + 1, st.pairs + have
        st.history.append(e)
        if e < st.error * (1 - c.min_gain):
            self._stale = 0
        else:
            self._stale += 1
        if e < st.error:
            st.code, st.error = code, e
        if self._stale >= c.patience:
            st.done = st.converged = True
        elif st.rounds >= c.max_rounds or self._plan() is None:
            st.done = True  # no round fits in the time left
        self._end()
        return st

    def _warped(self, wi: Tensor, wo: Tensor, f: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Body samples of an anisotropic code where its isotropic latent is read: the warped pairs and
        the values less the glow, over J (pairs the warp turns below the horizon, J = 0, are left out)."""
        code = torch.cat([self._network_code[:, :self.dec.spec.code], self.tail], -1)
        tail = body_tail(code[:1], self.dec.spec.code)
        wi2, wo2, j = body_pair(tail[0].to(wi.dtype), wi, wo, self.coat[0, 1].to(wi.dtype))
        f = (f - self.dec.glow(code[:, None, :].to(wi.dtype), wi[None], wo[None]).T.to(f.dtype)).clamp_min(0.0)
        keep = j > 1e-6
        return wi2[keep], wo2[keep], f[keep] / j[keep, None].to(f.dtype)

    def run(self, stop: Callable[[], bool] | None = None) -> RefineState:
        """Rounds until done (or ``stop``)."""
        st = self.start(stop)
        while not st.done and not (stop is not None and stop()):
            st = self.step(stop)
        return st


def check_refinable(material: Material) -> None:
    """One line for a material refinement cannot take (it needs a reference)."""
    check_uniform(material)
    if isinstance(material.base, LatentBase) and not material.interfaces:
        raise NbrdfError("layers[0]: a latent base has no reference to refine against; use --method neural")


def refined_code(dec: Decoder, material: Material, network_code: Tensor, cfg: RefineConfig = RefineConfig(),
                 cache: bool = True) -> tuple[Tensor, RefineState | CachedCode]:
    """The refined code (3, 34) of a uniform material (the network's when no
    round beats it on the held-out pairs) and how it was made; from the cache
    when an entry serves the budget."""
    cfg.check()
    did = dec.weights_id()
    if cache:
        hit = load_cached(material, did, network_code)
        if serves(hit, cfg.budget):
            return hit.code, hit
    st = Refiner(dec, material, network_code, cfg).run()
    if cache:
        save_cached(material, did, network_code, st, cfg.budget)
    return st.code, st


def refined_brdf(material: Material, model=None, budget: float | None = None, seed: int = 0, cache: bool = True):
    """``brdf_for(material, Method.REFINED)``: the decoder at the refined code (its albedo
    bounded, ``neural.energy``) plus its coat, sampled like the full neural path; ``.refinement`` tells how the
    code was made (a ``RefineState``, or the ``CachedCode`` it came from)."""
    cfg = RefineConfig(budget=DEFAULT_BUDGET if budget is None else float(budget), seed=seed)
    cfg.check()
    check_refinable(material)
    model = model or default_model()
    code, how = refined_code(model.decoder, material, model.material_latent(material), cfg, cache=cache)
    code = model.conserved(code)  # as the window shows a refined code: its albedo bounded (neural.energy)
    brdf = latent_brdf(model.decoder, code, material, model.sampler)
    brdf.refinement = how
    return brdf


__all__ = ["RefineConfig", "RefineState", "Refiner", "placed_pairs", "refined_brdf", "refined_code"]
