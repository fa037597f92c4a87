"""GL state as scopes: a block draws with the state it names, and the state
after it is the previewer's resting state (blending off, depth compared with
"<", both write masks on), whatever the block did. Every draw of the renderer
goes through one of these instead of setting flags by hand."""
from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

import moderngl


def _rest(ctx: moderngl.Context) -> None:
    ctx.disable(moderngl.BLEND)
    ctx.depth_func = "<"


@contextmanager
def depth_tested(ctx: moderngl.Context) -> Iterator[None]:
    """Opaque drawing with the depth test ("<"), no blending (G-buffers, depth pre-passes)."""
    ctx.enable(moderngl.DEPTH_TEST)
    _rest(ctx)
    try:
        yield
    finally:
        _rest(ctx)


@contextmanager
def float_gbuffer(ctx: moderngl.Context, size: tuple[int, int],
                  count: int = 2) -> Iterator[list[moderngl.Texture]]:
    """A framebuffer of ``count`` RGBA float32 targets and a depth buffer at ``size``, bound and cleared (zeros,
    depth 1) for one G-buffer draw, released after it; yields the targets (to read back inside the block)."""
    targets = [ctx.texture(size, 4, dtype="f4") for _ in range(count)]
    depth = ctx.depth_renderbuffer(size)
    fbo = ctx.framebuffer(targets, depth)
    try:
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        yield targets
    finally:
        for r in (fbo, depth, *targets):
            r.release()


@contextmanager
def flat(ctx: moderngl.Context) -> Iterator[None]:
    """Full-screen passes: neither the depth test nor blending."""
    ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
    try:
        yield
    finally:
        _rest(ctx)


def _colour_mask(fbo: moderngl.Framebuffer, on: bool):
    """moderngl's colour mask: one RGBA tuple, or one per attachment when there are several."""
    n = len(fbo.color_attachments)
    return (on,) * 4 if n <= 1 else [(on,) * 4] * n


@contextmanager
def masked(fbo: moderngl.Framebuffer, color: bool = True, depth: bool = True) -> Iterator[moderngl.Framebuffer]:
    """``fbo`` bound with these write masks (moderngl applies a framebuffer's masks
    when it is bound); afterwards both masks on and ``fbo`` bound again."""
    fbo.color_mask = _colour_mask(fbo, color)
    fbo.depth_mask = depth
    fbo.use()
    try:
        yield fbo
    finally:
        fbo.color_mask = _colour_mask(fbo, True)
        fbo.depth_mask = True
        fbo.use()


@contextmanager
def accumulating(ctx: moderngl.Context, fbo: moderngl.Framebuffer) -> Iterator[moderngl.Framebuffer]:
    """Passes added into ``fbo``'s float target: the visible surface only (depth
    "<=" against a depth buffer already written, which stays as it is) and
    additive blending."""
    with masked(fbo, depth=False):
        ctx.enable(moderngl.DEPTH_TEST | moderngl.BLEND)
        ctx.depth_func = "<="
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        try:
            yield fbo
        finally:
            _rest(ctx)


@contextmanager
def added(ctx: moderngl.Context) -> Iterator[None]:
    """Full-screen passes added into the bound target: additive blending, no depth test
    (a pass shaded in bands merged into its accumulation)."""
    ctx.disable(moderngl.DEPTH_TEST)
    ctx.enable(moderngl.BLEND)
    ctx.blend_func = moderngl.ONE, moderngl.ONE
    try:
        yield
    finally:
        _rest(ctx)
