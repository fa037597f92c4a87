"""The README's screenshots of the previewer: the main window and the compare
mode, rendered in a real window (run under Xvfb on a machine without a display):

    xvfb-run -s "-screen 0 1280x800x24" .venv/bin/python tools/readme_screenshots.py

Full resolution and several passes: minutes on software OpenGL.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import imageio.v3 as iio

from nbrdf.viewer.app import App
from nbrdf.viewer.options import DEFAULT_MATERIAL, ViewOptions

OUT = Path(__file__).resolve().parents[1] / "docs" / "figures" / "viewer"


def settle(app: App, frames: int) -> None:
    for _ in range(frames):
        app.step()


def main(size=(1000, 620)) -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    app = App(ViewOptions(material=DEFAULT_MATERIAL, size=size), size=size)
    app.BUDGET_STILL_MS = app.BUDGET_DRAG_MS = 1e9  # full resolution for the picture
    ld = app.lookdev
    try:
        ld.state.camera.distance = 3.6
        ld.invalidate()
        settle(app, 6)
        iio.imwrite(OUT / "main_window.png", app.read_pixels())
        ld.set_compare("side")
        settle(app, 1)
        t0 = time.monotonic()
        while "..." in ld.reference_status() and time.monotonic() - t0 < 240:
            time.sleep(2)
            app.step()
        settle(app, 4)
        iio.imwrite(OUT / "compare_mode.png", app.read_pixels())
        print(ld.reference_status())
    finally:
        app.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
