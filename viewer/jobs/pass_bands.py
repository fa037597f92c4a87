"""A still view's pass shaded over several frames, in bands of rows sized to a frame budget.

At full resolution one pass of the still view's estimator costs software
OpenGL a second or more, and the window reads its input only between frames.
``PassBands`` shades a pass in bands of rows (``Renderer.begin_pass``,
``shade_rows``, ``end_pass``, viewer/gpu/renderer.py), as many rows per frame
as the frame's budget allows, and adds the pass to the accumulation only once
it is complete: the accumulation holds whole passes, each with the random
numbers of its (pixel, pass), so it is the same estimator and the same image
as passes shaded whole.

A band's rows follow its measured cost: ``BandCost`` learns the milliseconds
per shaded pixel (off the object a pixel is cheap: lit.comp reads its coverage
and returns, so a row weighs mostly its pixels on the object, from the depth
the surface left; a band's fixed cost fitted beside it) per estimator and body,
and the cost of ending a pass (the merge, and the new image's composite). The
start of a pass (its pending image cleared; on a first pass the surface
rasterised and its coverage read) is timed as it happens, and its band gets
what is left of the budget. A cost not yet measured is probed with a band of
``PROBE_PIXELS``, and a band weighs at most ``GROWTH`` times the largest
measured (a fit over the rows off the object says little of the object's).
Every measurement waits for the GPU (``ctx.finish``): the band's time is the
frame's time it takes.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Hashable, Sequence

import moderngl
import numpy as np

from nbrdf.viewer.gpu.env_prefilter import baked_per_row
from nbrdf.viewer.gpu.lit_passes import LIT_GROUP
from nbrdf.viewer.gpu.lit_sampling import LitSampling
from nbrdf.viewer.gpu.renderer import Renderer, Shaded
from nbrdf.viewer.view_settings import ViewState

#: Pixels on the object the first band ever shades, its cost unknown (its time then sizes the
#: next bands; a new estimator or body starts from twice the cost last measured).
PROBE_PIXELS = 4096
#: Nodes of the body environment map (viewer/gpu/env_prefilter.py) the first bake band ever
#: bakes, its cost unknown.
PROBE_NODES = 256
#: What a pixel off the object weighs against one on it (lit.comp reads its coverage and returns;
#: measured on llvmpipe, 1280 x 800, the still estimator: about a tenth).
OFF_OBJECT_WEIGHT = 1.0 / 8.0
#: A band weighs at most this many times the largest band measured for its cost: a fit made on
#: rows off the object (or on a cheaper estimator) says little of the object's rows.
GROWTH = 2.0
#: How much of the cost fit the next band keeps (the rest is the new band's): recent bands
#: weigh most, as the machine's load changes.
COST_MEMORY = 0.6


@dataclass
class CostFit:
    """A band's milliseconds as ``fixed + per_pixel * weight``, least squares over the
    bands measured so far, older ones fading (``COST_MEMORY``): the fixed part is a
    dispatch's own cost, which a small band would otherwise make look expensive per pixel."""

    n: float = 0.0
    most: float = 0.0
    """The largest band measured (weighted pixels): a band grows at most to ``GROWTH`` times it."""
    sw: float = 0.0
    st: float = 0.0
    sww: float = 0.0
    swt: float = 0.0

    def add(self, weight: float, ms: float) -> None:
        m = COST_MEMORY
        self.most = max(self.most, weight)
        self.n, self.sw, self.st = m * self.n + 1.0, m * self.sw + weight, m * self.st + ms
        self.sww, self.swt = m * self.sww + weight * weight, m * self.swt + weight * ms

    def line(self) -> tuple[float, float]:
        """(fixed ms, ms per weighted pixel): the fitted line, or through the origin when the
        bands measured are too alike to tell the two apart (or the fit says a negative part)."""
        den = self.n * self.sww - self.sw * self.sw
        if den > 1e-6 * self.n * self.sww:
            k = (self.n * self.swt - self.sw * self.st) / den
            a = (self.st - k * self.sw) / self.n
            if k > 0 and a >= 0:
                return a, k
        return 0.0, self.st / max(self.sw, 1e-9)


