"""The bundled glTF test model, made by the project (no downloaded art).

``python -m nbrdf.viewer.assets.make_gltf`` writes ``meshes/car_paint_pebble.glb``:
a rounded box (a superellipsoid: flat faces that show an environment's panels
as crisp rectangles, rounded edges that sweep them) with one clear-coated red
metallic car-paint material:

- pbrMetallicRoughness: baseColorFactor red, metallicFactor 1, an ORM texture
  (R occlusion, G perceptual roughness in a fine flake-like pattern, B
  metallic 1) as metallicRoughnessTexture and occlusionTexture;
- KHR_materials_clearcoat: factor 1, clearcoatRoughnessFactor 0.1;
- KHR_materials_ior: 1.5.

It also writes ``meshes/pebble_on_plinth.glb``: the same pebble (coarser)
resting on a rough blue stone plinth (a second primitive with a second
material, placed by its node's translation) -- several materials per file.

``write_glb`` / ``write_glb_scene`` are the small binary-glTF writers it uses
(single-primitive meshes, embedded PNG images), also used by the tests to make variants.
Deterministic (fixed seed), so the committed file can be rebuilt.
"""
from __future__ import annotations

import io
import json
import struct
from pathlib import Path
from typing import NamedTuple

import imageio.v3 as iio
import numpy as np

HERE = Path(__file__).parent / "meshes"
NAME = "car_paint_pebble.glb"
#: The two-material scene: the pebble on a plinth (several materials per file).
SCENE_NAME = "pebble_on_plinth.glb"
PLINTH_RADII = (1.35, 0.14, 0.9)
TEX_SIZE = 64


