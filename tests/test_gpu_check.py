"""tools/gpu_check.sh: one JSON whatever happens. Its dry run on this machine (no GPU): the CUDA steps fail
soft with a one-line reason, the others still run, and a spent budget skips steps instead of overrunning."""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "tools" / "gpu_check.sh"
STEPS = ["setup", "offscreen_1080p", "window_1080p", "bench_render", "mitsuba_cuda", "walk_cuda"]


def gpu_check(tmp_path: Path, *args: str, timeout: float = 300, **env: str) -> dict:
    out = tmp_path / "gpu_check.json"
    e = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "GPU_CHECK_MI_VARIANT", "GPU_CHECK_WALK_DEVICE")}
    r = subprocess.run(["bash", str(SCRIPT), "--dry-run", *args, str(out)], env={**e, **env}, cwd=tmp_path,
                       capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(out.read_text())


def check_shape(res: dict) -> None:
    """The keys every run writes, and one line of reason for every step that did not run or failed."""
    assert res["tool"] == "tools/gpu_check.sh" and res["schema"] == 1 and res["dry_run"] is True
    assert {"started_utc", "seconds", "budget_s", "commit", "host", "device", "summary"} <= set(res)
    assert res["device"]["name"] or res["device"]["reason"]
    assert list(res["steps"]) == STEPS
    for name, step in res["steps"].items():
        assert step["status"] in ("ok", "failed", "skipped"), name
        assert isinstance(step["seconds"], float)
        if step["status"] != "ok":
            assert step["reason"] and "\n" not in step["reason"] and len(step["reason"]) <= 300, (name, step)
    assert res["summary"] == {s: sum(v["status"] == s for v in res["steps"].values())
                              for s in ("ok", "failed", "skipped")}


def test_syntax():
    assert subprocess.run(["bash", "-n", str(SCRIPT)], capture_output=True).returncode == 0


def test_cuda_walk_step_fails_soft_without_a_device(tmp_path):
    res = gpu_check(tmp_path, "--only", "walk_cuda", timeout=120)
    check_shape(res)
    steps = res["steps"]
    assert steps["setup"]["status"] == "ok" and steps["setup"]["figures"]["nbrdf_importable"] is True
    assert {steps[s]["status"] for s in ("offscreen_1080p", "bench_render", "mitsuba_cuda")} == {"skipped"}
    assert "not in --only" in steps["bench_render"]["reason"]
    walk = steps["walk_cuda"]
    if steps["setup"]["figures"]["torch_cuda_device"] is None:  # this machine: no GPU
        assert walk["status"] == "failed" and "CUDA" in walk["reason"] and walk["figures"]["device"] == "cuda"
    else:
        assert walk["status"] == "ok" and walk["figures"]["bench_reference"]["machine"]["walk"] == "numba-cuda"


def test_a_spent_budget_skips_steps_and_still_writes_the_json(tmp_path):
    res = gpu_check(tmp_path, timeout=120, GPU_CHECK_BUDGET_S="10")
    check_shape(res)
    assert all(res["steps"][s]["status"] == "skipped" for s in STEPS[1:])
    assert "budget is spent" in res["steps"]["bench_render"]["reason"]


@pytest.mark.gl
@pytest.mark.slow
def test_dry_run_renders_and_fails_the_cuda_steps_soft(tmp_path):
    """The whole dry run (about 2 min on 2 loaded cores): the offscreen frame is the per-pixel decoder on
    the compute path, the bench's JSON is kept, the Mitsuba CUDA variant fails soft here."""
    res = gpu_check(tmp_path, timeout=480)
    check_shape(res)
    steps = res["steps"]
    off = steps["offscreen_1080p"]
    assert off["status"] == "ok", off
    assert off["figures"]["compute_path"] is True and off["figures"]["body"] == "decoder per pixel"
    assert off["figures"]["finite_and_lit"] is True and off["figures"]["ms_per_pass"] > 0
    assert steps["window_1080p"]["status"] == "skipped" and "DISPLAY" in steps["window_1080p"]["reason"]
    assert steps["bench_render"]["status"] == "ok" and steps["bench_render"]["figures"]["size"] == "64x36"
    if steps["setup"]["figures"]["torch_cuda_device"] is None:
        assert steps["mitsuba_cuda"]["status"] == "failed" and "cuda_ad_rgb" in steps["mitsuba_cuda"]["reason"]
    assert res["seconds"] < res["budget_s"]
