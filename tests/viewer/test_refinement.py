"""The window's refinement policy (viewer/ui/refinement.py), driven with made-up frame times."""
from __future__ import annotations

import pytest

from nbrdf.viewer.ui.refinement import Refinement, RefinementSettings


def drive(policy: Refinement, changed: list[bool], frame_ms: float) -> list[tuple[float, bool]]:
    """Plans one frame per entry of ``changed``, each taking ``frame_ms``; (scale, interactive) per frame."""
    out = []
    for c in changed:
        plan = policy.plan(changed=c)
        policy.done(frame_ms)
        out.append((plan.scale, plan.interactive))
    return out


def test_still_view_refines_to_full_resolution_whatever_the_frame_time():
    # Frames of 10 s each (far past any budget): an edit, then a still view.
    p = Refinement()
    frames = drive(p, [True] + [False] * 5, frame_ms=10_000.0)
    assert frames[0] == (0.5, True)
    assert frames[1] == (1.0, False)          # resolution first: doubled to full
    assert all(f == (1.0, False) for f in frames[1:])  # then passes accumulate at full resolution


def test_previews_use_the_quick_estimator_and_are_dropped():
    p = Refinement(RefinementSettings(start_scale=0.25, min_scale=0.25))
    plans = []
    for changed in [True, False, False, False, False, False]:
        plans.append(p.plan(changed))
        p.done(5_000.0)
    assert [x.scale for x in plans] == [0.25, 0.5, 1.0, 1.0, 1.0, 1.0]
    assert [x.quick for x in plans] == [True, True, True, False, False, False]
    # A new scale restarts the accumulation (resolutions never mix); so does the first
    # full-estimator frame after the full-resolution preview (the preview is dropped).
    assert [x.restart for x in plans] == [True, True, True, True, False, False]


def test_interactive_scale_adapts_to_the_budget_within_its_bounds():
    p = Refinement(RefinementSettings(budget_ms=100.0, min_scale=0.5))
    # Slow interactive frames never go below min_scale.
    assert [s for s, _ in drive(p, [True] * 6, frame_ms=400.0)] == [0.5] * 6
    # Quick ones raise the scale a step per frame up to full size.
    scales = [s for s, _ in drive(p, [True] * 6, frame_ms=20.0)]
    assert scales == [0.5, 0.625, 0.75, 0.875, 1.0, 1.0]
    # Frames over the budget step back down.
    assert [s for s, _ in drive(p, [True] * 2, frame_ms=150.0)] == [1.0, 0.875]
    # Frames between half the budget and the budget keep the scale.
    assert [s for s, _ in drive(p, [True] * 3, frame_ms=80.0)] == [0.75, 0.75, 0.75]


def test_a_lower_interactive_scale_refines_by_doubling():
    p = Refinement(RefinementSettings(start_scale=0.25, min_scale=0.25))
    frames = drive(p, [True, False, False, False], frame_ms=1_000.0)
    assert [s for s, _ in frames] == [0.25, 0.5, 1.0, 1.0]
    assert [i for _, i in frames] == [True, False, False, False]


def test_still_frame_times_change_nothing():
    p = Refinement()
    drive(p, [True], frame_ms=60.0)  # under the budget, above raise_below: kept
    before = p.interactive_scale
    drive(p, [False] * 4, frame_ms=1.0)  # still frames, however quick
    assert p.interactive_scale == before


def test_not_adaptive_is_always_full_resolution_and_still():
    p = Refinement(RefinementSettings(adaptive=False))
    assert drive(p, [True, False, True], frame_ms=5_000.0) == [(1.0, False)] * 3


def test_a_pass_in_bands_completes_before_the_scale_doubles_or_the_preview_is_dropped():
    """A still frame's pass may take several frames (viewer/jobs/pass_bands.py): the preview
    at a new scale is shown complete before the next scale, or the full estimator, restarts it."""
    p = Refinement(RefinementSettings(start_scale=0.5))
    plans = [p.plan(True)]
    for complete in [True, False, False, True, False, True]:
        plans.append(p.plan(False, complete=complete))
    assert [x.scale for x in plans] == [0.5, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]
    assert [x.quick for x in plans] == [True, True, True, True, False, False, False]
    assert [x.restart for x in plans] == [True, True, False, False, True, False, False]


def test_still_frames_get_the_budget_the_rest_of_the_frame_leaves():
    p = Refinement(RefinementSettings(still_budget_ms=40.0, min_view_ms=20.0))
    assert p.plan(True).budget_ms is None  # interactive frames: whole passes at a reduced scale
    p.done(100.0)
    assert p.plan(False).budget_ms == 20.0  # no still frame measured yet: the floor
    for _ in range(5):
        p.done(45.0, 30.0)  # 15 ms of panels, swap and composite beside 30 ms of accumulation
        plan = p.plan(False)
    assert plan.budget_ms == pytest.approx(25.0)
    for _ in range(9):
        p.done(300.0, 20.0)  # a slow rest of the frame: the view still gets its floor
    assert p.plan(False).budget_ms == 20.0
    assert Refinement(RefinementSettings(banded=False)).plan(False).budget_ms is None
    assert Refinement(RefinementSettings(adaptive=False)).plan(False).budget_ms is None


def test_an_idle_interface_gives_the_view_most_of_the_frame_and_input_takes_it_back():
    """Hands off for ``idle_after_s``, a still frame's budget rises to ``idle_budget_ms`` less the measured rest
    of the frame; any input (idle 0) brings the short budget back at once; interactive frames have none."""
    r = Refinement(RefinementSettings(still_budget_ms=40.0, min_view_ms=20.0, idle_after_s=1.0, idle_budget_ms=150.0))
    r.plan(changed=False)
    for _ in range(9):
        r.done(50.0, accum_ms=25.0)  # 25 ms of panels and swap per still frame
    short = r.plan(changed=False, idle_s=0.2).budget_ms
    idle = r.plan(changed=False, idle_s=1.5).budget_ms
    back = r.plan(changed=False, idle_s=0.0).budget_ms
    assert short == pytest.approx(20.0) and idle == pytest.approx(125.0) and back == pytest.approx(20.0)
    assert r.plan(changed=True, idle_s=5.0).budget_ms is None
    off = Refinement(RefinementSettings(idle_budget_ms=0.0))
    assert off.plan(changed=False, idle_s=10.0).budget_ms == off.still_budget
