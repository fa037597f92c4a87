"""The view settings, declared once: everything that decides a frame besides
the material and the mesh.

``ViewState`` is a dataclass whose fields say, in their ``metadata``, where
each setting goes besides the renderer:

- ``session``: its (section, key) in the ``nbrdf-session/1`` document
  (``to_session`` / ``from_session`` read and write every such field);
- ``cli``: a ``nbrdf-view`` flag (``cli/config.py`` makes it from the field,
  its type and the docstring under it; ``bounds`` are checked by ``check_flags``);
- ``row``: a panel row (``Row``: which panel, the label, the widget and its range;
  viewer/ui/panels.py draws every row of a panel in field order);
- ``uniform``: (name, form) of the lit shader's uniform it sets (``bind_uniforms``;
  the lit passes call it for every lit program).

A new view setting of the lit pass is then one field here and the shader code
that reads its uniform (and, when it changes the light, the Monte Carlo
reference's model of it, viewer/reference/compare.py).
"""
from __future__ import annotations

import math
import types
import typing
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np

from nbrdf.imaging.tonemap import ToneMap
from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.modes import View
from nbrdf.viewer.scene.camera import OrbitCamera


def parse_point(text: str) -> tuple[float, float, float]:
    """``X,Y,Z`` -> a finite world position; one-line error otherwise."""
    try:
        point = tuple(float(x) for x in text.split(","))
    except ValueError:
        point = ()
    if len(point) != 3 or not all(math.isfinite(x) for x in point):
        raise NbrdfError(f"--point-light: expected X,Y,Z such as 2,-2,3, got {text!r}")
    return point  # type: ignore[return-value]


@dataclass(frozen=True)
class Row:
    """How a setting is shown in the panels."""

    panel: str
    """"view" or "scene": the panel section the row is in."""
    label: str
    """The widget's label."""
    widget: str = "slider"
    """slider, check, choice (an enum's words, ``labels``), radio (the same as buttons),
    direction (azimuth and elevation sliders of a unit vector) or point (a switch and a position)."""
    lo: float = 0.0
    """The slider's low end."""
    hi: float = 1.0
    """The slider's high end."""
    fmt: str = "%.3f"
    """The slider's number format."""
    when: str | None = None
    """Shown only while this other setting is not None."""
    labels: tuple[tuple[str, str], ...] = ()
    """(word, label) of a choice's items (a word without one shows as itself)."""


def setting(default: Any = None, *, session: tuple[str, str] | None = None, cli: bool = False,
            row: Row | None = None, bounds: tuple[float, float, bool] | None = None, optional: bool = False,
            uniform: tuple[str, str] | None = None, factory: Any = None, **meta: Any) -> Any:
    """A ``ViewState`` field: ``session`` (section, key) in the session document
    (``optional``: older files may lack it, the default is used); ``cli``: a
    flag; ``row``: a panel row; ``bounds`` (lo, hi, hi inclusive) checked on the
    flag; ``uniform``: (name, form) of the lit shader's uniform, form one of
    ``UNIFORM_FORMS``; further ``meta`` goes to cli/config.py (``parse``, ``metavar``)."""
    md = {"session": session, "cli": cli, "row": row, "bounds": bounds, "optional": optional,
          "uniform": uniform, **meta}
    if factory is not None:
        return field(default_factory=factory, metadata=md)
    return field(default=default, metadata=md)


TONEMAP_LABELS = ((ToneMap.ACES.value, "ACES filmic"), (ToneMap.AGX.value, "AgX"),
                  (ToneMap.NEUTRAL.value, "Khronos PBR Neutral"), (ToneMap.LINEAR.value, "linear"))


@dataclass
class ViewState:
    """Everything that decides a frame besides the material and the mesh."""

    view: View = setting(View.OBJECT, session=("view", "view"), cli=True, row=Row("view", "view", "radio"))
    """what the viewport shows"""
    theta_i: float = setting(30.0, session=("view", "theta_i"), cli=True, bounds=(0.0, 90.0, False),
                             row=Row("view", "incidence (deg)", lo=0.0, hi=89.0))
    """incidence angle of the lobe view, degrees"""
    camera: OrbitCamera = setting(factory=OrbitCamera, session=("camera", ""))
    """The orbit camera of the object view."""
    env_on: bool = setting(True, session=("lighting", "env_on"), uniform=("u_env_on", "int"),
                           row=Row("scene", "environment light", "check"))
    """False: the directional (and point) light alone."""
    env_rotation: float = setting(0.0, session=("lighting", "env_rotation"), cli=True,
                                  bounds=(-math.inf, math.inf, False),
                                  row=Row("scene", "env rotation", lo=-180.0, hi=180.0))
    """environment rotation about the up axis, degrees"""
    env_intensity: float = setting(0.6, session=("lighting", "env_intensity"), cli=True,
                                   bounds=(0.0, math.inf, False), uniform=("u_env_intensity", "float"),
                                   row=Row("scene", "env intensity", hi=4.0))
    """environment radiance scale"""
    light_dir: tuple[float, float, float] = setting((0.4, -0.6, 0.7), session=("light", "direction"),
                                                    uniform=("u_light_dir", "direction"),
                                                    row=Row("scene", "light", "direction"))
    """Toward the directional light, world space."""
    light_radiance: float = setting(3.0, session=("light", "radiance"), uniform=("u_light_radiance", "rgb"),
                                    row=Row("scene", "light intensity", hi=20.0))
    """The directional light's radiance."""
    point_light: tuple[float, float, float] | None = setting(
        None, session=("light", "point"), optional=True, cli=True, parse=parse_point, metavar="X,Y,Z",
        uniform=("u_point_pos", "point"),
        row=Row("scene", "point light", "point", lo=-20.0, hi=20.0))
    """a point light at this world position (z up)"""
    point_intensity: float = setting(20.0, session=("light", "point_intensity"), optional=True, cli=True,
                                     bounds=(0.0, math.inf, False), uniform=("u_point_intensity", "rgb"),
                                     row=Row("scene", "point intensity", hi=200.0, when="point_light"))
    """the point light's radiant intensity"""
    background: bool = setting(True, session=("lighting", "background"))
    """The environment behind the object (the backdrop's mode decides it where one is drawn)."""
    exposure: float = setting(0.0, session=("view", "exposure"), cli=True,
                              row=Row("scene", "exposure (EV)", lo=-6.0, hi=6.0, fmt="%+.1f EV"))
    """exposure in EV (stops: +1 doubles the brightness)"""
    tonemap: ToneMap = setting(ToneMap.NEUTRAL, session=("view", "tonemap"), cli=True,
                               row=Row("scene", "tone mapping", "choice", labels=TONEMAP_LABELS))
    """display transform of a .png or the window (Khronos PBR Neutral keeps base colours: presets read as
    their names)"""

    def __post_init__(self) -> None:
        try:
            self.view = View.parse(self.view, "--view")
            self.tonemap = ToneMap.parse(self.tonemap, "--tonemap")
        except ValueError as e:
            raise NbrdfError(str(e)) from None


