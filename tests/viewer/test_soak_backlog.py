"""tools/soak.py names the Monte Carlo requests piled up in the window while the reference worker is busy
(docs/decisions/108): counted with their arrays' bytes, and nothing when the queue is empty."""
from __future__ import annotations

import collections
import importlib.util
from pathlib import Path
from types import SimpleNamespace

import numpy as np

SOAK = Path(__file__).resolve().parents[2] / "tools" / "soak.py"


def load_soak():
    spec = importlib.util.spec_from_file_location("soak_tool", SOAK)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_request_backlog_counts_queued_jobs_and_their_arrays():
    soak = load_soak()
    jobs = [SimpleNamespace(key=f"k{i}", mask=np.zeros((64, 96), bool), wi=np.zeros((100, 3))) for i in range(3)]
    worker = SimpleNamespace(_requests=SimpleNamespace(_buffer=collections.deque(jobs)), _cache={"a": 1})
    out = soak.request_backlog(worker)
    assert out["requests"] == 3 and out["references_cached"] == 1
    assert abs(out["mb"] - 3 * (64 * 96 + 100 * 3 * 8) / 2**20) < 1e-9


def test_request_backlog_of_a_worker_never_started():
    soak = load_soak()
    assert soak.request_backlog(SimpleNamespace(_cache={})) == {"requests": 0, "mb": 0.0, "references_cached": 0}
