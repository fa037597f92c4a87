"""Calibration on idle: once a layered material has been still for a moment and the worker has nothing else to
do (a reference the compare view asked for and the idle refinement go first), the Monte Carlo worker process
walks the material's directional albedo (``training.calibration``), a round per worker round, so a newer request
pauses it; the window then scales the body of the code it shows to the walk's energy (``neural.body_scale``).
Walked albedos are cached per user by material content, so a material opened again is calibrated at once.

``IdleCalibrator`` is the window's side and sees no GL: ``edited`` on every material change, ``poll`` every
frame (from ``LookDev.update``); the session (viewer/session/lookdev.py) fits the scale and rebuilds the BRDF.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch

from nbrdf.neural.energy import EnergySettings
from nbrdf.neural.material import Material, material_to_dict, parse_material
from nbrdf.training.calibration import cached_walk_albedo, finish_walk, start_walk, uncalibrated
from nbrdf.training.refined_cache import material_hash

Walked = tuple[torch.Tensor, torch.Tensor]


@dataclass
class IdleCalibrateSettings:
    """When the previewer calibrates."""

    enabled: bool = field(default_factory=lambda: os.environ.get("NBRDF_IDLE_CALIBRATE", "1") != "0")
    """Calibrate still materials, and apply cached calibrations, at all (default on; NBRDF_IDLE_CALIBRATE=0
    turns it off: the test suite's windows show the networks' energy)."""
    still_seconds: float = 0.5
    """Seconds without an edit before the walk starts."""
    thetas: tuple[float, ...] = EnergySettings().thetas
    """The incidences walked: the energy settings' (the body scale's knots)."""


@dataclass
class CalibrateResult:
    """A walk as far as it has got (what the worker sends after each round)."""

    albedo: np.ndarray | None
    """(3, T) float64 once done (None before, or failed)."""
    se: np.ndarray | None
    """(3, T) its standard error."""
    done: bool
    error: str | None = None
    """One line when the walk failed."""


@dataclass
class CalibrateSpec:
    """A walk as it crosses the process boundary to the worker."""

    key: str
    material: dict
    material_dir: str
    thetas: tuple[float, ...]

    def start(self, interrupted: Callable[[], bool]) -> "_CalibrateRun":
        return _CalibrateRun(self)

    def failed(self, message: str) -> CalibrateResult:
        return CalibrateResult(None, None, True, message)


class _CalibrateRun:
    """The worker's side: one round of ``training.furnace.AlbedoWalk`` per ``step``."""

    def __init__(self, spec: CalibrateSpec):
        self.walk = start_walk(parse_material(spec.material, spec.material_dir), spec.thetas)

    def step(self) -> tuple[CalibrateResult, int, bool, None]:
        if not self.walk.step():
            return CalibrateResult(None, None, False), int(self.walk.count.max()), False, None
        a, se = finish_walk(self.walk)
        return CalibrateResult(a.numpy(), se.numpy(), True), int(self.walk.count.max()), True, None


#: The status while the walk runs, and once the material shows the walk's energy.
WALKING, WALKED = "energy: walking...", "energy: the walk's"


def job_key(material: Material) -> str:
    return f"calibrate:{material_hash(material)}"


class IdleCalibrator:
    """The window's side of calibration on idle (module docstring). ``worker`` is called when first needed;
    ``busy`` says whether other idle work (the refinement) still wants the worker first."""

    def __init__(self, worker: Callable[[], object], busy: Callable[[], bool],
                 settings: IdleCalibrateSettings | None = None, clock: Callable[[], float] = time.monotonic):
        self._worker, self._busy = worker, busy
        self.settings = settings or IdleCalibrateSettings()
        self.clock = clock
        self._material: Material | None = None
        self._key: str | None = None
        self._since = 0.0
        self.walked: Walked | None = None
        """The walk's albedo and standard error (3, T) of the material on screen (None: not yet, or none)."""
        self.status = ""
        """What the panel says: "" (not calibrated), ``WALKING``, ``WALKED`` or why the walk failed."""

    def edited(self, material: Material | None) -> Walked | None:
        """The material on screen changed (None: one that is not calibrated: a texture-mapped material, a
        blend); returns its cached walk albedo (None: none, and it is walked once the material is still)."""
        if self._key is not None:
            w = self._worker()
            if w.current == self._key:
                w.cancel()
        self._material, self._key, self.walked, self.status = None, None, None, ""
        if material is None or not self.settings.enabled or uncalibrated(material) is not None:
            return None
        self.walked = cached_walk_albedo(material, self.settings.thetas)
        if self.walked is None:
            self._material, self._key, self._since = material, job_key(material), self.clock()
        else:
            self.status = WALKED
        return self.walked

    def poll(self) -> Walked | None:
        """Call each frame: starts the walk once the material has been still for ``still_seconds`` and the
        worker is idle; returns the walk's albedo when it has finished (None: nothing new)."""
        if self._key is None or self._material is None:
            return None
        w = self._worker()
        r = w.result(self._key)
        if r is None or not (r.done or r.error):
            if w.current is None and not self._busy() and self.clock() - self._since >= self.settings.still_seconds:
                w.request(CalibrateSpec(self._key, material_to_dict(self._material), str(self._material.base_dir),
                                        tuple(self.settings.thetas)))
                self.status = WALKING
            return None
        self._key = None
        if r.error or r.albedo is None:
            self.status = f"energy: the walk failed ({r.error}); the networks'"
            return None
        self.walked = (torch.from_numpy(r.albedo), torch.from_numpy(r.se))
        self.status = WALKED
        return self.walked


__all__ = ["WALKED", "WALKING", "CalibrateResult", "CalibrateSpec", "IdleCalibrateSettings", "IdleCalibrator", "job_key"]
