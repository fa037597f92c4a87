"""Preset thumbnails: each material rendered once on the sphere (the gallery's
tile, viewer/gallery.py) and kept as a PNG in a cache folder.

A thumbnail's file name is a hash of what decides its pixels: the material's
content (its JSON document and the bytes of every texture and normal map it
names -- not its file name or location), the size, the passes and
``RENDERER_VERSION``. Editing a preset, or a renderer change that bumps the
version, renders it anew; everything else reads the PNG. An unreadable or
corrupt cache file is rendered again; an unwritable cache folder only loses
the memory, never the thumbnail.
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Callable

import imageio.v3 as iio
import numpy as np

from nbrdf.imaging.image_io import write_png8
from nbrdf.neural.material import Material, material_to_dict
from nbrdf.viewer.gallery import TileRenderer

#: Bump when the look of the offscreen sphere changes (shading, environment,
#: backdrop, tone mapping defaults): every cached thumbnail is then re-rendered.
RENDERER_VERSION = "1"
DEFAULT_SIZE = 96   #: thumbnail side, pixels
DEFAULT_SPP = 16    #: passes per thumbnail


def cache_dir() -> Path:
    """$XDG_CACHE_HOME/nbrdf/thumbnails (default ~/.cache)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "nbrdf" / "thumbnails"


def content_hash(material: Material, size: int, spp: int, version: str = RENDERER_VERSION) -> str:
    """The cache key: material document and referenced files' bytes, size, passes, renderer version."""
    h = hashlib.sha1()
    doc = material_to_dict(material)
    doc.pop("name", None)  # the name does not change a pixel
    h.update(json.dumps(doc, sort_keys=True).encode())
    files = [ref.resolved for _, ref in material.textures()]
    if material.normal_map:
        files.append(Path(material.base_dir) / material.normal_map)
    for f in sorted({str(p) for p in files}):
        try:
            h.update(Path(f).read_bytes())
        except OSError:
            h.update(f"missing:{f}".encode())
    h.update(f"|{size}|{spp}|{version}".encode())
    return h.hexdigest()


class ThumbnailCache:
    """Thumbnails by content; ``render`` (material, size, spp) -> uint8 (size, size, 3)
    is called only for those not cached (default: a ``gallery.TileRenderer`` made on first use)."""

    def __init__(self, folder: Path | str | None = None,
                 render: Callable[[Material, int, int], np.ndarray] | None = None,
                 size: int = DEFAULT_SIZE, spp: int = DEFAULT_SPP):
        self.folder = Path(folder) if folder is not None else cache_dir()
        self.size, self.spp = int(size), int(spp)
        self._render = render
        self._tiler = None
        self.rendered = 0
        """How many thumbnails this cache rendered (the rest were read)."""

    def path(self, material: Material) -> Path:
        """Where ``material``'s thumbnail is (or will be) kept."""
        return self.folder / f"{content_hash(material, self.size, self.spp)}.png"

    def _draw(self, material: Material) -> np.ndarray:
        if self._render is None:
            self._tiler = TileRenderer()
            self._render = self._tiler.render
        self.rendered += 1
        return self._render(material, self.size, self.spp)

    def get(self, material: Material) -> np.ndarray:
        """``material``'s thumbnail, uint8 (size, size, 3): read from the cache, or rendered once and stored."""
        p = self.path(material)
        if p.is_file():
            try:
                img = np.asarray(iio.imread(p, extension=".png"))
                if img.shape == (self.size, self.size, 3) and img.dtype == np.uint8:
                    return img
            except (OSError, ValueError, RuntimeError):
                pass  # corrupt or unreadable: render it again
        img = np.ascontiguousarray(self._draw(material), dtype=np.uint8)
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(suffix=".png", dir=p.parent)
            os.close(fd)
            write_png8(tmp, img)
            os.replace(tmp, p)
        except OSError:
            pass
        return img

    def close(self) -> None:
        """Releases the renderer's GPU resources (if this cache made one)."""
        if self._tiler is not None:
            self._tiler.release()
            self._tiler = None
