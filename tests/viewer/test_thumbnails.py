"""Preset thumbnails (viewer/thumbnails.py): rendered once, then read from the
cache folder; a changed material or renderer version renders anew; a corrupt
file is rendered again."""
from __future__ import annotations

import json

import numpy as np
import pytest

from nbrdf.neural.material import load_material, parse_material
from nbrdf.viewer.session.edits import presets
from nbrdf.viewer.thumbnails import ThumbnailCache, content_hash

GOLD = {"format": "nbrdf-material/1", "name": "g", "layers": [{"type": "conductor", "roughness": 0.3,
                                                             "r0": [1.0, 0.766, 0.336]}]}


def _fake(calls):
    def render(material, size, spp):
        calls.append(material.name)
        img = np.zeros((size, size, 3), np.uint8)
        img[..., 0] = 200
        return img
    return render


def test_a_thumbnail_is_rendered_once_and_read_back(tmp_path):
    calls = []
    m = parse_material(GOLD)
    a = ThumbnailCache(tmp_path, _fake(calls), size=16, spp=2).get(m)
    assert calls == ["g"] and a.shape == (16, 16, 3) and (tmp_path / f"{content_hash(m, 16, 2)}.png").is_file()
    fresh = ThumbnailCache(tmp_path, _fake(calls), size=16, spp=2)  # a new session: the same folder
    np.testing.assert_array_equal(fresh.get(m), a)
    assert calls == ["g"] and fresh.rendered == 0


def test_the_key_follows_the_content_not_the_name(tmp_path):
    m = parse_material(GOLD)
    renamed = parse_material({**GOLD, "name": "other"})
    rougher = parse_material({**GOLD, "layers": [{**GOLD["layers"][0], "roughness": 0.31}]})
    assert content_hash(m, 16, 2) == content_hash(renamed, 16, 2)
    assert content_hash(m, 16, 2) != content_hash(rougher, 16, 2)
    assert content_hash(m, 16, 2) != content_hash(m, 32, 2) != content_hash(m, 16, 4)
    assert content_hash(m, 16, 2) != content_hash(m, 16, 2, version="next")


def test_texture_bytes_are_part_of_the_key(tmp_path):
    import imageio.v3 as iio

    iio.imwrite(tmp_path / "r.png", np.full((4, 4), 100, np.uint8))
    doc = {"format": "nbrdf-material/1", "name": "t", "layers": [{"type": "conductor", "roughness": {
        "texture": "r.png", "channel": "r", "range": [0.1, 0.5]}, "r0": 0.9}]}
    (tmp_path / "t.json").write_text(json.dumps(doc))
    before = content_hash(load_material(tmp_path / "t.json"), 16, 2)
    iio.imwrite(tmp_path / "r.png", np.full((4, 4), 200, np.uint8))
    assert content_hash(load_material(tmp_path / "t.json"), 16, 2) != before


def test_a_corrupt_cache_file_is_rendered_again(tmp_path):
    calls = []
    m = parse_material(GOLD)
    cache = ThumbnailCache(tmp_path, _fake(calls), size=16, spp=2)
    cache.path(m).parent.mkdir(parents=True, exist_ok=True)
    cache.path(m).write_bytes(b"not a png")
    assert cache.get(m)[0, 0, 0] == 200 and calls == ["g"]


def test_an_unwritable_cache_still_gives_the_thumbnail(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    calls = []
    img = ThumbnailCache(blocker / "sub", _fake(calls), size=8, spp=1).get(parse_material(GOLD))
    assert img.shape == (8, 8, 3) and calls == ["g"]


@pytest.mark.gl
def test_a_real_preset_thumbnail(tmp_path):
    """A bundled preset rendered by the gallery's tile renderer: the sphere over its backdrop, cached."""
    cache = ThumbnailCache(tmp_path, size=24, spp=2)
    try:
        m = load_material(presets()["rough_gold"])
        img = cache.get(m)
        assert img.shape == (24, 24, 3) and cache.rendered == 1
        centre = img[10:14, 10:14].reshape(-1, 3).mean(0)
        assert centre[0] > centre[2] + 30  # gold: red well above blue at the sphere's centre
        assert cache.get(m) is not None and cache.rendered == 1
    finally:
        cache.close()
