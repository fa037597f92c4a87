"""Undo / redo over session snapshots (viewer/session/history.py), without GL."""
from __future__ import annotations

import pytest

from nbrdf.viewer.session.history import History


def snap(v: float) -> dict:
    return {"material": {"layers": [{"roughness": v}]}}


def test_undo_redo_walk_back_and_forth_and_a_new_edit_drops_the_redo():
    h = History()
    h.reset(snap(0.0))
    for v in (0.1, 0.2, 0.3):
        assert h.commit(snap(v))
    assert h.undo() == snap(0.2) and h.undo() == snap(0.1)
    assert h.redo() == snap(0.2)
    assert h.commit(snap(0.9)) and not h.can_redo and h.redo() is None
    assert h.undo() == snap(0.2)


def test_an_unchanged_snapshot_is_no_step():
    h = History()
    h.reset(snap(0.5))
    assert not h.commit(snap(0.5)) and not h.can_undo


def test_a_drag_in_one_group_is_one_step_and_two_drags_are_two():
    h = History()
    h.reset(snap(0.0))
    for v in (0.1, 0.2, 0.3):
        h.commit(snap(v), group="roughness")
    h.close_group()
    for v in (0.4, 0.5):
        h.commit(snap(v), group="roughness")
    assert len(h.undo_stack) == 2
    assert h.undo() == snap(0.3) and h.undo() == snap(0.0) and h.undo() is None


def test_at_least_100_steps_are_kept_and_the_oldest_go_first():
    h = History(limit=150)
    h.reset(snap(-1.0))
    for k in range(200):
        h.commit(snap(float(k)))
    back = [h.undo() for _ in range(150)]
    assert back[0] == snap(198.0) and back[-1] == snap(49.0) and h.undo() is None
    with pytest.raises(ValueError):
        History(limit=0)
