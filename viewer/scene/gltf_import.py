"""glTF 2.0 import: meshes with their materials as nbrdf layer stacks.

``import_gltf(path)`` reads a .gltf (JSON, buffers as files or data URIs) or
.glb (binary container) file itself - accessors, node transforms, images
(``viewer.scene.gltf_document``) - and returns one ``ImportedPrimitive`` (trimesh mesh, Material, notes) per
triangle primitive. Positions are turned from glTF's y-up into the
previewer's z-up world (x, y, z) -> (x, -z, y), so a model's front (+z in
glTF) faces the default camera; uvs follow trimesh's convention (v flipped,
origin bottom-left), which matches how textures are read (row 0 = v 0).

Material mapping (SPEC sections 3-4; roughness there is GGX alpha, so glTF's
perceptual roughness r becomes alpha = r^2, clamped into [0.01, 1]):

- metallic (>= 0.5, "nearest"; a metal/dielectric blend has no layer-stack
  equivalent): a conductor base, r0 = base colour, roughness alpha.
- dielectric (metallic < 0.5): what a glTF dielectric is physically: a
  diffuse base (albedo = base colour) under a dielectric interface of ior
  1.5 (or KHR_materials_ior) with the material's roughness.
- KHR_materials_clearcoat (factor >= 0.5): a dielectric coat of ior 1.5 on
  top with clearcoatRoughness. Under the coat, the base interface's ior is
  relative to the coat (base / 1.5); when that is below 1.05 the interface
  reflects nothing and is left out (noted).
- KHR_materials_ior: the interface ior (clamped into [1.05, 2], noted).
- KHR_materials_specular: a white specularFactor s scales the interface's
  normal-incidence reflectance F0(ior); the ior is changed to give s F0.
- KHR_materials_transmission (factor >= 0.5): a single dielectric layer
  (its surface reflection; the stack has no transmission, noted).
- Textures become TextureRef parameters on maps written next to a
  generated material JSON: the base colour decoded from sRGB and multiplied
  by its factor (one 16-bit linear grey map per channel), roughness maps from the G channel of
  metallicRoughnessTexture / clearcoatRoughnessTexture, squared to alpha
  and stored over their own [lo, hi] range; metallic (B) picks the nearest
  base kind by majority; normalTexture becomes the normal map.
- Everything else (emission, occlusion, sheen, alpha, texture transforms,
  second uv sets, ...) gives one line in the primitive's ``notes``.
"""
from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import re
import struct
import zlib
from pathlib import Path
from typing import Any, NamedTuple

import imageio.v3 as iio
import numpy as np

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import CONDUCTOR, DIELECTRIC, DIFFUSE
from nbrdf.neural.material import FORMAT, Material, load_material
from nbrdf.viewer.scene.gltf_document import SUPPORTED_EXTENSIONS, Gltf, GltfError

_Y_UP_TO_Z_UP = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
COAT_IOR = 1.5  # fixed by KHR_materials_clearcoat


class ImportedPrimitive(NamedTuple):
    """One triangle primitive of a glTF file, ready for the previewer."""

    mesh: Any               #: trimesh.Trimesh in the z-up world, uvs v-flipped (trimesh convention)
    material: Material      #: the converted layer stack (validated, textures resolved)
    notes: list[str]        #: one line per glTF property without an nbrdf equivalent


class MaterialGroup(NamedTuple):
    """The primitives of a file that share one material: one draw range of the previewer's mesh."""

    material: Material      #: the converted layer stack
    notes: list[str]        #: its one-line notes (and its primitives' own, each once)
    meshes: list[Any]       #: the trimesh meshes of its primitives, in file order


def material_groups(prims: "list[ImportedPrimitive] | tuple[ImportedPrimitive, ...]") -> list[MaterialGroup]:
    """Primitives grouped by material, in order of first appearance (the order
    of the previewer's draw ranges, viewer/scene/mesh.py, and of its material list)."""
    groups: dict[int, MaterialGroup] = {}
    for prim in prims:
        g = groups.setdefault(id(prim.material), MaterialGroup(prim.material, [], []))
        g.meshes.append(prim.mesh)
        g.notes.extend(n for n in prim.notes if n not in g.notes)
    return list(groups.values())


# ---------------------------------------------------------------- materials

