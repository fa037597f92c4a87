"""A code swapped in while the view is still (idle refinement) is handed over
(viewer/jobs/view_frames.py, ``ViewFrames.handover``): the image accumulated so far
stays on screen and fades into the new code's over its first passes, where a
restart would drop the view back to one noisy pass; once faded, the view is
exactly the new code's own accumulation. Edits, compare views and view changes
still start over."""
from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from nbrdf.neural.material import parse_material
from nbrdf.viewer.jobs.view_frames import HANDOVER_PASSES
from nbrdf.viewer.modes import BrdfMode

pytestmark = pytest.mark.gl

SIZE = (40, 32)
#: A material far from the default varnished copper: the "refined" code the tests hand over.
GOLD = {"format": "nbrdf-material/1", "name": "g", "layers": [
    {"type": "dielectric", "roughness": 0.05, "ior": 1.5},
    {"type": "conductor", "roughness": 0.3, "r0": [1.0, 0.78, 0.34]}]}
BLUE = {"format": "nbrdf-material/1", "name": "b", "layers": [
    {"type": "dielectric", "roughness": 0.05, "ior": 1.5},
    {"type": "diffuse", "albedo": [0.1, 0.2, 0.8]}]}


@pytest.fixture
def session(gl_ctx):
    from nbrdf.neural.material import load_material
    from nbrdf.viewer.options import DEFAULT_MATERIAL
    from nbrdf.viewer.session.lookdev import LookDev

    ld = LookDev(gl_ctx, load_material(DEFAULT_MATERIAL))
    fbo = gl_ctx.simple_framebuffer(SIZE, components=4)
    yield ld, fbo
    ld.close()


def shown(ld, fbo, passes: int = 1) -> np.ndarray:
    ld.render(fbo, SIZE, passes)
    return np.frombuffer(fbo.read(components=3), np.uint8).reshape(SIZE[1], SIZE[0], 3)[::-1].astype(float)


def diff(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).mean())


def swap_in(ld, spec: dict) -> None:
    """What the idle refinement does with a better code: a new BRDF for the same material, handed over."""
    ld.swap_brdf(ld.pipeline.build(parse_material(spec), BrdfMode.NEURAL))


def test_the_still_image_fades_into_the_new_codes_and_ends_as_its_own_accumulation(session):
    ld, fbo = session
    old = shown(ld, fbo, 16)
    swap_in(ld, GOLD)
    first = shown(ld, fbo)  # 1 pass of the new code, 7/8 of the old image
    assert ld.frames.fading and ld.passes == 1
    for _ in range(HANDOVER_PASSES - 2):
        shown(ld, fbo)
    assert ld.frames.fading
    last = shown(ld, fbo)
    assert not ld.frames.fading and ld.passes == HANDOVER_PASSES
    ld.invalidate()  # the new code's own accumulation from scratch, as many passes
    new = shown(ld, fbo, HANDOVER_PASSES)
    ld.invalidate()
    one = shown(ld, fbo, 1)  # what a restart shows right after the swap
    change = diff(old, new)
    assert change > 10  # the two codes look different: the test can see a fade
    assert diff(first, old) < 0.3 * change  # the swap's first frame is still mostly the old image...
    assert diff(one, old) > 0.7 * change  # ...where a restart shows the new code at once, from one pass
    assert diff(last, new) <= 0.5  # faded out: exactly the new code's accumulation (8-bit rounding aside)


def test_a_second_handover_during_a_fade_keeps_the_image_with_more_passes(session):
    ld, fbo = session
    old = shown(ld, fbo, 16)
    swap_in(ld, GOLD)
    shown(ld, fbo, 2)
    swap_in(ld, BLUE)  # the gold image has 2 passes, the copper one 16: the copper one is kept
    again = shown(ld, fbo)
    ld.invalidate()
    blue = shown(ld, fbo, 1)
    assert diff(again, old) < 0.3 * diff(blue, old)


def test_an_edit_during_a_fade_starts_over(session):
    ld, fbo = session
    shown(ld, fbo, 8)
    swap_in(ld, GOLD)
    shown(ld, fbo)
    assert ld.set_param(0, "roughness", 0.3)
    assert not ld.frames.fading and ld.passes == 0
    edited = shown(ld, fbo)
    ld.invalidate()
    assert diff(edited, shown(ld, fbo)) == 0.0  # nothing of the earlier images in the edit's frame


@pytest.mark.parametrize("view", ["compare", "lobe"])
def test_compare_and_lobe_views_start_over(session, view):
    ld, fbo = session
    if view == "compare":
        assert ld.set_compare("side")
    else:
        assert ld.set_view("lobe")
    shown(ld, fbo, 4)
    swap_in(ld, GOLD)
    assert not ld.frames.fading and ld.passes == 0


# ------------------------------------------------------------ a frame updates first, then renders
def test_a_refined_code_is_collected_by_update_never_by_a_render(session):
    """The idle refinement's code reaches the view in ``LookDev.update`` (the window's frame calls it
    before rendering); a render draws the session as it is and never calls back into it."""
    ld, fbo = session
    gold = ld.pipeline.build(parse_material(GOLD), BrdfMode.NEURAL).latent
    ld.idle_refine.poll = lambda: gold  # a round that beat the network's (the refiner's one seam the session asks)
    before = ld.brdf
    shown(ld, fbo, 4)
    assert ld.brdf is before and ld.passes == 4 and not ld.frames.fading
    ld.update()
    assert ld.brdf is not before and ld.frames.fading and ld.passes == 0  # handed over, not restarted


def test_renders_screenshots_and_turntables_never_update_the_session(session, tmp_path):
    ld, fbo = session

    def no_update():
        raise AssertionError("a render called back into the session")

    ld.update = no_update
    shown(ld, fbo, 2)
    assert ld.write_screenshot(tmp_path / "a.png", SIZE, 1), ld.error
    assert ld.start_screenshot(tmp_path / "b.png", SIZE, 2), ld.error
    while ld.screenshot_progress is not None:
        ld.step_screenshot()
    assert ld.error is None and (tmp_path / "b.png").is_file()
    ld.write_turntable(tmp_path / "t_%02d.npy", 2, (8, 8), 1)
    assert sorted(p.name for p in tmp_path.glob("t_*.npy")) == ["t_00.npy", "t_01.npy"]


def test_the_jobs_never_import_the_session():
    """viewer/jobs/ take the frame's description, the renderer and the targets (viewer/jobs/frame.py), not
    the session: no module there imports viewer/session/, not even for type checking."""
    jobs = Path(__file__).resolve().parents[2] / "viewer" / "jobs"
    wrong = []
    for path in sorted(jobs.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            wrong += [f"{path.name}: {n}" for n in names if n.startswith("nbrdf.viewer.session")]
    assert not wrong, wrong
