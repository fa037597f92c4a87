"""Assets the scenes generate instead of downloading: a globe's texture-mapped
layered material, a torus mesh with uv, and tangent-space normal maps.

Everything is a deterministic function of its parameters, written once under
``teapot.cache_dir()`` (versioned names) so that scene files and the
reference's texture reads can refer to plain files.

- ``globe_material()``: varnish over a medium whose albedo follows generated
  continents (land tinted green-brown, sea clear) over a diffuse base whose
  albedo does too (land light, sea deep blue): the paper's globe, a spatially
  varying medium albedo and base albedo under one clear coat. Equirectangular
  maps (u longitude, v latitude with the north pole at the top row), as
  Mitsuba's sphere lays out its uv.
- ``torus_ply(R, r)``: a torus in the xy plane with uv (u around the ring,
  v around the tube).
- ``normal_map(name)``: tangent-space normals (x along dp/du, y along dp/dv,
  rgb = (n + 1) / 2, Mitsuba's ``normalmap`` convention) of a generated height
  field: ``hammered`` (dimples on a hexagonal lattice), ``knurled``
  (crossed grooves).
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from nbrdf.mitsuba.teapot import cache_dir
from nbrdf.neural.errors import NbrdfError

#: Bumped when a generator changes, so old cached files are not reused.
VERSION = 1
GLOBE_SIZE = (256, 128)
NORMAL_MAPS = ("hammered", "knurled")


def _write_atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=path.suffix, dir=path.parent)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    os.replace(tmp, path)


def _png(path: Path, rgb: np.ndarray) -> None:
    """An (H, W, 3) float image in [0, 1] as an 8-bit PNG, row 0 at the top."""
    _write_atomic(path, iio.imwrite("<bytes>", (np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8), extension=".png"))


def continents(size: tuple[int, int] = GLOBE_SIZE, seed: int = 3) -> np.ndarray:
    """A land mask (H, W) in [0, 1] on an equirectangular grid (row 0: north):
    a sum of random spherical waves over the unit sphere, so it is seamless in
    longitude and smooth at the poles, thresholded softly at about 35 % land."""
    w, h = size
    lon = (np.arange(w) + 0.5) / w * 2 * math.pi
    lat = math.pi / 2 - (np.arange(h) + 0.5) / h * math.pi
    lon, lat = np.meshgrid(lon, lat)
    p = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], -1)
    rng = np.random.default_rng(seed)
    field = np.zeros((h, w))
    for octave in range(4):
        freq = 1.5 * 2 ** octave
        for _ in range(6):
            d = rng.normal(size=3)
            d /= np.linalg.norm(d)
            field += np.sin(freq * p @ d * math.pi + rng.uniform(0, 2 * math.pi)) / 2 ** octave
    t = np.quantile(field, 0.65)
    return 1.0 / (1.0 + np.exp(-(field - t) / (0.08 * field.std())))


def globe_material() -> Path:
    """The globe's material JSON (written with its maps on first use)."""
    d = cache_dir() / f"globe-v{VERSION}"
    path = d / "globe.json"
    if path.is_file():
        return path
    land = continents()[..., None]
    # the medium's albedo: land scatters green-brown, the sea is nearly clear
    medium = land * np.array([0.55, 0.6, 0.3]) + (1 - land) * np.array([0.9, 0.95, 0.97])
    # the base under it: light sand on land, deep blue sea floor
    base = land * np.array([0.75, 0.62, 0.4]) + (1 - land) * np.array([0.05, 0.16, 0.42])
    _png(d / "globe_medium.png", medium)
    _png(d / "globe_base.png", base)
    rgb = lambda f: [{"texture": f, "channel": c, "range": [0, 1]} for c in "rgb"]
    material = {"format": "nbrdf-material/1", "name": "varnished globe", "layers": [
        {"type": "dielectric", "roughness": 0.04, "ior": 1.5},
        {"type": "medium", "albedo": rgb("globe_medium.png"), "sigma_t": 1.2},
        {"type": "diffuse", "albedo": rgb("globe_base.png")}]}
    _write_atomic(path, json.dumps(material, indent=2).encode())
    return path


