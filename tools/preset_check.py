"""Every bundled preset beside its reference, as the window's compare view shows
it (neural left, reference right, labelled), in one image grid: the check by eye
that a preset looks like its name and that what the previewer shows is the
material (run under Xvfb on a machine without a display):

    xvfb-run -s "-screen 0 1280x800x24" .venv/bin/python tools/preset_check.py

The reference side is the closed form for a single layer and the Monte Carlo
walk (the compare worker) for stacks, under the same environment and key light.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from nbrdf.viewer.gpu.labels import rasterise
from nbrdf.viewer.options import ViewOptions
from nbrdf.viewer.session.edits import presets
from nbrdf.viewer.ui.app import App

OUT = Path(__file__).resolve().parents[1] / "docs" / "figures" / "viewer" / "presets_vs_reference.png"


def shot(app: App, name: str, passes: int, wait: float) -> np.ndarray:
    """The compare view of preset ``name`` once its reference has arrived (or ``wait`` s passed)."""
    ld = app.lookdev
    if not ld.load_preset(name):
        raise SystemExit(f"preset_check: {name}: {ld.error}")
    ld.set_compare("side")
    for _ in range(passes):
        app.step(1)
    t0 = time.monotonic()
    while "..." in ld.reference_status() and time.monotonic() - t0 < wait:
        time.sleep(1)
        app.step(1)
    app.step(1)
    print(f"{name}: {ld.reference_status()}", flush=True)
    return named(app.read_pixels(), name)


def named(img: np.ndarray, name: str) -> np.ndarray:
    """``img`` (H, W, C uint8) with the preset's name in its bottom-left corner, white on a black box."""
    cov = rasterise(name, 14)[: img.shape[0], : img.shape[1]]
    out = img.copy()
    h, w = cov.shape
    box = out[-h - 4:-4, 4:4 + w, :3].astype(np.float32) * 0.3
    out[-h - 4:-4, 4:4 + w, :3] = np.maximum(box, cov[..., None]).astype(np.uint8)
    return out


def main(size: tuple[int, int], passes: int, wait: float, columns: int, skip: tuple[str, ...]) -> int:
    app = App(ViewOptions(size=size), size=size)
    app.panels.visible = False
    app._adapt_scale = lambda w, h: 1.0  # the picture at full resolution, not the frame rate
    try:
        tiles = [shot(app, name, passes, wait) for name in presets() if name not in skip]
    finally:
        app.close()
    h, w = tiles[0].shape[:2]
    rows = -(-len(tiles) // columns)
    grid = np.zeros((rows * h, columns * w, tiles[0].shape[2]), tiles[0].dtype)
    for k, t in enumerate(tiles):
        r, c = divmod(k, columns)
        grid[r * h:(r + 1) * h, c * w:(c + 1) * w] = t
    OUT.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(OUT, grid)
    print(f"{OUT}: {len(tiles)} presets")
    return 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="320x200", help="window size WxH of one tile")
    ap.add_argument("--passes", type=int, default=48, help="passes of the neural side before the reference is awaited")
    ap.add_argument("--wait", type=float, default=120.0, help="seconds to wait for each Monte Carlo reference")
    ap.add_argument("--columns", type=int, default=3)
    ap.add_argument("--skip", default="worn_tiles", help="comma-separated presets left out (texture-mapped: no reference)")
    a = ap.parse_args()
    w, h = (int(x) for x in a.size.lower().split("x"))
    sys.exit(main((w, h), a.passes, a.wait, a.columns, tuple(s for s in a.skip.split(",") if s)))
