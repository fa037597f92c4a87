"""``nbrdf export MATERIAL --glsl OUT.glsl | --mtlx OUT.mtlx``: a material for other renderers, as one
self-contained GLSL include (``viewer.glsl_export``) or as an OpenPBR Surface MaterialX document
(``neural.mtlx``)."""
from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path

from nbrdf.cli.common import out_path
from nbrdf.cli.config import add_arguments, build
from nbrdf.neural.errors import NbrdfError


@dataclass
class ExportConfig:
    """``nbrdf export``: a material as a self-contained GLSL include (nbrdf_eval, nbrdf_sample, nbrdf_pdf), or as
    an OpenPBR Surface MaterialX document."""

    glsl: str | None = None
    """output .glsl: the decoder's weights, the material's code and its coat as constants, plus its sampler (an
    OpenPBR mix: every stack's, summed with its weight)"""
    mtlx: str | None = None
    """output .mtlx: the material as OpenPBR Surface inputs (a material that came from OpenPBR: its own inputs)"""
    material: str | None = field(default=None, metadata={"positional": True, "metavar": "MATERIAL"})
    """material JSON (SPEC section 4), a MaterialX document (FILE.mtlx[#Name]) or a code file from `nbrdf project`
    (required)"""
    model: str | None = None
    """bundle (default: the shipped weights)"""
    calibrate: bool = False
    """--glsl: each layered stack's body takes the walk's energy (its directional albedo, walked once and cached:
    5-90 s the first time; the networks' is 2 % off at the median, up to 30 %)"""


def cmd_export(a: argparse.Namespace) -> int:
    from nbrdf.viewer.glsl_export import export_file_glsl  # late: the previewer's shaders and torch, --help needs none

    c: ExportConfig = build(ExportConfig, a)
    if not c.material:
        raise NbrdfError("export: give a MATERIAL (a material JSON, a .mtlx document or a code file)")
    if not c.glsl and not c.mtlx:
        raise NbrdfError("export: give --glsl OUT.glsl and/or --mtlx OUT.mtlx")
    if c.mtlx:
        export_mtlx(c.material, out_path(c.mtlx, (".mtlx",)))
    if c.glsl:
        out = out_path(c.glsl, (".glsl",))
        text, parts = export_file_glsl(c.material, c.model, c.calibrate)
        out.write_text(text)
        if parts:  # said: an OpenPBR mix is exported whole, not as the largest stack its layers hold
            shown = ", ".join(f"{name} {w:.2g}" for w, _, name in parts)
            print(f"wrote {out}: all {len(parts)} stacks of the OpenPBR mix, weighted: {shown}")
    return 0


def export_mtlx(material: str, out: Path) -> None:
    """Writes the material as an OpenPBR Surface document: the inputs it was made from when it came from
    OpenPBR (a round trip that changes nothing); for any other stack, the inputs that match it best in render
    space (``training.openpbr_fit``), with the fit's HDR-FLIP in the document's doc string and printed."""
    from nbrdf.neural.material import (  # late: torch costs ~1 s, --help needs none
        is_material_file,
        load_material,
        material_to_dict,
    )
    from nbrdf.neural.mtlx import write_material_mtlx, write_mtlx  # late: MaterialX, as above

    if not is_material_file(material):
        raise NbrdfError(f"{material}: --mtlx takes a material (JSON or .mtlx), not a code file")
    m = load_material(material)
    name = m.name or Path(material.split("#")[0]).stem
    if m.openpbr is not None:
        for note in write_material_mtlx(material_to_dict(m, out.parent), out,
                                        doc=f"exported by nbrdf from {Path(material).name}"):
            print(f"{out}: {note}")
        print(f"wrote {out} (the material's own OpenPBR inputs{', its base colour image' if m.is_textured else ''})")
        return
    from nbrdf.training.openpbr_fit import fit_openpbr  # late: the walk and FLIP, for a fit only

    fit = fit_openpbr(m)
    doc = (f"nbrdf: OpenPBR inputs fitted to the stack of {Path(material).name} on the lit sphere (SPEC section 9); "
           f"HDR-FLIP {fit.flip:.3f} against the stack's Monte Carlo reference (neural path {fit.neural_flip:.3f})")
    write_mtlx(fit.inputs, name, out, doc=doc)
    for note in fit.notes:
        print(f"{out}: {note}")
    print(f"wrote {out}: fitted OpenPBR inputs, HDR-FLIP {fit.flip:.3f} against the stack's reference")


def register(sub: argparse._SubParsersAction) -> None:
    """Adds ``export`` to the ``nbrdf`` subcommands."""
    p = sub.add_parser("export", help="a material for other renderers (GLSL, OpenPBR MaterialX)", description=ExportConfig.__doc__)
    add_arguments(p, ExportConfig)
    p.set_defaults(fn=cmd_export)