#: How a setting's value becomes its uniform: int (a switch), float, rgb (a grey
#: vec3), direction (normalised vec3), point (a position, or off: its ``_on``
#: uniform, named as the position's with ``_pos`` replaced, says which).
UNIFORM_FORMS = ("int", "float", "rgb", "direction", "point")


def bind_uniforms(prog, state: ViewState) -> None:
    """Sets the uniforms of every setting marked ``uniform`` on a lit program."""
    for f in fields(ViewState):
        spec = f.metadata.get("uniform")
        if spec is None:
            continue
        name, form = spec
        x = getattr(state, f.name)
        if form == "int":
            prog[name].value = int(x)
        elif form == "float":
            prog[name].value = float(x)
        elif form == "rgb":
            prog[name].value = (float(x),) * 3
        elif form == "direction":
            d = np.asarray(x, dtype=np.float64)
            prog[name].value = tuple(d / np.linalg.norm(d))
        else:
            prog[name.replace("_pos", "_on")].value = int(x is not None)
            prog[name].value = tuple(x or (0.0, 0.0, 0.0))


def rows(panel: str) -> list:
    """(name, ``Row``, type) of every setting shown in ``panel``, in declaration order."""
    hints = typing.get_type_hints(ViewState)
    return [(f.name, f.metadata["row"], hints[f.name]) for f in fields(ViewState)
            if f.metadata.get("row") is not None and f.metadata["row"].panel == panel]


def cli_fields() -> list[str]:
    """The names of the settings that are ``nbrdf-view`` flags."""
    return [f.name for f in fields(ViewState) if f.metadata.get("cli")]


def check_flags(state: ViewState) -> ViewState:
    """Raises ``NbrdfError`` naming the flag of the first setting out of its ``bounds``."""
    for f in fields(ViewState):
        bounds = f.metadata.get("bounds")
        if bounds is None:
            continue
        lo, hi, closed = bounds
        x = getattr(state, f.name)
        flag = "--" + f.name.replace("_", "-")
        if math.isinf(hi) and not (math.isfinite(x) and x >= lo):
            raise NbrdfError(f"{flag}: {x} must be finite" + ("" if math.isinf(lo) else f" and >= {lo:g}"))
        if not math.isinf(hi) and not (lo <= x <= hi if closed else lo <= x < hi):
            raise NbrdfError(f"{flag}: {x} is outside [{lo:g}, {hi:g}{']' if closed else ')'}")
    return state


def _encode(value: Any) -> Any:
    if isinstance(value, (View, ToneMap)):
        return value.value
    if isinstance(value, OrbitCamera):
        return asdict(value)
    if isinstance(value, tuple):
        return list(value)
    return value


def to_session(state: ViewState) -> dict[str, dict]:
    """The settings' sections of a session document: {section: {key: value}}
    (the camera's section is the camera itself)."""
    out: dict[str, dict] = {}
    for f in fields(ViewState):
        section, key = f.metadata["session"]
        value = _encode(getattr(state, f.name))
        if key:
            out.setdefault(section, {})[key] = value
        else:
            out[section] = value
    return out


#: How a session names a mode enum in its one-line errors.
_ENUM_WHAT = {View: "view", ToneMap: "tone mapping"}


def _decode(tp: Any, value: Any) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        inner = [a for a in typing.get_args(tp) if a is not type(None)][0]
        return _decode(inner, value) if value else None
    if tp is OrbitCamera:
        return OrbitCamera(**value)
    if tp in _ENUM_WHAT:
        try:
            return tp.parse(value, _ENUM_WHAT[tp])
        except ValueError as e:
            raise NbrdfError(str(e)) from None
    if origin is tuple:
        return tuple(float(x) for x in value)
    return tp(value)


def from_session(data: dict) -> ViewState:
    """The view state of a session document's sections (an unknown mode word is a
    one-line ``NbrdfError``; KeyError, TypeError or ValueError on a malformed
    document: the session parser words them)."""
    hints = typing.get_type_hints(ViewState)
    values = {}
    for f in fields(ViewState):
        section, key = f.metadata["session"]
        raw = data[section]
        if key:
            if key not in raw and f.metadata.get("optional"):
                continue
            raw = raw[key]
        values[f.name] = _decode(hints[f.name], raw)
    return ViewState(**values)
