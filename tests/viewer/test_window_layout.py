"""The window on a 1280 x 800 screen (Xvfb): it opens at about 80 % of the
screen, remembers its size, docks the panels as side bars that cover neither
each other nor the 3D view, and frames the object in the view."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest
from xvfb import xvfb_server

pytestmark = pytest.mark.gl

SCRIPT = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    import numpy as np
    from imgui_bundle import imgui
    import glfw
    from nbrdf.viewer.ui.app import App
    from nbrdf.viewer.options import ViewOptions
    out = {}
    clipped = set()
    labels = set()
    def spy_widget(name):  # an item that ends beyond its side bar's work area is clipped
        real = getattr(imgui, name)
        def wrapped(*a, **k):
            r = real(*a, **k)
            window = imgui.internal.get_current_window()
            right = window.work_rect.max.x
            label = a[0] if a and isinstance(a[0], str) else name
            if window.name == "Material":
                labels.add(label.split('##')[0])
            if imgui.get_item_rect_max().x > right + 0.5 and window.name in ("Material", "Scene and view"):
                clipped.add(f"{name}: {label.split('##')[0]}")
            return r
        setattr(imgui, name, wrapped)
    for name in ("text", "text_colored", "button", "small_button", "slider_float", "slider_int", "input_text",
                 "combo", "checkbox", "color_edit3", "drag_float2", "drag_float3", "radio_button", "progress_bar"):  # (headers span the bar by design)
        spy_widget(name)
    app = App(ViewOptions())
    app._adapt_scale = lambda w, h: 0.125  # cheap frames on software OpenGL
    rects = {}
    draw = app.panels.draw
    def spy(size):  # the side bars where imgui actually put them
        draw(size)
        for name in ("Material", "Scene and view"):
            w = imgui.internal.find_window_by_name(name)
            rects[name] = [w.pos.x, w.pos.y, w.size.x, w.size.y]
    app.panels.draw = spy
    try:
        app.panels.expand_all = True  # every section open: the longest panels
        for _ in range(2):
            app.step()
        out["clipped"] = sorted(clipped)
        out["labels"] = sorted(labels)
        out["window"] = list(glfw.get_window_size(app.window))
        out["viewport"] = list(app.viewport())
        out["rects"] = {k: list(v) for k, v in rects.items()}
        out["camera"] = [app.lookdev.state.camera.distance, app.lookdev.state.camera.fov]
        vx, vy, vw, vh = app.viewport()
        _, _, mask = app.lookdev.renderer.gbuffer(app.lookdev.state, (vw // 4, vh // 4))  # the object's pixels
        ys, xs = np.nonzero(mask)
        out["object_box"] = [xs.min() / mask.shape[1], ys.min() / mask.shape[0],
                             (xs.max() + 1) / mask.shape[1], (ys.max() + 1) / mask.shape[0], vw / vh]
        glfw.set_window_size(app.window, 900, 560)
        for _ in range(2):
            app.step()
    finally:
        app.close()
    app2 = App(ViewOptions())
    out["reopened"] = list(glfw.get_window_size(app2.window))
    app2.close()
    Path(sys.argv[1]).write_text(json.dumps(out))
""")


@pytest.fixture(scope="module")
def screen_1280():
    yield from xvfb_server("1280x800")


def _layout(display: str, tmp) -> dict:
    env = dict(os.environ, DISPLAY=display, XDG_CONFIG_HOME=str(tmp / "config"))
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp / "out.json")], env=env, capture_output=True,
                       text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads((tmp / "out.json").read_text())


@pytest.fixture(scope="module")
def layout(screen_1280, tmp_path_factory):
    return _layout(screen_1280, tmp_path_factory.mktemp("layout"))


@pytest.fixture(scope="module")
def layout_1920(tmp_path_factory):
    screen = xvfb_server("1920x1080")
    display = next(screen)
    try:
        yield _layout(display, tmp_path_factory.mktemp("layout1920"))
    finally:
        screen.close()


def _overlap(a, b) -> bool:
    ax, ay, aw, ah = a
    bx, by, bw, bh = b
    return ax < bx + bw and bx < ax + aw and ay < by + bh and by < ay + ah


def test_no_panel_label_is_clipped_at_1280x800(layout):
    """Every widget of the side bars (all sections open) ends inside its bar: no
    clipped label ("remove", "material fi", "passes" were)."""
    assert layout["clipped"] == []


def test_no_panel_label_is_clipped_at_1920x1080(layout_1920):
    assert layout_1920["clipped"] == []


def test_the_stack_panel_offers_what_the_live_path_takes(layout):
    """Every live parameter of the default material's layers has its control (a conductor's optional F82 tint
    and the interfaces' anisotropy too); the brushing rotation shows only once a layer is anisotropic."""
    assert {"roughness", "ior", "f82_tint", "anisotropy"} <= set(layout["labels"]), layout["labels"]
    assert "brushing rotation" not in layout["labels"]


def test_window_opens_at_80_percent_of_the_screen_and_remembers(layout):
    assert layout["window"] == [1024, 640]
    assert layout["reopened"] == [900, 560]


def test_side_bars_cover_neither_each_other_nor_the_view(layout):
    (lm, sv), vp = layout["rects"].values(), layout["viewport"]
    w, h = layout["window"]
    assert not _overlap(lm, sv) and not _overlap(lm, vp) and not _overlap(sv, vp)
    for r in (lm, sv):
        assert r[0] >= 0 and r[0] + r[2] <= w and r[3] == h  # full-height bars inside the window
    assert vp[2] >= w / 2 and vp[3] == h  # the view keeps the rest: at least half the width


def test_object_is_framed_inside_the_view(layout):
    """The default sphere in the view left between the bars: inside with a margin, filling most of it."""
    x0, y0, x1, y1, aspect = layout["object_box"]
    assert min(x0, y0, 1 - x1, 1 - y1) > 0.05
    short = min(1.0, 1.0 / aspect)  # the shorter side, as a fraction of the width
    assert (x1 - x0) > 0.6 * short
