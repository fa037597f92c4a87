"""The material description (SPEC section 4): a validated dataclass model.

A material is a list of layers, top to bottom: dielectric interfaces, each
optionally followed by one medium slab, then a base (conductor, diffuse,
dielectric, measured or latent). Every parameter is checked against its
legal range; anything wrong raises ``NbrdfError`` with one line that names
the place (``layers[2].r0[1]: 1.3 is outside [0, 1]``). Nothing is clamped.
"""
from __future__ import annotations

import json
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.files import save_text
from nbrdf.neural.layer_kinds import (
    BASE_KINDS,
    CONDUCTOR,
    DIELECTRIC,
    DIFFUSE,
    FORMAT,
    KINDS,
    LATENT,
    MEASURED,
    MEDIUM,
    RANGES,
    ROTATION_RANGE,
)
from nbrdf.neural.openpbr import mix_summary


def _plain_default(v: Any) -> Any:
    """A parameter default as a material holds it: one number where the three channels agree."""
    if isinstance(v, tuple) and len(set(v)) == 1:
        return float(v[0])
    return v

CHANNELS = ("r", "g", "b", "a", "l")


@dataclass(frozen=True)
class TextureRef:
    """A parameter read from an image: texel value v in [0, 1] of ``channel``
    ("l" = luminance) maps to lo + v (hi - lo)."""

    path: str
    channel: str
    range: tuple[float, float]
    resolved: Path = field(compare=False)


Scalar = Union[float, TextureRef]
PerChannel = Union[float, tuple[Union[float, TextureRef], ...], TextureRef]


@dataclass(frozen=True)
class Dielectric:
    roughness: Scalar
    ior: Scalar
    anisotropy: Scalar = 0.0
    """SPEC section 10's a in [0, 0.95]: alpha_x, alpha_y from roughness; 0 = isotropic"""
    type: str = field(default=DIELECTRIC, init=False)


@dataclass(frozen=True)
class Medium:
    albedo: PerChannel
    sigma_t: PerChannel
    type: str = field(default=MEDIUM, init=False)


@dataclass(frozen=True)
class Conductor:
    roughness: Scalar
    r0: PerChannel
    f82_tint: PerChannel = 1.0
    """OpenPBR's F82-tint edge colour; 1 = Schlick's Fresnel"""
    anisotropy: Scalar = 0.0
    """SPEC section 10's a in [0, 0.95]: alpha_x, alpha_y from roughness; 0 = isotropic"""
    type: str = field(default=CONDUCTOR, init=False)


@dataclass(frozen=True)
class Diffuse:
    albedo: PerChannel
    type: str = field(default=DIFFUSE, init=False)


@dataclass(frozen=True)
class Measured:
    """A MERL .binary table."""

    path: str
    resolved: Path = field(compare=False)
    type: str = field(default=MEASURED, init=False)


@dataclass(frozen=True)
class LatentBase:
    """A saved latent (safetensors) used as the base."""

    path: str
    resolved: Path = field(compare=False)
    type: str = field(default=LATENT, init=False)


Layer = Union[Dielectric, Medium, Conductor, Diffuse, Measured, LatentBase]

#: layer type -> {parameter: "scalar" | "rgb" | "path"}, from the table of layer kinds.
_FIELDS: dict[str, dict[str, str]] = {k.name: {p.name: p.shape for p in k.params} for k in KINDS.values()}
#: layer type -> {optional parameter: the value it takes when left out}.
_OPTIONAL: dict[str, dict[str, Any]] = {k.name: {p.name: _plain_default(p.default) for p in k.params if p.optional}
                                        for k in KINDS.values()}
_CLASSES = {DIELECTRIC: Dielectric, MEDIUM: Medium, CONDUCTOR: Conductor, DIFFUSE: Diffuse,
            MEASURED: Measured, LATENT: LatentBase}
BASE_TYPES = BASE_KINDS


