"""The bundled texture-mapped material, made by the project (no downloaded art).

``python -m nbrdf.viewer.assets.procedural`` writes ``materials/worn_tiles.json`` and
its maps: silver and copper tiles under a varnish whose thickness and roughness
vary, with wear along scratches and a tangent-space normal map of bevelled
tile edges. Deterministic (fixed seed), so the committed files can be rebuilt.
"""
from __future__ import annotations

import json
from pathlib import Path

import imageio.v3 as iio
import numpy as np

HERE = Path(__file__).parent / "materials"
SIZE = 128
TILES = 8


def _value_noise(rng: np.random.Generator, size: int, cells: int) -> np.ndarray:
    """Smooth tileable noise in [0, 1]: bicubic-faded lattice values."""
    grid = rng.random((cells, cells))
    t = np.arange(size) * cells / size
    i0 = np.floor(t).astype(int)
    f = t - i0
    f = f * f * (3 - 2 * f)
    i1 = (i0 + 1) % cells
    rows = grid[i0][:, None, :] * (1 - f)[:, None, None] + grid[i1][:, None, :] * f[:, None, None]
    return rows[:, :, i0][:, 0] * (1 - f)[None] + rows[:, :, i1][:, 0] * f[None]


def _fbm(rng: np.random.Generator, size: int) -> np.ndarray:
    out = sum(_value_noise(rng, size, c) / k for k, c in enumerate((4, 8, 16, 32), 1))
    return (out - out.min()) / (out.max() - out.min())


def _scratches(rng: np.random.Generator, size: int, count: int = 24) -> np.ndarray:
    y, x = np.mgrid[0:size, 0:size] / size
    out = np.zeros((size, size))
    for _ in range(count):
        a = rng.uniform(0, np.pi)
        c = rng.random(2)
        d = np.abs((x - c[0]) * np.sin(a) - (y - c[1]) * np.cos(a))
        along = np.abs((x - c[0]) * np.cos(a) + (y - c[1]) * np.sin(a))
        out = np.maximum(out, np.exp(-(d * size / 0.8) ** 2) * (along < rng.uniform(0.1, 0.35)))
    return out


def make_maps(size: int = SIZE, seed: int = 7) -> dict[str, np.ndarray]:
    """uint8 images: colour (r0 per channel), rough (r: base, g: coat), coat
    (r: varnish thickness), normal (tangent space, OpenGL convention)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    tx, ty = np.floor(x * TILES).astype(int), np.floor(y * TILES).astype(int)
    silver = (tx + ty) % 2 == 0
    noise, wear = _fbm(rng, size), _scratches(rng, size)
    r0 = np.where(silver[..., None], [0.96, 0.95, 0.92], [0.95, 0.55, 0.42]) * (0.9 + 0.1 * noise[..., None])
    base_rough = np.clip(0.15 + 0.25 * noise + 0.4 * wear, 0, 1)
    coat_rough = np.clip(0.1 * noise + 0.6 * wear, 0, 1)
    thickness = np.clip(0.6 + 0.4 * _fbm(rng, size) - 0.9 * wear, 0, 1)
    # Height: bevelled tile edges plus fine noise; normals from its gradient.
    fx, fy = x * TILES - tx, y * TILES - ty
    edge = np.minimum.reduce([fx, 1 - fx, fy, 1 - fy])
    height = np.clip(edge / 0.12, 0, 1) + 0.05 * noise
    gy, gx = np.gradient(height * 0.6 * size / (TILES * 8))
    # Image rows go down while v goes up: +y (green) is minus the row gradient.
    n = np.stack([-gx, gy, np.ones_like(gx)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    u8 = lambda a: np.clip(np.round(a * 255), 0, 255).astype(np.uint8)
    return {
        "color": u8(r0),
        "rough": u8(np.stack([base_rough, coat_rough, np.zeros_like(noise)], -1)),
        "coat": u8(np.repeat(thickness[..., None], 3, -1)),
        "normal": u8(n * 0.5 + 0.5),
    }


def material_json(prefix: str = "maps/worn_tiles") -> dict:
    tex = lambda name, ch, lo, hi: {"texture": f"{prefix}_{name}.png", "channel": ch, "range": [lo, hi]}
    return {
        "format": "nbrdf-material/1",
        "name": "worn varnished tiles",
        "layers": [
            {"type": "dielectric", "roughness": tex("rough", "g", 0.02, 0.35), "ior": 1.5},
            {"type": "medium", "albedo": [0.92, 0.85, 0.7], "sigma_t": tex("coat", "r", 0.0, 1.5)},
            {"type": "conductor", "roughness": tex("rough", "r", 0.05, 0.6),
             "r0": [tex("color", "r", 0, 1), tex("color", "g", 0, 1), tex("color", "b", 0, 1)]},
        ],
        "normal_map": f"{prefix}_normal.png",
    }


def write(out: Path = HERE) -> Path:
    (out / "maps").mkdir(parents=True, exist_ok=True)
    for name, img in make_maps().items():
        iio.imwrite(out / "maps" / f"worn_tiles_{name}.png", img)
    path = out / "worn_tiles.json"
    path.write_text(json.dumps(material_json(), indent=2) + "\n")
    return path


if __name__ == "__main__":
    print(write())