def _g(x: float) -> str:
    return f"{x:.4g}"


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def png16(img: np.ndarray) -> bytes:
    """A 16-bit grey or RGB PNG of float (H, W[, 1 or 3]) values in [0, 1],
    row 0 at the top (Pillow writes no 16-bit PNG, so the few chunks are
    written here; it reads 16-bit grey back exactly, 16-bit RGB as 8 bits)."""
    x = np.asarray(img, np.float64)
    x = x[..., 0] if x.ndim == 3 and x.shape[2] == 1 else x
    h, w = x.shape[:2]
    data = np.round(np.clip(x, 0, 1) * 65535).astype(">u2").reshape(h, -1)
    raw = np.hstack([np.zeros((h, 1), np.uint8), data.view(np.uint8).reshape(h, -1)]).tobytes()

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    ihdr = struct.pack(">IIBBBBB", w, h, 16, 2 if x.ndim == 3 else 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")


def _f0(ior: float) -> float:
    return ((ior - 1) / (ior + 1)) ** 2


def _ior_from_f0(f0: float) -> float:
    s = math.sqrt(min(max(f0, 0.0), 0.99))
    return (1 + s) / (1 - s)


class _MaterialWriter:
    """Builds one material's JSON layers and writes its derived maps."""

    def __init__(self, gltf: Gltf, out_dir: Path, name: str, notes: list[str]):
        self.gltf, self.out_dir, self.name, self.notes = gltf, out_dir, name, notes

    def texture(self, info: Any, what: str) -> np.ndarray | None:
        if not isinstance(info, dict):
            return None
        if info.get("texCoord", 0) != 0:
            self.notes.append(f"{what}: texCoord {info['texCoord']} (only the first uv set is used)")
        if "KHR_texture_transform" in info.get("extensions", {}):
            self.notes.append(f"{what}: KHR_texture_transform has no equivalent (ignored)")
        return self.gltf.image(info.get("index"))

    def write(self, img: np.ndarray, suffix: str, bits: int = 16) -> str:
        """A derived map as maps/<material>_<suffix>.png (16-bit grey, or 8-bit)."""
        rel = f"maps/{self.name}_{suffix}.png"
        p = self.out_dir / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        if bits == 8:
            iio.imwrite(p, np.round(np.clip(img, 0, 1) * 255).astype(np.uint8))
        else:
            p.write_bytes(png16(img))
        return rel

    def roughness(self, perceptual: float, img: np.ndarray | None, what: str) -> Any:
        """GGX alpha from a factor and an optional texture (its G channel)."""
        p = np.full((1, 1), perceptual) if img is None else perceptual * img[..., min(1, img.shape[2] - 1)]
        alpha = p * p
        if alpha.min() < 0.01 or alpha.max() > 1:
            self.notes.append(f"{what}: GGX alpha (perceptual roughness squared) {_g(alpha.min())}"
                              f"{'' if alpha.size == 1 else '..' + _g(alpha.max())} clamped into [0.01, 1]")
        alpha = np.clip(alpha, 0.01, 1.0)
        lo, hi = float(alpha.min()), float(alpha.max())
        if img is None or hi - lo < 1e-4:
            return round(lo, 6)
        rel = self.write((alpha - lo) / (hi - lo), what.replace(" ", "_"))
        return {"texture": rel, "channel": "r", "range": [round(lo, 6), round(hi, 6)]}

    def colour(self, factor: list, tex_info: Any) -> Any:
        """Linear base colour: the sRGB texture times the factor, per channel."""
        rgb = np.asarray(factor[:3], np.float64)
        img = self.texture(tex_info, "baseColorTexture")
        if img is None:
            return [round(float(c), 6) for c in np.clip(rgb, 0, 1)]
        col = img[..., :3] if img.shape[2] >= 3 else np.repeat(img[..., :1], 3, 2)
        lin = srgb_to_linear(col) * rgb
        # one 16-bit grey map per channel: Pillow reads 16-bit RGB PNGs back as 8 bits
        return [{"texture": self.write(lin[..., k], f"base_colour_{c}"), "channel": "r", "range": [0.0, 1.0]}
                for k, c in enumerate("rgb")]


def _convert_material(gltf: Gltf, index: int | None, out_dir: Path,
                      used_names: set[str]) -> tuple[Material, list[str]]:
    """glTF material ``index`` (None: the default material) as a validated
    Material, its JSON and maps written to ``out_dir``, and its notes."""
    notes: list[str] = []
    m = gltf.item("materials", index) if index is not None else {}
    raw_name = str(m.get("name") or (f"material {index}" if index is not None else "default"))
    name = re.sub(r"[^A-Za-z0-9_-]+", "_", raw_name).strip("_") or "material"
    while name in used_names:
        name += "_"
    used_names.add(name)
    w = _MaterialWriter(gltf, out_dir, name, notes)
    pbr = m.get("pbrMetallicRoughness", {})
    ext = m.get("extensions", {}) or {}
    for e in ext:
        if e not in SUPPORTED_EXTENSIONS:
            notes.append(f"{e}: no equivalent in a layer stack (ignored)")
    mr_img = w.texture(pbr.get("metallicRoughnessTexture"), "metallicRoughnessTexture")
    is_metal = _is_metal(float(pbr.get("metallicFactor", 1.0)), mr_img, notes)
    roughness = w.roughness(float(pbr.get("roughnessFactor", 1.0)), mr_img, "roughness")
    base_factor = pbr.get("baseColorFactor", [1, 1, 1, 1])
    colour = w.colour(base_factor, pbr.get("baseColorTexture"))
    if (len(base_factor) > 3 and base_factor[3] < 1) or m.get("alphaMode", "OPAQUE") != "OPAQUE":
        notes.append(f"alpha (alphaMode {m.get('alphaMode', 'OPAQUE')}, "
                     f"baseColorFactor alpha {_g(base_factor[3] if len(base_factor) > 3 else 1)}): "
                     "no equivalent, rendered opaque")
    ior = _interface_ior(ext, is_metal, notes)
    trans = ext.get("KHR_materials_transmission", {})
    transmission = float(trans.get("transmissionFactor", 0.0))
    if "transmissionTexture" in trans:
        notes.append("KHR_materials_transmission.transmissionTexture: no equivalent (ignored)")
    layers = _layers(w, ext.get("KHR_materials_clearcoat"), is_metal, transmission, roughness, colour, ior, notes)
    _unsupported(m, notes)
    data: dict[str, Any] = {"format": FORMAT, "name": raw_name, "layers": layers}
    normal = m.get("normalTexture")
    if isinstance(normal, dict):
        img = w.texture(normal, "normalTexture")
        if float(normal.get("scale", 1.0)) != 1.0:
            notes.append(f"normalTexture.scale {_g(float(normal['scale']))}: no equivalent (taken as 1)")
        if img is not None and img.shape[2] >= 3:
            data["normal_map"] = w.write(img[..., :3], "normal", bits=8)
    json_path = out_dir / f"{name}.json"
    json_path.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    return load_material(json_path), notes


def _is_metal(metallic: float, mr_img, notes: list[str]) -> bool:
    """Metal or dielectric base, the nearest of the factor (times the texture's blue channel)."""
    if mr_img is not None and mr_img.shape[2] >= 3:
        share = float((metallic * mr_img[..., 2] >= 0.5).mean())
        if 0 < share < 1:
            notes.append(f"metallic varies over the texture ({share:.0%} metal): one base kind for the whole "
                         f"material, the majority ({'metal' if share >= 0.5 else 'dielectric'})")
        return share >= 0.5
    if 0 < metallic < 1:
        notes.append(f"metallicFactor {_g(metallic)}: a layer stack has no metal/dielectric blend; "
                     f"taken as {'metal' if metallic >= 0.5 else 'dielectric'} (nearest)")
    return metallic >= 0.5


def _interface_ior(ext: dict, is_metal: bool, notes: list[str]) -> float:
    """The interface's ior: KHR_materials_ior, then KHR_materials_specular, clamped into [1.05, 2]."""
    ior = float(ext.get("KHR_materials_ior", {}).get("ior", 1.5))
    spec = ext.get("KHR_materials_specular")
    if spec is not None and not is_metal:
        s = float(spec.get("specularFactor", 1.0))
        colour_f = spec.get("specularColorFactor", [1, 1, 1])
        if any(abs(c - 1) > 1e-6 for c in colour_f):
            notes.append("KHR_materials_specular.specularColorFactor: an interface is colourless (ignored)")
        for k in ("specularTexture", "specularColorTexture"):
            if k in spec:
                notes.append(f"KHR_materials_specular.{k}: a textured ior has no equivalent (ignored)")
        if abs(s - 1) > 1e-6:
            new = _ior_from_f0(s * _f0(ior))
            notes.append(f"KHR_materials_specular: specularFactor {_g(s)} taken as ior {_g(ior)} -> {_g(new)}")
            ior = new
    if ior == 0 or ior < 1.05 or ior > 2.0:  # glTF's ior 0 means a perfect mirror
        clamped = min(max(ior if ior > 0 else 2.0, 1.05), 2.0)
        notes.append(f"ior {_g(ior)} clamped into [1.05, 2] -> {_g(clamped)}")
        ior = clamped
    return ior


def _layers(w: "_MaterialWriter", coat: dict | None, is_metal: bool, transmission: float, roughness,
            colour, ior: float, notes: list[str]) -> list[dict]:
    """The layer stack: an optional clear coat over a conductor, a dielectric, or a
    dielectric interface over a diffuse base."""
    layers: list[dict] = []
    coat_factor = float(coat.get("clearcoatFactor", 0.0)) if coat else 0.0
    if coat is not None:
        if 0 < coat_factor < 1:
            notes.append(f"clearcoatFactor {_g(coat_factor)}: a coat is all or nothing; "
                         f"{'coated' if coat_factor >= 0.5 else 'left uncoated'} (nearest)")
        for k in ("clearcoatTexture", "clearcoatNormalTexture"):
            if k in coat:
                notes.append(f"KHR_materials_clearcoat.{k}: no equivalent (ignored)")
    coated = coat_factor >= 0.5
    if coated:
        layers.append({"type": DIELECTRIC, "ior": COAT_IOR,
                       "roughness": w.roughness(float(coat.get("clearcoatRoughnessFactor", 0.0)),
                                                w.texture(coat.get("clearcoatRoughnessTexture"),
                                                          "clearcoatRoughnessTexture"), "clearcoat roughness")})
    if is_metal:
        if transmission > 0:
            notes.append(f"transmissionFactor {_g(transmission)} on a metal: no effect (ignored)")
        layers.append({"type": CONDUCTOR, "roughness": roughness, "r0": colour})
    elif transmission >= 0.5:
        notes.append(f"transmissionFactor {_g(transmission)}: a layer stack does not transmit; "
                     "shown as its surface reflection (a single dielectric layer)")
        if coated:
            notes.append("clear coat over a transmissive base: the coat alone is kept")
        else:
            layers.append({"type": DIELECTRIC, "roughness": roughness, "ior": round(ior, 6)})
    else:
        if transmission > 0:
            notes.append(f"transmissionFactor {_g(transmission)}: taken as opaque (nearest)")
        rel_ior = ior / COAT_IOR if coated else ior
        if rel_ior >= 1.05:
            layers.append({"type": DIELECTRIC, "roughness": roughness, "ior": round(min(rel_ior, 2.0), 6)})
        else:
            notes.append(f"base interface under the clear coat: relative ior {_g(rel_ior)} < 1.05 "
                         "reflects nothing and is left out")
        layers.append({"type": DIFFUSE, "albedo": colour})
    return layers


def _unsupported(m: dict, notes: list[str]) -> None:
    """Notes on the material's properties without an equivalent."""
    emissive = m.get("emissiveFactor", [0, 0, 0])
    if any(float(c) > 0 for c in emissive) or "emissiveTexture" in m:
        notes.append(f"emission (emissiveFactor {[_g(float(c)) for c in emissive]}"
                     f"{', emissiveTexture' if 'emissiveTexture' in m else ''}): no equivalent (ignored)")
    if "occlusionTexture" in m:
        notes.append("occlusionTexture: no equivalent, the previewer computes its own lighting (ignored)")


# ---------------------------------------------------------------- meshes

def _primitive_mesh(gltf: Gltf, prim: dict, world: np.ndarray, place: str):
    import trimesh  # late: trimesh costs 1.1 s and only imported glTF primitives need it

    attrs = prim.get("attributes", {})
    if "POSITION" not in attrs:
        raise GltfError(f"{place} has no POSITION")
    pos = gltf.accessor(attrs["POSITION"])[:, :3]
    n = len(pos)
    if "indices" in prim:
        idx = gltf.accessor(prim["indices"])[:, 0].astype(np.int64)
    else:
        idx = np.arange(n)
    if len(idx) % 3 or (len(idx) and (idx.min() < 0 or idx.max() >= n)):
        raise GltfError(f"{place}: indices are not triangles over its {n} vertices")
    lin = _Y_UP_TO_Z_UP @ world[:3, :3]
    p = pos @ lin.T + _Y_UP_TO_Z_UP @ world[:3, 3]
    faces = idx.reshape(-1, 3)
    if np.linalg.det(world[:3, :3]) < 0:  # a mirroring transform flips the winding
        faces = faces[:, ::-1]
    kw: dict[str, Any] = {}
    if "NORMAL" in attrs:
        nrm = gltf.accessor(attrs["NORMAL"])[:, :3] @ np.linalg.inv(lin).T
        kw["vertex_normals"] = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    visual = None
    if "TEXCOORD_0" in attrs:
        uv = gltf.accessor(attrs["TEXCOORD_0"])[:, :2].copy()
        uv[:, 1] = 1.0 - uv[:, 1]  # trimesh's convention: origin bottom-left
        visual = trimesh.visual.TextureVisuals(uv=uv)
    mesh = trimesh.Trimesh(vertices=p, faces=faces, visual=visual, process=False, **kw)
    if "TANGENT" in attrs:  # xyz turned like positions, w the bitangent's handedness (mirrored by a mirroring node)
        t = gltf.accessor(attrs["TANGENT"])
        if t.shape[0] == n and t.shape[1] >= 4:
            w = t[:, 3:4] * (-1.0 if np.linalg.det(world[:3, :3]) < 0 else 1.0)
            mesh.vertex_attributes["tangent"] = np.hstack([t[:, :3] @ lin.T, w])
    return mesh


def default_out_dir(path: Path) -> Path:
    """Where a file's converted materials go: the user cache, keyed by content."""
    digest = hashlib.sha1(path.read_bytes()).hexdigest()[:12]
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "nbrdf" / "gltf" / f"{re.sub(r'[^A-Za-z0-9_-]+', '_', path.stem)}-{digest}"


def import_gltf(path: str | Path, out_dir: str | Path | None = None) -> list[ImportedPrimitive]:
    """Every triangle primitive of a .gltf/.glb file with its converted
    material; material JSONs and derived maps are written to ``out_dir``
    (default: ``default_out_dir(path)``). Bad files end in one NbrdfError line."""
    p = Path(path)
    if not p.is_file():
        raise NbrdfError(f"{path}: no such file")
    if p.suffix.lower() not in (".gltf", ".glb"):
        raise NbrdfError(f"{path}: expected a .gltf or .glb file")
    try:
        gltf = Gltf(p)
        out = Path(out_dir) if out_dir is not None else default_out_dir(p)
        out.mkdir(parents=True, exist_ok=True)
        materials: dict[int | None, tuple[Material, list[str]]] = {}
        used: set[str] = set()
        result: list[ImportedPrimitive] = []
        for mesh_index, world in gltf.world_transforms():
            mesh = gltf.item("meshes", mesh_index)
            for k, prim in enumerate(mesh.get("primitives", [])):
                place = f"meshes[{mesh_index}].primitives[{k}]"
                if prim.get("mode", 4) != 4:
                    raise GltfError(f"{place}: mode {prim['mode']} (only triangle lists are read)")
                mat_index = prim.get("material")
                if mat_index not in materials:
                    materials[mat_index] = _convert_material(gltf, mat_index, out, used)
                material, notes = materials[mat_index]
                extra = [f"{place}: morph targets ignored"] if prim.get("targets") else []
                result.append(ImportedPrimitive(_primitive_mesh(gltf, prim, world, place), material,
                                                list(notes) + extra))
        if not result:
            raise GltfError("no triangle meshes in the scene")
        return result
    except NbrdfError as e:
        raise NbrdfError(f"{path}: {e}") from None
    except GltfError as e:
        raise NbrdfError(f"{path}: not a valid glTF file ({e})") from None
    except (KeyError, IndexError, TypeError, ValueError, AttributeError, struct.error, UnicodeDecodeError,
            OverflowError) as e:
        if isinstance(e, KeyError):
            reason = f"missing key {e}"
        else:
            reason = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise NbrdfError(f"{path}: not a valid glTF file ({reason})") from None
    except OSError as e:
        raise NbrdfError(f"{path}: cannot be read or written ({e.strerror or type(e).__name__})") from None


def imported_scene(path: str | Path) -> tuple[ImportedPrimitive, ...]:
    """``import_gltf`` into the default folder, kept while the file is unchanged:
    opening a model reads it once for both its meshes and its material."""
    p = Path(path)
    if not p.is_file():
        raise NbrdfError(f"{path}: no such file")
    return _imported(str(p), p.resolve().stat().st_mtime_ns)


@functools.lru_cache(maxsize=4)
def _imported(path: str, mtime_ns: int) -> tuple[ImportedPrimitive, ...]:
    return tuple(import_gltf(path))

