"""The compare mode's ground truth: the worker's pooling and the geometry of
its slice and lit-object jobs against the GPU views."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from gpu_brdfs import closed_form

from nbrdf.neural.material import load_material, parse_material
from nbrdf.neural.model import default_model
from nbrdf.training.reference import reference_eval, single_layer_eval
from nbrdf.viewer.gpu.pipeline import gpu_brdf
from nbrdf.viewer.gpu.renderer import Renderer, ViewState
from nbrdf.viewer.options import DEFAULT_MATERIAL
from nbrdf.viewer.reference.worker import ReferenceWorker, lobe_job, slice_job

GOLD = {"format": "nbrdf-material/1", "name": "g", "layers": [{"type": "conductor", "roughness": 0.3,
                                                             "r0": [1.0, 0.78, 0.34]}]}


def test_worker_pools_rounds_like_one_long_run():
    m = load_material(DEFAULT_MATERIAL)
    job = lobe_job(m, "k", 40.0)
    sel = torch.arange(0, job.wi.shape[0], 97)  # a subset of pixels keeps it fast
    job.wi, job.wo, job.weight = job.wi[sel], job.wo[sel], job.weight[sel]
    mask = np.zeros(job.mask.size, bool)
    mask[np.flatnonzero(job.mask.reshape(-1))[sel.numpy()]] = True
    job.mask, job.max_spp = mask.reshape(job.mask.shape), 24
    w = ReferenceWorker(start_spp=8, round_spp=8)
    try:
        w.request(job)
        r = w.wait("k", 24)
    finally:
        w.close()
    assert r is not None and r.done and r.spp == 24 and r.error is None
    rounds = [reference_eval(m, job.wi, job.wo, spp=8, seed=7919 * k) for k in range(3)]
    expected = (sum(mk for mk, _ in rounds) / 3 * job.weight).numpy()
    np.testing.assert_allclose(r.image[job.mask], expected, rtol=1e-5, atol=1e-7)
    # the standard error pools like the paths: sqrt(sum of the rounds' (spp se)^2) / total
    se = (sum((ek.double() * 8) ** 2 for _, ek in rounds).sqrt() / 24 * job.weight).numpy()
    assert (se > 0).any()
    np.testing.assert_allclose(r.stderr[job.mask], se, rtol=1e-5, atol=1e-9)
    assert r.noise == pytest.approx(np.sqrt(np.mean(se ** 2)) / np.abs(expected[np.abs(expected).sum(-1) > 0]).mean(),
                                    rel=1e-4)


def test_the_reported_noise_is_the_error_against_an_independent_run():
    """Standard errors that hold in the compare view: the worker's image (its
    rounds pooled, 256 paths) against an independent 4096-path run of the
    benchmark's stack, red channel: the sum of z^2 over 480 pixels is
    chi-square with one degree per pixel (two-sided 0.1 % limits: a noise
    figure 25 % too small or too large fails)."""
    from scipy import stats

    from nbrdf.training.bench import STANDARD_STACK

    m = parse_material(STANDARD_STACK)
    job = _subset(lobe_job(m, "std", 30.0), 480, 256)
    w = ReferenceWorker(start_spp=32, round_spp=64, threads=1)
    try:
        w.request(job)
        r = w.wait("std", 256, timeout=300)
    finally:
        w.close()
    assert r is not None and r.done and r.spp == 256
    mi, ei = reference_eval(m, job.wi, job.wo, spp=4096, seed=424242)
    a, sa = r.image[job.mask][:, 0], r.stderr[job.mask][:, 0]
    b, sb = (mi * job.weight).numpy()[:, 0], (ei * job.weight.abs()).numpy()[:, 0]
    keep = (sa > 0) & (sb > 0)
    assert keep.sum() >= 400
    chi2 = float((((a - b) / np.sqrt(sa ** 2 + sb ** 2))[keep] ** 2).sum())
    n = int(keep.sum())
    assert stats.chi2.ppf(0.0005, n) < chi2 < stats.chi2.ppf(0.9995, n), (chi2, n)
    assert 0 < r.noise < 0.05


def test_worker_reports_errors_and_keeps_working():
    m = load_material(DEFAULT_MATERIAL)
    bad = lobe_job(m, "bad", 10.0)
    bad.wo = bad.wo[:-1]  # mismatched pairs: the simulation raises
    good = lobe_job(m, "good", 10.0)
    sel = slice(0, 50)
    good.wi, good.wo, good.weight, good.max_spp = good.wi[sel], good.wo[sel], good.weight[sel], 8
    good.mask = np.zeros_like(good.mask)
    good.mask.reshape(-1)[np.arange(50)] = True
    w = ReferenceWorker()
    try:
        w.request(bad)
        r = w.wait("bad", 8)
        assert r is not None and r.error and "\n" not in r.error
        w.request(good)
        assert w.wait("good", 8).error is None
    finally:
        w.close()


def test_slice_job_matches_the_glsl_slice(gl_ctx):
    m = parse_material(GOLD)
    gpu = Renderer(gl_ctx, closed_form(gl_ctx, m)).render_linear(ViewState(view="slice"), (24, 16))
    job = slice_job(m, "s", (24, 16))
    ref = single_layer_eval(m.base, job.wi, job.wo).numpy().reshape(16, 24, 3)
    np.testing.assert_allclose(gpu, ref, rtol=2e-3, atol=2e-4)


def test_gbuffer_directions_reproduce_the_light_only_render(gl_ctx):
    """The object reference evaluates f at the G-buffer's (wi, wo): with the
    neural BRDF in place of the simulation it must give the rendered pixels."""
    from nbrdf.viewer.gpu.neural_gpu import GpuDecoder

    model = default_model()
    m = parse_material(GOLD)
    z = model.material_latent(m)
    r = Renderer(gl_ctx, gpu_brdf(gl_ctx, m, GpuDecoder(gl_ctx, model.decoder), z), mesh="testmesh")
    state = ViewState(env_on=False, background=False)
    img = r.render_linear(state, (40, 32), spp=1)
    wi, wo, mask = r.gbuffer(state, (40, 32))
    assert 0.05 < mask.mean() < 0.9
    a, b = torch.from_numpy(wi[mask]), torch.from_numpy(wo[mask])
    with torch.no_grad():
        f = model.decoder.eval_rgb(z, a, b).numpy()
    ref = f * np.clip(wi[mask][:, 2:3], 0, None) * state.light_radiance
    np.testing.assert_allclose(img[mask], ref, rtol=1e-3, atol=1e-4)
    assert np.abs(img[~mask]).max() == 0


def _subset(job, n: int, max_spp: int):
    """The first n pixels of a lobe job (keeps the simulation short)."""
    job.wi, job.wo, job.weight, job.max_spp = job.wi[:n], job.wo[:n], job.weight[:n], max_spp
    job.mask = np.zeros_like(job.mask)
    job.mask.reshape(-1)[np.arange(n)] = True
    return job


def test_worker_is_a_process_that_cancels_caches_and_ends():
    """Checked by the order of events, not by the clock: a request returns while
    its job runs; a cancelled job sends no further rounds (none arrive while the
    worker computes a later job)."""
    import os

    m = load_material(DEFAULT_MATERIAL)
    w = ReferenceWorker(start_spp=8, round_spp=8, threads=1)
    try:
        endless = lobe_job(m, "endless", 30.0)
        endless.max_spp = 10 ** 9
        w.request(endless)  # never waits for the simulation (10^9 paths: it could not return otherwise)
        assert w.busy() and w.current == "endless"
        assert w.process is not None and w.process.pid != os.getpid() and w.process.is_alive()
        first = w.wait("endless", 8, timeout=120)
        assert first is not None and first.error is None and not first.done
        w.request(_subset(lobe_job(m, "short", 20.0), 40, 16))  # cancels the endless job
        r = w.wait("short", 16, timeout=120)
        assert r is not None and r.done and r.spp == 16 and not w.busy()
        seen = w.result("endless").spp
        w.request(_subset(lobe_job(m, "later", 40.0), 40, 16))  # rounds of the cancelled job would arrive first
        assert w.wait("later", 16, timeout=120).done
        assert w.result("endless").spp == seen  # no more rounds of the cancelled job
        w.request(_subset(lobe_job(m, "short", 20.0), 40, 16))  # cached: not run again
        assert not w.busy()
        proc = w.process
    finally:
        w.close()
    assert not proc.is_alive()
    assert w.result("short").done  # the cache outlives the process


def test_an_interrupted_job_resumes_with_its_paths():
    """A, interrupted by B, then requested again, ends as one uninterrupted run of A."""
    m = load_material(DEFAULT_MATERIAL)
    a = _subset(lobe_job(m, "a", 35.0), 30, 10 ** 6)
    w = ReferenceWorker(start_spp=8, round_spp=8, threads=1)
    try:
        w.request(a)
        assert w.wait("a", 8, timeout=120).spp >= 8
        w.request(_subset(lobe_job(m, "b", 15.0), 30, 8))
        assert w.wait("b", 8, timeout=120).done
        got = w.result("a").spp
        a.max_spp = got + 16
        w.request(a)
        r = w.wait("a", got + 16, timeout=120)
    finally:
        w.close()
    assert r.done and r.spp == got + 16
    rounds = [reference_eval(m, a.wi, a.wo, spp=8, seed=7919 * k)[0] for k in range(r.spp // 8)]
    np.testing.assert_allclose(r.image[a.mask], (sum(rounds) / len(rounds) * a.weight).numpy(), rtol=1e-5, atol=1e-7)


def test_the_references_kept_in_the_window_are_bounded():
    """Every orbit or edit of a compared view is a new job key: the window keeps the
    latest references within the cache's bounds, never the current job's dropped."""
    import queue

    class Alive:
        def is_alive(self) -> bool:
            return True

    w = ReferenceWorker()
    w._proc, w._results = Alive(), queue.Queue()  # a process that has sent 40 images (no process started)
    w._current = "job-0"  # still being computed: kept however old
    for k in range(40):
        w._results.put((f"job-{k}", np.zeros((8, 8, 3), np.float32), 8, k > 0, None, None))  # job-0 goes on
    assert w.result("job-39") is not None and w.result("job-0") is not None
    assert len(w._cache) == 16 and w.result("job-1") is None

    from nbrdf.viewer.reference.cache import ReferenceCache
    from nbrdf.viewer.reference.worker import ReferenceImage

    c = ReferenceCache(max_items=100, max_bytes=3 * 8 * 8 * 3 * 4)  # room for three 8 x 8 images
    for k in range(5):
        c.put(str(k), ReferenceImage(np.zeros((8, 8, 3), np.float32), 8, True))
    assert [c.get(str(k)) is not None for k in range(5)] == [False, False, True, True, True]
    c.put("big", ReferenceImage(np.zeros((64, 64, 3), np.float32), 8, True))  # over the bound alone: kept
    assert len(c) == 1 and c.get("big") is not None


def test_a_busy_worker_holds_one_unread_request_not_every_one():
    """While the process reads nothing (compiling the walk, a long round), requests do not pile up in the
    window: one waits in the pipe, the newest in hand; once the pipe's one is read, the newest goes."""
    import multiprocessing as mp
    import queue as q
    from types import SimpleNamespace

    from nbrdf.viewer.reference.worker import ReferenceWorker

    w = ReferenceWorker()
    w._proc = SimpleNamespace(is_alive=lambda: True)  # a process that never reads its pipe
    w._requests, w._results = q.Queue(), q.Queue()
    w._taken, w._sent, w._held = mp.get_context("spawn").Value("q", 0), 0, None
    for k in range(200):
        w.request(SimpleNamespace(key=f"job{k}"))
    assert w._requests.qsize() == 1 and w.unread == 2 and w._held.key == "job199"
    first = w._requests.get_nowait()
    assert first.key == "job0"
    with w._taken.get_lock():
        w._taken.value += 1  # what the process does when it reads
    w.collect()
    assert w._requests.get_nowait().key == "job199" and w._held is None and w.unread == 1
