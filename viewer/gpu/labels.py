"""Text drawn on the view: the labels of the compare halves ("neural",
"reference (MC, 320 spp)"), part of the image itself so they show in
screenshots as on screen.

A label is rasterised once per text and size on the CPU (Pillow's default
font, FreeType) into a small single-channel texture and drawn as a
pixel-aligned quad: white glyphs on a translucent black box, alpha-blended
over what the target's viewport shows.
"""
from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from nbrdf.viewer.gpu import shaders

MARGIN = 6    #: pixels between a label's box and the view's edge (or the split)
PADDING = 3   #: pixels between the text and its box
MAX_CACHED = 16  #: label textures kept (the texts change as the reference refines)


def font_px(view_height: int) -> int:
    """The text height for a view ``view_height`` pixels tall: about 1/32 of it, 10 to 24 pixels."""
    return int(np.clip(round(view_height / 32), 10, 24))


def rasterise(text: str, px: int) -> np.ndarray:
    """(H, W) uint8 coverage of ``text`` at ``px`` pixels, with ``PADDING`` around it, top row first."""
    font = ImageFont.load_default(size=px)
    x0, y0, x1, y1 = ImageDraw.Draw(Image.new("L", (1, 1))).textbbox((0, 0), text, font=font)
    img = Image.new("L", (x1 - x0 + 2 * PADDING, y1 - y0 + 2 * PADDING), 0)
    ImageDraw.Draw(img).text((PADDING - x0, PADDING - y0), text, fill=255, font=font)
    return np.asarray(img, np.uint8)


@dataclass
class Label:
    """One label: ``text`` anchored at ``x`` (a fraction of the view's width), along the top or at ``y``."""

    text: str
    x: float
    """Where the box's anchored edge sits, 0 (left edge of the view) .. 1 (right edge)."""
    align: str = "left"
    """"left": the box starts at ``x`` (plus the margin); "right": it ends there; "center": it is centred on it."""
    y: float | None = None
    """Where the box's centre sits, 0 (top) .. 1 (bottom); None: along the top edge (a side's name)."""

    def __post_init__(self) -> None:
        if self.align not in ("left", "right", "center"):
            raise ValueError(f"label align {self.align!r} is not one of left, right, center")


class Labels:
    """Draws ``Label`` lists into a framebuffer's current viewport."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.prog = ctx.program(vertex_shader=shaders.source("label.vert"), fragment_shader=shaders.source("label.frag"))
        self.vao = ctx.vertex_array(self.prog, [])
        self._tex: dict[tuple[str, int], moderngl.Texture] = {}

    def _texture(self, text: str, px: int) -> moderngl.Texture:
        key = (text, px)
        if key not in self._tex:
            cov = rasterise(text, px)
            tex = self.ctx.texture((cov.shape[1], cov.shape[0]), 1, np.ascontiguousarray(cov).tobytes())
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            if len(self._tex) >= MAX_CACHED:
                self._tex.pop(next(iter(self._tex))).release()
            self._tex[key] = tex
        return self._tex[key]

    def draw(self, target: moderngl.Framebuffer, labels: list[Label]) -> None:
        """Draws ``labels`` along the top of ``target``'s viewport."""
        if not labels:
            return
        _, _, vw, vh = target.viewport
        px = font_px(vh)
        target.use()
        self.ctx.enable(moderngl.BLEND)
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        self.prog["u_text"].value = 0
        for lab in labels:
            tex = self._texture(lab.text, px)
            w, h = tex.size
            x = round(lab.x * vw) + {"left": MARGIN, "right": -MARGIN - w, "center": -(w // 2)}[lab.align]
            x = int(np.clip(x, 0, max(0, vw - w)))
            # GL rows count from the bottom
            top = vh - MARGIN if lab.y is None else int(np.clip(round((1 - lab.y) * vh + h / 2), h, vh))
            rect = (2 * x / vw - 1, 2 * (top - h) / vh - 1, 2 * (x + w) / vw - 1, 2 * top / vh - 1)
            tex.use(0)
            self.prog["u_rect"].value = rect
            self.vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
        self.ctx.disable(moderngl.BLEND)

    def release(self) -> None:
        for t in self._tex.values():
            t.release()
        self._tex.clear()
        self.prog.release()
