"""Calibration on idle in the previewer (viewer/jobs/calibrate_job.py): the window's side against a scripted
worker (no process, no GL), then through LookDev with the real worker process: the walk, the scaled body on
screen, the cached walk when the material comes back."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from idle_jobs import Clock, FakeWorker

from nbrdf.neural.material import load_material, material_to_dict
from nbrdf.training.calibration import WalkAlbedoSettings, finish_walk, start_walk
from nbrdf.training.furnace import furnace_set
from nbrdf.viewer.jobs.calibrate_job import (
    WALKED,
    WALKING,
    CalibrateResult,
    CalibrateSpec,
    IdleCalibrateSettings,
    IdleCalibrator,
    job_key,
)
from nbrdf.viewer.options import DEFAULT_MATERIAL

LOOKDEV = DEFAULT_MATERIAL.parent


def _stack(name="lossless-d2-09"):
    return next(m for _, _, m in furnace_set() if m.name == name)


@pytest.fixture
def setup(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    w, clock, busy = FakeWorker(), Clock(), [False]
    c = IdleCalibrator(lambda: w, lambda: busy[0], IdleCalibrateSettings(enabled=True, still_seconds=0.5), clock)
    return c, w, clock, busy


def test_a_still_material_is_walked_once_the_worker_is_free(setup):
    c, w, clock, busy = setup
    assert c.edited(_stack()) is None and c.walked is None
    clock.t = 0.2
    assert c.poll() is None and not w.requests  # not still yet
    clock.t = 1.0
    busy[0] = True  # the refinement goes first
    assert c.poll() is None and not w.requests
    busy[0] = False
    w.current = "some reference"  # and so does the compare view's reference
    assert c.poll() is None and not w.requests
    w.current = None
    assert c.poll() is None and len(w.requests) == 1 and isinstance(w.requests[0], CalibrateSpec)
    assert c.status == WALKING
    key = w.requests[0].key
    w.results[key] = CalibrateResult(None, None, False)  # a round, not yet done
    assert c.poll() is None
    a, se = np.full((3, 9), 0.5), np.full((3, 9), 0.001)
    w.results[key] = CalibrateResult(a, se, True)
    got = c.poll()
    assert got is not None and np.array_equal(got[0].numpy(), a) and c.walked is got and c.status == WALKED
    assert c.poll() is None  # once


def test_an_edit_cancels_and_what_is_not_calibrated_asks_nothing(setup):
    c, w, clock, busy = setup
    c.edited(_stack())
    clock.t = 1.0
    c.poll()
    old = w.requests[0].key
    c.edited(_stack("lossless-d2-00"))
    assert w.cancels == 1 and w.current is None
    w.results[old] = CalibrateResult(np.ones((3, 9)), np.ones((3, 9)), True)  # the cancelled walk, late
    assert c.poll() is None and c.walked is None
    assert c.edited(None) is None and c.status == ""  # a blend, a texture-mapped material: nothing is walked
    single = load_material(LOOKDEV / "rough_gold.json")
    assert c.edited(single) is None
    clock.t = 9.0
    assert c.poll() is None and len(w.requests) == 1


def test_a_walked_material_comes_back_at_once(setup):
    c, w, clock, busy = setup
    m = _stack()
    walk = start_walk(m, IdleCalibrateSettings().thetas, WalkAlbedoSettings(paths=512, max_paths=1024))
    while not walk.step():
        pass
    # what the worker writes (finish_walk, under the default settings' key) is what edited() finds
    a, se = finish_walk(walk)
    got = c.edited(m)
    assert got is not None and torch.equal(got[0], a) and torch.equal(got[1], se) and c.status == WALKED
    clock.t = 9.0
    assert c.poll() is None and not w.requests


def test_the_worker_side_walks_a_round_per_step(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    m = _stack()
    spec = CalibrateSpec(job_key(m), material_to_dict(m), str(m.base_dir), (0.0, 45.0, 80.0))
    run = spec.start(lambda: False)
    steps = 0
    while True:
        r, paths, done, _ = run.step()
        steps += 1
        if done:
            break
        assert r.albedo is None and not r.done
    assert steps > 1  # rounds, so a newer request can pause it
    assert r.albedo.shape == (3, 3) and float((r.se / r.albedo).max()) < 0.01
    assert json.loads(next((tmp_path / "cache" / "nbrdf" / "albedo").glob("*.json")).read_text())["albedo"]
    assert spec.failed("boom").error == "boom"


# --- through LookDev and the real worker process -------------------------------------------
@pytest.mark.gl
@pytest.mark.slow
def test_lookdev_shows_the_walks_energy_and_reopening_shows_it_at_once(gl_ctx, monkeypatch, tmp_path):
    from nbrdf.viewer.session.lookdev import LookDev

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))  # before the worker process starts
    path = tmp_path / "stack.json"
    path.write_text(json.dumps(material_to_dict(_stack())))
    ld = LookDev(gl_ctx, load_material(path))
    try:
        ld.idle_calibrate.settings = IdleCalibrateSettings(enabled=True, still_seconds=0.0)
        ld.set_param(0, "roughness", ld.material.layers[0].roughness)  # an edit under these settings
        assert ld.brdf.body_scale is None
        import time

        end = time.monotonic() + 600.0  # a guard against a hang, not a timing assertion
        while time.monotonic() < end and ld.brdf.body_scale is None:
            ld.update()
            time.sleep(0.05)
        assert ld.brdf.body_scale is not None and "u_body_scale" in ld.brdf.uniforms
        assert float((ld.brdf.body_scale.g - 1).abs().max()) > 0.03  # the networks were 4-11 % off here
        assert ld.passes == 0  # the accumulation restarted with the calibrated body
        ld.open_material(path)
        ld.update()
        assert ld.idle_calibrate.walked is not None and ld.worker.current is None  # cached: no job
    finally:
        ld.close()


def test_a_failed_walk_says_so_and_keeps_the_networks_energy(setup):
    c, w, clock, busy = setup
    c.edited(_stack())
    clock.t = 1.0
    c.poll()
    w.results[w.requests[0].key] = CalibrateResult(None, None, True, "the walk ran out of memory")
    assert c.poll() is None and c.walked is None
    assert c.status == "energy: the walk failed (the walk ran out of memory); the networks'"
