"""Belcour 2018 beside the neural path in the previewer: the figure an artist
looks at (each material rendered by ``nbrdf-view M --offscreen --brdf neural``
and ``--brdf belcour``, labelled, side by side) and the lit frame time of each
(the sphere filling a square frame, one pass of the default environment
estimator and one of the directional light alone; medians of interleaved runs,
so a change of load on a shared machine hits both alike):

    .venv/bin/python tools/belcour_compare.py figure
    .venv/bin/python tools/belcour_compare.py time --size 256 --repeats 7
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from nbrdf.viewer.gpu.labels import rasterise
from nbrdf.viewer.options import DEFAULT_MATERIAL

ASSETS = DEFAULT_MATERIAL.parent
MATERIALS = (("default", "varnished copper"), ("car_paint", "car paint (3 layers)"))
OUT = Path(__file__).resolve().parents[1] / "docs" / "figures" / "viewer" / "belcour_vs_neural.png"


def label(img: np.ndarray, text: str) -> np.ndarray:
    """``img`` (H, W, 3 uint8) with ``text`` in its top-left corner, white on a dimmed box."""
    cov = rasterise(text, 12)[: img.shape[0], : img.shape[1]]
    out = img.copy()
    h, w = cov.shape
    box = out[2:2 + h, 2:2 + w, :3].astype(np.float32) * 0.3
    out[2:2 + h, 2:2 + w, :3] = np.maximum(box, cov[..., None]).astype(np.uint8)
    return out


def figure(size: int, spp: int) -> int:
    from nbrdf.cli.view import main as view

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, title in MATERIALS:
            row = []
            for brdf in ("neural", "belcour"):
                out = Path(tmp) / f"{name}_{brdf}.png"
                if view([str(ASSETS / f"{name}.json"), "--offscreen", "--out", str(out), "--size", f"{size}x{size}",
                         "--spp", str(spp), "--brdf", brdf]) != 0:
                    return 2
                row.append(label(iio.imread(out)[..., :3], f"{title}: {'Belcour 2018' if brdf == 'belcour' else brdf}"))
            rows.append(np.concatenate(row, 1))
    OUT.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(OUT, np.concatenate(rows, 0))
    print(OUT)
    return 0


def time_frames(size: int, repeats: int) -> int:
    """Per material: ms of one environment pass and of one directional-light pass with
    Belcour's model, the per-pixel decoder and the decoder's body baked into the still
    table (what the window shades a still uniform material with on software OpenGL);
    wall time and this process's CPU time (llvmpipe's threads included: on a machine
    shared with other work, CPU time is the steadier measure)."""
    import time
    from dataclasses import replace

    from nbrdf.neural.material import load_material
    from nbrdf.viewer.gpu.body_table_gpu import STILL, BodyTables
    from nbrdf.viewer.gpu.gl import offscreen_context
    from nbrdf.viewer.gpu.pipeline import MaterialPipeline
    from nbrdf.viewer.gpu.renderer import Renderer
    from nbrdf.viewer.view_settings import ViewState

    ctx = offscreen_context()
    pipe = MaterialPipeline(ctx)
    tables = BodyTables(ctx)
    r = Renderer(ctx)
    result: dict[str, object] = {"size": size, "renderer": ctx.info.get("GL_RENDERER"),
                                 "compute_lit_path": r.deferred, "repeats": repeats}
    for name, _ in MATERIALS:
        m = load_material(ASSETS / f"{name}.json")
        neural = pipe.build(m, "neural")
        brdfs = {"belcour": pipe.build(m, "belcour"), "neural": neural, "neural_table": tables.brdf(neural, STILL)}
        runs = {}
        for key, state in (("env_pass", ViewState(env_on=True, background=False)),
                           ("one_light", ViewState(env_on=False, background=False))):
            state = replace(state)
            state.camera.distance = 2.2  # the sphere fills the frame
            for b, brdf in brdfs.items():
                def frame(state=state, brdf=brdf):
                    r.accumulate(state, size, size, 0, 1, brdf)
                    ctx.finish()
                runs[f"{b}_{key}"] = frame
        for fn in runs.values():  # warm-up: programs built
            fn()
        wall: dict[str, list[float]] = {k: [] for k in runs}
        cpu: dict[str, list[float]] = {k: [] for k in runs}
        for _ in range(repeats):  # interleaved: a change of load hits every path alike
            for k, fn in runs.items():
                t0, c0 = time.perf_counter(), time.process_time()
                fn()
                wall[k].append(time.perf_counter() - t0)
                cpu[k].append(time.process_time() - c0)
        result[name] = {k: {"wall_ms": round(1000 * float(np.median(wall[k])), 1),
                            "cpu_ms": round(1000 * float(np.median(cpu[k])), 1)} for k in runs}
    tables.release()
    pipe.release()
    print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="job", required=True)
    f = sub.add_parser("figure", help=f"write {OUT.name}")
    f.add_argument("--size", type=int, default=192, help="side of one tile, pixels")
    f.add_argument("--spp", type=int, default=16)
    t = sub.add_parser("time", help="lit frame times, Belcour against neural")
    t.add_argument("--size", type=int, default=256, help="side of the square frame, pixels")
    t.add_argument("--repeats", type=int, default=5, help="timed rounds (the median is reported)")
    a = ap.parse_args()
    sys.exit(figure(a.size, a.spp) if a.job == "figure" else time_frames(a.size, a.repeats))