@dataclass
class BandCost:
    """Measured costs of banded passes: per (estimator, body) a band's fitted cost
    (``CostFit``), and per view pixel that of ending a pass (the merge)."""

    fits: dict[Hashable, CostFit] = field(default_factory=dict)
    """A band's milliseconds against its weighted pixels (``PassBands.weights``), per cost key."""
    end_ms_per_px: float | None = None
    """Ending a pass (the merge), per pixel of the view."""
    _last: Hashable = None  # the key measured last

    @staticmethod
    def _learn(old: float | None, new: float) -> float:
        """A rising cost is taken at once (a slow frame is late), a falling one a step at a time."""
        return new if old is None or new > old else COST_MEMORY * old + (1.0 - COST_MEMORY) * new

    def band(self, key: Hashable, weight: float, ms: float) -> None:
        """A band of ``weight`` weighted pixels took ``ms``."""
        if weight > 0:
            self.fits.setdefault(key, CostFit()).add(weight, ms)
            self._last = key

    def line(self, key: Hashable) -> tuple[float, float] | None:
        """(fixed ms, ms per weighted pixel) of a band for ``key``; a key not measured yet:
        twice the cost of the one measured last, None before any band."""
        fit = self.fits.get(key)
        if fit is not None:
            return fit.line()
        if not self.fits:
            return None
        fixed, per_px = self.fits[self._last].line()
        return 2.0 * fixed, 2.0 * per_px

    def most(self, key: Hashable) -> float:
        """The most weight a band for ``key`` may have: ``GROWTH`` times its largest band
        measured, ``PROBE_PIXELS`` before any."""
        fit = self.fits.get(key)
        return PROBE_PIXELS if fit is None else max(GROWTH * fit.most, PROBE_PIXELS)

    def end(self, pixels: int, ms: float) -> None:
        self.end_ms_per_px = self._learn(self.end_ms_per_px, ms / max(pixels, 1))


@dataclass
class _Pass:
    """The pass being shaded in bands."""

    key: tuple
    """What it is shaded for: size, slots, BRDFs, estimator, pass index (its random numbers)."""
    row: int = 0
    """The next row to shade (GL's rows, bottom up)."""


