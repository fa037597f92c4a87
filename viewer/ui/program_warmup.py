"""Shader variants compiled while the window is idle, before a view needs them.

The renderer builds a program per (shader, BRDF kind) on first use
(viewer/gpu/programs.py). Each of the window's views reaches a few: the lit pass
of the object view for every kind a frame can shade with (closed form,
decoder at a latent, decoder at a latent texture, baked body table), the
lobe and slice views for every kind but the table (and Belcour's model once
the session has used it). Built on first use, a
variant costs the frame that first needs it a compile (hundreds of
milliseconds on llvmpipe): the first compare of a single-layer material, the
first glTF file with a texture-mapped part. ``ProgramWarmup`` builds them one
per frame once the window has had no edit, view change or input for
``idle_s``, so the window's live programs are complete early in a session
and a later edit compiles nothing. The first frame is never delayed: nothing
is built before the window has been idle after it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.gpu.env_prefilter import DEFINE as ENV_TABLE_DEFINE
from nbrdf.viewer.gpu.pipeline import BrdfKind, GpuBrdf
from nbrdf.viewer.gpu.programs import GLSL_430, ProgramKey

if TYPE_CHECKING:
    from nbrdf.neural.material import Material
    from nbrdf.viewer.gpu.neural_gpu import GpuDecoder
    from nbrdf.viewer.gpu.renderer import Renderer

#: The kinds the lobe and slice views draw (a baked table shades the object view only).
VIEW_KINDS = (BrdfKind.ANALYTIC, BrdfKind.BELCOUR, BrdfKind.NEURAL, BrdfKind.TEXTURED)
#: The kinds whose programs compile the decoder in.
NEURAL_KINDS = (BrdfKind.NEURAL, BrdfKind.TEXTURED, BrdfKind.TABLE)


@dataclass
class WarmupSettings:
    """When the window compiles the variants it has not used yet."""

    enabled: bool = True
    """False: every variant is compiled on first use only."""
    idle_s: float = 1.0
    """Seconds without an edit, a view change or input before a variant is compiled
    (one per frame; a compile then delays a view that is not changing)."""


def reachable(renderer: "Renderer", decoder: "GpuDecoder | None", tables: bool,
              material: "Material", belcour: bool = False) -> list[tuple[ProgramKey, GpuBrdf]]:
    """Every (key, BRDF of its kind) the window's views can draw with on ``renderer``'s
    path (deferred compute or fragment): neural kinds only once the ``decoder`` exists,
    the table kind only where frames are shaded from baked ``tables``, Belcour's model
    once the session has shaded with it (``belcour``). The BRDFs stand in for their kind
    (``material`` is any: a program's source depends on the kind and the decoder only)."""
    kinds = [BrdfKind.ANALYTIC] + ([BrdfKind.BELCOUR] if belcour else [])
    if decoder is not None:
        kinds += [BrdfKind.NEURAL, BrdfKind.TEXTURED] + ([BrdfKind.TABLE] if tables else [])
    brdfs = {k: GpuBrdf(material, k, decoder=decoder if k in NEURAL_KINDS else None) for k in kinds}
    out: list[tuple[ProgramKey, GpuBrdf | None]] = []
    if renderer.deferred:
        # the G-buffer's program, and its own for plain surfaces (no normal map, no latent texture)
        out += [(ProgramKey("gbuffer_lit.frag", "object.vert", defines=d, version=GLSL_430), None)
                for d in ((), (("NB_PLAIN_SURFACE", 1),))]
        # the lit pass's program as the passes pick it (a program of its own per estimator, lit_passes.py)
        out += [(ProgramKey.of("lit.comp", b, vertex=None, defines=renderer.lit.specialised(b)), b)
                for b in brdfs.values()]
        if BrdfKind.TABLE in brdfs and (renderer.settings.prefilter or renderer.settings.quick_prefilter):  # body maps
            b = brdfs[BrdfKind.TABLE]
            out += [(ProgramKey.of(name, b, vertex=None, defines=ENV_TABLE_DEFINE), b)
                    for name in ("env_prefilter.comp", "lit.comp")]
        for k in VIEW_KINDS:
            if k in brdfs:
                for defines in ({"VIEW_IS_LOBE": 1}, None):
                    out.append((ProgramKey.of("view.comp", brdfs[k], vertex=None, defines=defines), brdfs[k]))
    else:
        out += [(ProgramKey.of("object.frag", b, vertex="object.vert"), b) for b in brdfs.values()]
        for k in VIEW_KINDS:
            if k in brdfs:
                out += [(ProgramKey.of(f, brdfs[k]), brdfs[k]) for f in ("lobe.frag", "slice.frag")]
    out.append((ProgramKey("gbuffer.frag", "object.vert"), None))  # references' G-buffer, material picking
    return out


class ProgramWarmup:
    """Builds the window's reachable variants on idle frames (module docstring)."""

    def __init__(self, renderer: "Renderer", variants: Callable[[], list[tuple[ProgramKey, GpuBrdf | None]]],
                 settings: WarmupSettings | None = None):
        """``variants``: the reachable (key, BRDF) pairs as the session stands now
        (asked again each time: a decoder made later adds the neural kinds)."""
        self.renderer = renderer
        self.variants = variants
        self.settings = settings or WarmupSettings()
        self.built: list[ProgramKey] = []
        """The variants this warm-up built (not those the views built first)."""
        self.failed: dict[ProgramKey, str] = {}
        """Variants whose build failed, with the one-line error (a view needing one reports it itself)."""
        self._changed_at = time.monotonic()

    def pending(self) -> list[tuple[ProgramKey, GpuBrdf | None]]:
        """The reachable variants neither built nor failed yet."""
        cache = self.renderer.programs
        return [(k, b) for k, b in self.variants() if k not in cache and k not in self.failed]

    @property
    def done(self) -> bool:
        return not self.pending()

    def frame(self, changed: bool, now: float | None = None) -> ProgramKey | None:
        """Call once per presented frame; ``changed``: this frame followed an edit, a view
        change or input. Builds one pending variant once the window has been idle for
        ``idle_s``; returns its key (None: nothing built)."""
        now = time.monotonic() if now is None else now
        if changed:
            self._changed_at = now
            return None
        if not self.settings.enabled or now - self._changed_at < self.settings.idle_s:
            return None
        todo = self.pending()
        if not todo:
            return None
        key, brdf = todo[0]
        try:
            self.renderer.programs.get(key, brdf)
        except NbrdfError as e:
            self.failed[key] = str(e)
            return None
        self.built.append(key)
        return key
