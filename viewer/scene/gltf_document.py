"""A glTF 2.0 document as ``viewer.scene.gltf_import`` reads it: a .gltf (JSON, buffers as files or data
URIs) or .glb (binary container) file, its accessors, images and node transforms. A malformed file is one
``GltfError`` whose message is the reason."""
from __future__ import annotations

import base64
import io
import json
import struct
from pathlib import Path
from typing import Any

import imageio.v3 as iio
import numpy as np

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_GLB_MAGIC, _CHUNK_JSON, _CHUNK_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942
#: Extensions whose properties are mapped (others get a note).
SUPPORTED_EXTENSIONS = ("KHR_materials_clearcoat", "KHR_materials_ior", "KHR_materials_specular",
                        "KHR_materials_transmission")


class GltfError(Exception):
    """A malformed file; the message is the reason."""


def read_document(path: Path) -> tuple[dict, bytes | None]:
    data = path.read_bytes()
    if path.suffix.lower() == ".glb" or data[:4] == b"glTF":
        if len(data) < 20:
            raise GltfError("the file is too short for a .glb header")
        magic, version, length = struct.unpack_from("<III", data, 0)
        if magic != _GLB_MAGIC:
            raise GltfError("no glTF magic number")
        if version != 2:
            raise GltfError(f"glTF version {version} (only 2 is read)")
        if length > len(data):
            raise GltfError(f"the header says {length} bytes, the file has {len(data)}")
        pos, doc, binary = 12, None, None
        while pos + 8 <= length:
            clen, ctype = struct.unpack_from("<II", data, pos)
            chunk = data[pos + 8: pos + 8 + clen]
            if len(chunk) != clen:
                raise GltfError("a chunk runs past the end of the file")
            if ctype == _CHUNK_JSON and doc is None:
                doc = json.loads(chunk.decode("utf-8"))
            elif ctype == _CHUNK_BIN and binary is None:
                binary = bytes(chunk)
            pos += 8 + clen + (-clen % 4)
        if doc is None:
            raise GltfError("no JSON chunk")
        return doc, binary
    return json.loads(data.decode("utf-8")), None


