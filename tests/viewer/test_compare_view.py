"""The compare view in a real window (Xvfb): the reference side shows what the
reference holds -- in particular the clear coat's highlight, which the README's
1000 x 620 capture lost behind the "Scene and view" panel (the panels floated
over the view) -- and the HDR-FLIP view's map and mean."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from dataclasses import replace

import numpy as np
import pytest

from nbrdf.viewer.options import DEFAULT_MATERIAL

pytestmark = pytest.mark.gl

SCRIPT = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    import numpy as np
    from nbrdf.viewer.ui.app import App
    from nbrdf.viewer.options import ViewOptions
    tmp = Path(sys.argv[2])
    size = (1000, 620)  # the README capture's window
    app = App(ViewOptions(material=sys.argv[1], size=size), size=size)
    app._adapt_scale = lambda w, h: 0.125  # the render scale software OpenGL settles at (cheap)
    ld = app.lookdev
    try:
        ld.set_compare("side")
        app.step()
        r = ld.worker.wait(ld.compare_part._job, 8, timeout=400)
        for _ in range(2):
            app.step()
        w, h = app.framebuffer_size()
        vp = app.viewport() if hasattr(app, "viewport") else (0, 0, w, h)
        cam = ld.state.camera
        np.savez(tmp / "side.npz", screen=app.read_pixels(), ref=r.image, vp=np.array(vp),
                 camera=np.array([cam.distance, cam.fov]))
    finally:
        app.close()
""")


@pytest.fixture(scope="module")
def side_run(xvfb_display, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("compare")
    env = dict(os.environ, DISPLAY=xvfb_display)
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(DEFAULT_MATERIAL), str(tmp)], env=env,
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    return np.load(tmp / "side.npz")


def test_reference_side_shows_the_coat_highlight(side_run):
    """The Monte Carlo image's brightest pixel (the clear coat's highlight of the
    default varnished copper) appears on screen where the right half of the
    view shows it: white, not covered by anything."""
    screen, ref, (vx, vy, vw, vh) = side_run["screen"], side_run["ref"], side_run["vp"]
    lum = ref @ np.array([0.2126, 0.7152, 0.0722])
    row, col = np.unravel_index(np.argmax(lum), lum.shape)
    assert lum[row, col] > 1.0  # the coat's highlight is in the reference (the tone mapper maps it to white)
    half = vw / 2
    x = int(vx + half + (col + 0.5) / ref.shape[1] * half)
    y = int(vy + (row + 0.5) / ref.shape[0] * vh)
    patch = screen[y - 1:y + 2, x - 1:x + 2].reshape(-1, 3)
    assert patch.min(1).max() >= 200, f"pixel ({x}, {y}) of the reference's highlight shows {patch.tolist()}"


def test_side_by_side_frames_the_object_in_each_half(side_run):
    """Each half is half the view's width: the camera fits the object into a
    view of that aspect (it used to keep the full view's framing, so each half
    cut the sphere off at its sides)."""
    from nbrdf.viewer.scene.camera import framing_distance

    (_, _, vw, vh), (distance, fov) = side_run["vp"], side_run["camera"]
    assert distance == pytest.approx(framing_distance(fov, (vw / 2) / vh), rel=1e-6)
    assert distance > 1.2 * framing_distance(fov, vw / vh)  # farther than the full view's framing


GOLD = {"format": "nbrdf-material/1", "name": "g", "layers": [{"type": "conductor", "roughness": 0.3,
                                                             "r0": [1.0, 0.78, 0.34]}]}


def _gold_in_the_flip_view(gl_ctx):
    """A session of GOLD in the FLIP view, 4 passes drawn at 40 x 32: (session, framebuffer, size, passes)."""
    from nbrdf.neural.material import parse_material
    from nbrdf.viewer.session.lookdev import LookDev

    ld = LookDev(gl_ctx, parse_material(GOLD))
    size, passes = (40, 32), 4
    assert ld.set_compare("flip")
    fbo = gl_ctx.simple_framebuffer(size, components=4)
    ld.render(fbo, size, passes)
    return ld, fbo, size, passes


