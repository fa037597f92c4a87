"""The README's screenshots of the previewer, taken in a real window as a person
uses it (run under Xvfb on a machine without a display):

    xvfb-run -s "-screen 0 1920x1080x24" .venv/bin/python tools/readme_screenshots.py --size 1920x1080

The main window converged (``--passes`` at ``--scale`` of the view), a slider
edit as the window shows it at once and after ``--settle`` seconds of its own
progressive refinement, the compare mode against the Monte Carlo reference
(labelled halves), and the lobe view: minutes on software OpenGL.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import imageio.v3 as iio

from nbrdf.viewer.options import DEFAULT_MATERIAL, ViewOptions
from nbrdf.viewer.ui.app import App

OUT = Path(__file__).resolve().parents[1] / "docs" / "figures" / "viewer"


def settle(app: App, frames: int, passes: int = 1) -> None:
    for _ in range(frames):
        app.step(passes)


def main(size=(1100, 680), scale: float = 0.5, passes: int = 24, wait: float = 300.0,
         settle_s: float = 10.0) -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    app = App(ViewOptions(material=DEFAULT_MATERIAL, size=size), size=size)
    ld = app.lookdev
    try:
        # A slider edit as the window shows it: the frame right after, then the still view refining itself.
        settle(app, 2)
        base = ld.editor.doc["layers"][-1]
        ld.set_param(len(ld.editor.doc["layers"]) - 1, "roughness", min(1.0, base["roughness"] + 0.25))
        app.step()
        iio.imwrite(OUT / "edit_at_once.png", app.read_pixels())
        t0 = time.monotonic()
        while time.monotonic() - t0 < settle_s:
            app.step()
        iio.imwrite(OUT / f"edit_after_{int(settle_s)}s.png", app.read_pixels())
        assert ld.undo(), ld.error
        # The converged main window, at a fixed render scale (the picture, not the frame rate).
        app._adapt_scale = lambda w, h: scale
        settle(app, 3, passes // 3)
        iio.imwrite(OUT / "main_window.png", app.read_pixels())
        ld.set_view("lobe")
        settle(app, 2)
        iio.imwrite(OUT / "lobe_view.png", app.read_pixels())
        ld.set_view("object")
        ld.set_compare("side")
        settle(app, 1, passes)
        t0 = time.monotonic()
        while "..." in ld.reference_status() and time.monotonic() - t0 < wait:
            time.sleep(2)
            app.step(1)
        settle(app, 1)
        iio.imwrite(OUT / "compare_mode.png", app.read_pixels())
        print(ld.reference_status())
    finally:
        app.close()
    return 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="1100x680", help="window size WxH")
    ap.add_argument("--settle", type=float, default=10.0, help="seconds the edited view refines on its own")
    ap.add_argument("--scale", type=float, default=0.5)
    ap.add_argument("--passes", type=int, default=24)
    ap.add_argument("--wait", type=float, default=300.0, help="seconds to wait for the Monte Carlo reference")
    a = ap.parse_args()
    w, h = (int(x) for x in a.size.lower().split("x"))
    sys.exit(main(size=(w, h), scale=a.scale, passes=a.passes, wait=a.wait, settle_s=a.settle))