@dataclass(frozen=True)
class Material:
    name: str
    layers: tuple[Layer, ...]
    normal_map: str | None = None
    base_dir: Path = field(default=Path("."), compare=False)
    openpbr: tuple[tuple[str, Any], ...] | None = None
    """the OpenPBR Surface inputs this stack was made from (name, number or (r, g, b)), in the file's
    order; None for a material made here (SPEC section 11: round trips and editing in OpenPBR's terms)"""
    anisotropy_rotation: float = 0.0
    """degrees the tangent turns about the normal, counter-clockwise seen from above, shared by every
    interface (SPEC section 10); written only where it is not 0"""

    @property
    def base(self) -> Layer:
        return self.layers[-1]

    @property
    def interfaces(self) -> list[tuple[Dielectric, Medium | None]]:
        """Every interface above the base with the medium below it (None: no medium)."""
        out: list[tuple[Dielectric, Medium | None]] = []
        for layer in self.layers[:-1]:
            if isinstance(layer, Dielectric):
                out.append((layer, None))
            elif isinstance(layer, Medium):
                out[-1] = (out[-1][0], layer)
        return out

    @property
    def is_textured(self) -> bool:
        return bool(self.textures())

    def textures(self) -> list[tuple[str, TextureRef]]:
        """(place, reference) of every texture-mapped parameter."""
        found = []
        for i, layer in enumerate(self.layers):
            for key in _FIELDS[layer.type]:
                v = getattr(layer, key)
                if isinstance(v, TextureRef):
                    found.append((f"layers[{i}].{key}", v))
                elif isinstance(v, tuple):
                    found += [(f"layers[{i}].{key}[{c}]", x) for c, x in enumerate(v) if isinstance(x, TextureRef)]
        return found

    @staticmethod
    def rgb(value: PerChannel) -> tuple[float, float, float]:
        """A scalar or per-channel parameter as three floats."""
        if isinstance(value, TextureRef) or (isinstance(value, tuple) and any(isinstance(x, TextureRef) for x in value)):
            raise NbrdfError(f"{value}: a texture-mapped parameter has no single value")
        if isinstance(value, tuple):
            r, g, b = (float(x) for x in value if not isinstance(x, TextureRef))
            return (r, g, b)
        return (float(value), float(value), float(value))


# --- parsing ---------------------------------------------------------------------------
def _number(v: Any, place: str, lo: float, hi: float) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise NbrdfError(f"{place}: expected a number, got {_kind(v)}")
    f = float(v)
    if not math.isfinite(f):
        raise NbrdfError(f"{place}: {v} is not a finite number")
    if not lo <= f <= hi:
        raise NbrdfError(f"{place}: {_g(f)} is outside [{_g(lo)}, {_g(hi)}]")
    return f


def _g(x: float) -> str:
    return f"{x:g}" if abs(x) < 1e6 else repr(x)


def _kind(v: Any) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, str):
        return f"the string {json.dumps(v)[:40]}"
    if isinstance(v, list):
        return "a list"
    if isinstance(v, dict):
        return "an object"
    return type(v).__name__


def _texture(v: dict, place: str, key: str, base_dir: Path) -> TextureRef:
    for k in v:
        if k not in ("texture", "channel", "range"):
            raise NbrdfError(f"{place}.{k}: unknown key")
    path = v.get("texture")
    if not isinstance(path, str) or not path or "\0" in path:
        raise NbrdfError(f"{place}.texture: expected a file path, got {_kind(path)}")
    channel = v.get("channel", "r")
    if channel not in CHANNELS:
        raise NbrdfError(f"{place}.channel: expected one of {', '.join(CHANNELS)}, got {_kind(channel)}")
    lo, hi = RANGES[key]
    rng = v.get("range", [lo, hi])
    if not isinstance(rng, list) or len(rng) != 2:
        raise NbrdfError(f"{place}.range: expected [lo, hi]")
    a = _number(rng[0], f"{place}.range[0]", lo, hi)
    b = _number(rng[1], f"{place}.range[1]", lo, hi)
    if a > b:
        raise NbrdfError(f"{place}.range: lo {_g(a)} is above hi {_g(b)}")
    resolved = (base_dir / path).resolve()
    if not resolved.is_file():
        raise NbrdfError(f"{place}.texture: {resolved} not found")
    return TextureRef(path, channel, (rng[0], rng[1]), resolved)


def _scalar(v: Any, place: str, key: str, base_dir: Path) -> Scalar:
    if isinstance(v, dict):
        return _texture(v, place, key, base_dir)
    if isinstance(v, list):
        raise NbrdfError(f"{place}: {key} is shared by the three channels; expected one number")
    lo, hi = RANGES[key]
    _number(v, place, lo, hi)
    return v


def _rgb(v: Any, place: str, key: str, base_dir: Path) -> PerChannel:
    if isinstance(v, list):
        if len(v) != 3:
            raise NbrdfError(f"{place}: expected 3 values (r, g, b), got {len(v)}")
        return tuple(_scalar(x, f"{place}[{c}]", key, base_dir) for c, x in enumerate(v))
    return _scalar(v, place, key, base_dir)


