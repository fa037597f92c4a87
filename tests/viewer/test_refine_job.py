"""Refinement on idle in the previewer (viewer/jobs/refine_job.py): the window's
side against a scripted worker (no process, no GL), then through LookDev's
API with the real worker process: the swap, the cancel, the cached code."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from idle_jobs import Clock, FakeWorker

from nbrdf.neural.material import load_material
from nbrdf.training.refine import RefineConfig
from nbrdf.viewer.jobs.refine_job import IdleRefiner, IdleRefineSettings, RefineResult, RefineSpec, job_key

LOOKDEV = Path(__file__).resolve().parents[2] / "training" / "sets" / "lookdev"
BLACK = LOOKDEV / "car-paint-black.json"


class FakeDecoder:
    def weights_id(self) -> str:
        return "f" * 40


@pytest.fixture
def setup(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    w, clock = FakeWorker(), Clock()
    r = IdleRefiner(lambda: w, FakeDecoder, IdleRefineSettings(enabled=True, still_seconds=0.5), clock)
    return r, w, clock


def result(code, heldout, network=1.0, done=False, seconds=3.2):
    return RefineResult(code, heldout, network, seconds, 1, done)


def test_waits_for_a_still_moment_then_swaps_a_better_code_in(setup):
    r, w, clock = setup
    m = load_material(BLACK)
    z = torch.zeros(3, 34)
    assert r.edited(m, z) is None  # nothing cached
    assert r.poll() is None and not w.requests  # not still long enough
    clock.t = 0.6
    assert r.poll() is None
    (job,) = w.requests
    assert isinstance(job, RefineSpec) and job.code.shape == (3, 34) and job.config.budget == 10.0
    assert r.status == "refining..."
    better = np.full((3, 34), 0.5, np.float32)
    w.results[job.key] = result(better, 0.4)
    got = r.poll()
    assert got is not None and np.array_equal(got.numpy(), better)
    assert r.status == "refined, 3 s, refining..."  # later rounds still run
    assert r.poll() is None  # the same result is not swapped twice
    w.results[job.key] = result(better * 2, 0.6, done=True)  # worse than what is shown: kept
    assert r.poll() is None and r.status == "refined, 3 s"


def test_later_rounds_swap_only_a_clearly_better_code_until_the_end(setup):
    """Each swap starts the still view's accumulation anew (faded, record 103): while
    rounds run, a code replaces the refined one shown only when its held-out error is at
    most ``reswap_ratio`` of the shown one's; the best code is shown when the work ends."""
    r, w, clock = setup
    assert r.settings.reswap_ratio == 0.7
    r.edited(load_material(BLACK), torch.zeros(3, 34))
    clock.t = 1.0
    r.poll()
    key = w.requests[0].key
    codes = [np.full((3, 34), k, np.float32) for k in range(5)]
    w.results[key] = result(codes[1], 0.5)  # the first beats the network's: shown at once
    assert np.array_equal(r.poll().numpy(), codes[1])
    w.results[key] = result(codes[2], 0.4, seconds=5.0)  # 0.8 of the shown error: kept back
    assert r.poll() is None and r.status == "refined, 3 s, refining..."
    w.results[key] = result(codes[3], 0.34, seconds=6.0)  # 0.68: shown
    assert np.array_equal(r.poll().numpy(), codes[3]) and r.status == "refined, 6 s, refining..."
    w.results[key] = result(codes[4], 0.33, seconds=9.6, done=True)  # the end: the best code, however close
    assert np.array_equal(r.poll().numpy(), codes[4]) and r.status == "refined, 10 s"
    assert r.poll() is None


def test_a_result_worse_than_the_network_is_never_shown(setup):
    r, w, clock = setup
    r.edited(load_material(BLACK), torch.zeros(3, 34))
    clock.t = 1.0
    r.poll()
    w.results[w.requests[0].key] = result(np.ones((3, 34), np.float32), 1.2, network=1.0, done=True)
    assert r.poll() is None and r.status == ""


def test_an_edit_cancels_at_once_and_a_stale_result_is_ignored(setup):
    r, w, clock = setup
    m = load_material(BLACK)
    r.edited(m, torch.zeros(3, 34))
    clock.t = 1.0
    r.poll()
    old = w.requests[0].key
    edited = load_material(LOOKDEV / "coated-gold.json")
    assert r.edited(edited, torch.zeros(3, 34)) is None
    assert w.cancels == 1 and w.current is None and r.status == ""
    w.results[old] = result(np.ones((3, 34), np.float32), 0.1)  # the cancelled job's round arrives late
    assert r.poll() is None
    clock.t = 1.2  # still not a still moment after the edit
    assert r.poll() is None and len(w.requests) == 1


