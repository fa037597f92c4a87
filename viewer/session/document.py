"""The look-development session document: what an artist saves and reopens.

``SessionDoc`` is the ``nbrdf-session/1`` file as a typed value: the material
document, the mesh, the environment, the view state (camera, lights, view,
tone mapping), the compare settings and the interpolation. ``parse`` checks a
whole file before anything is applied, so a bad file changes nothing; files
written by every earlier version of the previewer (the same format, with the
optional keys they lacked) still open.
"""
from __future__ import annotations

import json
import math
import os
import typing
from dataclasses import asdict, dataclass, field, fields, is_dataclass
from pathlib import Path

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.files import save_text
from nbrdf.neural.material import Material, material_to_dict, parse_material
from nbrdf.viewer.gpu.backdrop import BackdropSettings
from nbrdf.viewer.modes import Against, CompareMode
from nbrdf.viewer.view_settings import ViewState, from_session, to_session

SESSION_FORMAT = "nbrdf-session/1"


INTERPOLATION_MODES = ("latent", "brdf")
"""latent: blend the latents and decode once; brdf: blend the two decoded BRDF values (two renders)."""


@dataclass
class Interpolation:
    """The second material of an interpolation and the blend between the two."""

    other: dict | None = None
    """The second material's document (None: interpolation off)."""
    other_dir: str = "."
    """The folder its relative texture paths resolve against."""
    t: float = 0.0
    """The weight of the second material, in [0, 1]."""
    mode: str = "latent"
    """``latent`` (blend the latents) or ``brdf`` (blend the BRDF values)."""

    def __post_init__(self) -> None:
        if self.mode not in INTERPOLATION_MODES:
            raise NbrdfError(f"interpolation mode {self.mode!r}: latent or brdf")
        if not (math.isfinite(float(self.t)) and 0.0 <= float(self.t) <= 1.0):
            raise NbrdfError(f"interpolation weight {self.t} is outside [0, 1]")
        self.t = float(self.t)

    @property
    def active(self) -> bool:
        return self.other is not None

    @property
    def brdf_blend(self) -> bool:
        """Two renders blended per pixel (rather than one render of the blended latent)."""
        return self.other is not None and self.mode == "brdf"

    def other_material(self) -> Material | None:
        return None if self.other is None else parse_material(self.other, self.other_dir)


@dataclass
class CompareSettings:
    """How the reference is shown beside the neural image."""

    mode: CompareMode = CompareMode.OFF
    """off, side, wipe or error."""
    wipe: float = 0.5
    """The x of the A/B wipe line, 0..1 of the view."""
    error_scale: float = 0.25
    """The relative error shown as full red in the error view."""
    against: Against = Against.REFERENCE
    """What the neural image is compared with: the stack's reference, or MaterialX's shader of its OpenPBR inputs."""

    def __post_init__(self) -> None:
        self.mode = CompareMode.parse(self.mode, "compare mode")
        self.against = Against.parse(self.against, "compare against")
        self.wipe, self.error_scale = float(self.wipe), float(self.error_scale)
        if not (0.0 <= self.wipe <= 1.0) or not (math.isfinite(self.error_scale) and self.error_scale > 0):
            raise NbrdfError(f"compare: wipe {self.wipe} must be in [0, 1], error scale {self.error_scale} > 0")


def require_finite(data: object, source: str, where: str = "") -> None:
    """One-line ``NbrdfError`` naming the first non-finite number in a session
    document (JSON reads ``NaN`` and ``Infinity``; no field of a session takes
    them, and one would render black or move the camera to nowhere). On a
    dataclass (the parsed view state) it also refuses a field typed ``float``
    that holds anything but a number (a string "nan" converts with ``float``)."""
    if is_dataclass(data):
        hints = typing.get_type_hints(type(data))
        for f in fields(data):
            value, name = getattr(data, f.name), f"{where}.{f.name}".lstrip(".")
            tp = hints[f.name]
            if tp is float or (typing.get_origin(tp) is tuple and set(typing.get_args(tp)) == {float}):
                for x in value if isinstance(value, (tuple, list)) else (value,):
                    if isinstance(x, bool) or not isinstance(x, (int, float)):
                        raise NbrdfError(f"{source}: {name} is {x!r}, not a number")
            require_finite(value, source, name)
        return
    if isinstance(data, float) and not math.isfinite(data):
        raise NbrdfError(f"{source}: {where or 'value'} is {data}, not a finite number")
    items = data.items() if isinstance(data, dict) else enumerate(data) if isinstance(data, (list, tuple)) else ()
    for key, value in items:
        require_finite(value, source, f"{where}[{key}]" if isinstance(key, int) else f"{where}.{key}".lstrip("."))


