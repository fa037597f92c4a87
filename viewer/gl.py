"""OpenGL contexts: offscreen through EGL (tests, batch renders, no display)
and version checks with one-line errors."""
from __future__ import annotations

import moderngl

from nbrdf.neural.errors import NbrdfError

MIN_VERSION = 330  # OpenGL 3.3 core: float textures, texelFetch, fragment shaders


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


def describe(ctx: moderngl.Context) -> str:
    return f"{ctx.info.get('GL_RENDERER', '?')} / OpenGL {ctx.info.get('GL_VERSION', '?')}"
