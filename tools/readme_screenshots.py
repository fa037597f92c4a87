"""The README's screenshots of the previewer: the main window and the compare
mode, rendered in a real window (run under Xvfb on a machine without a display):

    xvfb-run -s "-screen 0 1280x800x24" .venv/bin/python tools/readme_screenshots.py

The view renders at half the window's resolution (``--scale``) with 24 passes:
minutes on software OpenGL.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import imageio.v3 as iio

from nbrdf.viewer.app import App
from nbrdf.viewer.options import DEFAULT_MATERIAL, ViewOptions

OUT = Path(__file__).resolve().parents[1] / "docs" / "figures" / "viewer"


def settle(app: App, frames: int, passes: int = 1) -> None:
    for _ in range(frames):
        app.step(passes)


def main(size=(1100, 680), scale: float = 0.5, passes: int = 24, wait: float = 300.0) -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    app = App(ViewOptions(material=DEFAULT_MATERIAL, size=size), size=size)
    app._adapt_scale = lambda w, h: scale  # a fixed render scale: the picture, not the frame rate
    ld = app.lookdev
    try:
        settle(app, 3, passes // 3)
        iio.imwrite(OUT / "main_window.png", app.read_pixels())
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
    ap.add_argument("--scale", type=float, default=0.5)
    ap.add_argument("--passes", type=int, default=24)
    ap.add_argument("--wait", type=float, default=300.0, help="seconds to wait for the Monte Carlo reference")
    a = ap.parse_args()
    sys.exit(main(scale=a.scale, passes=a.passes, wait=a.wait))
