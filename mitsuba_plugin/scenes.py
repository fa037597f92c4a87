"""Scenes for ``nbrdf render`` and ``nbrdf report scenes``: a small JSON (or a
preset name) -> a Mitsuba 3 scene, path traced with global illumination.

A scene JSON::

    {"camera": {"origin": [x, y, z], "target": [x, y, z], "up": [0, 0, 1], "fov": 30},
     "environment": {"preset": "studio", "scale": 1.0},        # optional (or just "studio")
     "point_light": {"position": [x, y, z], "intensity": 20},  # optional; intensity: W/sr, a number or RGB
     "max_depth": 8,                                            # optional
     "shapes": [{"type": "sphere", "center": [x, y, z], "radius": r, "material": M},
                {"type": "rectangle", "center": [x, y, z], "size": [w, h], "material": M},
                {"type": "teapot", "center": [x, y, z], "scale": s, "rotate_z": deg, "material": M},
                {"type": "torus", "center": [x, y, z], "radius": R, "tube": r, "rotate_z": deg, "material": M}]}

Any shape may carry ``"normal_map": {"name": "hammered"|"knurled", "tiles": [nu, nv],
"strength": s}`` (a generated tangent-space normal map, ``generated.normal_map``),
applied through Mitsuba's ``normalmap`` BSDF to the neural and the reference
material alike; spheres also take ``rotate_z``.

where a material ``M`` is a path (the ``nbrdf`` neural material; ``generated:globe`` is the
generated globe material, ``generated.globe_material``), ``{"reference": PATH}``
(its Monte Carlo ground truth, ``nbrdf_reference``) or ``{"diffuse": [r, g, b]}``.
Relative paths are relative to the scene file; preset scenes use the bundled
materials. World z is up; the environment is one of the project's generated
presets (``imaging/env_presets.py``), oriented as the previewer shows it.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mitsuba as mi
import numpy as np

from nbrdf.imaging.env_presets import ENV_PRESETS, make_environment
from nbrdf.mitsuba.generated import NORMAL_MAPS, globe_material, normal_map, torus_ply
from nbrdf.mitsuba.kernel import Body
from nbrdf.mitsuba.teapot import teapot_ply
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import is_material_file, load_material
from nbrdf.neural.methods import Method

ASSETS = Path(__file__).resolve().parents[1] / "viewer" / "assets" / "materials"
#: Size of the environment map handed to Mitsuba (texels ~0.7 degrees).
ENV_SIZE = (512, 256)
#: Path-tracing depth unless a scene sets ``max_depth``.
MAX_DEPTH = 8

PRESETS: dict[str, dict[str, Any]] = {
    # three spheres with different nbrdf materials on a grey floor, studio environment and a point light
    "still_life": {
        "camera": {"origin": [0.0, -6.2, 2.2], "target": [0.0, 0.0, 0.55], "up": [0, 0, 1], "fov": 30},
        "environment": {"preset": "studio", "scale": 1.0},
        "point_light": {"position": [-2.5, -2.0, 4.0], "intensity": 12.0},
        "shapes": [
            {"type": "sphere", "center": [-1.25, 0.2, 0.6], "radius": 0.6, "material": "@coated_copper.json"},
            {"type": "sphere", "center": [0.0, 0.6, 0.6], "radius": 0.6, "material": "@car_paint.json"},
            {"type": "sphere", "center": [1.25, 0.2, 0.6], "radius": 0.6, "material": "@rough_gold.json"},
            {"type": "rectangle", "center": [0.0, 0.5, 0.0], "size": [8.0, 6.0], "material": {"diffuse": [0.35, 0.35, 0.33]}},
        ],
    },
    # the paper's globe: a texture-mapped layered material (varnish over a medium and a base whose albedos follow
    # generated continents) on a sphere
    "globe": {
        "camera": {"origin": [0.0, -6.0, 2.0], "target": [0.0, 0.0, 0.85], "up": [0, 0, 1], "fov": 26},
        "environment": {"preset": "studio", "scale": 1.0},
        "point_light": {"position": [-2.5, -3.0, 4.0], "intensity": 12.0},
        "shapes": [
            {"type": "sphere", "center": [0.0, 0.0, 0.9], "radius": 0.9, "rotate_z": -100.0,
             "material": "generated:globe"},
            {"type": "rectangle", "center": [0.0, 0.5, 0.0], "size": [8.0, 6.0], "material": {"diffuse": [0.35, 0.35, 0.33]}},
        ],
    },
    # a generated shape with a generated normal map: a hammered copper torus
    "torus": {
        "camera": {"origin": [0.0, -6.0, 3.2], "target": [0.0, 0.0, 0.4], "up": [0, 0, 1], "fov": 26},
        "environment": {"preset": "studio", "scale": 1.0},
        "point_light": {"position": [2.0, -3.0, 4.5], "intensity": 12.0},
        "shapes": [
            {"type": "torus", "center": [0.0, 0.0, 0.42], "radius": 1.0, "tube": 0.4, "rotate_z": 20.0,
             "material": "@coated_copper.json", "normal_map": {"name": "hammered", "tiles": [6, 2], "strength": 1.0}},
            {"type": "rectangle", "center": [0.0, 0.5, 0.0], "size": [8.0, 6.0], "material": {"diffuse": [0.35, 0.35, 0.33]}},
        ],
    },
    # the Utah teapot in a layered (varnished gold) material on a floor, studio environment and a point light
    "teapot": {
        "camera": {"origin": [0.0, -7.5, 3.6], "target": [0.15, 0.0, 0.75], "up": [0, 0, 1], "fov": 28},
        "environment": {"preset": "studio", "scale": 1.0},
        "point_light": {"position": [2.5, -3.0, 4.5], "intensity": 15.0},
        "shapes": [
            {"type": "teapot", "center": [0.0, 0.0, 0.0], "scale": 0.5, "rotate_z": -25.0,
             "material": "@varnished_gold.json"},
            {"type": "rectangle", "center": [0.0, 0.5, 0.0], "size": [8.0, 6.0], "material": {"diffuse": [0.35, 0.35, 0.33]}},
        ],
    },
}
SCENE_PRESETS = tuple(PRESETS)


@dataclass
class Scene:
    """A parsed scene: the JSON's content with material paths made absolute."""

    spec: dict[str, Any]
    """the scene JSON (validated; material paths absolute)"""
    name: str
    """the preset name or the file's stem"""