def test_the_compare_views_reference_goes_first(setup):
    r, w, clock = setup
    r.edited(load_material(BLACK), torch.zeros(3, 34))
    w.current = "some reference"
    clock.t = 5.0
    r.poll()
    assert not w.requests


def test_untextured_uniform_materials_only(setup, tmp_path):
    r, w, clock = setup
    assert r.edited(None, None) is None  # a blend, a texture-mapped material
    clock.t = 5.0
    assert r.poll() is None and not w.requests


def test_the_environment_switch_turns_it_off(monkeypatch, tmp_path):
    monkeypatch.setenv("NBRDF_IDLE_REFINE", "0")
    w, clock = FakeWorker(), Clock()
    r = IdleRefiner(lambda: w, FakeDecoder, IdleRefineSettings(still_seconds=0.0), clock)
    assert r.edited(load_material(BLACK), torch.zeros(3, 34)) is None
    clock.t = 5.0
    assert r.poll() is None and not w.requests
    monkeypatch.setenv("NBRDF_IDLE_REFINE", "1")
    assert IdleRefineSettings().enabled


# --- through LookDev and the real worker process -------------------------------------------
TINY = RefineConfig(budget=600.0, round_pairs=256, heldout_pairs=256, spp=32, steps=40, max_rounds=1)


def _lookdev(gl_ctx, monkeypatch, tmp_path, config=TINY):
    from nbrdf.viewer.session.lookdev import LookDev

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))  # before the worker process starts
    ld = LookDev(gl_ctx, load_material(BLACK))
    ld.idle_refine.settings = IdleRefineSettings(enabled=True, still_seconds=0.0, config=config)
    ld.set_param(0, "roughness", ld.material.layers[0].roughness)  # an edit under these settings (the first
    # was made before them)
    return ld


def _poll_until(ld, cond, timeout=600.0):
    import time

    end = time.monotonic() + timeout  # a guard against a hang, not a timing assertion
    while time.monotonic() < end and not cond():
        ld.update()
        time.sleep(0.05)
    return cond()


@pytest.mark.gl
@pytest.mark.slow
def test_lookdev_swaps_the_refined_code_in_and_reopening_shows_it_at_once(gl_ctx, monkeypatch, tmp_path):
    """car paint black: the network's code is far from its simulation
    (held-out error about 15 times the refined one), so one round beats it."""
    ld = _lookdev(gl_ctx, monkeypatch, tmp_path)
    try:
        network = ld.latent().clone()
        assert torch.equal(ld.brdf.latent, network)
        assert _poll_until(ld, lambda: ld.idle_refine.status.startswith("refined, "))
        shown = ld.brdf.latent
        assert not torch.equal(shown, network)
        assert torch.equal(shown[:, -2:], network[:, -2:])  # the coat stays exact
        assert ld.passes == 0  # the accumulation restarted with the refined code
        r = ld.worker.result(job_key(ld.material, ld.model.decoder.weights_id()))
        assert r.done and r.heldout < r.network_error
        assert list((tmp_path / "cache" / "nbrdf" / "refined").glob("*.json"))
        # Opening the material again: the cached code at once, no job.
        ld.open_material(BLACK)
        assert torch.equal(ld.brdf.latent, shown) and ld.idle_refine.status.startswith("refined, ")
        assert ld.worker.current is None
    finally:
        ld.close()


@pytest.mark.gl
@pytest.mark.slow
def test_an_edit_cancels_the_refinement_in_the_worker(gl_ctx, monkeypatch, tmp_path):
    from nbrdf.viewer.reference.worker import ReferenceJob

    long = RefineConfig(budget=600.0, round_pairs=256, heldout_pairs=256, spp=32, steps=4000, max_rounds=24,
                        patience=24)
    ld = _lookdev(gl_ctx, monkeypatch, tmp_path, long)
    try:
        ld.update()
        key = ld.worker.current
        assert key is not None and key.startswith("refine:")
        network = ld.latent().clone()
        assert ld.set_param(0, "roughness", 0.2)  # an edit
        assert ld.worker.current is None  # cancelled at once on the window's side
        assert ld.idle_refine.status == ""
        assert torch.equal(ld.brdf.latent, ld.latent()) and not torch.equal(ld.latent(), network)
        # The worker moved on: a small reference job finishes while the refinement stays unfinished.
        ld.idle_refine.settings = IdleRefineSettings(enabled=False)
        ld.set_param(0, "roughness", 0.25)
        wi = torch.tensor([[0.0, 0.0, 1.0]]).expand(4, 3).contiguous()
        ld.worker.request(ReferenceJob("probe", ld.material, wi, wi, torch.ones(4, 1), np.ones((2, 2), bool), 8))
        assert ld.worker.wait("probe", 8, timeout=600.0).done
        r = ld.worker.result(key)
        assert r is None or not r.done
    finally:
        ld.close()
