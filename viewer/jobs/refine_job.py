"""Refinement on idle: once an untextured material has been still for a
moment, the Monte Carlo worker process (viewer/reference/worker.py, with its
supervision) refines the layering network's code against the material's own
simulation (``training.refine``), one round per worker round; the window
swaps the refined code in whenever a round's held-out error beats the
network's, and an edit cancels the work at once (the worker checks between
the fit's steps). Refined codes are cached per user by material content, so
a material opened again shows its refined look at once.

``IdleRefiner`` is the window's side and sees no GL: ``edited`` on every
material change, ``poll`` every frame (from ``LookDev.update``); the session
(viewer/session/lookdev.py) rebuilds the BRDF with the code either returns.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material, material_to_dict, parse_material
from nbrdf.neural.model import default_model
from nbrdf.training.refine import RefineConfig, Refiner, check_refinable
from nbrdf.training.refined_cache import load_cached, material_hash, save_cached, serves


@dataclass
class IdleRefineSettings:
    """When and how the previewer refines."""

    enabled: bool = field(default_factory=lambda: os.environ.get("NBRDF_IDLE_REFINE", "1") != "0")
    """Refine still materials, and show cached refined codes, at all (default on; the environment
    variable NBRDF_IDLE_REFINE=0 turns it off: the test suite's windows show the network's codes)."""
    still_seconds: float = 0.5
    """Seconds without an edit before the refinement starts."""
    reswap_ratio: float = 0.7
    """While the refinement runs, a later round's code replaces a refined code already shown only
    when its held-out error is at most this fraction of the shown one's (each swap fades the still
    view into a new accumulation, record 103); the best code is always shown when the refinement
    ends. The first code that beats the network's is shown at once."""
    config: RefineConfig = field(default_factory=RefineConfig)
    """The refinement's settings (its ``budget``: seconds from the start of the work)."""


@dataclass
class RefineResult:
    """A refinement as far as it has got (what the worker sends after each round)."""

    code: np.ndarray | None
    """(3, code) float32, the best code so far (the network's until a round beats it); None: failed."""
    heldout: float
    """The held-out error of ``code``."""
    network_error: float
    """The held-out error of the network's code."""
    seconds: float
    """Seconds the refinement has spent."""
    rounds: int
    """Rounds finished."""
    done: bool
    """No round follows."""
    error: str | None = None
    """One line when the refinement failed."""

    @property
    def improved(self) -> bool:
        return self.code is not None and self.heldout < self.network_error


@dataclass
class RefineSpec:
    """A refinement as it crosses the process boundary to the worker."""

    key: str
    material: dict
    material_dir: str
    code: np.ndarray
    """(3, code) float32: the network's code, the warm start."""
    decoder_id: str
    """The window's decoder (the worker refuses another)."""
    config: RefineConfig

    def start(self, interrupted: Callable[[], bool]) -> "_RefineRun":
        return _RefineRun(self, interrupted)

    def failed(self, message: str) -> RefineResult:
        return RefineResult(None, float("inf"), float("inf"), 0.0, 0, True, message)


class _RefineRun:
    """The worker's side: one ``training.refine.Refiner`` round per ``step``."""

    def __init__(self, spec: RefineSpec, interrupted: Callable[[], bool]):
        self.spec, self.interrupted = spec, interrupted
        self.material = parse_material(spec.material, spec.material_dir)
        self.dec = default_model().decoder
        if self.dec.weights_id() != spec.decoder_id:
            raise NbrdfError("refinement: the window's decoder is not the shipped one the worker loads")
        self.refiner = Refiner(self.dec, self.material, torch.from_numpy(spec.code), spec.config)

    def step(self) -> tuple[RefineResult, int, bool, None]:
        st = self.refiner.step(self.interrupted)
        if st.done:
            save_cached(self.material, self.spec.decoder_id, self.spec.code, st, self.spec.config.budget)
        res = RefineResult(st.code.numpy().astype(np.float32), st.error, st.network_error, st.seconds, st.rounds,
                           st.done)
        return res, st.rounds, st.done, None