def superellipsoid(n_u: int = 72, n_v: int = 40, radii=(1.0, 0.45, 0.6), e: float = 0.35):
    """Positions, normals (analytic, seam-consistent), uvs and uint16 indices
    of |x/a|^(2/e) + |y/b|^(2/e) + |z/c|^(2/e) = 1 in glTF's y-up frame."""
    a, b, c = radii
    u = np.linspace(0, 2 * np.pi, n_u + 1)
    v = np.linspace(0, np.pi, n_v + 1)
    V, U = np.meshgrid(v, u, indexing="ij")

    def spow(x, p):
        return np.sign(x) * np.abs(x) ** p

    sv, cv = np.sin(V), np.cos(V)
    x = a * spow(sv, e) * spow(np.cos(U), e)
    y = b * spow(cv, e)
    z = c * spow(sv, e) * spow(np.sin(U), e)
    k = 2 / e - 1  # gradient of the implicit function, per axis
    n = np.stack([spow(x / a, k) / a, spow(y / b, k) / b, spow(z / c, k) / c], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n[0] = [0, 1, 0]
    n[-1] = [0, -1, 0]
    pos = np.stack([x, y, z], -1).reshape(-1, 3).astype(np.float32)
    uv = np.stack([U / (2 * np.pi), V / np.pi], -1).reshape(-1, 2).astype(np.float32)
    w = n_u + 1
    quads = []
    for i in range(n_v):
        s = np.arange(n_u) + i * w
        # counter-clockwise seen from outside (glTF front faces)
        quads.append(np.stack([s, s + 1, s + w, s + 1, s + w + 1, s + w], 1))
    ind = np.concatenate(quads).reshape(-1).astype(np.uint16)
    return pos, n.reshape(-1, 3).astype(np.float32), uv, ind


def orm_texture(size: int = TEX_SIZE, seed: int = 7) -> np.ndarray:
    """uint8 (size, size, 3): R occlusion (darker toward v = 0.5 +- 0.5),
    G perceptual roughness 0.3..0.6 in a flake-like cell pattern, B metallic 1."""
    rng = np.random.default_rng(seed)
    cells = rng.uniform(0.3, 0.6, (size // 4, size // 4))
    g = np.kron(cells, np.ones((4, 4)))
    v = (np.arange(size) + 0.5) / size
    occl = np.repeat((0.75 + 0.25 * np.sin(np.pi * v))[:, None], size, 1)
    img = np.stack([occl, g, np.ones_like(g)], -1)
    return np.round(img * 255).astype(np.uint8)


def png_bytes(img: np.ndarray) -> bytes:
    buf = io.BytesIO()
    iio.imwrite(buf, img, extension=".png")
    return buf.getvalue()


def car_paint_material() -> dict:
    return {
        "name": "red car paint",
        "pbrMetallicRoughness": {"baseColorFactor": [0.6, 0.025, 0.02, 1.0], "metallicFactor": 1.0,
                                 "roughnessFactor": 1.0, "metallicRoughnessTexture": {"index": 0}},
        "occlusionTexture": {"index": 0},
        "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 1.0, "clearcoatRoughnessFactor": 0.1},
                       "KHR_materials_ior": {"ior": 1.5}},
    }


class Part(NamedTuple):
    """One node of a written scene: a mesh with one primitive and its material."""

    name: str                 #: the node's and the mesh's name
    positions: np.ndarray     #: (V, 3) float32, glTF's y-up frame
    normals: np.ndarray       #: (V, 3) float32
    uvs: np.ndarray           #: (V, 2) float32
    indices: np.ndarray       #: (3T,) uint16
    material: int             #: index into the scene's materials
    translation: tuple[float, float, float] | None = None  #: the node's translation (None: none)


def write_glb(path: str | Path, positions: np.ndarray, normals: np.ndarray, uvs: np.ndarray,
              indices: np.ndarray, material: dict, images: list[bytes]) -> None:
    """One mesh with one primitive and one material; ``images`` are PNG files
    embedded in the binary chunk, texture i sampling image i."""
    write_glb_scene(path, [Part("pebble", positions, normals, uvs, indices, 0)], [material], images)


def write_glb_scene(path: str | Path, parts: list[Part], materials: list[dict], images: list[bytes]) -> None:
    """A scene of ``parts`` (one node and one single-primitive mesh each) with
    ``materials``; ``images`` are PNG files embedded in the binary chunk,
    texture i sampling image i."""
    chunks: list[bytes] = []
    views: list[dict] = []

    def add(data: bytes, target: int | None = None) -> int:
        offset = sum(len(c) for c in chunks)
        chunks.append(data + b"\0" * (-len(data) % 4))
        view = {"buffer": 0, "byteOffset": offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        views.append(view)
        return len(views) - 1

    accessors: list[dict] = []
    nodes: list[dict] = []
    meshes: list[dict] = []
    for k, part in enumerate(parts):
        first = len(accessors)
        accessors += [
            {"bufferView": add(part.positions.astype("<f4").tobytes(), 34962), "componentType": 5126,
             "count": len(part.positions), "type": "VEC3",
             "min": part.positions.min(0).tolist(), "max": part.positions.max(0).tolist()},
            {"bufferView": add(part.normals.astype("<f4").tobytes(), 34962), "componentType": 5126,
             "count": len(part.normals), "type": "VEC3"},
            {"bufferView": add(part.uvs.astype("<f4").tobytes(), 34962), "componentType": 5126,
             "count": len(part.uvs), "type": "VEC2"},
            {"bufferView": add(part.indices.astype("<u2").tobytes(), 34963), "componentType": 5123,
             "count": len(part.indices), "type": "SCALAR"},
        ]
        node: dict = {"mesh": k, "name": part.name}
        if part.translation is not None:
            node["translation"] = [float(x) for x in part.translation]
        nodes.append(node)
        meshes.append({"name": part.name, "primitives": [
            {"attributes": {"POSITION": first, "NORMAL": first + 1, "TEXCOORD_0": first + 2},
             "indices": first + 3, "material": part.material}]})
    image_views = [add(png) for png in images]
    extensions = sorted({e for m in materials for e in m.get("extensions", {})})
    doc = {
        "asset": {"version": "2.0", "generator": "nbrdf.viewer.assets.make_gltf"},
        "scene": 0, "scenes": [{"nodes": list(range(len(parts)))}], "nodes": nodes,
        "meshes": meshes, "materials": materials, "accessors": accessors, "bufferViews": views,
        "buffers": [{"byteLength": sum(len(c) for c in chunks)}],
    }
    if images:
        doc["images"] = [{"bufferView": v, "mimeType": "image/png"} for v in image_views]
        doc["samplers"] = [{"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497}]
        doc["textures"] = [{"source": i, "sampler": 0} for i in range(len(images))]
    if extensions:
        doc["extensionsUsed"] = extensions
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    binary = b"".join(chunks)
    total = 12 + 8 + len(js) + 8 + len(binary)
    with open(path, "wb") as f:
        f.write(struct.pack("<III", 0x46546C67, 2, total))
        f.write(struct.pack("<II", len(js), 0x4E4F534A) + js)
        f.write(struct.pack("<II", len(binary), 0x004E4942) + binary)


def plinth_material() -> dict:
    """A rough blue-grey dielectric (a glTF dielectric: diffuse under a rough ior 1.5 interface)."""
    return {"name": "blue stone", "pbrMetallicRoughness": {"baseColorFactor": [0.16, 0.28, 0.55, 1.0],
                                                           "metallicFactor": 0.0, "roughnessFactor": 0.8}}


def write_plinth_scene(out: Path) -> None:
    """The car-paint pebble (coarser) resting on a blue stone plinth: two
    primitives, two materials, the plinth placed by its node's translation."""
    pebble = superellipsoid(48, 28)
    plinth = superellipsoid(40, 16, radii=PLINTH_RADII, e=0.2)
    drop = -(0.45 + PLINTH_RADII[1])  # the plinth's top touches the pebble's bottom (glTF y up)
    write_glb_scene(out, [Part("pebble", *pebble, 0), Part("plinth", *plinth, 1, (0.0, drop, 0.0))],
                    [car_paint_material(), plinth_material()], [png_bytes(orm_texture())])


def main() -> None:
    HERE.mkdir(parents=True, exist_ok=True)
    pos, nrm, uv, ind = superellipsoid()
    out = HERE / NAME
    write_glb(out, pos, nrm, uv, ind, car_paint_material(), [png_bytes(orm_texture())])
    print(f"wrote {out} ({out.stat().st_size / 1024:.0f} KiB)")
    two = HERE / SCENE_NAME
    write_plinth_scene(two)
    print(f"wrote {two} ({two.stat().st_size / 1024:.0f} KiB)")


if __name__ == "__main__":
    main()
