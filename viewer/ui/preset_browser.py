"""The preset browser: the bundled materials as a grid of thumbnails (the
sphere under the previewer's default look, viewer/thumbnails.py); a click
loads the preset. And ``preset_combo``, the presets as a list. Both name a
preset by its material's name (``preset_name``: "car paint (three layers)",
not the file's "car_paint") and load it by its key.

Thumbnails come from the cache folder; one not cached yet is rendered in the
window's own OpenGL context, one per frame (a progress line shows how many
are left), so the window stays responsive and the next start reads them all.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import moderngl
import numpy as np
from imgui_bundle import imgui

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material
from nbrdf.viewer.gallery import TileRenderer
from nbrdf.viewer.session.edits import preset_name, presets
from nbrdf.viewer.session.lookdev import LookDev
from nbrdf.viewer.thumbnails import ThumbnailCache

THUMB_PX = 64      #: thumbnail side on screen and in the cache, pixels
THUMB_SPP = 16     #: passes per thumbnail
BUTTON_CHARS = 9   #: characters of a name on a button without a thumbnail yet


def preset_combo(label: str, preview: str, pick: Callable[[str], object]) -> None:
    """A combo ``label`` (showing ``preview``) listing the presets by their materials'
    names; ``pick(key)`` with the chosen preset's key."""
    if imgui.begin_combo(label, preview):
        for key, path in presets().items():
            if imgui.selectable(f"{preset_name(path)}##{key}", False)[0]:
                pick(key)
        imgui.end_combo()


class PresetBrowser:
    """A grid of preset thumbnails for the material panel (``section`` each frame)."""

    def __init__(self, ld: LookDev, cache: ThumbnailCache | None = None, default_open: bool = False):
        self.ld = ld
        self.cache = cache or ThumbnailCache(size=THUMB_PX, spp=THUMB_SPP)
        self.default_open = default_open
        """Whether the browser's header starts open (closed: no thumbnail work until the user opens it)."""
        self._tiler = None
        self._textures: dict[str, moderngl.Texture] = {}
        self.failed: dict[str, str] = {}
        """Presets (by key) whose thumbnail could not be made, with the one-line reason."""

    def _renderer(self):
        """The tile renderer in the window's context (made when a thumbnail is first missing)."""
        if self._tiler is None:
            self._tiler = TileRenderer(self.ld.ctx)
            self.cache._render = self._tiler.render
        return self._tiler

    def _texture(self, key: str, path: Path) -> moderngl.Texture | None:
        """The thumbnail of preset ``key`` (its file stem) as a texture: cached, or read, or rendered now."""
        if key in self._textures or key in self.failed:
            return self._textures.get(key)
        try:
            m = load_material(path)
            if not self.cache.path(m).is_file():
                self._renderer()
            img = self.cache.get(m)
        except (NbrdfError, OSError, ValueError) as e:
            self.failed[key] = str(e).splitlines()[0] if str(e) else type(e).__name__
            return None
        data = np.ascontiguousarray(np.dstack([img, np.full(img.shape[:2], 255, np.uint8)]))
        tex = self.ld.ctx.texture((data.shape[1], data.shape[0]), 4, data.tobytes())
        self._textures[key] = tex
        return tex

    def pending(self) -> int:
        """Presets without a thumbnail yet."""
        return sum(1 for n in presets() if n not in self._textures and n not in self.failed)

    def draw(self, columns: int | None = None) -> None:
        """The grid (``columns`` None: as many as fit the panel's width); at most one
        missing thumbnail is made per call."""
        if columns is None:
            cell = THUMB_PX + 2 * imgui.get_style().frame_padding.x + imgui.get_style().item_spacing.x
            columns = max(1, int((imgui.get_content_region_avail().x + imgui.get_style().item_spacing.x) // cell))
        made = False
        items = list(presets().items())
        for k, (key, path) in enumerate(items):
            name = preset_name(path)
            tex = self._textures.get(key)
            if tex is None and not made and key not in self.failed:
                tex, made = self._texture(key, path), True
            if k % columns:
                imgui.same_line()
            imgui.begin_group()
            if tex is not None:
                # imgui draws uv (0, 0) at the top left; the texture's first row is the image's top.
                clicked = imgui.image_button(f"preset_{key}", imgui.ImTextureRef(tex.glo),
                                             imgui.ImVec2(THUMB_PX, THUMB_PX))
            else:
                clicked = imgui.button(f"{name[:BUTTON_CHARS]}##preset_{key}",
                                       imgui.ImVec2(THUMB_PX + 8, THUMB_PX + 8))
            if imgui.is_item_hovered():
                imgui.set_tooltip(f"{name}: {self.failed[key]}" if key in self.failed else name)
            imgui.end_group()
            if clicked:
                self.ld.load_preset(key)
        left = self.pending()
        if left:
            imgui.text(f"rendering thumbnails: {left} left")

    def section(self) -> None:
        """The grid under a collapsing header (the material panel's one call)."""
        if self.default_open:
            imgui.set_next_item_open(True, imgui.Cond_.once)
        if imgui.collapsing_header("preset browser"):
            self.draw()

    def release(self) -> None:
        for t in self._textures.values():
            t.release()
        self._textures.clear()
        if self._tiler is not None:
            self._tiler.release()
            self._tiler = None