def test_flip_view_shows_the_hdr_flip_of_neural_against_reference(gl_ctx):
    """The FLIP view's mean and map are flip-evaluator's HDR-FLIP of the neural
    image against its reference (here the closed form of a conductor), and the
    view draws the map in magma (black where FLIP is 0)."""
    from nbrdf.imaging.flip import flip

    ld, fbo, size, passes = _gold_in_the_flip_view(gl_ctx)
    try:
        shown = np.frombuffer(fbo.read(components=3), np.uint8).reshape(size[1], size[0], 3)[::-1]
        state = replace(ld.state, background=False)  # the error views score the object alone
        neural = ld.renderer.render_linear(state, size, passes, ld.brdf)
        reference = ld.renderer.render_linear(state, size, passes, ld.ref_brdf)
        mean, fmap = flip(reference, neural)
        assert ld.flip_mean == pytest.approx(mean, rel=1e-4, abs=1e-6) and 0.0 < mean < 0.5
        # Magma: the worst pixel is the brightest of the view; zero error is near black.
        worst = np.unravel_index(np.argmax(fmap), fmap.shape)
        best = np.unravel_index(np.argmin(fmap), fmap.shape)
        assert shown[worst].astype(int).sum() > shown[best].astype(int).sum() + 60
        assert ld.set_compare("error")
        ld.render(fbo, size, passes)
        other = np.frombuffer(fbo.read(components=3), np.uint8).reshape(size[1], size[0], 3)[::-1]
        assert np.abs(other.astype(int) - shown).mean() > 5  # a different view, not the same picture
    finally:
        ld.close()


def test_the_window_flip_runs_in_a_process_of_its_own_and_shows_the_same_map(gl_ctx):
    """With ``run_async`` (the window) a frame never waits for FLIP: the first frames show no mean while the
    evaluation runs in its own process; once it is finished the mean shown is the synchronous evaluation's
    (to 1e-6: the same images, the same evaluator)."""
    import time

    ld, fbo, size, _ = _gold_in_the_flip_view(gl_ctx)
    try:
        sync = ld.flip_mean
        flip = ld.compare_part.flip
        flip.run_async = True
        flip.clear()  # score the same view again, now in the process
        ld.render(fbo, size, 0)
        assert ld.flip_mean is None and flip.job is not None  # submitted, not waited for
        deadline = time.monotonic() + 120.0
        while ld.flip_mean is None and time.monotonic() < deadline:
            time.sleep(0.05)
            ld.render(fbo, size, 0)
        assert ld.flip_mean == pytest.approx(sync, rel=1e-6) and flip.notice == ""
    finally:
        ld.close()


def test_the_status_line_states_the_references_noise(gl_ctx):
    """The compare view tells how far its Monte Carlo reference can be
    trusted: paths per pixel and the relative noise of the image."""
    from nbrdf.neural.material import parse_material
    from nbrdf.training.bench import STANDARD_STACK
    from nbrdf.viewer.reference.compare import Compare
    from nbrdf.viewer.reference.worker import ReferenceImage, ReferenceWorker

    w = ReferenceWorker()
    c = Compare(gl_ctx, None, worker=w)  # the status line needs no renderer
    img = np.zeros((2, 2, 3), np.float32)
    img[0] = 0.5  # two lit pixels at 0.5, two dark ones that must not dilute the figure
    se = np.where(img > 0, 0.01, 0.0).astype(np.float32)
    c._job, c._shown = "k", ReferenceImage(img, 512, False, None, se)  # what the last frame drew
    assert c.status(parse_material(STANDARD_STACK), "lobe") == "reference: Monte Carlo, 512 paths per pixel, noise 2.0 %..."
    w._cache["k"] = ReferenceImage(img, 1024, False, None, se / 2)  # a newer round, not drawn yet: the line waits
    assert c.status(parse_material(STANDARD_STACK), "lobe").startswith("reference: Monte Carlo, 512 paths per pixel")
    c._shown = ReferenceImage(img, 4096, True, None, se / 4)
    assert c.status(parse_material(STANDARD_STACK), "object") == (
        "reference: Monte Carlo lights and body, 4096 samples per pixel, noise 0.5 %; the coat in closed form on the GPU")


def _waiting_lookdev(gl_ctx, monkeypatch):
    """A session on the default stack (a Monte Carlo reference) whose worker never
    computes: its requests are recorded and nothing arrives until the test puts a
    round in the worker's cache."""
    from nbrdf.neural.material import load_material
    from nbrdf.viewer.session.lookdev import LookDev

    ld = LookDev(gl_ctx, load_material(DEFAULT_MATERIAL))
    sent = []
    monkeypatch.setattr(ld.worker, "request", sent.append)
    return ld, sent