def _vec(x: Any, n: int, what: str) -> list[float]:
    if (not isinstance(x, (list, tuple)) or len(x) != n
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in x)):
        raise NbrdfError(f"{what}: expected {n} finite numbers, got {x!r}")
    return [float(v) for v in x]


def _num(x: Any, what: str, lo: float = 0.0) -> float:
    if not isinstance(x, (int, float)) or isinstance(x, bool) or not math.isfinite(x) or x <= lo:
        raise NbrdfError(f"{what}: expected a finite number above {lo:g}, got {x!r}")
    return float(x)


def _material(m: Any, base: Path, what: str) -> dict[str, Any]:
    """A material entry -> {"neural": path} | {"reference": path} | {"diffuse": rgb}."""
    def path(p: Any) -> str:
        if not isinstance(p, str) or not p:
            raise NbrdfError(f"{what}: expected a material path, got {p!r}")
        if p.startswith("generated:"):
            if p != "generated:globe":
                raise NbrdfError(f"{what}: unknown generated material {p!r} (expected generated:globe)")
            return str(globe_material())
        q = ASSETS / p[1:] if p.startswith("@") else (base / p)
        if not q.is_file():
            raise NbrdfError(f"{what}: material file {p} not found")
        return str(q.resolve())

    if isinstance(m, str):
        return {"neural": path(m)}
    if isinstance(m, dict) and len(m) == 1:
        (k, v), = m.items()
        if k in ("neural", "reference"):
            return {k: path(v)}
        if k == "diffuse":
            rgb = _vec([v] * 3 if isinstance(v, (int, float)) else v, 3, f"{what}.diffuse")
            if not all(0 <= c <= 1 for c in rgb):
                raise NbrdfError(f"{what}.diffuse: albedo must lie in [0, 1], got {rgb}")
            return {"diffuse": rgb}
    raise NbrdfError(f"{what}: expected a material path, {{\"reference\": path}} or {{\"diffuse\": rgb}}, got {m!r}")


SHAPES = ("sphere", "rectangle", "teapot", "torus")


