"""A still view's kept composite (viewer/jobs/view_frames.py): more passes of the same image
are put on screen at most once per ``COMPOSE_INTERVAL_S`` (a composite costs software OpenGL a
slow frame), anything else that changes what is shown at once, and ``shown_passes`` says which
passes the image on screen holds."""
from __future__ import annotations

from nbrdf.viewer.jobs.view_frames import COMPOSE_AT_ONCE, COMPOSE_INTERVAL_S, MAX_PASSES, ViewFrames


def _frames(copy_key, composed_at: float, passes: int) -> ViewFrames:
    vf = object.__new__(ViewFrames)  # the throttle's state alone: no GL stage needed
    vf._copy_key, vf._composed_at, vf.passes, vf.cap = copy_key, composed_at, passes, MAX_PASSES
    return vf


def _key(passes: int, w: int = 640, held=None, exposure: float = 0.0) -> tuple:
    return ((800, 600), (w, 480, ("main", "other"), passes, held), ("state", exposure), "backdrop")


def test_more_passes_of_the_same_image_wait_for_the_interval():
    vf = _frames(_key(3), composed_at=100.0, passes=5)
    assert vf._more_passes_only(_key(5), 100.0 + 0.5 * COMPOSE_INTERVAL_S)
    assert not vf._more_passes_only(_key(5), 100.0 + 1.01 * COMPOSE_INTERVAL_S)  # old enough: shown
    assert vf.shown_passes == 3  # the image on screen holds the copy's passes, not the accumulation's


def test_anything_else_is_shown_at_once():
    vf = _frames(_key(3), composed_at=100.0, passes=5)
    now = 100.0 + 0.1 * COMPOSE_INTERVAL_S
    assert not vf._more_passes_only(_key(5, w=320), now)  # another image (a new size)
    assert not vf._more_passes_only(_key(5, held=("main_b", 8)), now)  # a handover's fade
    assert not vf._more_passes_only(_key(5, exposure=1.0), now)  # a setting of the frame
    assert not vf._more_passes_only(_key(MAX_PASSES), now)  # the last pass: the accumulation stops
    assert not _frames(None, 0.0, 1)._more_passes_only(_key(1), now)  # nothing kept yet
    assert not _frames(_key(1), 100.0, 2)._more_passes_only(_key(COMPOSE_AT_ONCE), now)  # an image's first passes
    assert _frames(None, 0.0, 4).shown_passes == 4
