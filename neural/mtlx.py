"""MaterialX documents in and out (SPEC section 11): materials read as stacks, OpenPBR written back.

``read_mtlx`` reads a document with the ``materialx`` package, validates it against MaterialX's
own libraries, picks a ``surfacematerial`` (by name or the first) and its surface shader
(open_pbr_surface, standard_surface, gltf_pbr or UsdPreviewSurface), reads every input (unset ones
at the node definition's default), translates to OpenPBR and maps that to a stack with
``neural.openpbr``. An image on the base colour becomes a texture reference; any other connection
is one note and the input's uniform value. ``write_mtlx`` writes an OpenPBR document. MaterialX is
imported only inside these functions: importing this module costs nothing.
"""
from __future__ import annotations

import functools
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.files import save_text
from nbrdf.neural.openpbr import OpenPbr, input_type, openpbr_from_record, openpbr_to_material
from nbrdf.neural.surface_models import gltf_pbr_to_openpbr, standard_surface_to_openpbr, usd_preview_surface_to_openpbr

__all__ = ["list_mtlx_materials", "openpbr_from_record", "read_mtlx", "read_openpbr", "split_material_ref",
           "base_color_image", "data_library", "openpbr_document", "write_material_mtlx",
           "write_mtlx"]

Translate = Callable[[Mapping[str, Any]], tuple[OpenPbr, list[str]]]


def _open_pbr(inputs: Mapping[str, Any]) -> tuple[OpenPbr, list[str]]:
    return OpenPbr(**inputs), []


#: The surface shaders read, with their translation to OpenPBR.
SHADERS: dict[str, Translate] = {
    "open_pbr_surface": _open_pbr,
    "standard_surface": standard_surface_to_openpbr,
    "gltf_pbr": gltf_pbr_to_openpbr,
    "UsdPreviewSurface": usd_preview_surface_to_openpbr,
}
#: Per shader, the input that becomes OpenPBR's base_color unchanged (so an image on it maps affinely).
BASE_COLOR_INPUT = {"open_pbr_surface": "base_color", "standard_surface": "base_color", "gltf_pbr": "base_color",
                    "UsdPreviewSurface": "diffuseColor"}
IMAGE_NODES = ("image", "tiledimage")
LINEAR_SPACES = ("", "lin_rec709", "raw")
ROUGHNESS_INPUTS = ("specular_roughness", "coat_roughness", "roughness", "clearcoat_roughness", "clearcoatRoughness")


def _materialx():
    """The MaterialX module."""
    import MaterialX  # lazy: nbrdf --help and every material that is not MaterialX must not load it
    return MaterialX


@functools.lru_cache(maxsize=1)
def data_library():
    """MaterialX's standard data libraries (node definitions), loaded once."""
    mx = _materialx()
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    return lib


def _first_line(text: object) -> str:
    lines = [s.strip() for s in str(text).splitlines() if s.strip()]
    return lines[0] if lines else "no detail given"


def split_material_ref(s: str) -> tuple[Path, str | None]:
    """``FILE.mtlx#Name`` -> (FILE.mtlx, "Name"); a reference without ``#`` after ``.mtlx`` -> (path, None)."""
    head, sep, tail = s.rpartition("#")
    if not sep or not head.lower().endswith(".mtlx"):
        return Path(s), None
    if not tail:
        raise NbrdfError(f"{s}: expected a material name after '#'")
    return Path(head), tail


def _load(path: str | Path):
    """The validated document; every failure is one NbrdfError line."""
    mx = _materialx()
    p = Path(path)
    if not p.is_file():
        raise NbrdfError(f"{path}: no such file")
    try:
        p.read_bytes().decode("utf-8")  # MaterialX's Python strings would fail later, mid-read
    except UnicodeDecodeError:
        raise NbrdfError(f"{path}: not a UTF-8 text file (not a MaterialX document)") from None
    except OSError as e:
        raise NbrdfError(f"{path}: cannot be read ({e.strerror})") from None
    doc = mx.createDocument()
    try:
        mx.readFromXmlFile(doc, str(p))
    except mx.ExceptionParseError as e:
        raise NbrdfError(f"{path}: not a MaterialX document ({_first_line(e)})") from None
    except mx.ExceptionFileMissing as e:
        raise NbrdfError(f"{path}: {_first_line(e)}") from None
    except Exception as e:  # noqa: BLE001 - any other reader failure is a bad file
        raise NbrdfError(f"{path}: cannot be read as MaterialX ({_first_line(e) or type(e).__name__})") from None
    doc.setDataLibrary(data_library())
    ok, message = doc.validate()
    if not ok:
        raise NbrdfError(f"{path}: invalid MaterialX document: {_first_line(message)}")
    return doc


