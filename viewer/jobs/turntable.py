"""Turntables: one turn of the camera around the object, written as a video,
a looping GIF or numbered frames, at once (offscreen) or a frame per displayed
frame (the window: the session's update steps the capture). This module owns
the frames' cameras, the capture in progress and the file; the frames are drawn
from the frame description each call is given (viewer/jobs/frame.py)."""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from nbrdf.imaging.image_io import tonemap as to_srgb8
from nbrdf.imaging.image_io import write_image
from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.jobs.frame import Frame, Stage
from nbrdf.viewer.modes import View
from nbrdf.viewer.view_settings import ViewState

#: Frames per second of a turntable video or GIF.
TURNTABLE_FPS = 24


def turntable_kind(out: Path) -> str:
    """"video", "gif" or "frames" (a pattern such as frame_%03d.png); one line otherwise."""
    if "%" in out.name:
        try:
            name = out.name % 0
        except (TypeError, ValueError):
            raise NbrdfError(f"{out}: a frame pattern takes one integer field, e.g. frame_%03d.png") from None
        if Path(name).suffix.lower() not in (".png", ".exr", ".npy"):
            raise NbrdfError(f"{out}: frames must be .png, .exr or .npy")
        return "frames"
    kinds = {".mp4": "video", ".gif": "gif"}
    if out.suffix.lower() not in kinds:
        raise NbrdfError(f"--turntable: {out} must be .mp4, .gif or a frame pattern such as frame_%03d.png")
    return kinds[out.suffix.lower()]


def turntable_states(state: ViewState, frames: int) -> list[ViewState]:
    """``frames`` copies of ``state`` whose cameras make one turn about the up axis."""
    out = []
    for k in range(frames):
        s = copy.deepcopy(state)
        s.camera.orbit(360.0 * k / frames, 0.0)
        out.append(s)
    return out


def write_turntable(out: Path, frames: list, exposure: float, tonemap) -> None:
    """Linear frames -> a video (.mp4, H.264 through imageio's ffmpeg plugin), a looping GIF, or numbered files."""
    import imageio.v2 as iio  # late: ~100 ms of start-up, only needed when a turntable is written

    kind = turntable_kind(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if kind == "frames":
        for k, img in enumerate(frames):
            write_image(out.parent / (out.name % k), img, exposure, tonemap)
        return
    pictures = [to_srgb8(img, exposure, tonemap) for img in frames]
    if kind == "gif":
        iio.mimwrite(out, pictures, duration=1000.0 / TURNTABLE_FPS, loop=0)
    else:
        iio.mimwrite(out, pictures, fps=TURNTABLE_FPS, macro_block_size=2, quality=8)


@dataclass
class TurntableCapture:
    """A turntable being rendered, one frame per step."""

    out: Path
    """.mp4, .gif or a frame pattern such as frame_%03d.png."""
    states: list
    """The view state of every frame (one camera turn)."""
    size: tuple[int, int]
    """Pixels per frame."""
    spp: int
    """Passes per frame."""
    frames: list = field(default_factory=list)
    """Linear frames rendered so far."""

    @classmethod
    def of(cls, path: str | Path, state: ViewState, frames: int, size: tuple[int, int],
           spp: int) -> "TurntableCapture":
        """A capture of ``frames`` frames around ``state``'s camera; one-line error for a bad request."""
        out = Path(path)
        turntable_kind(out)
        if not (1 <= int(frames) <= 3600) or min(size) < 1 or spp < 1:
            raise NbrdfError(f"turntable: {frames} frames of {size} x {spp} passes is out of range")
        if View.parse(state.view) != View.OBJECT:
            raise NbrdfError("turntable: turns the camera around the object (object view)")
        return cls(out, turntable_states(state, int(frames)), (int(size[0]), int(size[1])), int(spp))

    @property
    def progress(self) -> float:
        return len(self.frames) / len(self.states)

    def step(self, render: Callable[[ViewState, tuple[int, int], int], np.ndarray], exposure: float,
             tonemap) -> bool:
        """Renders the next frame with ``render(state, size, spp)``; after the last
        writes the file and returns True."""
        self.frames.append(render(self.states[len(self.frames)], self.size, self.spp))
        if len(self.frames) < len(self.states):
            return False
        write_turntable(self.out, self.frames, exposure, tonemap)
        return True

    def run(self, render: Callable[[ViewState, tuple[int, int], int], np.ndarray], exposure: float,
            tonemap) -> None:
        """Renders every frame and writes the file (offscreen)."""
        while not self.step(render, exposure, tonemap):
            pass


class Turntables:
    """A session's turntables: captured from the window a frame per displayed
    frame (``start``, then ``step`` from the session's update), or written at
    once (``write``, offscreen). Frames are the object over its backdrop."""

    def __init__(self, stage: Stage):
        self.stage = stage
        self.capture: TurntableCapture | None = None
        """The capture running in the window (None: none)."""

    def _renders(self, frame: Frame) -> Callable[[ViewState, tuple[int, int], int], np.ndarray]:
        """What renders a turntable frame of ``frame``'s material and backdrop at a given view state."""
        def render(state: ViewState, size: tuple[int, int], spp: int) -> np.ndarray:
            return self.stage.backdrop.render_linear(state, size, spp, frame.brdf, frame.backdrop)
        return render

    def start(self, frame: Frame, path: str | Path, frames: int = 36, size: tuple[int, int] = (480, 480),
              spp: int = 16) -> None:
        """Starts rendering one camera turn of ``frames`` frames to ``path``
        (.mp4, .gif or frame_%03d.png), one frame per ``step`` (a bad request raises ``NbrdfError``)."""
        self.capture = TurntableCapture.of(path, frame.state, frames, size, spp)

    @property
    def progress(self) -> float | None:
        """The share of the capture's frames rendered (None: no capture running)."""
        return None if self.capture is None else self.capture.progress

    def step(self, frame: Frame) -> str | None:
        """Renders the capture's next frame; writes the file after the last and returns
        the notice then (a failure ends the capture and is raised)."""
        job, self.capture = self.capture, None
        if job is None:
            return None
        if not job.step(self._renders(frame), frame.state.exposure, frame.state.tonemap):
            self.capture = job
            return None
        return f"wrote {job.out} ({len(job.frames)} frames)"

    def write(self, frame: Frame, path: str | Path, frames: int, size: tuple[int, int], spp: int) -> None:
        """Renders a whole turntable of ``frame``'s view at once and writes it."""
        TurntableCapture.of(path, frame.state, frames, size, spp).run(self._renders(frame), frame.state.exposure,
                                                                      frame.state.tonemap)
