"""The window's progressive refinement: what resolution and which body a frame uses.

While the view changes (a slider drag, an orbit, any edit that restarts the
accumulation) frames are *interactive*: rendered at a reduced scale that keeps
a frame within ``budget_ms`` (adapted from the measured times of the
interactive frames, never below ``min_scale``), with the quick body (the
baked table on software OpenGL, viewer/gpu/body_source.py) and the quick
estimator (``LitSampling.quick``). As soon as the view is still it *always*
refines, whatever the frame time: the scale doubles each frame up to full
resolution, then passes accumulate at full resolution until the session's cap.
A frame at a new scale is a *preview* (the quick estimator: the sharper image
sooner); the frame after the first full-resolution preview restarts the
accumulation with the full estimator, so the preview's noisier pass is not
averaged into the converging image. A scale change restarts the accumulation,
so passes of two resolutions are never mixed.

A still frame never waits on a whole pass: it has a *budget* for the view's
accumulation work (``FramePlan.budget_ms``), and the view shades a band of the
pass per frame (viewer/jobs/pass_bands.py), so the interface keeps drawing
and reading input at ``still_budget_ms`` per frame at any window size. The
budget is ``still_budget_ms`` less the rest of a still frame (panels, swap,
composite: the median of the last still frames' measured time outside the
accumulation), never under ``min_view_ms``. Once no input has come for
``idle_after_s`` (hands off, watching the sphere), the budget rises to
``idle_budget_ms``: most of each frame goes to the view, which converges about
twice as fast on two cores, and the first event after it brings the short
budget back on the next frame. A pass shaded in bands is complete
only after several frames: the scale doubles, and the preview gives way to the
full estimator, only once the accumulation has a complete pass.

The policy sees no clock: the window tells it whether the view changed and how
long each frame took, so tests drive it with made-up frame times.
"""
from __future__ import annotations

import statistics
from collections import deque
from dataclasses import dataclass, field


@dataclass
class RefinementSettings:
    """The refinement policy's knobs."""

    adaptive: bool = True
    """False: every frame at full resolution with the still view's body (tests that compare pixels)."""
    budget_ms: float = 100.0
    """An interactive frame's target duration (edit to frame on screen)."""
    scales: tuple[float, ...] = (0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0)
    """The scales an interactive frame may use (fractions of the view's width and height), ascending."""
    start_scale: float = 0.5
    """The interactive scale before any frame time is known."""
    min_scale: float = 0.5
    """Interactive frames never go below this scale: half the view's width is the least
    that reads as the material (a useful image beats the budget on slow machines)."""
    raise_below: float = 0.5
    """An interactive frame shorter than this fraction of the budget raises the interactive scale a step."""
    banded: bool = True
    """Still frames shade their passes in bands within a budget (False: a whole pass per frame)."""
    still_budget_ms: float = 40.0
    """A still frame's target duration: the interface at 25 fps while the view accumulates
    (the frame-to-frame goal is 50 ms; the rest is the margin of a band's predicted cost)."""
    min_view_ms: float = 20.0
    """The least accumulation work a still frame gets, however slow the rest of the frame:
    the view converges at a useful rate on any machine."""
    overhead_frames: int = 9
    """Still frames whose time outside the accumulation (median) is the budget's overhead."""
    idle_after_s: float = 1.0
    """Seconds without any input (key, click, pointer move, scroll) after which still frames get ``idle_budget_ms``."""
    idle_budget_ms: float = 400.0
    """A still frame's target duration once the interface is idle: the view converges faster, and the first
    event after the idle spell waits at most about this long (0: never raised)."""


@dataclass(frozen=True)
class FramePlan:
    """What the next frame renders."""

    scale: float
    """The render scale (fraction of the view's width and height)."""
    interactive: bool
    """True: the view is changing (quick body, reduced scale); False: refining a still view."""
    quick: bool = False
    """The quick estimator: interactive frames and previews at a new scale."""
    restart: bool = False
    """Restart the accumulation before this frame (a new scale, or the end of a preview)."""
    budget_ms: float | None = None
    """The accumulation work this frame may take (a band of a pass, still frames); None: whole passes."""