def _materials(doc) -> list:
    return [m for m in doc.getMaterialNodes() if m.getCategory() == "surfacematerial"]


def list_mtlx_materials(path: str | Path) -> list[str]:
    """The names of the document's surface materials, in document order (possibly none)."""
    return [m.getName() for m in _materials(_load(path))]


@dataclass(frozen=True)
class ShaderRead:
    """A material's surface shader as read: its OpenPBR inputs and what could not be read."""

    material: str
    """the surfacematerial's name"""
    category: str
    """the shader's node category (open_pbr_surface, standard_surface, gltf_pbr, UsdPreviewSurface)"""
    openpbr: OpenPbr
    """the shader's inputs, translated to OpenPBR (connected inputs at their uniform value)"""
    base_color_image: Path | None
    """the image file (resolved) connected to the base colour, to become texture references"""
    notes: tuple[str, ...]
    """one line per input read only in part (connections, colour spaces, the model's own inputs)"""


def _parse(value: str, kind: str, place: str) -> Any:
    """A MaterialX value string of type ``kind``."""
    try:
        if kind == "float":
            return float(value)
        if kind == "integer":
            return int(value)
        if kind == "boolean":
            if value not in ("true", "false"):
                raise ValueError(value)
            return value == "true"
        if kind in ("color3", "vector3"):
            parts = tuple(float(x) for x in value.split(","))
            if len(parts) != 3:
                raise ValueError(value)
            return parts
    except ValueError:
        raise NbrdfError(f"{place}: {value!r} is not a {kind} value") from None
    raise NbrdfError(f"{place}: inputs of type {kind} are not read")


def _srgb_to_linear(c: float) -> float:
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def _uniform(node_input, default: Any, kind: str, place: str, notes: list[str]) -> Any:
    """An unconnected input's value (colours brought to linear from sRGB; other spaces noted)."""
    if node_input is None or not node_input.hasValueString():
        return default
    v = _parse(node_input.getValueString(), kind, place)
    space = node_input.getActiveColorSpace() if kind == "color3" else ""
    if space == "srgb_texture":
        v = tuple(_srgb_to_linear(c) for c in v)
    elif space not in LINEAR_SPACES:
        notes.append(f"{place}: colour space {space} is not converted; the values are used as linear Rec. 709")
    return v


def _image_file(node, doc_dir: Path, place: str) -> tuple[Path, str]:
    """An image node's file, resolved against the document's folder, and its colour space."""
    f = node.getInput("file")
    if f is not None and f.hasInterfaceName() and f.getInterfaceInput() is not None:
        f = f.getInterfaceInput()
    name = f.getResolvedValueString() if f is not None else ""
    if not name:
        raise NbrdfError(f"{place}: image node {node.getName()!r} names no file")
    p = Path(name)
    resolved = (p if p.is_absolute() else doc_dir / p).resolve()
    if not resolved.is_file():
        raise NbrdfError(f"{place}: image {name} not found ({resolved})")
    return resolved, f.getActiveColorSpace()


def _connection(inp, name: str, kind: str, uniform: Any, category: str, doc_dir: Path, where: str,
                notes: list[str]) -> tuple[Any, Path | None]:
    """A connected input: (the value to use, the image file when it is an image on the base colour);
    a note for whatever is not read."""
    place = f"{category}.{name}"
    src = inp.getConnectedNode()
    shown = f"{uniform:g}" if isinstance(uniform, float) else str(uniform) if uniform is not None else "(none)"
    if src is None:
        notes.append(f"{name}: connected to an output with no node; the uniform value {shown} is used")
        return uniform, None
    category_of_src = src.getCategory()
    value_input = src.getInput("value")
    if category_of_src == "constant" and value_input is not None and value_input.hasValueString():
        return _uniform(value_input, uniform, kind, place, notes), None
    if category_of_src not in IMAGE_NODES:
        notes.append(f"{name}: connected to {category_of_src} node {src.getName()!r}, which is not read; "
                     f"the uniform value {shown} is used")
        return uniform, None
    file, space = _image_file(src, doc_dir, f"{where}: {name}")
    if name != BASE_COLOR_INPUT[category] or src.getType() != "color3":
        why = ("the stack's GGX alpha = r^2 is not an affine function of it" if name in ROUGHNESS_INPUTS
               else "only the base colour maps onto the stack affinely")
        notes.append(f"{name}: image {file.name} is not read ({why}); the uniform value {shown} is used")
        return uniform, None
    if space not in LINEAR_SPACES:
        notes.append(f"{name}: image {file.name} is in {space}; the stack reads its texels as linear values")
    if category_of_src == "tiledimage":
        for k, neutral in (("uvtiling", "1,1"), ("uvoffset", "0,0")):
            t = src.getInput(k)
            if t is not None and t.hasValueString() and t.getValueString().replace(" ", "") != neutral:
                notes.append(f"{name}: {k} {t.getValueString()} of image {file.name} is not read (the mesh's uv is used)")
    return uniform, file


