"""``nbrdf export MATERIAL --glsl OUT.glsl``: a material for other renderers,
as one self-contained GLSL include (``viewer.glsl_export``)."""
from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path

from nbrdf.cli.common import out_path
from nbrdf.cli.config import add_arguments, build
from nbrdf.neural.errors import NbrdfError


@dataclass
class ExportConfig:
    """``nbrdf export``: a material as a self-contained GLSL include (nbrdf_eval, nbrdf_sample, nbrdf_pdf)."""

    glsl: str
    """output .glsl: the decoder's weights, the material's code and its coat as constants, plus its sampler"""
    material: str | None = field(default=None, metadata={"positional": True, "metavar": "MATERIAL"})
    """material JSON (SPEC section 4) or a code file from `nbrdf project` (required)"""
    model: str | None = None
    """bundle (default: the shipped weights)"""


def cmd_export(a: argparse.Namespace) -> int:
    from nbrdf.neural.material_code import load_code  # late: torch costs ~1 s, --help needs none
    from nbrdf.viewer.glsl_export import export_glsl  # late: the previewer's shaders and torch, as above

    c: ExportConfig = build(ExportConfig, a)
    if not c.material:
        raise NbrdfError("export: give a MATERIAL (a material JSON or a code file)")
    out = out_path(c.glsl, (".glsl",))
    model, code = load_code(c.material, c.model)
    out.write_text(export_glsl(model, code, Path(c.material).name))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Adds ``export`` to the ``nbrdf`` subcommands."""
    p = sub.add_parser("export", help="a material for other renderers (GLSL)", description=ExportConfig.__doc__)
    add_arguments(p, ExportConfig)
    p.set_defaults(fn=cmd_export)
