"""The preset browser in the window (Xvfb, through the app's API): every
bundled preset gets a thumbnail, drawn in the material panel; a second start
reads them all from the cache (none rendered). And what the preset lists say
(imgui recorded, no window): the materials' names, not their file names."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

SCRIPT = textwrap.dedent("""
    import json, sys
    import numpy as np
    from nbrdf.viewer.ui.app import App
    from nbrdf.viewer.options import ViewOptions
    size = (900, 700)
    app = App(ViewOptions(size=size), size=size)
    app._adapt_scale = lambda w, h: 0.125
    browser = app.panels.presets
    browser.default_open = True
    browser.cache.spp = 2
    out = {}
    try:
        for _ in range(40):
            app.step()
            if browser.pending() == 0:  # every thumbnail made (the header opened at once)
                break
        app.step()
        out = {"pending": browser.pending(), "failed": browser.failed, "rendered": browser.cache.rendered,
               "shown": len(browser._textures)}
        np.save(sys.argv[1] + ".npy", app.read_pixels())
        x0, y0, vw, vh = app.viewport()
        out["view_x"] = x0
    finally:
        app.close()
    json.dump(out, open(sys.argv[1], "w"))
""")


def _run(env, path):
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(path)], env=env, capture_output=True, text=True,
                       timeout=1200)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(path.read_text()), np.load(str(path) + ".npy")


@pytest.mark.gl
@pytest.mark.slow
def test_browser_shows_cached_thumbnails(xvfb_display, tmp_path):
    from nbrdf.viewer.session.edits import presets

    env = dict(os.environ, DISPLAY=xvfb_display, HOME=str(tmp_path), XDG_CACHE_HOME=str(tmp_path / "cache"))
    first, screen = _run(env, tmp_path / "a.json")
    n = len(presets())
    assert first["pending"] == 0 and first["failed"] == {} and first["shown"] == n and first["rendered"] == n
    assert len(list((tmp_path / "cache" / "nbrdf" / "thumbnails").glob("*.png"))) == n
    # The thumbnails are on screen in the left panel: gold presets put saturated warm pixels there.
    panel = screen[:, :first["view_x"]].astype(int)
    warm = (panel[..., 0] - panel[..., 2] > 60) & (panel[..., 0] > 120)
    assert warm.sum() > 200
    second, _ = _run(env, tmp_path / "b.json")
    assert second["shown"] == n and second["rendered"] == 0  # read from the cache, none rendered again


class RecordingImgui:
    """The imgui calls the preset lists make, recorded: every text a user can read
    (a label's part before "##", a tooltip, a line), and a click on the entry whose
    text is ``click``."""

    ImVec2 = staticmethod(lambda x, y: (x, y))
    ImTextureRef = staticmethod(lambda glo: glo)

    def __init__(self, click: str | None = None):
        self.click = click
        self.shown: list[str] = []
        self.ids: list[str] = []

    def _item(self, label: str) -> bool:
        text, _, ident = label.partition("##")
        self.shown.append(text)
        self.ids.append(ident)
        return text == self.click

    def button(self, label: str, size=None) -> bool:
        return self._item(label)

    def selectable(self, label: str, selected: bool) -> tuple[bool, bool]:
        return self._item(label), selected

    def set_tooltip(self, text: str) -> None:
        self.shown.append(text)

    def text(self, text: str) -> None:
        self.shown.append(text)

    def begin_combo(self, label: str, preview: str) -> bool:
        return True

    def is_item_hovered(self) -> bool:
        return True

    def __getattr__(self, name: str):  # layout calls (same_line, begin_group, end_combo, ...): nothing to record
        return lambda *args, **kwargs: None


class Session:
    """What the preset lists call on the session: the presets picked, by key."""

    def __init__(self):
        self.loaded: list[str] = []
        self.blended: list[str] = []

    def load_preset(self, key: str) -> bool:
        self.loaded.append(key)
        return True

    def set_interpolation(self, key: str) -> bool:
        self.blended.append(key)
        return True


def _names() -> dict[str, str]:
    """Each bundled preset's key (file stem) and the name its JSON gives."""
    from nbrdf.viewer.session.edits import presets

    return {key: json.loads(path.read_text())["name"] for key, path in presets().items()}


def test_the_browser_names_presets_by_their_materials(monkeypatch):
    """Without thumbnails yet, the browser's buttons and tooltips say the
    materials' names ("car paint (three layers)"), not the file names
    ("car_paint"); a click loads the preset by its key."""
    from nbrdf.viewer.ui import preset_browser
    from nbrdf.viewer.ui.preset_browser import PresetBrowser

    names = _names()
    assert names["car_paint"] == "car paint (three layers)"
    ui = RecordingImgui(click="car paint")  # the button (no thumbnail yet) says the name's start
    monkeypatch.setattr(preset_browser, "imgui", ui)
    session = Session()
    browser = PresetBrowser(session, cache=object())
    monkeypatch.setattr(browser, "_texture", lambda *args: None)  # no thumbnail: the fallback buttons
    browser.draw(columns=4)
    shown = " | ".join(ui.shown)
    for key, name in names.items():
        assert name in ui.shown, (name, shown)
        if key not in name:
            assert key not in shown, (key, shown)
    assert session.loaded == ["car_paint"]


def test_the_preset_lists_name_presets_by_their_materials(monkeypatch, tmp_path):
    """The "preset" and "blend with" lists say the materials' names and pick
    by key; a preset whose name is empty, missing or unreadable is listed by its
    file name."""
    from nbrdf.viewer.session import edits
    from nbrdf.viewer.ui import preset_browser

    ui = RecordingImgui(click="varnished copper")
    monkeypatch.setattr(preset_browser, "imgui", ui)
    session = Session()
    preset_browser.preset_combo("preset", "choose...", session.load_preset)
    assert ui.shown == list(_names().values()) and session.loaded == ["default"]
    preset_browser.preset_combo("blend with", "off", session.set_interpolation)
    assert session.blended == ["default"]

    (tmp_path / "plain.json").write_text(json.dumps({"format": "nbrdf-material/1", "name": " ", "layers": []}))
    (tmp_path / "anonymous.json").write_text(json.dumps({"format": "nbrdf-material/1", "layers": []}))
    (tmp_path / "broken.json").write_text("{not json")
    (tmp_path / "named.json").write_text(json.dumps({"name": "my lacquer", "layers": []}))
    monkeypatch.setattr(edits, "PRESETS_DIR", tmp_path)
    ui.shown.clear()
    preset_browser.preset_combo("preset", "choose...", session.load_preset)
    assert ui.shown == ["anonymous", "broken", "my lacquer", "plain"]
    assert ui.ids == [*ui.ids[:-4], "anonymous", "broken", "named", "plain"]  # imgui ids: the keys, unique