def _read_shader(doc, path: Path, material) -> ShaderRead:
    mx = _materialx()
    mat_name = material.getName()
    shaders = mx.getShaderNodes(material)
    where = f"{path}#{mat_name}"
    if not shaders:
        raise NbrdfError(f"{where}: its surfaceshader input is connected to no shader")
    shader = shaders[0]
    category = shader.getCategory()
    if category not in SHADERS:
        raise NbrdfError(f"{where}: shader {shader.getName()!r} is a {category!r}; supported: {', '.join(SHADERS)}")
    nodedef = shader.getNodeDef()
    if nodedef is None:
        raise NbrdfError(f"{where}: shader {shader.getName()!r} matches no MaterialX node definition")
    notes: list[str] = []
    values: dict[str, Any] = {}
    image: Path | None = None
    doc_dir = path.resolve().parent
    for d in nodedef.getActiveInputs():
        name, kind = d.getName(), d.getType()
        place = f"{category}.{name}"
        inp = shader.getInput(name)
        connected = inp is not None and (inp.getConnectedNode() is not None or bool(inp.getNodeName()) or inp.hasNodeGraphString())
        if kind == "vector3":  # geometric streams (normal, tangent): only a connection or a set value matters
            if connected:
                src = inp.getConnectedNode()
                notes.append(f"{name}: connected to {src.getCategory() if src else 'a node'} "
                             f"{src.getName() if src else ''!r}; normals and tangents from MaterialX are not read")
            elif inp is not None and inp.hasValueString() and not d.hasDefaultGeomPropString() and \
                    inp.getValueString().replace(" ", "") != d.getValueString().replace(" ", ""):
                notes.append(f"{name} {inp.getValueString()}: a changed normal is not read")
            continue
        dv = d.getValueString()
        default = _parse(dv, kind, f"{category} definition {name}") if dv else None
        uniform = _uniform(inp, default, kind, place, notes)
        if uniform is not None:  # None: no value and no default (the translation's own default holds)
            values[name] = uniform
        if not connected:
            continue
        value, found = _connection(inp, name, kind, uniform, category, doc_dir, where, notes)
        if value is not None:
            values[name] = value
        image = found or image
    p, model_notes = SHADERS[category](values)
    return ShaderRead(mat_name, category, p, image, tuple(notes + model_notes))


def _pick(doc, path: Path, material_name: str | None):
    materials = _materials(doc)
    if not materials:
        raise NbrdfError(f"{path}: holds no surfacematerial (no material to read)")
    if material_name is None:
        return materials[0]
    for m in materials:
        if m.getName() == material_name:
            return m
    raise NbrdfError(f"{path}: no material named {material_name!r}; it holds: {', '.join(m.getName() for m in materials)}")


def _read(path: str | Path, material_name: str | None) -> ShaderRead:
    p = Path(path)
    doc = _load(p)
    return _read_shader(doc, p, _pick(doc, p, material_name))


def read_openpbr(path: str | Path, material_name: str | None = None) -> tuple[OpenPbr, list[str]]:
    """A document's material (by name, or the first) as OpenPBR inputs and the reading notes; no stack
    is made (nothing is refused here)."""
    r = _read(path, material_name)
    return r.openpbr, list(r.notes)


def read_mtlx(path: str | Path, material_name: str | None = None,
              base_dir: str | Path | None = None) -> tuple[dict, list[str]]:
    """A document's material (by name, or the first) as a material JSON dict (with its "openpbr" record)
    and the notes. An image on the base colour becomes per-channel texture references, their paths
    relative to ``base_dir`` (the folder the JSON will live in; default the document's folder)."""
    r = _read(path, material_name)
    material, notes = openpbr_to_material(r.openpbr, r.material)
    if r.base_color_image is not None:
        base = material["layers"][-1]
        key = "r0" if base["type"] == "conductor" else "albedo"
        weight = min(max(r.openpbr.base_weight, 0.0), 1.0)
        folder = Path(base_dir) if base_dir is not None else Path(path).resolve().parent
        rel = Path(os.path.relpath(r.base_color_image, folder.resolve())).as_posix()
        base[key] = [{"texture": rel, "channel": c, "range": [0.0, weight]} for c in "rgb"]
    return material, list(r.notes) + notes


