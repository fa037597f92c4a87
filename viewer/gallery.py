"""The preset gallery: every bundled material rendered offscreen on the sphere
under the default environment, backdrop and tone mapper of ``nbrdf-view``,
in one labelled image grid (``nbrdf report gallery --out docs/figures/gallery.png``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont
from tqdm import tqdm

from nbrdf.imaging.env_presets import resolve_environment
from nbrdf.imaging.image_io import check_output, tonemap, write_png8
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material
from nbrdf.viewer.gpu.backdrop import Backdrop
from nbrdf.viewer.gpu.gl import offscreen_context
from nbrdf.viewer.gpu.pipeline import MaterialPipeline
from nbrdf.viewer.gpu.renderer import Renderer
from nbrdf.viewer.modes import BrdfMode
from nbrdf.viewer.options import ViewOptions
from nbrdf.viewer.session.edits import presets
from nbrdf.viewer.view_settings import ViewState


@dataclass
class GalleryConfig:
    """What the gallery renders and how large."""

    out: Path
    """The grid PNG."""
    tile: int = 160
    """Pixels per side of one material's tile."""
    spp: int = 32
    """Passes per pixel of each tile."""
    columns: int = 4
    """Tiles per row."""
    materials: list[Path] = field(default_factory=list)
    """Material files to show (empty: every bundled preset)."""


def _label(tile: np.ndarray, text: str) -> np.ndarray:
    """``text`` on a dark strip along the tile's bottom edge (Pillow's built-in font)."""
    img = Image.fromarray(tile)
    draw = ImageDraw.Draw(img)
    try:
        font = ImageFont.load_default(size=max(10, tile.shape[0] // 13))
    except TypeError:  # Pillow < 10.1: one size
        font = ImageFont.load_default()
    h = tile.shape[0] // 8
    draw.rectangle([0, tile.shape[0] - h, tile.shape[1], tile.shape[0]], fill=(16, 16, 16))
    draw.text((6, tile.shape[0] - h + (h - font.size if hasattr(font, "size") else 0) // 2), text,
              fill=(235, 235, 235), font=font)
    return np.asarray(img)


class TileRenderer:
    """One material on the sphere, offscreen, under the previewer's defaults
    (environment, backdrop, exposure, tone mapper): the gallery's tiles and the
    preset browser's thumbnails (viewer/thumbnails.py). Owns an EGL context's resources."""

    def __init__(self, ctx=None):
        self.opts = ViewOptions()
        self.ctx = ctx or offscreen_context()
        self.pipeline = MaterialPipeline(self.ctx)
        self.renderer = Renderer(self.ctx, mesh="sphere", environment=resolve_environment(self.opts.env))
        self.backdrop = Backdrop(self.ctx, self.renderer)
        self.state = ViewState(exposure=self.opts.state.exposure, tonemap=self.opts.state.tonemap)

    def render(self, material, size: int, spp: int) -> np.ndarray:
        """The tone-mapped tile, uint8 (size, size, 3), row 0 on top."""
        brdf = self.pipeline.build(material, BrdfMode.AUTO)
        img = self.backdrop.render_linear(self.state, (size, size), spp, brdf, self.opts.backdrop())
        return tonemap(img, self.opts.state.exposure, self.opts.state.tonemap.value)

    def release(self) -> None:
        self.backdrop.release()
        self.pipeline.release()


def render_gallery(cfg: GalleryConfig) -> Path:
    """Renders the tiles (a progress bar per material) and writes the grid; returns its path."""
    if cfg.tile < 16 or cfg.spp < 1 or cfg.columns < 1:
        raise NbrdfError("gallery: --tile >= 16, --spp >= 1 and --columns >= 1")
    out = Path(cfg.out)
    if out.suffix.lower() != ".png":
        raise NbrdfError(f"{out}: the gallery is a .png")
    check_output(out)
    paths = [Path(p) for p in cfg.materials] or list(presets().values())
    materials = [load_material(p) for p in paths]  # every file is read before minutes of rendering
    tiler = TileRenderer()
    tiles = []
    for path, m in tqdm(list(zip(paths, materials)), desc="gallery", unit="material"):
        tiles.append(_label(tiler.render(m, cfg.tile, cfg.spp), m.name or path.stem))
    rows = math.ceil(len(tiles) / cfg.columns)
    grid = np.zeros((rows * cfg.tile, min(cfg.columns, len(tiles)) * cfg.tile, 3), np.uint8)
    for k, t in enumerate(tiles):
        r, c = divmod(k, cfg.columns)
        grid[r * cfg.tile:(r + 1) * cfg.tile, c * cfg.tile:(c + 1) * cfg.tile] = t
    out.parent.mkdir(parents=True, exist_ok=True)
    write_png8(out, grid)
    tiler.release()
    return out
