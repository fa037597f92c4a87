"""Faults: the Monte Carlo worker killed mid-run is detected, reported and
restarted; saving to a folder that cannot be written is one line and loses
nothing already saved."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
import torch
from gpu_brdfs import closed_form

from nbrdf.neural.material import load_material
from nbrdf.viewer.options import DEFAULT_MATERIAL
from nbrdf.viewer.reference.worker import ReferenceWorker, lobe_job


def small_job(key: str, max_spp: int):
    job = lobe_job(load_material(DEFAULT_MATERIAL), key, 40.0)
    sel = torch.arange(0, job.wi.shape[0], 97)
    job.wi, job.wo, job.weight = job.wi[sel], job.wo[sel], job.weight[sel]
    mask = np.zeros(job.mask.size, bool)
    mask[np.flatnonzero(job.mask.reshape(-1))[sel.numpy()]] = True
    job.mask, job.max_spp = mask.reshape(job.mask.shape), max_spp
    return job


def kill_and_wait(proc) -> None:
    os.kill(proc.pid, signal.SIGKILL)
    proc.join(30)
    assert not proc.is_alive()


def test_a_killed_worker_is_detected_reported_and_restarted():
    w = ReferenceWorker(start_spp=8, round_spp=8, threads=1)
    try:
        job = small_job("k", 10**6)  # never finishes: it is mid-run when killed
        w.request(job)
        r = w.wait("k", 8, timeout=300)
        assert r is not None and r.spp >= 8 and r.error is None
        first = w.process
        kill_and_wait(first)
        assert w.busy()  # the job is still wanted: detection restarts it
        assert w.deaths == 1 and w.process is not first and w.process.is_alive()
        assert "killed by signal 9" in w.notice and "restarted" in w.notice and "\n" not in w.notice
        # the new process picks the job up again: fresh rounds arrive (the dead process's
        # queue was dropped unread, so any new image is the new process's; it may run
        # several rounds between two looks, so its paths are not compared)
        before = w.result("k")
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and w.result("k") is before:
            time.sleep(0.05)
        r = w.result("k")
        assert r is not before and r.error is None and not r.done
        # another job goes through the new process as usual
        w.request(small_job("k2", 16))
        r2 = w.wait("k2", 16, timeout=300)
        assert r2 is not None and r2.done and r2.spp == 16
    finally:
        w.close()
    assert not w.process.is_alive()


def test_a_job_that_keeps_killing_the_worker_is_failed_not_retried_forever():
    w = ReferenceWorker(start_spp=8, round_spp=8, threads=1)
    try:
        w.request(small_job("k", 10**6))
        for n in range(ReferenceWorker.MAX_DEATHS_PER_JOB):
            assert w.wait("k", 1, timeout=300) is not None or n > 0
            kill_and_wait(w.process)
            w.busy()
        r = w.result("k")
        assert not w.busy() and r.done and "3 times" in r.error and "\n" not in r.error
        assert w.deaths == 3
    finally:
        w.close()


def test_the_compare_status_line_reports_the_restart(gl_ctx):
    from nbrdf.viewer.gpu.renderer import Renderer
    from nbrdf.viewer.reference.compare import Compare

    m = load_material(DEFAULT_MATERIAL)
    c = Compare(gl_ctx, Renderer(gl_ctx, closed_form(gl_ctx, m)))
    try:
        c.worker.request(small_job("k", 10**6))
        c._job = "k"
        assert c.worker.wait("k", 8, timeout=300) is not None
        kill_and_wait(c.worker.process)
        c.worker.busy()
        line = c.status(m, "lobe")
        assert line.startswith("reference: Monte Carlo") and "killed by signal 9; restarted" in line
    finally:
        c.close()


# ----------------------------------------------------------------------- saving to an unwritable folder
def _unwritable(tmp_path):
    """A folder nothing can be created in, whoever runs the test (root ignores permission bits)."""
    blocker = tmp_path / "ro"
    blocker.write_text("")
    return blocker / "sub"


WINDOW = textwrap.dedent("""
    import json, os, signal, sys, time
    from pathlib import Path
    from nbrdf.viewer.ui.app import App
    from nbrdf.viewer.options import ViewOptions
    good, bad, out = Path(sys.argv[2]), Path(sys.argv[3]), {}
    app = App(ViewOptions(material=sys.argv[1], size=(48, 32)), size=(48, 32))
    ld = app.lookdev
    try:
        app.step()
        out["saved"] = [ld.save_material(good / "m.json"), ld.save_session(good / "s.json"),
                        ld.write_screenshot(good / "shot.png", (16, 16), 1)]
        ld.set_param(len(ld.material.layers) - 1, "roughness", 0.61)
        out["bad"] = []
        for call in (lambda: ld.save_material(bad / "m.json"), lambda: ld.save_session(bad / "s.json"),
                     lambda: ld.write_screenshot(bad / "shot.png", (16, 16), 1),
                     lambda: ld.write_screenshot(bad / "shot.exr", (16, 16), 1)):
            out["bad"].append([call(), ld.error])
        out["roughness_after"] = ld.material.layers[-1].roughness
        # the Monte Carlo worker killed while the window runs a compare view of a stack
        ld.state.view = "lobe"
        ld.set_compare("side")
        # waits end on an event; the deadlines only turn a hang into a failure (a loaded machine is slow)
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:
            app.step()
            if ld.worker.process is not None and ld.worker.result(ld.compare_part._job) is not None:
                break
            time.sleep(0.1)
        first = ld.worker.process
        os.kill(first.pid, signal.SIGKILL)
        first.join(30)
        for _ in range(3):
            app.step()
        out["status"] = ld.reference_status()
        out["restarted"] = ld.worker.process is not None and ld.worker.process.pid != first.pid \\
            and ld.worker.process.is_alive()
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:
            app.step()
            r = ld.worker.result(ld.compare_part._job)
            if r is not None and r.spp > 0 and ld.worker.process.is_alive():
                break
            time.sleep(0.1)
        out["after"] = [r.spp if r else 0, r.error if r else None]
        out["pixels"] = int(app.read_pixels().sum())
    finally:
        app.close()
    print(json.dumps(out), flush=True)
