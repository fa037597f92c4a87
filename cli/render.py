"""``nbrdf render SCENE --spp N --out IMAGE``: a scene path traced in Mitsuba 3
with the ``nbrdf`` materials (optional extra ``mitsuba``); ``nbrdf report
scenes`` lives in ``cli/report.py``."""
from __future__ import annotations

import argparse
from dataclasses import dataclass, field

from nbrdf.cli.common import progress
from nbrdf.cli.config import add_arguments, build
from nbrdf.imaging.image_io import check_output, write_image
from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.options import parse_size


@dataclass
class RenderConfig:
    """``nbrdf render``: a scene (JSON or preset) path traced in Mitsuba 3 with global illumination."""

    out: str
    """output image: .exr (linear) or .png (tone-mapped, see --tonemap)"""
    scene: str | None = field(default=None, metadata={"positional": True, "metavar": "SCENE"})
    """a scene JSON or a preset: still_life, teapot, globe, torus (required)"""
    spp: int = 64
    """samples per pixel"""
    size: tuple[int, int] = field(default=(320, 240), metadata={"parse": parse_size, "metavar": "WxH", "shown": "320x240"})
    """image size in pixels"""
    seed: int = 0
    """seed of the samplers"""
    chunk: int = 4
    """samples per pixel per Mitsuba pass (the progress bar's step)"""
    exposure: float = 0.0
    """PNG only: exposure in EV before tone mapping"""
    tonemap: str = field(default="neutral", metadata={"choices": ("linear", "aces", "agx", "neutral")})
    """PNG only: the display transform (the previewer's default: Khronos PBR Neutral)"""
    neural_body: str = field(default="decoder", metadata={"choices": ("decoder", "table")})
    """the nbrdf materials' body: decoder (the network in the kernel, Dr.Jit's wavefront mode) or table (baked
    once at load, no weights: renders in symbolic mode, several times faster on a CPU; materials a table
    cannot hold keep the decoder)"""


def cmd_render(a: argparse.Namespace) -> int:
    c: RenderConfig = build(RenderConfig, a)
    if not c.scene:
        raise NbrdfError("render: give a SCENE (a scene JSON or a preset: still_life, teapot, globe, torus)")
    out = check_output(c.out)
    if out.suffix.lower() not in (".exr", ".png"):
        raise NbrdfError(f"{c.out}: expected an .exr or .png output")
    if c.spp < 1 or c.chunk < 1:
        raise NbrdfError(f"--spp and --chunk must be at least 1 (got {c.spp}, {c.chunk})")
    try:
        from nbrdf.mitsuba import render, scenes  # optional: mitsuba
    except ModuleNotFoundError as e:
        if e.name not in ("mitsuba", "drjit"):
            raise
        raise NbrdfError("render: Mitsuba 3 is not installed (pip install -e '.[mitsuba]')") from None
    except ImportError as e:  # installed but unusable (no LLVM for its variant)
        raise NbrdfError(str(e)) from None
    scene = scenes.with_body(scenes.load_scene(c.scene), c.neural_body)
    with progress(c.spp, f"render {scene.name}", unit="spp", disable=False) as bar:
        res = render.render(scene, c.size, c.spp, seed=c.seed, chunk_spp=c.chunk,
                            progress=lambda n: bar.update(min(n, c.spp) - bar.n))
    write_image(out, res.image, exposure=c.exposure, mode=c.tonemap)
    print(f"{out}: {c.size[0]}x{c.size[1]}, {res.spp} spp in {res.seconds:.1f} s")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Adds ``render`` to the ``nbrdf`` subcommands."""
    p = sub.add_parser("render", help="path trace a scene in Mitsuba 3 (optional extra mitsuba)",
                       description=RenderConfig.__doc__)
    add_arguments(p, RenderConfig)
    p.set_defaults(fn=cmd_render)