@dataclass
class SessionDoc:
    """One look-development session, as saved to and read from a file."""

    material: Material
    """The edited material."""
    mesh: str = "sphere"
    """sphere, testmesh or a mesh file."""
    environment: str | None = None
    """An equirectangular environment file (None: the built-in sky)."""
    state: ViewState = field(default_factory=ViewState)
    """Camera, lights, view, exposure and tone mapping."""
    compare: CompareSettings = field(default_factory=CompareSettings)
    """The compare mode and its settings."""
    mipmapping: bool = True
    """Trilinear latent-texture lookup (off shows the aliasing)."""
    interpolation: Interpolation = field(default_factory=Interpolation)
    """The material interpolation (off unless ``other`` is set)."""
    backdrop: BackdropSettings = field(default_factory=BackdropSettings)
    """The background behind the object and the ground's contact shadow."""

    def to_dict(self) -> dict:
        """The ``nbrdf-session/1`` document."""
        settings = to_session(self.state)
        view = settings.pop("view")
        return {
            "format": SESSION_FORMAT,
            "material": material_to_dict(self.material),
            "material_dir": str(self.material.base_dir),
            "mesh": self.mesh,
            "environment": self.environment,
            **settings,
            "view": {**view, "compare": self.compare.mode.value, "wipe": self.compare.wipe,
                     "error_scale": self.compare.error_scale, "against": self.compare.against.value,
                     "mipmapping": self.mipmapping},
            "interpolation": asdict(self.interpolation),
            "backdrop": {"mode": self.backdrop.mode.value, "flat_colour": list(self.backdrop.flat_colour),
                         "ground": self.backdrop.ground},
        }

    def save(self, path: str | Path) -> None:
        """Writes the document atomically (a failed write leaves any previous file whole)."""
        save_text(path, json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def parse(cls, data: object, source: str = "session") -> "SessionDoc":
        """A session from its document; every field is checked, errors are one line."""
        if not isinstance(data, dict) or data.get("format") != SESSION_FORMAT:
            raise NbrdfError(f"{source}: not an {SESSION_FORMAT} file")
        require_finite(data, source)
        try:
            mat = parse_material(data["material"], data.get("material_dir", "."), source=f"{source}: material")
            v = data["view"]
            state = from_session(data)
            require_finite(state, source)
            interp = Interpolation(**data.get("interpolation", {}))
            bd = data.get("backdrop") or {}  # older sessions: the defaults
            backdrop = BackdropSettings(bd.get("mode", BackdropSettings.mode), bd.get("flat_colour", (0.18,) * 3),
                                        bd.get("ground", True))
            try:
                compare = CompareSettings(v.get("compare", CompareMode.OFF.value), v.get("wipe", 0.5),
                                          v.get("error_scale", 0.25), v.get("against", Against.REFERENCE.value))
            except ValueError as e:
                raise NbrdfError(f"{source}: {e}") from None
        except NbrdfError as e:
            msg = str(e)
            raise NbrdfError(msg if msg.startswith(source) else f"{source}: {msg}") from None
        except (KeyError, TypeError, ValueError, AttributeError) as e:
            raise NbrdfError(f"{source}: malformed session ({type(e).__name__}: {e})") from None
        return cls(material=mat, mesh=data.get("mesh", "sphere"), environment=data.get("environment"),
                   state=state, compare=compare, mipmapping=bool(v.get("mipmapping", True)), interpolation=interp,
                   backdrop=backdrop)

    @classmethod
    def load(cls, path: str | Path) -> "SessionDoc":
        """Reads and checks a session file."""
        p = Path(path)
        if not p.is_file():
            raise NbrdfError(f"{p}: no such file")
        try:
            data = json.loads(p.read_text(encoding="utf-8"))  # NaN or Infinity: require_finite names the field
        except json.JSONDecodeError as e:
            raise NbrdfError(f"{p}: not JSON ({e.msg} at line {e.lineno})") from None
        except UnicodeDecodeError:
            raise NbrdfError(f"{p}: not a UTF-8 text file") from None
        except ValueError as e:
            raise NbrdfError(f"{p}: {e}") from None
        except RecursionError:
            raise NbrdfError(f"{p}: nested too deeply") from None
        except OSError as e:
            raise NbrdfError(f"{p}: cannot be read ({e.strerror or type(e).__name__})") from None
        return cls.parse(data, str(p))


# --- the window's remembered size ---------------------------------------------------------
#: The share of the screen a first window opens at (each side).
SCREEN_SHARE = 0.8
WINDOW_PREFS_FORMAT = "nbrdf-window/1"


def prefs_path() -> Path:
    """Where the window's size is kept between runs: $XDG_CONFIG_HOME/nbrdf/window.json."""
    base = os.environ.get("XDG_CONFIG_HOME") or os.path.join(os.path.expanduser("~"), ".config")
    return Path(base) / "nbrdf" / "window.json"


@dataclass
class WindowPrefs:
    """What the window remembers between runs (not part of a session: a session
    opened on another screen keeps that screen's window)."""

    size: tuple[int, int] | None = None
    """The window's last size in screen coordinates (None: never opened)."""

    def initial_size(self, screen: tuple[int, int] | None) -> tuple[int, int]:
        """The size a window opens at: the remembered one if it fits ``screen``,
        else ``SCREEN_SHARE`` of the screen (1024 x 640 when it is unknown)."""
        if screen is None or screen[0] <= 0 or screen[1] <= 0:
            return self.size or (1024, 640)
        if self.size is not None and self.size[0] <= screen[0] and self.size[1] <= screen[1]:
            return self.size
        return max(320, round(screen[0] * SCREEN_SHARE)), max(240, round(screen[1] * SCREEN_SHARE))

    @classmethod
    def load(cls, path: Path | None = None) -> "WindowPrefs":
        """The remembered preferences; a missing or unreadable file gives the defaults
        (the window must open whatever is in it)."""
        p = path or prefs_path()
        try:
            data = json.loads(p.read_text())
            w, h = (int(x) for x in data["size"])
            if data.get("format") != WINDOW_PREFS_FORMAT or not (100 <= w <= 16384 and 100 <= h <= 16384):
                return cls()
            return cls(size=(w, h))
        except (OSError, ValueError, KeyError, TypeError):
            return cls()

    def save(self, path: Path | None = None) -> None:
        """Writes the preferences (a read-only home only loses the memory, never the session)."""
        p = path or prefs_path()
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text(json.dumps({"format": WINDOW_PREFS_FORMAT,
                                     "size": list(self.size) if self.size else None}) + "\n")
        except OSError:
            pass