#: The status's tail while a refined code is shown and later rounds still run.
RUNNING = ", refining..."


def job_key(material: Material, decoder_id: str) -> str:
    return f"refine:{material_hash(material)}:{decoder_id[:12]}"


class IdleRefiner:
    """The window's side of refinement on idle (module docstring). ``worker``
    and ``decoder`` are called when first needed (the worker process starts
    on its first job; the decoder loads with the model)."""

    def __init__(self, worker: Callable[[], object], decoder: Callable[[], object],
                 settings: IdleRefineSettings | None = None, clock: Callable[[], float] = time.monotonic):
        self._worker, self._decoder = worker, decoder
        self.settings = settings or IdleRefineSettings()
        self.clock = clock
        self._material: Material | None = None
        self._code: np.ndarray | None = None
        self._key: str | None = None
        self._since = 0.0
        self._shown = float("inf")  # the held-out error of the refined code on screen (inf: the network's)
        self.status = ""
        """What the panel says: "" (nothing refined), "refining...", "refined, N s" (with
        ``RUNNING`` while later rounds run)."""

    def _decoder_id(self) -> str:
        return self._decoder().weights_id()

    @property
    def pending(self) -> bool:
        """Whether the material on screen still waits for (or is in) a refinement."""
        return self._key is not None

    def edited(self, material: Material | None, code: torch.Tensor | None) -> torch.Tensor | None:
        """The material on screen changed (None: one refinement does not take: a
        texture-mapped material, a blend); cancels any refinement at once.
        Returns a cached refined code to show instead of ``code`` (None: none)."""
        if self._key is not None:
            w = self._worker()
            if w.current == self._key:
                w.cancel()
        self._material, self._key, self._shown, self.status = None, None, float("inf"), ""
        if material is None or code is None or not self.settings.enabled or material.is_textured:
            return None
        try:
            check_refinable(material)
        except NbrdfError:
            return None
        did = self._decoder_id()
        self._material, self._code = material, code.detach().numpy().astype(np.float32)
        self._key, self._since = job_key(material, did), self.clock()
        hit = load_cached(material, did, self._code)
        if serves(hit, self.settings.config.budget):
            self._key = None  # nothing left to do
            if hit.error < hit.network_error:
                self._shown = hit.error
                self.status = f"refined, {hit.seconds:.0f} s"
                return hit.code
        return None

    def poll(self) -> torch.Tensor | None:
        """Call each frame: starts the refinement once the material has been
        still for ``still_seconds`` and the worker is idle (a reference the
        compare view asked for goes first); returns a refined code to swap in
        when a round beat the network's and the code shown (None: nothing new)."""
        if self._key is None or self._material is None:
            return None
        w = self._worker()
        r = w.result(self._key)
        if r is None or not (r.done or r.error):
            if w.current is None and self.clock() - self._since >= self.settings.still_seconds:
                w.request(RefineSpec(self._key, material_to_dict(self._material), str(self._material.base_dir),
                                     self._code, self._decoder_id(), self.settings.config))
                self.status = self.status or "refining..."
        if r is None:
            return None
        if r.error:
            self.status, self._key = f"refinement failed: {r.error}", None
            return None
        if r.done:
            self._key = None
            self.status = self.status.removesuffix(RUNNING)
            if not r.improved:
                self.status = "" if self._shown == float("inf") else self.status
        # The first code that beats the network's passes at once (``_shown`` is inf until then).
        if r.improved and r.heldout < self._shown and (
                r.done or r.heldout <= self.settings.reswap_ratio * self._shown):
            self._shown = r.heldout
            self.status = f"refined, {r.seconds:.0f} s" + ("" if r.done else RUNNING)
            return torch.from_numpy(r.code)
        return None


__all__ = ["IdleRefineSettings", "IdleRefiner", "RefineResult", "RefineSpec", "job_key"]
