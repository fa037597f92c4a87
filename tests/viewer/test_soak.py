"""A short soak of the window (tools/soak.py; `make soak` runs 1,000 edits):
25 random edits played twice, sampled in one state every 5 edits. The second
pass replays what the first did with every cache already full, so anything it
adds is a leak: it leaves no GL object behind (the same live objects of every
kind after each pass, and never more in one state than the first pass had),
its heap in use does not grow, and no edit fails."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.gl, pytest.mark.slow]

SOAK = Path(__file__).resolve().parents[2] / "tools" / "soak.py"
#: Heap in use a replayed pass of 25 edits may add (MB): 160 KB per edit. The window's own
#: fluctuation between two visits of one state is under 1 MB (make soak: 197-206 MB over 800
#: edits); a latent texture, a reference image or a set of render targets kept per edit is more.
HEAP_GROWTH_MB = 4.0


def test_fifty_edits_leave_no_gl_objects_and_no_memory_behind(xvfb_display, tmp_path):
    env = dict(os.environ, DISPLAY=xvfb_display, NBRDF_STATE_DIR=str(tmp_path / "state"))
    r = subprocess.run([sys.executable, str(SOAK), "--edits", "25", "--repeat", "2", "--every", "5", "--warmup", "0",
                        "--in-state", "--seed", "3", "--out", str(tmp_path / "soak.json")], env=env,
                       capture_output=True, text=True, timeout=900, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads((tmp_path / "soak.json").read_text())
    assert res["failures"] == [] and sum(res["kinds"].values()) == 50  # 2 x 25
    assert len(res["kinds"]) == 5  # every kind of edit ran: param, view, preset, compare, mesh
    # the second pass of the same 25 edits, ending in the same state, leaves the same live GL objects of
    # every kind as the first (its caches are full): nothing leaks per edit
    first, second = res["passes"][1:]
    assert second["gl"] == first["gl"]
    states = res["in_state"]
    gl = {p: max(sum(s["gl"].values()) for s in states if (s["edit"] > 25) == p) for p in (False, True)}
    assert gl[True] <= gl[False], gl
    # the heap in use in that state at the end of each pass (the least of the last samples: a frame's
    # transient buffers are not growth)
    ends = {False: (20, 25), True: (45, 50)}
    used = {p: min([s["malloc_mb"]["used"] for s in states if s["edit"] in ends[p]]
                   + [(second if p else first)["malloc_mb"]["used"]]) for p in (False, True)}
    assert used[True] - used[False] < HEAP_GROWTH_MB, used
