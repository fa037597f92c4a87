"""A screenshot rendered in steps: the window renders a few passes of it per
frame (``LookDev.step_screenshot``), shows its progress, and stays responsive.

``ScreenshotJob`` is what is being rendered and how far it is; the passes are
drawn by ``LookDev`` into accumulation slots of their own (``SHOT_SLOTS``), so
the result is the image a one-shot render of the same passes gives.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.camera import OrbitCamera

#: Screenshot files: .png is the displayed composite, .exr / .npy the linear neural image.
SHOT_SUFFIXES = (".png", ".exr", ".npy")
#: Accumulation slots of a screenshot: the image, the second image of a blend.
SHOT_SLOTS = ("shot", "shot-other")
#: The slot of a linear (.exr / .npy) screenshot's accumulation.
SHOT_LINEAR_SLOT = "shot-linear"
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
    from nbrdf.viewer.image_io import write_png8

    path.parent.mkdir(parents=True, exist_ok=True)
    write_png8(path, rgb8)