def _draw(gl_ctx, ld, size, passes: int = 2) -> np.ndarray:
    """The view as shown, (H, W, 3) uint8, top row first."""
    fbo = gl_ctx.simple_framebuffer(size, components=4)
    ld.render(fbo, size, passes)
    return np.frombuffer(fbo.read(components=3), np.uint8).reshape(size[1], size[0], 3)[::-1]


def _deliver(ld, job, image: np.ndarray) -> None:
    """The worker's first round of ``job`` arrives with ``image``."""
    from nbrdf.viewer.reference.worker import ReferenceImage

    ld.worker._cache.put(job.key, ReferenceImage(image.astype(np.float32), 8, False))
    ld.invalidate()


def _extent(img: np.ndarray) -> tuple[int, int]:
    """(width, height) in pixels of what is not background (black) in ``img``."""
    ys, xs = np.nonzero(img.astype(int).sum(-1) > 24)
    return int(np.ptp(xs)) + 1, int(np.ptp(ys)) + 1


def test_the_lobe_reference_is_drawn_like_the_neural_lobe(gl_ctx, monkeypatch):
    """Side by side, the Monte Carlo lobe (a 64 x 64 image of the unit disc) is the
    disc the neural half shows, same size and round -- it was stretched to fill its
    half (an ellipse); here the reference is the neural lobe itself, so the relative
    error view shows next to nothing (the stretched image made it large)."""
    ld, sent = _waiting_lookdev(gl_ctx, monkeypatch)
    try:
        ld.compare_part.show_labels = False
        assert ld.set_view("lobe") and ld.set_compare("side")
        size = (192, 72)  # two 96 x 72 halves: a disc 72 pixels across in each
        _draw(gl_ctx, ld, size)
        own = ld.renderer.render_linear(replace(ld.state, background=False), (64, 64), 1, ld.brdf)
        _deliver(ld, sent[-1], own)
        shown = _draw(gl_ctx, ld, size)
        (nw, nh), (rw, rh) = _extent(shown[:, :96]), _extent(shown[:, 96:])
        assert abs(nw - nh) <= 2 and nh >= 60  # the neural disc, round
        assert abs(rw - nw) <= 2 and abs(rh - nh) <= 2, ((nw, nh), (rw, rh))
        assert np.abs(shown[:, 96:].astype(int) - shown[:, :96]).mean() < 3  # the same picture
        assert ld.set_compare("error")
        err = _draw(gl_ctx, ld, size).astype(int)
        blue = err[..., 2] > err[..., 0] + 40  # the ramp's low end (dark blue .. cyan), not green .. red
        assert blue.mean() > 0.97, blue.mean()
    finally:
        ld.close()


def _hatched(half: np.ndarray) -> float:
    """The fraction of ``half``'s pixels that are the placeholder's hatch."""
    from nbrdf.viewer.reference.compare import PLACEHOLDER_GREYS

    px = half.astype(int)
    grey = (px.max(-1) - px.min(-1)) <= 1
    return float((grey & np.isin(px[..., 0], [round(255 * g) for g in PLACEHOLDER_GREYS])).mean())


@pytest.mark.parametrize("view", ["object", "lobe"])
def test_a_computing_reference_shows_a_placeholder(gl_ctx, monkeypatch, view):
    """Until the Monte Carlo reference's first round arrives, its half is the
    placeholder's grey hatch with "computing reference..." -- no object: the
    lit object used to show the stack's coat over a black body (a black
    material, for 14 s and more on three layers), the lobe an empty black half.
    The first round replaces it."""
    ld, sent = _waiting_lookdev(gl_ctx, monkeypatch)
    try:
        ld.compare_part.show_labels = False  # the sides' names off; the placeholder's words stay
        assert ld.set_view(view) and ld.set_compare("side")
        size = (256, 96)
        shown = _draw(gl_ctx, ld, size)
        assert sent, "no reference was asked for"
        assert _hatched(shown[:, 128:]) > 0.7 and _hatched(shown[:, :128]) < 0.05
        assert ld.compare_part.placeholder == "computing reference..."
        words = shown[40:56, 128:].astype(int).sum(-1)  # the words' white glyphs on their dark box, mid-height
        assert (words > 600).any() and (words < 120).mean() > 0.3  # the hatch (183, 246) dimmed by the box
        job = sent[-1]
        body = np.zeros((*job.mask.shape, 3), np.float32)
        body[job.mask] = 0.3
        _deliver(ld, job, body)
        shown = _draw(gl_ctx, ld, size)
        assert _hatched(shown[:, 128:]) < 0.05 and ld.compare_part.placeholder is None
    finally:
        ld.close()