def _normal_map(nm: Any, what: str) -> dict[str, Any]:
    """A shape's generated normal map entry -> {"name", "tiles", "strength"}."""
    if not isinstance(nm, dict) or nm.get("name") not in NORMAL_MAPS or set(nm) - {"name", "tiles", "strength"}:
        raise NbrdfError(f"{what}: expected {{\"name\": {' | '.join(NORMAL_MAPS)}, \"tiles\": [nu, nv], "
                         f"\"strength\": s}}, got {nm!r}")
    tiles = _vec(nm.get("tiles", [1, 1]), 2, f"{what}.tiles")
    if min(tiles) <= 0:
        raise NbrdfError(f"{what}.tiles: expected positive repeats, got {tiles}")
    return {"name": nm["name"], "tiles": tiles, "strength": _num(nm.get("strength", 1.0), f"{what}.strength")}


def parse_scene(spec: Any, base: Path, name: str) -> Scene:
    """Validates a scene dict (one-line ``NbrdfError`` naming the bad field)."""
    if not isinstance(spec, dict):
        raise NbrdfError(f"scene {name}: expected a JSON object, got {type(spec).__name__}")
    known = {"camera", "environment", "point_light", "shapes", "max_depth"}
    extra = set(spec) - known
    if extra:
        raise NbrdfError(f"scene {name}: unknown key(s) {', '.join(sorted(extra))} (expected {', '.join(sorted(known))})")
    cam = spec.get("camera")
    if not isinstance(cam, dict):
        raise NbrdfError(f"scene {name}: camera: expected an object with origin, target, up, fov")
    out: dict[str, Any] = {"camera": {"origin": _vec(cam.get("origin"), 3, "camera.origin"),
                                      "target": _vec(cam.get("target"), 3, "camera.target"),
                                      "up": _vec(cam.get("up", [0, 0, 1]), 3, "camera.up"),
                                      "fov": _num(cam.get("fov", 30), "camera.fov")}}
    if out["camera"]["fov"] >= 170:
        raise NbrdfError(f"camera.fov: expected below 170 degrees, got {out['camera']['fov']}")
    env = spec.get("environment")
    if env is not None:
        env = {"preset": env} if isinstance(env, str) else env
        if not isinstance(env, dict) or env.get("preset") not in ENV_PRESETS:
            raise NbrdfError(f"environment: expected one of {', '.join(ENV_PRESETS)} (or {{\"preset\": ..., "
                             f"\"scale\": s}}), got {spec.get('environment')!r}")
        out["environment"] = {"preset": env["preset"], "scale": _num(env.get("scale", 1.0), "environment.scale")}
    light = spec.get("point_light")
    if light is not None:
        if not isinstance(light, dict):
            raise NbrdfError(f"point_light: expected an object with position and intensity, got {light!r}")
        inten = light.get("intensity", 10.0)
        inten = _vec([inten] * 3 if isinstance(inten, (int, float)) and not isinstance(inten, bool) else inten, 3,
                     "point_light.intensity")
        out["point_light"] = {"position": _vec(light.get("position"), 3, "point_light.position"), "intensity": inten}
    if "environment" not in out and "point_light" not in out:
        raise NbrdfError(f"scene {name}: no light (give an environment and/or a point_light)")
    depth = spec.get("max_depth", MAX_DEPTH)
    if not isinstance(depth, int) or isinstance(depth, bool) or not 1 <= depth <= 64:
        raise NbrdfError(f"max_depth: expected an integer in [1, 64], got {depth!r}")
    out["max_depth"] = depth
    shapes = spec.get("shapes")
    if not isinstance(shapes, list) or not shapes:
        raise NbrdfError(f"scene {name}: shapes: expected a non-empty list")
    out["shapes"] = []
    for i, s in enumerate(shapes):
        what = f"shapes[{i}]"
        if not isinstance(s, dict) or s.get("type") not in SHAPES:
            raise NbrdfError(f"{what}: expected an object with type {', '.join(SHAPES)}, got {s!r}")
        t = s["type"]
        d: dict[str, Any] = {"type": t, "center": _vec(s.get("center", [0, 0, 0]), 3, f"{what}.center"),
                             "material": _material(s.get("material"), base, f"{what}.material")}
        if t in ("sphere", "torus"):
            d["radius"] = _num(s.get("radius", 1.0), f"{what}.radius")
            d["rotate_z"] = float(_vec([s.get("rotate_z", 0.0)], 1, f"{what}.rotate_z")[0])
        if t == "torus":
            d["tube"] = _num(s.get("tube", 0.3), f"{what}.tube")
            if d["tube"] >= d["radius"]:
                raise NbrdfError(f"{what}.tube: expected below the radius {d['radius']}, got {d['tube']}")
        elif t == "rectangle":
            d["size"] = _vec(s.get("size", [1, 1]), 2, f"{what}.size")
            if min(d["size"]) <= 0:
                raise NbrdfError(f"{what}.size: expected positive sizes, got {d['size']}")
        elif t == "teapot":
            d["scale"] = _num(s.get("scale", 1.0), f"{what}.scale")
            d["rotate_z"] = float(_vec([s.get("rotate_z", 0.0)], 1, f"{what}.rotate_z")[0])
        if "normal_map" in s:
            d["normal_map"] = _normal_map(s["normal_map"], f"{what}.normal_map")
        out["shapes"].append(d)
    return Scene(out, name)