def _layer(v: Any, i: int, base_dir: Path) -> Layer:
    place = f"layers[{i}]"
    if not isinstance(v, dict):
        raise NbrdfError(f"{place}: expected an object, got {_kind(v)}")
    t = v.get("type")
    if not isinstance(t, str) or t not in _FIELDS:
        if "type" not in v:
            raise NbrdfError(f'{place}: missing key "type"')
        raise NbrdfError(f"{place}.type: unknown layer type {_kind(t) if not isinstance(t, str) else json.dumps(t)}"
                         f" (expected one of {', '.join(_FIELDS)})")
    fields = _FIELDS[t]
    for k in v:
        if k != "type" and k not in fields:
            raise NbrdfError(f"{place}.{k}: unknown key")
    optional = _OPTIONAL[t]
    for k in fields:
        if k not in v and k not in optional:
            raise NbrdfError(f'{place}: missing key "{k}"')
    kw: dict[str, Any] = {}
    for k, kind in fields.items():
        p = f"{place}.{k}"
        if k not in v:
            kw[k] = optional[k]
            continue
        if kind == "scalar":
            kw[k] = _scalar(v[k], p, k, base_dir)
        elif kind == "rgb":
            kw[k] = _rgb(v[k], p, k, base_dir)
        else:
            if not isinstance(v[k], str) or not v[k] or "\0" in v[k]:
                raise NbrdfError(f"{p}: expected a file path, got {_kind(v[k])}")
            resolved = (base_dir / v[k]).resolve()
            if not resolved.is_file():
                raise NbrdfError(f"{p}: {resolved} not found")
            kw[k] = v[k]
            kw["resolved"] = resolved
    return _CLASSES[t](**kw)


def _check_stack(layers: list[Layer]) -> None:
    """Interfaces (each optionally followed by one medium) above one base."""
    n = len(layers)
    for i, layer in enumerate(layers):
        kind = KINDS[layer.type]
        if isinstance(layer, Medium):
            if i == 0 or i == n - 1 or not isinstance(layers[i - 1], Dielectric):
                raise NbrdfError(f"layers[{i}]: a medium must sit between two interfaces")
        elif i < n - 1 and not kind.interface:
            raise NbrdfError(f"layers[{i}]: a {layer.type} can only be the base (the last layer); "
                             "above the base come dielectric interfaces and media")


def parse_material(data: object, base_dir: Path | str = ".", source: str = "material") -> Material:
    """Validates a decoded JSON document; paths resolve against ``base_dir``."""
    base_dir = Path(base_dir)
    if not isinstance(data, dict):
        raise NbrdfError(f"{source}: expected a JSON object at the top level, got {_kind(data)}")
    for k in data:
        if k not in ("format", "name", "layers", "normal_map", "openpbr", "anisotropy_rotation"):
            raise NbrdfError(f"{k}: unknown key")
    if "format" not in data:
        raise NbrdfError(f'{source}: missing key "format" (expected "{FORMAT}")')
    if data["format"] != FORMAT:
        raise NbrdfError(f'format: expected "{FORMAT}", got {_kind(data["format"]) if not isinstance(data["format"], str) else json.dumps(data["format"])}')
    name = data.get("name", "")
    if not isinstance(name, str):
        raise NbrdfError(f"name: expected a string, got {_kind(name)}")
    if "layers" not in data:
        raise NbrdfError(f'{source}: missing key "layers"')
    raw = data["layers"]
    if not isinstance(raw, list) or not raw:
        raise NbrdfError("layers: expected a non-empty list of layers")
    layers = [_layer(v, i, base_dir) for i, v in enumerate(raw)]
    _check_stack(layers)
    normal = data.get("normal_map")
    if normal is not None:
        if not isinstance(normal, str) or not normal or "\0" in normal:
            raise NbrdfError(f"normal_map: expected a file path, got {_kind(normal)}")
        if not (base_dir / normal).is_file():
            raise NbrdfError(f"normal_map: {(base_dir / normal).resolve()} not found")
    record = _openpbr_record(data["openpbr"]) if "openpbr" in data else None
    rotation = data.get("anisotropy_rotation", 0.0)
    _number(rotation, "anisotropy_rotation", *ROTATION_RANGE)
    return Material(name=name, layers=tuple(layers), normal_map=normal, base_dir=base_dir.resolve(), openpbr=record,
                    anisotropy_rotation=rotation)


def _openpbr_record(v: Any) -> tuple[tuple[str, Any], ...]:
    """The "openpbr" object: input names to numbers or [r, g, b] (the inputs themselves are
    checked where they are used, ``neural.openpbr``)."""
    if not isinstance(v, dict):
        raise NbrdfError(f"openpbr: expected an object of OpenPBR inputs, got {_kind(v)}")
    out: list[tuple[str, Any]] = []
    for k, x in v.items():
        place = f"openpbr.{k}"
        if isinstance(x, list):
            if len(x) != 3:
                raise NbrdfError(f"{place}: expected a number or 3 values (r, g, b), got {len(x)}")
            out.append((k, tuple(_number(c, f"{place}[{i}]", -math.inf, math.inf) for i, c in enumerate(x))))
        elif isinstance(x, bool):
            out.append((k, x))
        else:
            out.append((k, _number(x, place, -math.inf, math.inf)))
    return tuple(out)


def _reject_constant(token: str):
    raise ValueError(f"{token} is not a number")


