"""A short soak of the window (tools/soak.py; `make soak` runs 1,000 edits):
25 random edits played twice: the second pass leaves no GL object behind
(the same state after each pass holds the same live objects of every kind)
and no edit fails."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.gl, pytest.mark.slow]

SOAK = Path(__file__).resolve().parents[2] / "tools" / "soak.py"


def test_fifty_edits_leave_no_gl_objects_behind(xvfb_display, tmp_path):
    env = dict(os.environ, DISPLAY=xvfb_display, NBRDF_STATE_DIR=str(tmp_path / "state"))
    r = subprocess.run([sys.executable, str(SOAK), "--edits", "25", "--repeat", "2", "--every", "5", "--warmup", "0",
                        "--seed", "3", "--out", str(tmp_path / "soak.json")], env=env, capture_output=True,
                       text=True, timeout=900, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads((tmp_path / "soak.json").read_text())
    assert res["failures"] == [] and sum(res["kinds"].values()) == 50  # 2 x 25
    assert len(res["kinds"]) == 5  # every kind of edit ran: param, view, preset, compare, mesh
    # the second pass of the same 25 edits, ending in the same state, leaves the same live GL objects of
    # every kind as the first (its caches are full): nothing leaks per edit
    first, second = res["passes"][1:]
    assert second["gl"] == first["gl"]
