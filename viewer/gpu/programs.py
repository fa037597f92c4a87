"""The renderer's shader programs: what one is built from (``ProgramKey``, a
small frozen record that is also its cache key), the one place its source is
assembled (``assemble``: the shader file with the BRDF's kind filled in for
``//@INCLUDE brdf``), and the cache (``ProgramCache``)."""
from __future__ import annotations

from dataclasses import dataclass

import moderngl

from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.gpu import shaders
from nbrdf.viewer.gpu.belcour_gpu import brdf_snippet, kinds_snippet
from nbrdf.viewer.gpu.neural_gpu import WeightStorage
from nbrdf.viewer.gpu.pipeline import BrdfKind, GpuBrdf, body_scale_defines

#: The define of an anisotropic code's programs (anisotropy.glsl; the shading frame follows the tangent).
ANISO_DEFINE = "NB_ANISO"
#: The GLSL version line of compute shaders and of the G-buffer the compute lit pass reads.
GLSL_430 = "#version 430 core"


@dataclass(frozen=True)
class ProgramKey:
    """What one program is built from."""

    shader: str
    """The fragment shader's file, or the compute shader's (``vertex`` None)."""
    vertex: str | None = "fullscreen.vert"
    """The vertex shader's file (None: a compute shader)."""
    kind: BrdfKind | None = None
    """The BRDF compiled in for ``//@INCLUDE brdf`` (None: none)."""
    decoder: int = 0
    """Which decoder on the GPU a neural kind compiles in (its id; 0 otherwise)."""
    storage: WeightStorage | None = None
    """Where a neural compute shader reads the weights (None: the decoder's default)."""
    defines: tuple[tuple[str, object], ...] = ()
    """Extra ``#define`` lines, sorted by name."""
    version: str | None = None
    """The GLSL version line (None: the shader kind's default)."""

    @classmethod
    def of(cls, shader: str, brdf: GpuBrdf | None = None, vertex: str | None = "fullscreen.vert",
           defines: dict | None = None, version: str | None = None) -> "ProgramKey":
        """The key of ``shader`` for ``brdf``'s kind (a compute shader when ``vertex`` is None)."""
        neural = brdf is not None and brdf.neural
        storage = brdf.decoder.compute_storage if neural and vertex is None else None
        if brdf is not None and brdf.anisotropic:
            defines = {**(defines or {}), ANISO_DEFINE: 1}
        if brdf is not None and brdf.neural and brdf.body_scale is not None:
            defines = {**(defines or {}), **body_scale_defines(brdf.body_scale)}
        return cls(shader, vertex, None if brdf is None else brdf.kind, id(brdf.decoder) if neural else 0,
                   storage, tuple(sorted((defines or {}).items())), version)

    @property
    def compute(self) -> bool:
        return self.vertex is None


def neural_snippets(brdf: GpuBrdf) -> tuple[dict[str, str], dict[str, object]]:
    """The ``brdf`` snippet of a neural kind and its defines: the decoder (at a
    uniform latent or a latent texture), or the baked body table (NB_BODY_TABLE,
    no decoder compiled in). The decoder at a uniform latent compiles the table in
    too, as the lit pass's resampling target (NB_GUIDE_TABLE, viewer/gpu/body_guide.py)."""
    code = shaders.read("neural_brdf.glsl")
    if brdf.kind == BrdfKind.TEXTURED:
        code = shaders.read("latent_texture.glsl") + "\n" + code
    if brdf.kind == BrdfKind.TABLE:
        return {"brdf": code, "neural_decoder.glsl": ""}, {"NB_BODY_TABLE": 1}
    if brdf.kind == BrdfKind.NEURAL:
        return {"brdf": code}, {"NB_GUIDE_TABLE": 1}
    return {"brdf": code, "body_table.glsl": ""}, {}


def assemble(key: ProgramKey, brdf: GpuBrdf | None) -> str:
    """The source of ``key``'s shader with ``brdf`` (of ``key.kind``) filled in:
    the closed form, Belcour's model, or the decoder (weights where ``key.storage`` says) with
    its snippets; None: the shader as it is."""
    defines = dict(key.defines) or None
    version = key.version or (GLSL_430 if key.compute else shaders.VERSION)
    if brdf is None:
        return shaders.source(key.shader, version=version, defines=defines)
    if brdf.kind == BrdfKind.ANALYTIC:
        return shaders.source(key.shader, {"brdf": shaders.read("analytic_brdf.glsl")}, version=version,
                              defines=defines)
    if brdf.kind == BrdfKind.BELCOUR:
        return shaders.source(key.shader, {"brdf": brdf_snippet(), "belcour_kinds": kinds_snippet()},
                              version=version, defines=defines)
    snippets, extra = neural_snippets(brdf)
    return brdf.decoder.source(key.shader, snippets, storage=key.storage, defines={**extra, **(defines or {})})


class ProgramCache:
    """Programs and compute shaders built on first use and kept, by ``ProgramKey``."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self._programs: dict[ProgramKey, moderngl.Program | moderngl.ComputeShader] = {}

    def __contains__(self, key: ProgramKey) -> bool:
        return key in self._programs

    def __len__(self) -> int:
        return len(self._programs)

    def get(self, key: ProgramKey, brdf: GpuBrdf | None = None):
        """The program of ``key`` (``brdf``: the BRDF of ``key.kind``, for its source)."""
        if key not in self._programs:
            self._programs[key] = self._build(key, brdf)
        return self._programs[key]

    def _build(self, key: ProgramKey, brdf: GpuBrdf | None):
        src = assemble(key, brdf)
        try:
            if key.compute:
                return self.ctx.compute_shader(src)
            return self.ctx.program(vertex_shader=shaders.source(key.vertex), fragment_shader=src)
        except moderngl.Error as e:
            raise NbrdfError(f"{'compute ' if key.compute else ''}shader build failed on "
                             f"{self.ctx.info.get('GL_RENDERER', '?')}: {str(e).splitlines()[0]}") from None