def is_mtlx(path: str | Path) -> bool:
    """Whether ``path`` names a MaterialX document (``FILE.mtlx``, or ``FILE.mtlx#Material`` for one of several)."""
    s = str(path).lower()
    head, sep, _ = s.rpartition("#")
    return s.endswith(".mtlx") or (bool(sep) and head.endswith(".mtlx"))


def is_material_file(path: str | Path) -> bool:
    """Whether ``path`` names a material description (JSON or MaterialX), not a code file."""
    return is_mtlx(path) or str(path).lower().endswith(".json")


def load_material(path: str | Path, notes: list[str] | None = None) -> Material:
    """Reads and validates a material file: the project's JSON, or a MaterialX document (``FILE.mtlx``,
    ``FILE.mtlx#Name``) mapped to a stack (``neural.openpbr``, SPEC section 11). What the stack cannot hold
    comes back as one-line notes, each starting with the file: appended to ``notes``, or, without a list,
    printed on stderr (never dropped in silence)."""
    if is_mtlx(path):
        from nbrdf.neural.mtlx import read_mtlx, split_material_ref  # late: MaterialX loads for .mtlx files only

        file, name = split_material_ref(str(path))
        data, found = read_mtlx(file, name)
        material = parse_material(data, Path(file).parent, source=str(path))
        mixed = mix_summary(material.openpbr, textured=True) if material.openpbr and material.is_textured else None
        lines = [f"{path}: {note}" for note in (found if mixed is None else [*found, mixed])]
        if notes is None:
            for line in lines:
                print(line, file=sys.stderr)
        else:
            notes.extend(lines)
        return material
    p = Path(path)
    if not p.is_file():
        raise NbrdfError(f"{path}: no such file")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise NbrdfError(f"{path}: not a UTF-8 text file") from None
    except OSError as e:
        raise NbrdfError(f"{path}: cannot be read ({e.strerror})") from None
    if not text.strip():
        raise NbrdfError(f"{path}: the file is empty")
    try:
        data = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as e:
        raise NbrdfError(f"{path}: not valid JSON at line {e.lineno}, column {e.colno} ({e.msg})") from None
    except ValueError as e:
        raise NbrdfError(f"{path}: {e}") from None
    except RecursionError:
        raise NbrdfError(f"{path}: nested too deeply") from None
    material = parse_material(data, p.parent, source=str(path))
    if material.openpbr is not None:  # an OpenPBR mix saved as JSON: said as the .mtlx reader says it
        note = mix_summary(material.openpbr, material.is_textured)
        if note is not None:
            if notes is None:
                print(f"{path}: {note}", file=sys.stderr)
            else:
                notes.append(f"{path}: {note}")
    return material


# --- writing ---------------------------------------------------------------------------
def _rel(resolved: Path, new_dir: Path) -> str:
    return os.path.relpath(resolved, new_dir.resolve())


def _value_to_json(v: Any, new_dir: Path | None) -> Any:
    if isinstance(v, TextureRef):
        path = v.path if new_dir is None else _rel(v.resolved, new_dir)
        return {"texture": path, "channel": v.channel, "range": list(v.range)}
    if isinstance(v, tuple):
        return [_value_to_json(x, new_dir) for x in v]
    return v


def material_to_dict(m: Material, new_dir: Path | None = None) -> dict:
    """The JSON form; with ``new_dir``, file paths are rewritten relative to it."""
    layers = []
    for layer in m.layers:
        d: dict[str, Any] = {"type": layer.type}
        for k in _FIELDS[layer.type]:
            if k in _OPTIONAL[layer.type] and getattr(layer, k) == _OPTIONAL[layer.type][k]:
                continue  # left out: the file stays as it was before the parameter existed
            if isinstance(layer, (Measured, LatentBase)) and k == "path":
                d[k] = layer.path if new_dir is None else _rel(layer.resolved, new_dir)
            else:
                d[k] = _value_to_json(getattr(layer, k), new_dir)
        layers.append(d)
    out: dict[str, Any] = {"format": FORMAT, "name": m.name, "layers": layers}
    if m.openpbr is not None:
        out["openpbr"] = {k: list(v) if isinstance(v, tuple) else v for k, v in m.openpbr}
    if m.anisotropy_rotation != 0:
        out["anisotropy_rotation"] = m.anisotropy_rotation
    if m.normal_map is not None:
        out["normal_map"] = m.normal_map if new_dir is None else _rel(m.base_dir / m.normal_map, new_dir)
    return out


def save_material(m: Material, path: str | Path) -> None:
    """Writes pretty JSON; relative paths still point at the same files."""
    p = Path(path)
    if not p.parent.is_dir():
        raise NbrdfError(f"{path}: the folder {p.parent} does not exist")
    save_text(p, json.dumps(material_to_dict(m, p.parent), indent=2) + "\n")
