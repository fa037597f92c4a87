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


#: The context limits a render target's side must respect, with the names users can look up.
SIZE_LIMITS = ("GL_MAX_RENDERBUFFER_SIZE", "GL_MAX_TEXTURE_SIZE", "GL_MAX_VIEWPORT_DIMS")


def check_target_size(ctx: moderngl.Context, size: tuple[int, int], flag: str = "--size") -> None:
    """One line (``NbrdfError``) when this context cannot render a (w, h) image:
    a side beyond the context's reported limits, or a float render target of that
    size the driver refuses (software OpenGL caps a texture's bytes below its
    reported side limits: llvmpipe reports 16384 and refuses 12000 x 12000 RGBA32F)."""
    w, h = (int(v) for v in size)
    for name in SIZE_LIMITS:
        limit = ctx.info.get(name)
        if limit is None:
            continue
        lw, lh = (limit, limit) if isinstance(limit, int) else (int(limit[0]), int(limit[1]))
        if w > lw or h > lh:
            raise NbrdfError(f"{flag} {w}x{h}: this OpenGL context allows at most {lw}x{lh} ({name}, "
                             f"{describe(ctx)})")
    tex = depth = fbo = None
    try:  # the largest attachment the renderer makes: an RGBA32F target with a depth buffer
        tex = ctx.texture((w, h), 4, dtype="f4")
        depth = ctx.depth_renderbuffer((w, h))
        fbo = ctx.framebuffer([tex], depth)
    except Exception as e:  # noqa: BLE001 - any refusal is the same one-line answer
        gib = w * h * 16 / 2 ** 30
        raise NbrdfError(f"{flag} {w}x{h}: this OpenGL context cannot make a float render target that large "
                         f"({gib:.1f} GiB; reported limits {ctx.info.get('GL_MAX_RENDERBUFFER_SIZE')} per side, "
                         f"{describe(ctx)}: {str(e).splitlines()[0] if str(e) else type(e).__name__})") from None
    finally:
        for r in (fbo, depth, tex):
            if r is not None:
                r.release()
