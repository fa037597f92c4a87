"""The previewer without a window: the session ``nbrdf-view``'s options open,
rendered through EGL to an image file or a turntable. ``nbrdf-view
--offscreen`` runs this, and so does a window-less machine."""
from __future__ import annotations

import os
import sys
from pathlib import Path

from nbrdf.imaging.image_io import check_output, write_image
from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.gpu.gl import check_target_size, offscreen_context
from nbrdf.viewer.jobs.turntable import turntable_kind
from nbrdf.viewer.modes import View
from nbrdf.viewer.options import HEADLESS_OUT, ViewOptions
from nbrdf.viewer.session.lookdev import LookDev

PROG = "nbrdf-view"


def has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def render_offscreen(opts: ViewOptions, fallback: str | None = None) -> Path:
    """Renders the view through EGL and writes ``opts.out``: the session the
    options open (``LookDev.from_options``, as the window does) writes its image,
    turntable or (with ``--session``) its screenshot. As the fallback for a
    window (``fallback`` = why there is none, said in one line), it is a
    preview: on software OpenGL at most 256 x 256 and 32 passes (the default
    32 take about 20 s on two cores with the compute lit pass and leave 0.93 %
    relative noise; full size costs minutes)."""
    out = Path(opts.out or HEADLESS_OUT)
    if opts.turntable:
        turntable_kind(out)  # before minutes of rendering, not after
    else:
        check_output(out)
    ctx = offscreen_context()
    if fallback is not None:
        print(f"{PROG}: {fallback}; rendering offscreen to {out} instead{_preview(ctx, opts)}", file=sys.stderr)
    check_target_size(ctx, opts.size)  # before any rendering: one line naming the limit
    ld = LookDev.from_options(ctx, opts, brdf=opts.brdf, threaded=False)
    try:
        for note in ld.notes + ([ld.brdf_note] if ld.brdf_note else []):
            print(f"{PROG}: {note}", file=sys.stderr)
        if opts.session:
            if not ld.write_screenshot(out, opts.size, opts.spp):
                raise NbrdfError(ld.error or f"{opts.session}: cannot render the session")
        elif opts.turntable:
            ld.write_turntable(out, opts.turntable, opts.size, opts.spp)
        else:
            img = ld.render_linear(opts.size, opts.spp)
            if ld.state.view == View.LOBE and out.suffix.lower() == ".png":
                img = img[::-1]  # a picture shows +y up
            write_image(out, img, ld.state.exposure, ld.state.tonemap)
    finally:
        ld.close()
    return out


def _preview(ctx, opts: ViewOptions) -> str:
    """On software OpenGL, shrinks ``opts`` to a preview's size and passes; the note saying so."""
    if not any(k in ctx.info.get("GL_RENDERER", "").lower() for k in ("llvmpipe", "softpipe", "swrast")):
        return ""
    w, h = opts.size
    scale = min(1.0, 256 / max(w, h))
    size, spp = (max(1, round(w * scale)), max(1, round(h * scale))), min(opts.spp, 32)
    if (size, spp) == (opts.size, opts.spp):
        return ""
    opts.size, opts.spp = size, spp
    return f" (software OpenGL: a {size[0]}x{size[1]}, {spp}-pass preview)"

