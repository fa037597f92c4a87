"""Undo / redo of a LookDev session (offscreen GL): every material and scene
edit is a step, a session or preset opened is one step, the camera's place
is not one; files dropped on the window open by kind."""
from __future__ import annotations

import json

import numpy as np
import pytest

from nbrdf.neural.material import load_material
from nbrdf.viewer.options import DEFAULT_MATERIAL

pytestmark = pytest.mark.gl


@pytest.fixture()
def ld(gl_ctx):
    from nbrdf.viewer.session.lookdev import LookDev

    session = LookDev(gl_ctx, load_material(DEFAULT_MATERIAL))
    yield session
    session.close()


def test_every_kind_of_edit_undoes_and_redoes(ld):
    base = ld.snapshot()
    edits = [lambda: ld.set_param(2, "roughness", 0.6), lambda: ld.add_coat(),
             lambda: ld.update_state(exposure=1.5), lambda: ld.set_backdrop(ground=False),
             lambda: ld.set_environment("sky"), lambda: ld.set_compare("wipe"), lambda: ld.set_wipe(0.3),
             lambda: ld.set_fov(50.0), lambda: ld.set_view("lobe"), lambda: ld.load_preset("rough_gold"),
             lambda: ld.set_mesh("testmesh")]
    snaps = [base]
    for edit in edits:
        assert edit(), ld.error
        snaps.append(ld.snapshot())
    assert len(ld.history.undo_stack) == len(edits)
    for k in range(len(edits), 0, -1):
        assert ld.undo(), ld.error
        assert ld.snapshot() == snaps[k - 1]
    assert not ld.undo()
    for k in range(1, len(edits) + 1):
        assert ld.redo(), ld.error
        assert ld.snapshot() == snaps[k]


def test_a_coalesced_drag_is_one_step_and_navigation_is_none(ld):
    before = ld.editor.doc["layers"][2]["roughness"]
    with ld.coalescing("2.roughness"):
        for v in np.linspace(0.3, 0.9, 12):
            ld.set_param(2, "roughness", float(v))
    ld.end_group()
    ld.orbit(30, 10)
    ld.zoom(0.5)
    assert len(ld.history.undo_stack) == 1
    yaw = ld.state.camera.yaw
    assert ld.undo() and ld.editor.doc["layers"][2]["roughness"] == before
    assert ld.state.camera.yaw == yaw  # undo leaves the camera where the user put it


def test_at_least_100_steps(ld):
    for k in range(120):
        ld.update_state(exposure=round(0.01 * (k + 1), 3))
    for _ in range(100):
        assert ld.undo()
    assert ld.state.exposure == pytest.approx(0.2)


def test_a_session_opened_is_one_step(ld, tmp_path):
    ld.set_param(2, "roughness", 0.7)
    ld.update_state(exposure=2.0)
    ld.save_session(tmp_path / "s.json")
    ld.undo()
    ld.undo()
    n = len(ld.history.undo_stack)
    assert ld.open_session(tmp_path / "s.json")
    assert len(ld.history.undo_stack) == n + 1
    assert ld.undo() and ld.state.exposure == 0.0


def test_dropped_files_open_by_kind(ld, tmp_path):
    from nbrdf.viewer.session.edits import presets

    assert ld.open_file(presets()["rough_gold"]) and ld.material.name == "rough gold"
    ld.save_session(tmp_path / "s.json")  # a session is a .json too: told apart by content
    ld.set_param(0, "roughness", 0.9)
    assert ld.open_file(tmp_path / "s.json") and ld.editor.doc["layers"][0]["roughness"] == 0.5
    doc = ld.editor.doc
    for bad, words in (("a.txt", "cannot open a .txt"), ("missing.json", "no such file"),
                       ("missing.hdr", "missing.hdr"), ("missing.glb", "missing.glb")):
        assert not ld.open_file(tmp_path / bad)
        assert words in ld.error and "\n" not in ld.error
    (tmp_path / "broken.json").write_text("{ not json")
    assert not ld.open_file(tmp_path / "broken.json") and "not JSON" in ld.error
    (tmp_path / "other.json").write_text(json.dumps({"hello": 1}))
    assert not ld.open_file(tmp_path / "other.json") and "\n" not in ld.error
    assert ld.editor.doc == doc


def test_a_tiled_screenshot_is_the_one_shot_image_up_to_noise(ld, tmp_path):
    import imageio.v3 as iio

    assert ld.write_screenshot(tmp_path / "sync.png", (150, 100), 8)
    assert ld.start_screenshot(tmp_path / "job.png", (150, 100), 8)
    ld.shots.job = type(ld.shots.job)(ld.shots.job.path, ld.shots.job.size, ld.shots.job.passes, tiled=True)  # the tiled path
    steps = 0
    while ld.screenshot_progress is not None:
        ld.step_screenshot(budget_ms=1.0)
        steps += 1
    assert steps >= 6 and ld.error is None  # 6 tiles of 64 pixels, several steps each
    a, b = (iio.imread(tmp_path / n).astype(int) for n in ("sync.png", "job.png"))
    assert a.shape == b.shape == (100, 150, 3)
    assert np.abs(a - b).mean() < 2.0 and np.abs(a.mean((0, 1)) - b.mean((0, 1))).max() < 1.0
    assert ld.start_screenshot(tmp_path / "job.exr", (40, 30), 2)
    while ld.screenshot_progress is not None:
        ld.step_screenshot()
    assert (tmp_path / "job.exr").is_file() and ld.error is None
    assert not ld.start_screenshot(tmp_path / "x.bmp", (8, 8)) and ".png" in ld.error


def test_frame_clock_counts_presented_frames():
    from nbrdf.viewer.ui.app import FrameClock

    c = FrameClock(window=10)
    for k in range(25):
        c.presented(t=0.1 * k)  # 10 frames a second
    assert c.fps == pytest.approx(10.0) and c.frame_ms == pytest.approx(100.0)


def test_a_rename_keeps_the_view_accumulating_and_is_one_undo_step(ld):
    ld.render(ld.ctx.simple_framebuffer((48, 40)), (48, 40), passes=3)
    passes, latent = ld.passes, ld.brdf.latent
    assert passes == 3

    def reference_key():  # the compare view's Monte Carlo reference: the same job after a rename
        return ld.stage.compare.job_key(ld.material, ld.state, (48, 40), "sphere")
    before = reference_key()
    assert ld.set_name("copper, renamed"), ld.error
    assert reference_key() == before
    assert ld.brdf.material.name == "copper, renamed" and ld.material.name == "copper, renamed"
    assert ld.brdf.latent is latent and ld.passes == passes  # nothing rebuilt, nothing restarted
    ld.render(ld.ctx.simple_framebuffer((48, 40)), (48, 40), passes=1)
    assert ld.passes == passes + 1
    assert ld.undo() and ld.material.name != "copper, renamed"
    assert ld.set_param(2, "roughness", 0.5) and ld.passes == 0  # an edit still starts the view over