def _value_string(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, tuple):
        return ", ".join(repr(float(x)) for x in v)
    return repr(float(v))


def openpbr_document(p: OpenPbr, name: str, doc: str = "", base_color_image: str | None = None):
    """A MaterialX 1.39 document (``MaterialX.Document``, its data library set): one open_pbr_surface
    ``SR_<name>`` (only the inputs that differ from OpenPBR's defaults) and its surfacematerial ``name`` (made a
    valid MaterialX name), ``doc`` as both elements' doc string; ``base_color_image``: a file (as the document
    names it) read by an ``image`` node into base_color. Refused (one line) unless it validates."""
    mx = _materialx()
    document = mx.createDocument()
    mat_name = mx.createValidName(name) if name else "material"
    shader = document.addNode("open_pbr_surface", f"SR_{mat_name}", "surfaceshader")
    for k, v in p.changed().items():
        shader.addInput(k, input_type(k)).setValueString(_value_string(v))
    if base_color_image is not None:
        image = document.addNode("image", f"{mat_name}_base_color", "color3")
        image.addInput("file", "filename").setValueString(base_color_image)
        inp = shader.getInput("base_color") or shader.addInput("base_color", "color3")
        inp.setConnectedNode(image)
    material = document.addMaterialNode(mat_name, shader)
    if doc:
        material.setDocString(doc)
        shader.setDocString(doc)
    document.setDataLibrary(data_library())
    ok, message = document.validate()
    if not ok:
        raise NbrdfError(f"the OpenPBR document would be invalid: {_first_line(message)}")
    return document


def write_mtlx(p: OpenPbr, name: str, path: str | Path, doc: str = "", base_color_image: str | None = None) -> None:
    """Writes ``openpbr_document(p, name, doc, base_color_image)`` to ``path``, atomically."""
    try:
        document = openpbr_document(p, name, doc, base_color_image)
    except NbrdfError as e:
        raise NbrdfError(f"{path}: {e}") from None
    save_text(path, _materialx().writeToXmlString(document))


def write_material_mtlx(material: Mapping[str, Any], path: str | Path, doc: str = "") -> list[str]:
    """Writes a material made from OpenPBR back as an OpenPBR document. ``material`` is its JSON
    (``neural.material.material_to_dict`` relative to ``path``'s folder). The document carries the material's
    inputs (a round trip that changes nothing) and the image on its base colour where its base reads one as
    ``read_mtlx`` made it. Returns one note per thing the document does not carry (a normal map). A material
    with no OpenPBR inputs, or whose textures are not the reader's base colour image, is refused in one line."""
    out = Path(path)
    record, name = material.get("openpbr"), material.get("name") or out.stem
    if record is None:
        raise NbrdfError(f"{path}: {name} has no OpenPBR inputs (it was not made from OpenPBR, or its stack was "
                         f"edited); `nbrdf export MATERIAL --mtlx OUT.mtlx` fits them to its stack")
    if not out.parent.is_dir():
        raise NbrdfError(f"{path}: the folder {out.parent} does not exist")
    p = openpbr_from_record(record)
    write_mtlx(p, name, out, doc, base_color_image(material["layers"], p, out))
    return ["the normal map is not written (OpenPBR documents here carry no normal-map node graph)"] \
        if material.get("normal_map") is not None else []


def base_color_image(layers: list[dict], p: OpenPbr, where: str | Path) -> str | None:
    """The one image file the base's colour reads (as the material JSON's ``layers`` name it), as ``read_mtlx``
    wrote it: r, g, b of one file over [0, base_weight]; None for a material without textures; anything else
    is refused in one line starting with ``where``."""
    textured = [(i, k) for i, layer in enumerate(layers) for k, v in layer.items()
                if isinstance(v, list) and any(isinstance(x, dict) and "texture" in x for x in v)]
    if not textured:
        return None
    base = layers[-1]
    key = "r0" if base["type"] == "conductor" else "albedo"
    refs = base.get(key)
    weight = min(max(p.base_weight, 0.0), 1.0)
    same = (textured == [(len(layers) - 1, key)] and isinstance(refs, list) and len(refs) == 3
            and all(isinstance(r, dict) and r.get("channel") == c and list(r.get("range", [0.0, 1.0])) == [0.0, weight]
                    for r, c in zip(refs, "rgb"))
            and len({r.get("texture") for r in refs}) == 1)
    if not same or not isinstance(refs, list):
        raise NbrdfError(f"{where}: the material's textures are not one image on OpenPBR's base colour; "
                         "an OpenPBR document cannot carry them")
    return str(refs[0]["texture"])
