"""PNG output is tagged sRGB: every display-referred PNG the previewer writes
(offscreen renders, window screenshots, thumbnails, the gallery) carries the
sRGB chunk before its image data."""
from __future__ import annotations

import struct

import imageio.v3 as iio
import numpy as np

from nbrdf.imaging.image_io import write_image, write_png8
from nbrdf.viewer.jobs.screenshot import write_display_png


def _chunks(path) -> list[tuple[bytes, bytes]]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    out, i = [], 8
    while i < len(data):
        (n,), kind = struct.unpack(">I", data[i:i + 4]), data[i + 4:i + 8]
        out.append((kind, data[i + 8:i + 8 + n]))
        i += 12 + n
    return out


def _srgb_before_idat(path) -> bool:
    kinds = [k for k, _ in _chunks(path)]
    return b"sRGB" in kinds and kinds.index(b"sRGB") < kinds.index(b"IDAT") \
        and dict(_chunks(path))[b"sRGB"] == b"\x00"


def test_every_png_writer_tags_srgb(tmp_path):
    rgb8 = (np.arange(4 * 6 * 3) % 256).astype(np.uint8).reshape(4, 6, 3)
    write_png8(tmp_path / "a.png", rgb8)
    write_display_png(tmp_path / "b.png", rgb8)
    write_image(tmp_path / "c.png", np.full((4, 6, 3), 0.5, np.float32))
    for name in "abc":
        assert _srgb_before_idat(tmp_path / f"{name}.png"), name
    assert np.array_equal(iio.imread(tmp_path / "a.png"), rgb8)  # the pixels are untouched
