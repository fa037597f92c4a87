"""The preset gallery: one labelled tile per material, in a grid, under the
previewer's default look; bad outputs end in one line before any rendering."""
from __future__ import annotations

import numpy as np
import pytest

from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.gallery import GalleryConfig, render_gallery
from nbrdf.viewer.session.edits import presets

pytestmark = pytest.mark.gl


def test_gallery_grid_has_one_rendered_tile_per_material(tmp_path):
    import imageio.v3 as iio

    table = presets()
    mats = [table["rough_gold"], table["smooth_gold"], table["glass_reflection"]]
    out = render_gallery(GalleryConfig(tmp_path / "g.png", tile=32, spp=1, columns=2, materials=mats))
    grid = iio.imread(out)
    assert grid.shape == (64, 64, 3)
    tiles = [grid[:32, :32], grid[:32, 32:], grid[32:, :32]]
    centres = [t[10:20, 10:22].astype(int).mean((0, 1)) for t in tiles]
    assert np.abs(centres[0] - centres[2]).max() > 10  # gold and glass differ where the sphere is
    assert grid[32:, 32:].max() == 0  # the unused cell stays empty
    assert np.median(tiles[0][-2:]) <= 20  # the label strip


def test_gallery_rejects_bad_outputs_first(tmp_path):
    with pytest.raises(NbrdfError, match="png"):
        render_gallery(GalleryConfig(tmp_path / "g.jpg"))
    with pytest.raises(NbrdfError):
        render_gallery(GalleryConfig(tmp_path / "g.png", materials=[tmp_path / "missing.json"]))