@dataclass
class Refinement:
    """Decides each frame's scale and kind (module docstring). Call ``plan``
    before a frame and ``done`` with its duration after it."""

    settings: RefinementSettings = field(default_factory=RefinementSettings)
    interactive_scale: float = -1.0
    """The scale of interactive frames, adapted to the budget (-1: ``settings.start_scale``)."""
    scale: float = 1.0
    """The scale of the frame planned last."""
    interactive: bool = False
    """Whether the frame planned last was interactive."""
    quick: bool = False
    """Whether the frame planned last used the quick estimator."""

    overheads: deque[float] = field(default_factory=deque)
    """The last still frames' milliseconds outside the accumulation (``done``)."""

    def __post_init__(self) -> None:
        if self.interactive_scale < 0:
            self.interactive_scale = self.settings.start_scale
        self.overheads = deque(self.overheads, maxlen=self.settings.overhead_frames)

    @property
    def still_budget(self) -> float:
        """A still frame's accumulation budget: ``still_budget_ms`` less the measured rest of the
        frame (``min_view_ms`` until a still frame was measured), never under ``min_view_ms``."""
        s = self.settings
        if not self.overheads:
            return s.min_view_ms
        return max(s.min_view_ms, s.still_budget_ms - statistics.median(self.overheads))

    def plan(self, changed: bool, complete: bool = True, idle_s: float = 0.0) -> FramePlan:
        """The next frame: ``changed`` says the view changed since the last frame
        (its accumulation was restarted by an edit, a camera move, ...); ``complete``
        that the accumulation holds a whole pass (a pass shaded in bands may not yet);
        ``idle_s`` how long the interface has had no input."""
        s = self.settings
        restart = False
        if not s.adaptive:
            scale, self.interactive, quick = 1.0, False, False
        elif changed:  # the accumulation was restarted by the change itself
            scale, self.interactive, quick = self.interactive_scale, True, True
        elif not complete and not self.interactive:  # the still frame's pass is being shaded: on with it
            scale, quick = self.scale, self.quick
        elif self.scale < 1.0:  # still: resolution first, doubling; a preview at each new scale
            scale, self.interactive, quick = min(1.0, self.scale * 2.0), False, True
        else:  # then samples at full resolution, after the preview is dropped
            scale, self.interactive, quick, restart = 1.0, False, False, self.quick
        restart = restart or scale != self.scale
        self.scale, self.quick = scale, quick
        budget = self.still_budget if s.adaptive and s.banded and not self.interactive else None
        if budget is not None and s.idle_budget_ms > 0 and idle_s >= s.idle_after_s:
            overhead = statistics.median(self.overheads) if self.overheads else 0.0
            budget = max(budget, s.idle_budget_ms - overhead)
        return FramePlan(scale, self.interactive, quick, restart, budget)

    def done(self, frame_ms: float, accum_ms: float = 0.0) -> None:
        """The duration of the frame planned last and of its accumulation work; interactive
        frames adapt the interactive scale one step toward the budget (down past it, up well
        under it). Still frames measure the rest of the frame (``still_budget``); the
        refinement itself never waits on time."""
        s = self.settings
        if not frame_ms >= 0 or not s.adaptive:
            return
        if not self.interactive:
            self.overheads.append(max(0.0, frame_ms - max(accum_ms, 0.0)))
            return
        ladder = [x for x in s.scales if x >= s.min_scale] or [s.min_scale]
        i = min(range(len(ladder)), key=lambda k: abs(ladder[k] - self.interactive_scale))
        if frame_ms > s.budget_ms and i > 0:
            self.interactive_scale = ladder[i - 1]
        elif frame_ms < s.raise_below * s.budget_ms and i + 1 < len(ladder):
            self.interactive_scale = ladder[i + 1]


__all__ = ["FramePlan", "Refinement", "RefinementSettings"]
