"""OpenGL contexts: offscreen through EGL (tests, batch renders, no display)
and version checks with one-line errors."""
from __future__ import annotations

import os
import sys

import moderngl

from nbrdf.neural.errors import NbrdfError

MIN_VERSION = 330  # OpenGL 3.3 core: float textures, texelFetch, fragment shaders
COMPUTE_VERSION = 430  # OpenGL 4.3 core: compute shaders, images, SSBOs (the deferred lit path)
#: Set to 1 to force the fragment-shader lit path where compute shaders exist (tests, comparisons).
FRAGMENT_ENV = "NBRDF_FRAGMENT_PATH"
_noticed: set[str] = set()


def offscreen_context() -> moderngl.Context:
    """A standalone OpenGL context through EGL (Mesa llvmpipe without a GPU)."""
    try:
        ctx = moderngl.create_context(standalone=True, backend="egl", require=MIN_VERSION)
    except Exception as e:  # noqa: BLE001 - any failure here is an environment problem
        raise NbrdfError(f"no offscreen OpenGL {MIN_VERSION // 100}.{MIN_VERSION % 100 // 10} context through EGL "
                         f"({str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__}); "
                         "install Mesa's EGL (apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri)") from None
    check_version(ctx)
    return ctx


def check_version(ctx: moderngl.Context, need: int = MIN_VERSION, what: str = "the renderer") -> None:
    if ctx.version_code < need:
        raise NbrdfError(f"{what} needs OpenGL {need // 100}.{need % 100 // 10}; this context offers "
                         f"{ctx.info.get('GL_VERSION', ctx.version_code)}")


#: GLSL extensions with 16-bit float arithmetic (probed at run time; Mesa llvmpipe has none).
HALF_FLOAT_EXTENSIONS = ("GL_NV_gpu_shader5", "GL_AMD_gpu_shader_half_float",
                         "GL_EXT_shader_explicit_arithmetic_types_float16")


def half_float_extensions(ctx: moderngl.Context) -> list[str]:
    """Those of ``HALF_FLOAT_EXTENSIONS`` this context offers."""
    have = set(ctx.extensions)
    return [e for e in HALF_FLOAT_EXTENSIONS if e in have]


def describe(ctx: moderngl.Context) -> str:
    return f"{ctx.info.get('GL_RENDERER', '?')} / OpenGL {ctx.info.get('GL_VERSION', '?')}"


def use_compute(ctx: moderngl.Context, want: bool | None = None) -> bool:
    """Whether the lit view shades in the deferred compute pass (OpenGL 4.3)
    rather than in fragment shaders. ``want`` None: wherever the context has
    compute shaders and ``NBRDF_FRAGMENT_PATH`` is not set; False: never; True:
    required. Choosing the fallback prints one notice line on stderr (once per reason)."""
    if want is False:
        return False
    if ctx.version_code < COMPUTE_VERSION:
        if want:
            check_version(ctx, COMPUTE_VERSION, "the deferred compute lit path")
        _notice(f"nbrdf: OpenGL {ctx.info.get('GL_VERSION', ctx.version_code)} has no compute shaders (4.3): "
                "the lit view shades in fragment shaders (slower fallback)")
        return False
    if want is None and os.environ.get(FRAGMENT_ENV, "") not in ("", "0"):
        _notice(f"nbrdf: {FRAGMENT_ENV} is set: the lit view shades in fragment shaders (fallback path)")
        return False
    return True


def _notice(line: str) -> None:
    if line not in _noticed:
        _noticed.add(line)
        print(line, file=sys.stderr)
