"""The FLIP view's map: HDR-FLIP (imaging/flip.py) of the neural image against what stands beside it, scored at
most ``FLIP_SIZE`` pixels on the longest side and kept as a texture the compositor draws in magma.

FLIP is CPU work whose cost grows with the images' size and dynamic range: at 256 px an image with a sun
highlight takes 0.1-2.5 s on 2 cores. flip-evaluator holds the GIL for the whole evaluation, so in the window
(``run_async``) it runs in a process of its own and the map shown is the last one finished; batch renders and
tests score at once.
"""
from __future__ import annotations

import multiprocessing
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor

import moderngl
import numpy as np

from nbrdf.imaging.flip import flip

#: The longest side of the images the FLIP view scores, pixels (a reference at the view's size, MaterialX's, took
#: 1-11 s per evaluation at 960 x 540 on 2 cores; the Monte Carlo reference is smaller than this already).
FLIP_SIZE = 256


class FlipView:
    """The FLIP map of the view and its mean."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.mean: float | None = None
        """The mean HDR-FLIP of the map shown (None: nothing scored yet)."""
        self.texture: moderngl.Texture | None = None
        """The map shown, (w, h) float, at most ``FLIP_SIZE`` on its longest side."""
        self.key: tuple | None = None
        """What the map shown scores (None: nothing)."""
        self.run_async = False
        """Score in a process of its own, the map shown the last one finished (the window); off: at once."""
        self.notice = ""
        """One line when the FLIP process failed and scoring went back to this process."""
        self.job: tuple[tuple, Future] | None = None
        """(key, evaluation) in flight."""
        self._pool: ProcessPoolExecutor | None = None

    def clear(self) -> None:
        """Nothing to score against: no map, no mean (an evaluation in flight is dropped)."""
        self.mean, self.key, self.job = None, None, None

    def update(self, key: tuple, images: Callable[[], tuple[np.ndarray, np.ndarray]]) -> float | None:
        """Scores the (test, reference) pair ``images`` makes (linear (H, W, 3), the same size) unless the map
        shown is of ``key`` already or an evaluation is in flight; takes a finished one. Returns the mean of the
        map shown."""
        job = self.job
        if job is not None and job[1].done():
            self.job = None
            try:
                self._show(job[0], *job[1].result())
            except Exception as e:  # noqa: BLE001 - the FLIP process died or refused: said, scored here next
                self.notice, self.run_async = f"FLIP in its own process failed ({e}); computed here", False
        if key != self.key and self.job is None:
            test, ref = images()
            if self.run_async:
                self.job = (key, self._process().submit(flip, ref, test))
            else:
                self._show(key, *flip(ref, test))
        return self.mean

    @staticmethod
    def size(size: tuple[int, int]) -> tuple[int, int]:
        """The (w, h) a (w, h) image is scored at."""
        k = min(1.0, FLIP_SIZE / max(size))
        return max(1, round(size[0] * k)), max(1, round(size[1] * k))

    def _show(self, key: tuple, mean: float, fmap: np.ndarray) -> None:
        """Makes a finished evaluation the map shown."""
        self.mean = mean
        data = np.ascontiguousarray(fmap, dtype="f4")
        if self.texture is not None:
            self.texture.release()
        self.texture = self.ctx.texture((data.shape[1], data.shape[0]), 1, data.tobytes(), dtype="f4")
        self.key = key

    def _process(self) -> ProcessPoolExecutor:
        """The process the evaluations run in (flip-evaluator holds the GIL: a thread would stop the window)."""
        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn"))
        return self._pool

    def release(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
        if self.texture is not None:
            self.texture.release()
        self.texture, self.job = None, None