""")


@pytest.mark.gl
@pytest.mark.slow
def test_the_window_survives_a_killed_worker_and_unwritable_folders(xvfb_display, tmp_path):
    good = tmp_path / "good"
    good.mkdir()
    bad = _unwritable(tmp_path)
    env = dict(os.environ, DISPLAY=xvfb_display, NBRDF_STATE_DIR=str(tmp_path / "state"))
    r = subprocess.run([sys.executable, "-c", WINDOW, str(DEFAULT_MATERIAL), str(good), str(bad)], env=env,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["saved"] == [True, True, True]
    saved = {p.name: p.read_bytes() for p in good.iterdir()}
    for ok, msg in out["bad"]:
        assert ok is False and msg and "\n" not in msg and "Traceback" not in msg
    assert out["roughness_after"] == 0.61  # the edit is still there to save elsewhere
    assert {p.name: p.read_bytes() for p in good.iterdir()} == saved  # nothing already saved was touched
    assert json.loads(saved["s.json"].decode())["format"] == "nbrdf-session/1"
    assert "killed by signal 9; restarted" in out["status"] and out["restarted"]
    assert out["after"][0] > 0 and out["after"][1] is None and out["pixels"] > 0


# ----------------------------------------------------------------------- a full disk
def _full_disk(monkeypatch, module):
    """Every write through ``module``'s os.replace fails as on a full disk (after the temporary file)."""
    def replace(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(module.os, "replace", replace)


def test_a_full_disk_keeps_the_saved_material_and_session(tmp_path, monkeypatch):
    import nbrdf.neural.files as files
    from nbrdf.neural.errors import NbrdfError
    from nbrdf.neural.material import save_material
    from nbrdf.viewer.session.document import SessionDoc

    m = load_material(DEFAULT_MATERIAL)
    save_material(m, tmp_path / "m.json")
    SessionDoc(m).save(tmp_path / "s.json")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    _full_disk(monkeypatch, files)
    with pytest.raises(NbrdfError, match="No space left on device.*unchanged"):
        save_material(m, tmp_path / "m.json")
    with pytest.raises(NbrdfError, match="No space left on device.*unchanged"):
        SessionDoc(m).save(tmp_path / "s.json")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before  # whole, and no temporary left


@pytest.mark.parametrize("suffix", [".png", ".exr", ".npy"])
def test_a_full_disk_keeps_the_saved_screenshot(tmp_path, monkeypatch, suffix):
    import nbrdf.imaging.image_io as image_io
    from nbrdf.neural.errors import NbrdfError

    img = np.full((4, 6, 3), 0.5, np.float32)
    image_io.write_image(tmp_path / f"shot{suffix}", img)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    _full_disk(monkeypatch, image_io)
    with pytest.raises(NbrdfError, match="No space left on device.*unchanged"):
        image_io.write_image(tmp_path / f"shot{suffix}", img * 2)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_an_unwritable_folder_is_one_line(tmp_path):
    from nbrdf.imaging.image_io import write_image
    from nbrdf.neural.errors import NbrdfError
    from nbrdf.neural.material import save_material
    from nbrdf.viewer.session.document import SessionDoc

    bad = _unwritable(tmp_path)
    m = load_material(DEFAULT_MATERIAL)
    for save in (lambda: save_material(m, bad / "m.json"), lambda: SessionDoc(m).save(bad / "s.json"),
                 lambda: write_image(bad / "x.exr", np.zeros((2, 2, 3)))):
        with pytest.raises(NbrdfError) as e:
            save()
        assert "\n" not in str(e.value) and str(bad) in str(e.value)