def load_scene(spec: str) -> Scene:
    """A preset name or a scene JSON file -> ``Scene`` (one line on bad input)."""
    if spec in PRESETS:
        return parse_scene(PRESETS[spec], ASSETS, spec)
    p = Path(spec)
    if p.suffix.lower() != ".json":
        raise NbrdfError(f"scene {spec}: not a preset ({', '.join(SCENE_PRESETS)}) nor a .json file")
    try:
        data = json.loads(p.read_text())
    except OSError as e:
        raise NbrdfError(f"scene {spec}: cannot read it ({e.strerror or e})") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise NbrdfError(f"scene {spec}: not valid JSON ({e})") from None
    return parse_scene(data, p.parent, p.stem)


def with_method(scene: Scene, method: str, body: str = Body.DECODER.value) -> Scene:
    """The scene with every nbrdf material rendered as ``neural`` or ``reference``
    (the words of ``Method.NEURAL`` and ``Method.REFERENCE``); ``body`` (neural): the plugin's ``body`` for every uniform material
    ("table": a baked table, ``kernel.TableBody``; a parametric one for a
    texture-mapped material whose maps vary at most two albedos); other
    texture-mapped materials keep the decoder."""
    shapes = []
    for s in scene.spec["shapes"]:
        m = s["material"]
        if "diffuse" not in m:
            path = m.get("neural", m.get("reference"))
            m = _neural_entry(path, body) if method == Method.NEURAL else {str(method): path}
        shapes.append({**s, "material": m})
    return Scene({**scene.spec, "shapes": shapes}, scene.name)


def with_body(scene: Scene, body: str) -> Scene:
    """The scene with ``body`` for every ``nbrdf`` (neural) material that can take it
    (see ``with_method``); reference and diffuse materials are left as they are."""
    shapes = [{**s, "material": _neural_entry(s["material"]["neural"], body)} if "neural" in s["material"] else s
              for s in scene.spec["shapes"]]
    return Scene({**scene.spec, "shapes": shapes}, scene.name)


def _neural_entry(path: str, body: str) -> dict[str, Any]:
    """A neural material entry with ``body`` where the material can take it."""
    m: dict[str, Any] = {"neural": path}
    if body != Body.DECODER and (not is_textured(path) or table_fits(path)):
        m["body"] = body
    return m


def is_textured(path: str) -> bool:
    """Whether the material at ``path`` is texture-mapped (a code file never is)."""
    if not is_material_file(path):
        return False
    return load_material(path).is_textured


def table_fits(path: str) -> bool:
    """Whether a texture-mapped material can read its body from a parametric table
    (``neural.param_table.table_params``)."""
    from nbrdf.neural.param_table import table_params  # start-up: torch; parsing a scene needs none

    try:
        table_params(load_material(path))
    except NbrdfError:
        return False
    return True


def neural_bodies(scene: Scene) -> set[str]:
    """The ``body`` options (``kernel.Body`` words) of the scene's ``nbrdf`` materials ("decoder" unless set)."""
    return {s["material"].get("body", Body.DECODER.value) for s in scene.spec["shapes"] if "neural" in s["material"]}


def uses_reference(scene: Scene) -> bool:
    """Whether any shape uses ``nbrdf_reference`` (rendered in Dr.Jit's wavefront mode)."""
    return any("reference" in s["material"] for s in scene.spec["shapes"])