def torus_mesh(major: float, minor: float, n_u: int = 96, n_v: int = 48) -> tuple[np.ndarray, ...]:
    """(positions (V, 3), normals (V, 3), uv (V, 2), triangles (F, 3)) of a
    torus around z; the seam rows are duplicated so uv runs 0..1 without a jump."""
    u = np.linspace(0.0, 1.0, n_u + 1)
    v = np.linspace(0.0, 1.0, n_v + 1)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    a, b = uu * 2 * math.pi, vv * 2 * math.pi
    ring = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], -1)
    normal = np.cos(b)[..., None] * ring + np.sin(b)[..., None] * np.array([0.0, 0.0, 1.0])
    pos = major * ring + minor * normal
    idx = np.arange((n_u + 1) * (n_v + 1)).reshape(n_u + 1, n_v + 1)
    q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
    tris = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    return (pos.reshape(-1, 3), normal.reshape(-1, 3), np.stack([uu, vv], -1).reshape(-1, 2), tris)


def torus_ply(major: float, minor: float) -> Path:
    """The torus as a binary PLY with normals and uv (cached)."""
    if not (major > minor > 0):
        raise NbrdfError(f"torus: expected radius > tube > 0, got {major}, {minor}")
    path = cache_dir() / f"torus-{major:g}-{minor:g}-v{VERSION}.ply"
    if path.is_file():
        return path
    pos, nrm, uv, tris = torus_mesh(major, minor)
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(pos)}\n"
            "property float x\nproperty float y\nproperty float z\n"
            "property float nx\nproperty float ny\nproperty float nz\n"
            "property float u\nproperty float v\n"
            f"element face {len(tris)}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    verts = np.concatenate([pos, nrm, uv], 1).astype("<f4")
    faces = np.zeros(len(tris), dtype=[("n", "u1"), ("i", "<i4", 3)])
    faces["n"], faces["i"] = 3, tris
    _write_atomic(path, head + verts.tobytes() + faces.tobytes())
    return path


def height_field(name: str, size: int = 256) -> np.ndarray:
    """A tileable height field (size, size) in texel units of depth."""
    y, x = np.mgrid[0:size, 0:size] / size
    if name == "hammered":
        # dimples on a lattice of 12 x 12 with every other row shifted by half a cell (tileable)
        k = 12
        best = np.full(x.shape, np.inf)
        for row in range(-1, k + 2):
            for col in range(-1, k + 2):
                cx, cy = (col + 0.5 * (row % 2)) / k, row / k
                best = np.minimum(best, (x - cx) ** 2 + (y - cy) ** 2)
        r = np.sqrt(best) * k
        return -np.clip(1 - (r / 0.62) ** 2, 0, None) ** 1.5 * 3.0
    if name == "knurled":
        k = 16
        s = lambda t: np.abs(((t * k) % 1.0) - 0.5)
        return -2.0 * (np.minimum(s(x + y), 0.5) + np.minimum(s(x - y), 0.5))
    raise NbrdfError(f"normal map {name!r}: expected one of {', '.join(NORMAL_MAPS)}")


def normal_map(name: str, size: int = 256, strength: float = 1.0) -> np.ndarray:
    """Tangent-space normals as rgb (size, size, 3) in [0, 1] (row 0 = v 0),
    from central differences of ``height_field`` (wrapping: tileable)."""
    h = height_field(name, size) * strength
    dx = (np.roll(h, -1, 1) - np.roll(h, 1, 1)) / 2
    dy = (np.roll(h, -1, 0) - np.roll(h, 1, 0)) / 2
    n = np.stack([-dx, -dy, np.ones_like(h)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return ((n + 1) / 2).astype(np.float32)
