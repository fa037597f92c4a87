"""Whether a large texture fits, asked before it is made.

A texture-mapped material's latent texture becomes a float texture array of
3 x width / 4 + 1 RGBA layers with its mip chain (viewer/gpu/neural_gpu.py), made
from a per-texel share of the decoder's first layer computed on the CPU: a
2048 x 2048 map is gigabytes. OpenGL does not fail loudly on a texture over its
limits (moderngl makes it and leaves GL_INVALID_VALUE behind, the material then
shades black), and an allocation over the machine's memory ends the process.
``check_texture`` says in one line which limit a texture would exceed, before
any of it is allocated.
"""
from __future__ import annotations

import moderngl

from nbrdf.neural.errors import NbrdfError

#: Bytes of one RGBA32F texel.
RGBA32F = 16


def available_bytes() -> int | None:
    """The memory the machine can still hand out (``MemAvailable``, Linux); None where unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def texture_limits(ctx: moderngl.Context) -> tuple[int, int]:
    """(texels per side, layers of an array texture) this context allows."""
    info = ctx.info
    return int(info.get("GL_MAX_TEXTURE_SIZE", 2048)), int(info.get("GL_MAX_ARRAY_TEXTURE_LAYERS", 256))


def _gb(n: float) -> str:
    return f"{n / 2**30:.1f} GB" if n >= 2**30 else f"{n / 2**20:.0f} MB"


def check_texture(ctx: moderngl.Context, what: str, size: tuple[int, int], layers: int = 1,
                  staging_bytes: int = 0, mipmaps: bool = True) -> None:
    """Raises a one-line ``NbrdfError`` when an RGBA32F texture (array) of ``size``
    (height, width) and ``layers`` exceeds the context's size limits, or when it
    and the CPU memory that prepares it (``staging_bytes``) exceed the memory
    available now. The texture's bytes count against the machine's memory too:
    software OpenGL keeps textures there, and a GPU driver keeps a copy while uploading."""
    h, w = size
    side, max_layers = texture_limits(ctx)
    if max(h, w) > side:
        raise NbrdfError(f"{what} {w}x{h}: larger than this OpenGL's texture limit of {side} texels per side "
                         "(GL_MAX_TEXTURE_SIZE); use smaller maps")
    if layers > max_layers:
        raise NbrdfError(f"{what}: {layers} layers exceed this OpenGL's limit of {max_layers} "
                         "(GL_MAX_ARRAY_TEXTURE_LAYERS)")
    need = h * w * layers * RGBA32F * (4 / 3 if mipmaps else 1.0) + staging_bytes
    free = available_bytes()
    if free is not None and need > free:
        raise NbrdfError(f"{what} {w}x{h}: needs {_gb(need)} of memory to build and upload, {_gb(free)} "
                         "available; use smaller maps")


def raise_if_gl_out_of_memory(ctx: moderngl.Context, what: str) -> None:
    """One line for an allocation the GL refused (its error flag after the upload)."""
    err = ctx.error
    if err in ("GL_OUT_OF_MEMORY", "GL_INVALID_VALUE"):
        raise NbrdfError(f"{what}: the OpenGL driver could not allocate it ({err})")


__all__ = ["available_bytes", "check_texture", "raise_if_gl_out_of_memory", "texture_limits"]
