"""Screenshots of the session's view: at once (``Screenshots.write``, the
command line and scripts) or in steps, a few passes per window frame
(``Screenshots.start`` / ``step``), showing their progress while the window
stays responsive.

``ScreenshotJob`` is what is being rendered and how far it is; the passes are
drawn by the session's ``ViewFrames`` into accumulation slots of their own
(``SHOT_SLOTS``), so the result is the image a one-shot render of the same
passes gives. Each call takes the frame's description (``Frame``); results go
back as return values (the notice) and exceptions (the error), which the
session reports: a screenshot never calls back into the session.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import moderngl
import numpy as np

from nbrdf.imaging.image_io import check_output, tonemap, write_image, write_png8
from nbrdf.imaging.tonemap import ToneMap
from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.jobs.frame import Frame, Stage, render_linear
from nbrdf.viewer.jobs.view_frames import ViewFrames
from nbrdf.viewer.modes import View
from nbrdf.viewer.scene.camera import OrbitCamera

#: Screenshot files: .png is the displayed composite, .exr / .npy the linear neural image.
SHOT_SUFFIXES = (".png", ".exr", ".npy")
#: Accumulation slots of a screenshot: the image, the second image of a blend.
SHOT_SLOTS = ("shot", "shot-other")
#: The slot of a linear (.exr / .npy) screenshot's accumulation.
SHOT_LINEAR_SLOT = "shot-linear"
#: The time one step of a screenshot may take (ms): the window stays responsive.
SHOT_STEP_MS = 150.0
#: The side of a screenshot's tile (pixels): a few passes of one fit a frame on software OpenGL.
TILE = 64


@dataclass
class TileCamera(OrbitCamera):
    """The orbit camera seen through one tile of an image: its projection is the
    full image's narrowed to the tile (an off-axis frustum), so the tiles of an
    image put together are the image."""

    full_aspect: float = 1.0
    """Width / height of the whole image."""
    ndc: tuple[float, float, float, float] = (-1.0, -1.0, 1.0, 1.0)
    """The tile in the whole image's normalised device coordinates: x0, y0, x1, y1 (y up)."""

    def projection(self, aspect: float) -> np.ndarray:
        x0, y0, x1, y1 = self.ndc
        crop = np.eye(4)
        crop[0, 0], crop[0, 3] = 2.0 / (x1 - x0), -(x1 + x0) / (x1 - x0)
        crop[1, 1], crop[1, 3] = 2.0 / (y1 - y0), -(y1 + y0) / (y1 - y0)
        return crop @ super().projection(self.full_aspect)

    @classmethod
    def of(cls, camera: OrbitCamera, size: tuple[int, int], rect: tuple[int, int, int, int]) -> "TileCamera":
        """The tile ``rect`` = (x, y, w, h), top-left origin, of an image of ``size`` seen by ``camera``."""
        (W, H), (x, y, w, h) = size, rect
        ndc = (2.0 * x / W - 1.0, 1.0 - 2.0 * (y + h) / H, 2.0 * (x + w) / W - 1.0, 1.0 - 2.0 * y / H)
        fields = {k: getattr(camera, k) for k in ("yaw", "pitch", "distance", "target", "fov", "near", "far")
                  if hasattr(camera, k)}
        return cls(**fields, full_aspect=W / H, ndc=ndc)


def tiles(size: tuple[int, int], tile: int = TILE) -> list[tuple[int, int, int, int]]:
    """The (x, y, w, h) tiles of an image, top-left origin, row by row."""
    w, h = size
    return [(x, y, min(tile, w - x), min(tile, h - y)) for y in range(0, h, tile) for x in range(0, w, tile)]