#: Mitsuba's envmap looks up local direction (x, y, z) at u = atan2(x, -z) / 2 pi, v = acos(y) / pi; the
#: project's maps use world z up with u = atan2(y, x) / 2 pi, v = acos(z) / pi. This rotation maps Mitsuba's
#: local frame to the world: world = (-z_l, x_l, y_l).
ENV_TO_WORLD = [[0.0, 0.0, -1.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]


def environment_bitmap(preset: str, scale: float = 1.0, size: tuple[int, int] = ENV_SIZE):
    """The preset at ``size`` (w, h) as a Mitsuba RGB bitmap (linear radiance)."""
    img = make_environment(preset, *size) * np.float32(scale)
    return mi.Bitmap(np.ascontiguousarray(img, np.float32), mi.Bitmap.PixelFormat.RGB)


def _bsdf(m: dict[str, Any], pixel_angle: float) -> dict[str, Any]:
    if "diffuse" in m:
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": m["diffuse"]}}
    if "neural" in m:
        # the camera's angle per pixel: a latent texture's mip level per hit follows from it
        d = {"type": "nbrdf", "material": m["neural"], "pixel_angle": pixel_angle}
        if "body" in m:
            d["body"] = m["body"]
        return d
    return {"type": "nbrdf_reference", "material": m["reference"]}


def _with_normal_map(bsdf: dict[str, Any], nm: dict[str, Any]) -> dict[str, Any]:
    """``bsdf`` under Mitsuba's ``normalmap`` with a generated map tiled ``tiles`` times."""
    tex = normal_map(nm["name"], strength=nm["strength"])
    su, sv = nm["tiles"]
    return {"type": "normalmap", "bsdf": bsdf,
            "normalmap": {"type": "bitmap", "raw": True, "filter_type": "bilinear",
                          "bitmap": mi.Bitmap(np.ascontiguousarray(tex), mi.Bitmap.PixelFormat.RGB),
                          "to_uv": mi.ScalarTransform4f().scale([su, sv, 1.0])}}


def mitsuba_dict(scene: Scene, size: tuple[int, int], spp: int) -> dict[str, Any]:
    """The ``mi.load_dict`` description of ``scene`` at ``size`` (w, h) with
    ``spp`` samples per pixel per ``mi.render`` call."""
    s = scene.spec
    T = mi.ScalarTransform4f
    cam = s["camera"]
    w, h = size
    d: dict[str, Any] = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": s["max_depth"]},
        "camera": {"type": "perspective", "fov": cam["fov"], "fov_axis": "y",
                   "to_world": T().look_at(origin=cam["origin"], target=cam["target"], up=cam["up"]),
                   "film": {"type": "hdrfilm", "width": int(w), "height": int(h), "rfilter": {"type": "box"},
                            "pixel_format": "rgb"},
                   "sampler": {"type": "independent", "sample_count": int(spp)}},
    }
    if "environment" in s:
        e = s["environment"]
        d["environment"] = {"type": "envmap", "bitmap": environment_bitmap(e["preset"], e["scale"]),
                            "to_world": T(ENV_TO_WORLD)}
    if "point_light" in s:
        p = s["point_light"]
        d["point_light"] = {"type": "point", "position": p["position"],
                            "intensity": {"type": "rgb", "value": p["intensity"]}}
    pixel_angle = math.radians(cam["fov"]) / h
    for i, sh in enumerate(s["shapes"]):
        inner = _bsdf(sh["material"], pixel_angle)
        if "normal_map" in sh:
            inner = _with_normal_map(inner, sh["normal_map"])
        # two-sided: a one-sided BSDF would render back faces black (the teapot's inside, a plane seen from below)
        bsdf = {"type": "twosided", "material": inner}
        c = sh["center"]
        if sh["type"] == "sphere":
            shape = {"type": "sphere", "bsdf": bsdf,
                     "to_world": T().translate(c).rotate([0, 0, 1], sh["rotate_z"]).scale(sh["radius"])}
        elif sh["type"] == "torus":
            shape = {"type": "ply", "filename": str(torus_ply(sh["radius"], sh["tube"])), "bsdf": bsdf,
                     "to_world": T().translate(c).rotate([0, 0, 1], sh["rotate_z"])}
        elif sh["type"] == "rectangle":
            sx, sy = sh["size"]
            shape = {"type": "rectangle", "to_world": T().translate(c).scale([sx / 2, sy / 2, 1.0]), "bsdf": bsdf}
        else:
            shape = {"type": "ply", "filename": str(teapot_ply()), "bsdf": bsdf,
                     "to_world": T().translate(c).rotate([0, 0, 1], sh["rotate_z"]).scale(sh["scale"])}
        d[f"shape_{i}"] = shape
    return d