class Gltf:
    """Buffers, accessors, images and the node tree of one document."""

    def __init__(self, path: Path):
        self.path = path
        self.doc, self._glb_bin = read_document(path)
        if not isinstance(self.doc, dict) or not isinstance(self.doc.get("asset"), dict):
            raise GltfError('no "asset" object')
        version = str(self.doc["asset"].get("version", ""))
        if not version.startswith("2"):
            raise GltfError(f"glTF version {version or '?'} (only 2.x is read)")
        required = [e for e in self.doc.get("extensionsRequired", []) if e not in SUPPORTED_EXTENSIONS]
        if required:
            raise GltfError(f"requires extensions this importer does not read: {', '.join(required)}")
        self._buffers: dict[int, bytes] = {}

    def list(self, key: str) -> list:
        v = self.doc.get(key, [])
        if not isinstance(v, list):
            raise GltfError(f'"{key}" is not a list')
        return v

    def item(self, key: str, index: Any) -> dict:
        items = self.list(key)
        if not isinstance(index, int) or not 0 <= index < len(items) or not isinstance(items[index], dict):
            raise GltfError(f"{key}[{index}] does not exist")
        return items[index]

    def _uri(self, uri: str) -> bytes:
        if uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            if not head.endswith(";base64"):
                raise GltfError("a data URI that is not base64")
            return base64.b64decode(payload)
        p = (self.path.parent / uri).resolve()
        if not p.is_file():
            raise GltfError(f"{uri}: referenced file not found")
        return p.read_bytes()

    def buffer(self, index: int) -> bytes:
        if index not in self._buffers:
            b = self.item("buffers", index)
            if "uri" in b:
                data = self._uri(b["uri"])
            elif index == 0 and self._glb_bin is not None:
                data = self._glb_bin
            else:
                raise GltfError(f"buffers[{index}] has no data")
            if len(data) < int(b.get("byteLength", 0)):
                raise GltfError(f"buffers[{index}] holds {len(data)} bytes, byteLength says {b.get('byteLength')}")
            self._buffers[index] = data
        return self._buffers[index]

    def view(self, index: int) -> tuple[bytes, int, int | None]:
        v = self.item("bufferViews", index)
        data = self.buffer(v["buffer"])
        start, length = int(v.get("byteOffset", 0)), int(v["byteLength"])
        if start + length > len(data):
            raise GltfError(f"bufferViews[{index}] runs past its buffer")
        return data[start:start + length], length, v.get("byteStride")

    def accessor(self, index: int) -> np.ndarray:
        a = self.item("accessors", index)
        if "sparse" in a:
            raise GltfError(f"accessors[{index}] is sparse (not read)")
        dtype = _COMPONENTS.get(a.get("componentType"))
        width = _WIDTH.get(a.get("type"))
        if dtype is None or width is None:
            raise GltfError(f"accessors[{index}]: unknown component type or element type")
        count = int(a["count"])
        if "bufferView" not in a:
            return np.zeros((count, width), np.float32)
        data, length, stride = self.view(a["bufferView"])
        item = np.dtype(dtype).itemsize * width
        stride = stride or item
        offset = int(a.get("byteOffset", 0))
        if count and offset + stride * (count - 1) + item > length:
            raise GltfError(f"accessors[{index}] runs past its buffer view")
        raw = np.frombuffer(data, np.uint8, count=stride * (count - 1) + item if count else 0, offset=offset)
        rows = np.lib.stride_tricks.as_strided(raw, (count, item), (stride, 1)) if count else raw.reshape(0, item)
        out = np.ascontiguousarray(rows).view(dtype).reshape(count, width)
        if a.get("normalized") and np.issubdtype(dtype, np.integer):
            out = np.maximum(out / float(np.iinfo(dtype).max), -1.0)
        return out.astype(np.float64 if np.issubdtype(dtype, np.floating) or a.get("normalized") else np.int64)

    def image(self, texture_index: int) -> np.ndarray:
        """Texels of a texture's image as float (H, W, C) in [0, 1], row 0 = the file's top row."""
        tex = self.item("textures", texture_index)
        img = self.item("images", tex.get("source"))
        if "uri" in img:
            data = self._uri(img["uri"])
        elif "bufferView" in img:
            data = self.view(img["bufferView"])[0]
        else:
            raise GltfError(f"images[{tex.get('source')}] has no data")
        try:
            x = np.asarray(iio.imread(io.BytesIO(data)))
        except Exception as e:  # noqa: BLE001 - any decoder failure is a bad image
            raise GltfError(f"images[{tex.get('source')}] cannot be decoded ({type(e).__name__})") from None
        scale = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(x.dtype, 1.0)
        x = x.astype(np.float64) / scale
        return x[..., None] if x.ndim == 2 else x

    def world_transforms(self) -> list[tuple[int, np.ndarray]]:
        """(mesh index, 4x4 world matrix) of every mesh instance in the scene."""
        scenes = self.list("scenes")
        if scenes:
            roots = self.item("scenes", self.doc.get("scene", 0)).get("nodes", [])
        else:  # no scene: every node that is nobody's child
            children = {c for n in self.list("nodes") for c in n.get("children", [])}
            roots = [i for i in range(len(self.list("nodes"))) if i not in children]
        out, stack = [], [(r, np.eye(4), 0) for r in reversed(roots)]  # depth first, in file order
        if not self.list("nodes"):  # meshes without nodes: each once, untransformed
            return [(i, np.eye(4)) for i in range(len(self.list("meshes")))]
        while stack:
            i, parent, depth = stack.pop()
            if depth > 64:
                raise GltfError("the node tree is too deep (a cycle?)")
            node = self.item("nodes", i)
            m = parent @ node_matrix(node)
            if "mesh" in node:
                out.append((node["mesh"], m))
            stack += [(c, m, depth + 1) for c in reversed(node.get("children", []))]
        return out


def node_matrix(node: dict) -> np.ndarray:
    if "matrix" in node:
        return np.asarray(node["matrix"], np.float64).reshape(4, 4).T  # column-major
    t = np.asarray(node.get("translation", [0, 0, 0]), np.float64)
    x, y, z, w = np.asarray(node.get("rotation", [0, 0, 0, 1]), np.float64)
    s = np.asarray(node.get("scale", [1, 1, 1]), np.float64)
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3] = r * s[None, :]
    m[:3, 3] = t
    return m