@dataclass
class ScreenshotJob:
    """One screenshot being rendered."""

    path: Path
    """The file written at the end (.png, .exr or .npy)."""
    size: tuple[int, int]
    """Pixels (width, height)."""
    passes: int
    """Passes accumulated before the file is written."""
    tiled: bool = False
    """Rendered tile by tile (the object view); else a whole pass per step."""
    done: int = 0
    """Pass-tiles accumulated so far (an edit meanwhile starts them over)."""
    rects: list = field(default_factory=list)
    """The tiles (one whole-image tile when not tiled)."""
    image: np.ndarray | None = None
    """The result so far: uint8 (H, W, 3) for .png, float32 linear for .exr / .npy; row 0 on top."""
    ms_per_pixel_pass: float | None = None
    """Measured cost of one pass over one pixel (sets the passes per step)."""

    def __post_init__(self) -> None:
        self.path = Path(self.path)
        if self.path.suffix.lower() not in SHOT_SUFFIXES:
            raise NbrdfError(f"{self.path}: a screenshot is .png, .exr or .npy")
        w, h = (int(x) for x in self.size)
        if w < 1 or h < 1 or int(self.passes) < 1:
            raise NbrdfError(f"screenshot: {w} x {h} pixels and {self.passes} passes is out of range")
        self.size, self.passes = (w, h), int(self.passes)
        self.rects = tiles(self.size) if self.tiled else [(0, 0, w, h)]
        self.image = np.zeros((h, w, 3), np.float32 if self.linear else np.uint8)

    @property
    def total(self) -> int:
        """Pass-tiles to render in all."""
        return self.passes * len(self.rects)

    @property
    def finished(self) -> bool:
        return self.done >= self.total

    def current(self) -> tuple[int, tuple[int, int, int, int], int]:
        """(tile index, its rect, passes it has) of the tile being rendered."""
        k = min(self.done // self.passes, len(self.rects) - 1)
        return k, self.rects[k], self.done - k * self.passes

    @property
    def linear(self) -> bool:
        """Whether the file holds the linear image (.exr, .npy) rather than the displayed one."""
        return self.path.suffix.lower() != ".png"

    @property
    def progress(self) -> float:
        """The share of the passes rendered, 0 ... 1."""
        return min(1.0, self.done / self.total)

    def restart(self) -> None:
        """The session changed: the passes start over (the file shows it as it is at the end)."""
        self.done = 0


def write_display_png(path: Path, rgb8: np.ndarray) -> None:
    """Writes the displayed (tone-mapped) image, uint8 (H, W, 3) with row 0 at the top."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_png8(path, rgb8)


def _write_linear(path: Path, img: np.ndarray, state) -> None:
    write_image(path, img, state.exposure, ToneMap.parse(state.tonemap).value)


#: What a failed screenshot step raises (the session reports it in one line).
SHOT_ERRORS = (NbrdfError, OSError, ValueError, moderngl.Error)


class Screenshots:
    """A session's screenshots: one-shot (``write``), or one rendered in steps
    (``start``, then ``step`` per frame; ``job``, its image so far in ``texture``
    for the window to show). Drawn with the session's ``stage`` and ``frames``."""

    def __init__(self, stage: Stage, frames: ViewFrames):
        self.stage, self.frames = stage, frames
        self.job: ScreenshotJob | None = None
        self.texture: moderngl.Texture | None = None
        """The screenshot being rendered as far as it is (RGBA8, row 0 at the bottom)."""
        self._fbos: dict[tuple[int, int], moderngl.Framebuffer] = {}

    def write(self, frame: Frame, path: str | Path, size: tuple[int, int], passes: int = 16) -> str:
        """Renders and writes a screenshot of ``frame`` at once; returns the notice
        (a bad request raises ``NbrdfError``). .png: the displayed composite
        (tone-mapped, compare included); .exr/.npy: the linear neural image of the view.
        The view's accumulation starts over after it (its slots were used)."""
        p = Path(path)
        suffix = p.suffix.lower()
        if suffix not in SHOT_SUFFIXES:
            raise NbrdfError(f"{p}: a screenshot is .png, .exr or .npy")
        if frame.brdf is None:
            raise NbrdfError("the latent texture is still building")
        if suffix == ".png":
            fbo = self.stage.ctx.simple_framebuffer(size, components=4)
            try:
                self.frames.restart()
                self.frames.render(frame, fbo, size, passes)
                data = np.frombuffer(fbo.read(components=3), np.uint8).reshape(size[1], size[0], 3)[::-1]
                write_display_png(p, data)
            finally:
                fbo.release()
                self.frames.restart()
        else:
            _write_linear(p, render_linear(self.stage, frame, size, passes), frame.state)
        return f"wrote {p}"

    def start(self, frame: Frame, path: str | Path, size: tuple[int, int], passes: int = 16,
              budget_ms: float = SHOT_STEP_MS) -> str:
        """Starts a screenshot that ``step`` renders a step per frame: the same file
        ``write`` writes at once; returns the notice. Where a whole pass would not fit
        ``budget_ms`` (software OpenGL), the object view is rendered tile by tile."""
        if frame.brdf is None:
            raise NbrdfError("the latent texture is still building")
        job = ScreenshotJob(Path(path), size, passes)
        check_output(job.path)
        rate = self.frames.ms_per_pixel_pass
        whole_ms = None if rate is None else rate * job.size[0] * job.size[1]
        if frame.view == View.OBJECT and not frame.comparing and (whole_ms is None or whole_ms > budget_ms):
            job = ScreenshotJob(job.path, job.size, job.passes, tiled=True)
        job.ms_per_pixel_pass = rate
        if self.texture is not None:
            self.texture.release()
        self.texture = self.stage.ctx.texture(job.size, 4)
        self.job = job
        return f"rendering {job.path.name}..."

    def cancel(self) -> None:
        self.job = None

    @property
    def progress(self) -> float | None:
        """The share of the screenshot being rendered that is done (None: none running)."""
        return None if self.job is None else self.job.progress

    def restart(self) -> None:
        """The session changed: the screenshot being rendered starts over."""
        if self.job is not None:
            self.job.restart()

    def step(self, frame: Frame, budget_ms: float = SHOT_STEP_MS) -> str | None:
        """Renders the next step of the screenshot (passes of one tile within
        ``budget_ms``, or one whole pass) and writes the file after the last;
        returns the notice then (the view's accumulation starts over: its slots
        may have been used). An error (``SHOT_ERRORS``) ends the screenshot and is raised."""
        job = self.job
        if job is None or frame.brdf is None:
            return None
        try:
            self._step(frame, job, budget_ms)
        except Exception:
            self.job = None
            raise
        if not job.finished:
            return None
        self.job = None
        if job.linear:
            _write_linear(job.path, job.image, frame.state)
        else:
            write_display_png(job.path, job.image)
        self.frames.restart()
        return f"wrote {job.path}"

    def _step(self, frame: Frame, job: ScreenshotJob, budget_ms: float) -> None:
        stage, state = self.stage, frame.state
        k, (x, y, w, h), have = job.current()
        view = frame.view
        n = 1
        if job.tiled and job.ms_per_pixel_pass:
            n = int(np.clip(budget_ms / (job.ms_per_pixel_pass * w * h), 1, job.passes - have))
        cam = TileCamera.of(state.camera, job.size, (x, y, w, h)) if job.tiled else None
        body = stage.bodies.for_frame(frame.brdf, False) if view == View.OBJECT else frame.brdf
        stage.renderer.quick = False  # a still image: the full estimator
        t0 = time.perf_counter()
        if job.linear:
            img, n = self._linear_step(frame, job, cam, body, (x, y, w, h), have, n)
            rgb8 = tonemap(img, state.exposure, ToneMap.parse(state.tonemap).value)
        else:
            if (w, h) not in self._fbos:
                self._fbos[(w, h)] = stage.ctx.simple_framebuffer((w, h), components=4)
            fbo = self._fbos[(w, h)]
            fbo.use()
            fbo.viewport = (0, 0, w, h)
            got = self.frames.draw(frame, fbo, w, h, have, n, SHOT_SLOTS, camera=cam, body=body)
            n = job.passes - have if view != View.OBJECT else got - have  # the lobe and slice: drawn once
            rgb8 = np.frombuffer(fbo.read(components=3), np.uint8).reshape(h, w, 3)[::-1]
            job.image[y:y + h, x:x + w] = rgb8
        stage.ctx.finish()
        if job.tiled and n:
            job.ms_per_pixel_pass = (time.perf_counter() - t0) * 1000.0 / (w * h * n)
        job.done += max(n, 1)
        rgba = np.concatenate([rgb8, np.full(rgb8.shape[:2] + (1,), 255, np.uint8)], -1)[::-1]
        self.texture.write(np.ascontiguousarray(rgba).tobytes(), viewport=(x, job.size[1] - y - h, w, h))

    def _linear_step(self, frame: Frame, job: ScreenshotJob, cam, body, rect, have: int, n: int):
        """One step of a linear (.exr / .npy) screenshot into ``job.image``: (the tile's image, passes added)."""
        stage = self.stage
        x, y, w, h = rect
        state = frame.state
        if frame.view != View.OBJECT:  # one pass: the lobe and slice views are not accumulated
            img, n = stage.renderer.render_linear(state, job.size, 1, frame.brdf), job.passes - have
        else:
            if cam is not None:
                state = replace(state, camera=cam)
            acc = stage.renderer.accumulate(replace(state, background=False), w, h, have, n, body,
                                            SHOT_LINEAR_SLOT)
            tex = stage.backdrop.apply(acc, have + n, state, frame.backdrop, SHOT_LINEAR_SLOT)
            img = np.frombuffer(tex.read(), dtype="f4").reshape(h, w, 4)[::-1, :, :3]
        job.image[y:y + h, x:x + w] = img
        return img, n

    def release(self) -> None:
        for fbo in self._fbos.values():
            fbo.release()
        self._fbos.clear()
        if self.texture is not None:
            self.texture.release()
            self.texture = None
