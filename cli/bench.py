"""``nbrdf bench reference|render|app|operations|mitsuba``: speed benchmarks, each
printed as one JSON object (the measuring code lives in the library)."""
from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, field
from pathlib import Path

import nbrdf.viewer
from nbrdf.cli.common import at_least, model_or_default
from nbrdf.cli.config import Parser, add_arguments, build
from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.options import parse_size


@dataclass
class ReferenceBench:
    """``nbrdf bench reference``: Monte Carlo paths per second and time to a converged lobe."""

    quick: bool = False
    """a short run (for tests)"""


@dataclass
class RenderBench:
    """``nbrdf bench render``: GLSL decoder and full shading frame times, GLSL vs torch throughput."""

    size: tuple[int, int] = field(default=(1920, 1080), metadata={"parse": parse_size, "shown": "1920x1080",
                                                                    "metavar": "WxH"})
    """size of the timed frames"""
    repeats: int = 3
    """timed frames per measurement (the median is reported)"""
    storages: str = "texture,ssbo,ubo,const"
    """compute-shader weight storages timed, comma-separated (texture, ssbo, ubo, const)"""


@dataclass
class AppBench:
    """``nbrdf bench app``: the window's frame times (edits, and the interface while the still view accumulates),
    slider-to-frame and click-to-frame latency (needs a display; the keys: viewer/ui/bench_app.py ``bench_app``)."""

    size: tuple[int, int] = field(default=(1000, 620), metadata={"parse": parse_size, "shown": "1000x620",
                                                                   "metavar": "WxH"})
    """size of the window"""
    edits: int = 8
    """slider edits timed"""
    material: str = ""
    """the material the window opens (default: the previewer's default, varnished copper); its base's roughness
    is the slider"""


@dataclass
class OperationsBench:
    """``nbrdf bench operations``: CPU latency of leaf encoders and layering (what a slider runs)."""

    model: str | None = None
    """bundle (default: the shipped weights)"""
    repeats: int = 1000
    """timed calls per operation"""


@dataclass
class MitsubaBench:
    """``nbrdf bench mitsuba``: RGB evaluations per second of the nbrdf BSDF inside Mitsuba's kernel, and of torch."""

    material: str = ""
    """material JSON or code file (default: the bundled three-layer car paint)"""
    pairs: int = 1 << 20
    """direction pairs per timed wavefront"""
    repeats: int = 5
    """timed runs (the median is reported)"""


def cmd_bench_reference(a: argparse.Namespace) -> int:
    from nbrdf.training.bench import bench_reference  # late: torch and the compiled walk, --help needs neither

    c: ReferenceBench = build(ReferenceBench, a)
    print(json.dumps(bench_reference(quick=c.quick), indent=2))
    return 0


def cmd_bench_render(a: argparse.Namespace) -> int:
    from nbrdf.viewer.bench import bench_render  # late: moderngl and torch, --help needs neither

    c: RenderBench = build(RenderBench, a)
    at_least("--repeats", c.repeats)
    storages = tuple(x.strip() for x in c.storages.split(",") if x.strip())
    print(json.dumps(bench_render(c.size, repeats=c.repeats, storages=storages), indent=2))
    return 0


def cmd_bench_app(a: argparse.Namespace) -> int:
    from nbrdf.viewer import offscreen  # late: the previewer (GL, torch), --help needs none
    from nbrdf.viewer.ui.bench_app import bench_app  # late: the window (glfw, imgui)

    if not offscreen.has_display():
        raise NbrdfError("bench app: no display (run it under xvfb-run on a headless machine)")
    c: AppBench = build(AppBench, a)
    at_least("--edits", c.edits)
    print(json.dumps(bench_app(c.size, c.edits, material=c.material or None), indent=2))
    return 0


def cmd_bench_operations(a: argparse.Namespace) -> int:
    from nbrdf.neural.bench import bench_operations  # late: torch costs ~1 s, --help needs none

    c: OperationsBench = build(OperationsBench, a)
    at_least("--repeats", c.repeats)
    print(json.dumps(bench_operations(model_or_default(c.model), c.repeats), indent=2))
    return 0


def cmd_bench_mitsuba(a: argparse.Namespace) -> int:
    c: MitsubaBench = build(MitsubaBench, a)
    at_least("--pairs", c.pairs)
    at_least("--repeats", c.repeats)
    try:
        from nbrdf.mitsuba import bench, bsdf  # optional: mitsuba
    except ModuleNotFoundError as e:
        raise NbrdfError(f"bench mitsuba: {e.name} is not installed (pip install -e '.[mitsuba]')") from None
    except ImportError as e:
        raise NbrdfError(f"bench mitsuba: {e}") from None
    material = c.material or str(Path(nbrdf.viewer.__file__).parent / "assets" / "materials" / "car_paint.json")
    try:
        print(json.dumps(bench.bench_mitsuba(material, c.pairs, c.repeats, torch_n=min(c.pairs, 1 << 16)),
                         indent=2))
    except (bsdf.PluginError, RuntimeError) as e:
        raise NbrdfError(str(e).strip().splitlines()[-1].removeprefix("PluginError: ").removeprefix("nbrdf: ")) from None
    return 0


#: ``nbrdf bench`` subcommands: name -> (config, command).
BENCHES = {
    "reference": (ReferenceBench, cmd_bench_reference),
    "render": (RenderBench, cmd_bench_render),
    "app": (AppBench, cmd_bench_app),
    "operations": (OperationsBench, cmd_bench_operations),
    "mitsuba": (MitsubaBench, cmd_bench_mitsuba),
}


def register(sub: argparse._SubParsersAction) -> None:
    """Adds ``bench`` and its subcommands to the ``nbrdf`` subcommands."""
    b = sub.add_parser("bench", help="speed benchmarks, printed as JSON")
    bsub = b.add_subparsers(dest="what", required=True, parser_class=Parser)
    for name, (cls, fn) in BENCHES.items():
        doc = (cls.__doc__ or ": ").split(": ", 1)[1]
        p = bsub.add_parser(name, help=doc.rstrip("."), description=cls.__doc__)
        add_arguments(p, cls)
        p.set_defaults(fn=fn)
