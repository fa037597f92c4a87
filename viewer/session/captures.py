"""A session's screenshots, turntables and polar-plot curves as session methods.

The jobs (viewer/jobs/screenshot.py, turntable.py, plane_curves.py) take the
frame's description and return their notices or raise their errors; the
methods here run them as guarded edits and report the outcome in the
session's ``notice`` and ``error``, so the panels, the offscreen path and the
tests call the session alone. ``Captures`` is a mixin of ``LookDev``
(viewer/session/lookdev.py), which supplies the members declared below.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import moderngl
import numpy as np
import torch

from nbrdf.neural.material import Material
from nbrdf.neural.model import NeuralModel
from nbrdf.viewer.jobs.frame import Frame
from nbrdf.viewer.jobs.plane_curves import PlaneCurves
from nbrdf.viewer.jobs.screenshot import SHOT_ERRORS, SHOT_STEP_MS, Screenshots
from nbrdf.viewer.jobs.turntable import Turntables
from nbrdf.viewer.view_settings import ViewState


class Captures:
    """Screenshots (at once or a step per frame), turntables and saved curves of a session."""

    # What the session supplies (viewer/session/lookdev.py, viewer/session/edits.py).
    shots: Screenshots
    turntables: Turntables
    curves: PlaneCurves
    state: ViewState
    material: Material
    model: NeuralModel
    notice: str
    error: str | None
    describe: Callable[[], Frame]
    guarded: Callable[..., bool]
    invalidate: Callable[[], None]
    latent: Callable[[], torch.Tensor]

    def write_screenshot(self, path: str | Path, size: tuple[int, int], passes: int = 16) -> bool:
        """Renders and writes a screenshot at once (a guarded edit: False with ``error``
        on bad input). .png: the displayed composite (tone-mapped, compare included);
        .exr/.npy: the linear neural image of the view."""
        def go():
            self.notice = self.shots.write(self.describe(), path, size, passes)
            self.invalidate()
        return self.guarded(go)

    def start_screenshot(self, path: str | Path, size: tuple[int, int], passes: int = 16,
                         budget_ms: float = SHOT_STEP_MS) -> bool:
        """Starts a screenshot rendered a step per frame (``step_screenshot``; a guarded edit)."""
        return self.guarded(lambda: setattr(self, "notice", self.shots.start(self.describe(), path, size, passes,
                                                                             budget_ms)))

    def step_screenshot(self, budget_ms: float = SHOT_STEP_MS) -> None:
        """Renders the next step of the screenshot being rendered and writes the file
        after the last (then ``notice``); an error ends it and becomes ``error``."""
        try:
            notice = self.shots.step(self.describe(), budget_ms)
        except SHOT_ERRORS as e:
            self.error = f"screenshot: {str(e).splitlines()[0] if str(e) else type(e).__name__}"
            return
        if notice:
            self.notice = notice
            self.invalidate()  # the view's reference and accumulation slots may have been used

    def cancel_screenshot(self) -> None:
        self.shots.cancel()
        self.notice = "screenshot cancelled"

    @property
    def screenshot_progress(self) -> float | None:
        """The share of the screenshot being rendered that is done (None: none running)."""
        return self.shots.progress

    @property
    def screenshot_image(self) -> moderngl.Texture | None:
        """The screenshot being rendered as far as it is (RGBA8, row 0 at the bottom)."""
        return self.shots.texture

    def start_turntable(self, path: str | Path, frames: int = 36, size: tuple[int, int] = (480, 480),
                        spp: int = 16) -> bool:
        """Starts rendering one camera turn of ``frames`` frames to ``path`` (.mp4, .gif or
        frame_%03d.png), one frame per ``update`` (a guarded edit)."""
        return self.guarded(lambda: self.turntables.start(self.describe(), path, frames, size, spp))

    def write_turntable(self, path: str | Path, frames: int, size: tuple[int, int], spp: int) -> None:
        """Renders a whole turntable of the view at once and writes it (offscreen)."""
        self.turntables.write(self.describe(), path, frames, size, spp)

    @property
    def turntable_progress(self) -> float | None:
        """The share of the capture's frames rendered (None: no capture running)."""
        return self.turntables.progress

    def _turntable_step(self) -> None:
        notice = self.turntables.step(self.describe())
        if notice:
            self.notice = notice

    def save_curve(self, name: str | None = None) -> None:
        """Keeps the current material's curve for the polar plot (two at most)."""
        self.curves.save(name or self.material.name, self.latent())

    def plane_curves(self, n: int = 181) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """The polar plot's curves at the view's incidence (viewer/jobs/plane_curves.py)."""
        return self.curves.curves(self.material, self.latent, self.model.decoder, self.state.theta_i, n)