class PassBands:
    """The still view's passes in bands (module docstring): ``advance`` shades the next
    band of the pass in progress within a budget and says when the pass is complete."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.cost = BandCost()
        self._pass: _Pass | None = None
        self._coverage: tuple[tuple, np.ndarray] | None = None  # (size and slot, pixels per row)
        self.ms = 0.0
        """The last ``advance``'s milliseconds (GPU work waited for)."""
        self.bake_ms_per_node: float | None = None
        """The body environment map's bake, milliseconds per node baked (None: not measured; a
        rising cost taken at once, a falling one a step at a time)."""
        self._bake_rows: tuple[tuple, np.ndarray] | None = None  # (map key, nodes baked per row)
        self._baking = False  # the last advance baked the map

    def reset(self) -> None:
        """Drops the pass in progress (the accumulation was started over or shaded whole)."""
        self._pass, self._coverage, self._baking = None, None, False

    @property
    def in_progress(self) -> bool:
        """Whether a pass has bands shaded but is not complete, or its body environment map is baking."""
        return self._baking or (self._pass is not None and self._pass.row > 0)

    @staticmethod
    def weights(coverage: np.ndarray, w: int) -> np.ndarray:
        """The weighted pixels of each row: on the object 1, off it ``OFF_OBJECT_WEIGHT``."""
        c = coverage.astype(np.float64)
        return c + OFF_OBJECT_WEIGHT * (w - c)

    def _timed(self, work: Callable[[], object]) -> float:
        """Runs ``work`` and waits for the GPU; its milliseconds."""
        t0 = time.perf_counter()
        work()
        self.ctx.finish()
        return (time.perf_counter() - t0) * 1000.0

    def advance(self, renderer: Renderer, state: ViewState, w: int, h: int, index: int,
                shaded: Sequence[Shaded], budget_ms: float, cost_key: Hashable,
                end_extra_ms: float = 0.0) -> bool:
        """Shades the next band of pass ``index`` of the accumulations ``shaded`` ((slot, BRDF) or
        (slot, BRDF, estimator: the renderer's sampling for that one, e.g. a reference's coat
        alone) each, one band of each) at (w, h), as many rows as ``budget_ms`` allows by the measured
        costs (at least one); ends the pass when its last row is in (``end_extra_ms``: what else
        the frame then costs, the new image's composite). Returns whether the pass is complete
        (each slot's accumulation then holds it)."""
        self.ctx.finish()  # the frame's earlier GL work is not this band's
        t0 = time.perf_counter()
        self._baking = self._bake(renderer, state, shaded, budget_ms)
        if self._baking:
            self.ms = (time.perf_counter() - t0) * 1000.0
            return False
        entries = [(e[0], e[1], e[2] if len(e) > 2 else None) for e in shaded]
        key = (w, h, tuple((s, id(b)) for s, b, _ in entries), cost_key, index)
        p = self._pass
        spent = 0.0
        if p is None or p.key != key:
            p = self._pass = _Pass(key)
            ms = self._timed(lambda: [_with(renderer, sm, lambda: renderer.begin_pass(state, w, h, index, b, s))
                                      for s, b, sm in entries])
            if index == 0 or self._coverage is None or self._coverage[0] != (w, h, shaded[0][0]):
                t1 = time.perf_counter()
                self._coverage = ((w, h, shaded[0][0]), renderer.row_coverage(w, h, shaded[0][0]))
                ms += (time.perf_counter() - t1) * 1000.0
            spent += ms  # measured: the band gets the rest of the budget
        weights = self.weights(self._coverage[1], w) * len(shaded)
        end_px = self.cost.end_ms_per_px
        end_ms = (end_px if end_px is not None else 0.0) * w * h
        y1 = self._rows(p.row, weights, self.cost.line(cost_key), budget_ms - spent, end_ms + end_extra_ms,
                        self.cost.most(cost_key))
        ms = self._timed(lambda: [_with(renderer, sm, lambda: renderer.shade_rows(state, w, h, index, (p.row, y1), b, s))
                                  for s, b, sm in entries])
        self.cost.band(cost_key, float(weights[p.row:y1].sum()), ms)
        p.row = y1
        done = y1 >= h
        if done:
            ms = self._timed(lambda: [renderer.end_pass(state, w, h, index, s) for s, _, _ in entries])
            self.cost.end(w * h, ms)
            self._pass = None
        self.ms = (time.perf_counter() - t0) * 1000.0
        return done

    def _bake(self, renderer: Renderer, state: ViewState, shaded: Sequence[Shaded],
              budget_ms: float) -> bool:
        """Bakes rows of the body environment map (viewer/gpu/env_prefilter.py) within
        ``budget_ms`` while a shaded BRDF reads one that is not complete; True when this frame
        went to it (the pass waits for the map)."""
        lit = renderer.lit
        # a mix: each component's map; an entry with its own estimator (a reference's coat alone) reads none
        for b in (c for e in shaded if len(e) < 3 or e[2] is None for c in e[1].components()):
            key = lit.prefilter_key(state, b, renderer.env)
            before = lit.prefilter_rows(key)
            size = lit.prefilter().size if key is not None else 0
            if before is None or before >= size:
                continue
            if self._bake_rows is None or self._bake_rows[0] != key:
                self._bake_rows = (key, baked_per_row(state, size, lit.sphere_radius or 1.0))
            nodes = np.cumsum(self._bake_rows[1][before:])
            per_node = self.bake_ms_per_node
            rows = (int(np.searchsorted(nodes, PROBE_NODES, side="right")) if per_node is None
                    else int(np.searchsorted(nodes, budget_ms / per_node, side="right")))
            t0 = time.perf_counter()
            lit.bake_prefilter(state, b, renderer.env, max(rows, 1))
            done = int(nodes[min(lit.prefilter_rows(key) - before, len(nodes)) - 1])
            ms = (time.perf_counter() - t0) * 1000.0  # bake_rows waited for the GPU
            if done > 0:
                self.bake_ms_per_node = BandCost._learn(per_node, ms / done)
            return True
        return False

    @staticmethod
    def _rows(row: int, weights: np.ndarray, line: tuple[float, float] | None, budget_ms: float,
              end_ms: float, most: float = np.inf) -> int:
        """The end of the band from ``row``: the rows whose predicted time (``line``: fixed ms,
        ms per weighted pixel) fits ``budget_ms`` (the pass's end, ``end_ms``, included when the
        band reaches it) and whose weight is at most ``most``; ``PROBE_PIXELS`` of weight when
        the cost is unknown (None); at least one row; a band of ``LIT_GROUP`` rows or more ends
        on a work group's edge."""
        h = len(weights)
        cum = np.cumsum(weights[row:])
        if line is None:
            n = int(np.searchsorted(cum, PROBE_PIXELS, side="right")) + 1
        else:
            fixed, per_px = line
            n = int(np.searchsorted(cum, min(max(budget_ms - fixed, 0.0) / per_px, most), side="right"))
            if n >= len(cum) and fixed + cum[-1] * per_px + end_ms > budget_ms:
                n = len(cum) - 1  # the rest fits but not with the merge: the last row next frame
        end = row + max(n, 1)
        if end < h and n >= LIT_GROUP:  # whole work groups, unless the band is thinner than one
            end -= end % LIT_GROUP
        return min(end, h)


def _with(renderer: Renderer, sampling: LitSampling | None, work: Callable[[], object]) -> None:
    """``work`` with the renderer's estimator set to ``sampling`` (None: as it is)."""
    if sampling is None:
        work()
        return
    old = renderer.sampling
    renderer.sampling = sampling
    try:
        work()
    finally:
        renderer.sampling = old


__all__ = ["BandCost", "CostFit", "PassBands", "PROBE_PIXELS"]
