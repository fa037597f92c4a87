"""Environments the project makes itself (no downloads): a studio room, a
physical clear sky with a sun, and a single-softbox product-shot setup.

Every map is float32 (H, W, 3) linear radiance in the equirectangular
convention of ``imaging/environment.py`` (world z up; row j covers theta =
pi (j + [0, 1]) / H from the zenith, column i phi = 2 pi (i + [0, 1]) / W),
so ``EnvironmentMap`` samples it like a file environment. The default camera
(``OrbitCamera``) sits on the -y side looking along +y with +x to its right,
so "in front of the object" is -y and "camera left" is -x.

- ``studio``: an inward-facing room seen from its centre, ray-cast per texel:
  grey walls, floor and ceiling at modest radiance, two boxes on the floor,
  and rectangular emissive panels 30-60x brighter than the walls (ceiling
  strips, a key panel on the left wall, a large panel behind the camera), so a
  clear coat shows crisp rectangular reflections.
- ``sky``: the Preetham, Shirley and Smits (1999) analytic daylight model
  (Perez luminance and chromaticity distributions, zenith values from
  turbidity and sun angle), xyY -> XYZ -> linear sRGB; a sun disc of the
  physical 0.533 degree diameter whose radiance is the extraterrestrial sun
  (128 klx) dimmed by Rayleigh and Angstrom-aerosol transmittance along the
  air mass (Preetham's appendix), area-weighted into the texels it covers; a
  Lambertian ground lit by sun and sky below the horizon.
- ``softbox``: a dark backdrop (a slightly brighter table below the
  horizon), one large soft rectangular key at camera left above with a mild
  hot centre and soft edges, and a weak square fill at camera right.

Each map is scaled so that a white Lambertian card facing its brightest side
reads 1.0 (a grey card 0.18) at 0 EV: the presets read correctly under every
tone mapper without per-preset exposure. Generated maps are cached as .npy
under ``$XDG_CACHE_HOME/nbrdf/environments`` (default ``~/.cache``), keyed by
name, size and ``VERSION``.
"""
from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from nbrdf.imaging.environment import LUMA
from nbrdf.imaging.image_io import read_environment
from nbrdf.neural.errors import NbrdfError

#: The preset names, in the order a menu lists them (the first is the default).
ENV_PRESETS: tuple[str, ...] = ("studio", "sky", "softbox")
#: Bumped whenever a preset's look changes, so old caches are not reused.
VERSION = 1
#: A white Lambertian card facing a preset's brightest side reads this.
KEY_WHITE = 1.0
#: The size maps are made at unless asked otherwise (texels ~0.35 degrees).
DEFAULT_SIZE = (1024, 512)
_MAX_SIZE = 8192


# ---------------------------------------------------------------- geometry

def texel_directions(width: int, height: int, samples: int = 1) -> np.ndarray:
    """Unit directions (H, W, s*s, 3) at a stratified s x s grid in every texel."""
    o = (np.arange(samples) + 0.5) / samples
    theta = ((np.arange(height)[:, None] + o[None, :]) / height * math.pi)        # (H, s)
    phi = ((np.arange(width)[:, None] + o[None, :]) / width * 2 * math.pi)        # (W, s)
    T = theta[:, None, :, None]
    P = phi[None, :, None, :]
    d = np.stack(np.broadcast_arrays(np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)), -1)
    return d.reshape(height, width, samples * samples, 3)


def texel_solid_angles(width: int, height: int) -> np.ndarray:
    """Exact solid angle (H,) of a texel in each row."""
    t0 = np.arange(height) / height * math.pi
    t1 = (np.arange(height) + 1) / height * math.pi
    return (np.cos(t0) - np.cos(t1)) * 2 * math.pi / width


@dataclass(frozen=True)
class Panel:
    """An emissive (or plain) rectangle: points c + a u + b v, |a| <= half[0], |b| <= half[1]."""

    center: tuple[float, float, float]  #: the rectangle's centre, metres from the probe
    u: tuple[float, float, float]       #: first in-plane unit axis
    v: tuple[float, float, float]       #: second in-plane unit axis (normal = u x v)
    half: tuple[float, float]           #: half extents along u and v, metres
    radiance: tuple[float, float, float]  #: linear RGB radiance it emits toward the probe
    hot_centre: float = 0.0             #: relative radiance lost at the edge, 1 - h r^2 (softbox diffusion)
    soft_edge: float = 0.0              #: width of the edge fall-off, as a fraction of the half extents

    def hit(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distances (N,) along rays from the origin (inf where missed) and radiance (N, 3)."""
        c, u, v = (np.asarray(x, np.float64) for x in (self.center, self.u, self.v))
        n = np.cross(u, v)
        dn = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(np.abs(dn) > 1e-12, (c @ n) / dn, np.inf)
        p = d * t[:, None] - c
        a = (p @ u) / self.half[0]
        b = (p @ v) / self.half[1]
        inside = (t > 0) & (np.abs(a) <= 1) & (np.abs(b) <= 1)
        shade = 1.0 - self.hot_centre * (a * a + b * b) / 2
        if self.soft_edge > 0:
            edge = np.minimum(1 - np.abs(a), 1 - np.abs(b)) / self.soft_edge
            shade = shade * np.clip(edge, 0, 1) ** 2 * (3 - 2 * np.clip(edge, 0, 1))
        rad = np.clip(shade, 0, None)[:, None] * np.asarray(self.radiance)
        return np.where(inside, t, np.inf), rad


def _box_entry(d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entry distance (inf if missed) and entry-face axis*sign code for rays
    from the origin (outside the box) against an axis-aligned box."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / np.where(np.abs(d) > 1e-12, d, 1e-12)
    t0, t1 = lo * inv, hi * inv
    tn, tf = np.minimum(t0, t1), np.maximum(t0, t1)
    t_near, axis = tn.max(1), tn.argmax(1)
    hit = (t_near > 0) & (t_near <= tf.min(1))
    face = np.where(d[np.arange(len(d)), axis] > 0, -1, 1) * (axis + 1)  # outward normal: -sign(d)
    return np.where(hit, t_near, np.inf), face


def _supersampled(fn, width: int, height: int, samples: int, what: str = "environment") -> np.ndarray:
    """The mean of ``fn`` (directions (N, 3) -> radiance (N, 3)) over an s x s
    grid in every texel, in bands of rows (bounded memory, a progress bar)."""
    d = texel_directions(width, height, samples)
    out = np.empty((height, width, 3))
    band = max(1, 65536 // (width * samples * samples))
    for j in tqdm(range(0, height, band), desc=f"making the {what}", unit="band", leave=False, disable=None):
        rows = d[j:j + band]
        out[j:j + band] = fn(rows.reshape(-1, 3)).reshape(*rows.shape[:3], 3).mean(2)
    return out


# ---------------------------------------------------------------- studio

_ROOM_LO = np.array([-5.0, -5.0, -1.5])
_ROOM_HI = np.array([5.0, 5.0, 3.5])
_WALL = np.array([0.26, 0.25, 0.24])
_FLOOR = np.array([0.16, 0.155, 0.15])
_CEILING = np.array([0.3, 0.3, 0.3])
_BOXES = (  # (lo, hi, top radiance, side radiance)
    (np.array([-3.2, 1.8, -1.5]), np.array([-1.8, 3.2, -0.2]), 0.45, 0.18),
    (np.array([2.0, 2.6, -1.5]), np.array([3.4, 3.4, 1.2]), 0.4, 0.2),
)
_STUDIO_PANELS = (
    # two long ceiling strips along x
    Panel((0.0, -1.4, 3.49), (1, 0, 0), (0, 1, 0), (2.6, 0.35), (12.0, 12.0, 12.0)),
    Panel((0.0, 1.4, 3.49), (1, 0, 0), (0, 1, 0), (2.6, 0.35), (12.0, 12.0, 12.0)),
    # key: a large panel on the left wall (x = -5), toward the front
    Panel((-4.99, -1.2, 0.9), (0, 1, 0), (0, 0, 1), (1.5, 1.0), (15.0, 14.6, 14.0)),
    # behind the camera (y = -5): the reflection a clear coat shows front on
    Panel((0.6, -4.99, 1.0), (1, 0, 0), (0, 0, 1), (1.6, 0.7), (9.0, 9.0, 9.0)),
    # weaker, cooler fill on the right wall (x = +5)
    Panel((4.99, 0.5, 0.6), (0, 1, 0), (0, 0, 1), (1.0, 0.75), (5.0, 5.3, 6.0)),
    # a tall rim strip on the back wall (y = +5)
    Panel((-1.6, 4.99, 0.8), (1, 0, 0), (0, 0, 1), (0.3, 1.6), (8.0, 8.0, 8.0)),
)


def _studio_radiance(d: np.ndarray) -> np.ndarray:
    # the room seen from inside: the exit distance of each ray
    with np.errstate(divide="ignore"):
        inv = 1.0 / np.where(np.abs(d) > 1e-12, d, 1e-12)
    t_axes = np.maximum(_ROOM_LO * inv, _ROOM_HI * inv)
    t, axis = t_axes.min(1), t_axes.argmin(1)
    up = d[np.arange(len(d)), axis] > 0
    rad = np.where((axis == 2)[:, None], np.where(up[:, None], _CEILING, _FLOOR), _WALL)
    # walls darken a little toward the floor, like a room lit from above
    z = np.clip((d[:, 2] * t - _ROOM_LO[2]) / (_ROOM_HI[2] - _ROOM_LO[2]), 0, 1)
    rad = rad * np.where((axis == 2)[:, None], 1.0, (0.7 + 0.3 * z)[:, None])
    for lo, hi, top, side in _BOXES:
        tb, face = _box_entry(d, lo, hi)
        closer = tb < t
        t = np.where(closer, tb, t)
        rad = np.where(closer[:, None], np.where((face == 3)[:, None], top, side) * np.ones(3), rad)
    for panel in _STUDIO_PANELS:
        tp, prad = panel.hit(d)
        closer = tp < t
        t = np.where(closer, tp, t)
        rad = np.where(closer[:, None], prad, rad)
    return rad


# ---------------------------------------------------------------- sky (Preetham 1999)

SUN_ELEVATION = math.radians(35.0)
SUN_AZIMUTH = math.radians(-125.0)   # behind-left of the default camera's view axis
SUN_DIAMETER = math.radians(0.533)
TURBIDITY = 2.5
_GROUND_ALBEDO = np.array([0.25, 0.22, 0.18])
_XYZ_TO_SRGB = np.array([[3.2404542, -1.5371385, -0.4985314],
                         [-0.9692660, 1.8760108, 0.0415560],
                         [0.0556434, -0.2040259, 1.0572252]])


def _perez(cos_theta: np.ndarray, gamma: np.ndarray, c: tuple[float, ...]) -> np.ndarray:
    a, b, cc, dd, e = c
    return (1 + a * np.exp(b / cos_theta)) * (1 + cc * np.exp(dd * gamma) + e * np.cos(gamma) ** 2)


def preetham_coefficients(turbidity: float) -> dict[str, tuple[float, ...]]:
    """Perez A..E for Y, x and y (Preetham et al. 1999, appendix A.2)."""
    T = turbidity
    return {
        "Y": (0.1787 * T - 1.4630, -0.3554 * T + 0.4275, -0.0227 * T + 5.3251, 0.1206 * T - 2.5771, -0.0670 * T + 0.3703),
        "x": (-0.0193 * T - 0.2592, -0.0665 * T + 0.0008, -0.0004 * T + 0.2125, -0.0641 * T - 0.8989, -0.0033 * T + 0.0452),
        "y": (-0.0167 * T - 0.2608, -0.0950 * T + 0.0092, -0.0079 * T + 0.2102, -0.0441 * T - 1.6537, -0.0109 * T + 0.0529),
    }


def preetham_zenith(turbidity: float, theta_s: float) -> tuple[float, float, float]:
    """Zenith luminance (kcd/m^2) and chromaticity x, y (Preetham et al. 1999, A.2)."""
    T, t = turbidity, theta_s
    chi = (4.0 / 9.0 - T / 120.0) * (math.pi - 2 * t)
    Y = (4.0453 * T - 4.9710) * math.tan(chi) - 0.2155 * T + 2.4192
    t3 = np.array([t ** 3, t ** 2, t, 1.0])
    Tv = np.array([T * T, T, 1.0])
    mx = np.array([[0.00166, -0.00375, 0.00209, 0.0], [-0.02903, 0.06377, -0.03202, 0.00394],
                   [0.11693, -0.21196, 0.06052, 0.25886]])
    my = np.array([[0.00275, -0.00610, 0.00317, 0.0], [-0.04214, 0.08970, -0.04153, 0.00516],
                   [0.15346, -0.26756, 0.06670, 0.26688]])
    return Y, float(Tv @ mx @ t3), float(Tv @ my @ t3)


def sun_direction() -> np.ndarray:
    ce = math.cos(SUN_ELEVATION)
    return np.array([ce * math.cos(SUN_AZIMUTH), ce * math.sin(SUN_AZIMUTH), math.sin(SUN_ELEVATION)])


def preetham_sky_rgb(d: np.ndarray, turbidity: float = TURBIDITY) -> np.ndarray:
    """Linear sRGB sky radiance (N, 3) in kcd/m^2-luminance units for directions
    above the horizon (cos theta is floored at 0.01 at the horizon)."""
    s = sun_direction()
    theta_s = math.pi / 2 - SUN_ELEVATION
    cos_t = np.maximum(d[:, 2], 0.01)
    gamma = np.arccos(np.clip(d @ s, -1, 1))
    coef = preetham_coefficients(turbidity)
    zen = preetham_zenith(turbidity, theta_s)
    vals = [z * _perez(cos_t, gamma, coef[k]) / _perez(np.array(1.0), np.array(theta_s), coef[k])
            for z, k in zip(zen, ("Y", "x", "y"))]
    Y, x, y = vals
    X = x / y * Y
    Z = (1 - x - y) / y * Y
    return np.clip(np.stack([X, Y, Z], -1) @ _XYZ_TO_SRGB.T, 0, None)


def sun_rgb(turbidity: float = TURBIDITY) -> np.ndarray:
    """Linear sRGB radiance of the sun disc, kcd/m^2 units like the sky: the
    extraterrestrial sun (128 klx over its solid angle, taken as white)
    times the Rayleigh and aerosol transmittance at 650/550/450 nm along the
    Kasten air mass (Preetham et al. 1999, appendix A.1)."""
    theta_s = math.pi / 2 - SUN_ELEVATION
    deg = math.degrees(theta_s)
    air_mass = 1.0 / (math.cos(theta_s) + 0.15 * (93.885 - deg) ** -1.253)
    lam = np.array([0.65, 0.55, 0.45])  # micrometres
    beta = 0.04608 * turbidity - 0.04586
    tau = 0.008735 * lam ** -4.08 + beta * lam ** -1.3
    trans = np.exp(-tau * air_mass)
    omega = 2 * math.pi * (1 - math.cos(SUN_DIAMETER / 2))
    lum = 128.0 / omega  # kcd/m^2: 128 klx spread over the disc
    return lum * trans


def _sky(width: int, height: int, samples: int) -> np.ndarray:
    s = sun_direction()

    img = _supersampled(lambda d: np.where((d[:, 2] >= 0)[:, None], preetham_sky_rgb(d), 0.0), width, height,
                        samples, "sky environment")
    # Sun: the disc's coverage of each nearby texel on a fine grid, so its power is right at any size.
    cos_r = math.cos(SUN_DIAMETER / 2)
    dirs = texel_directions(width, height, 1)[:, :, 0]
    texel = max(math.pi / height, 2 * math.pi / width)  # a texel's largest angular extent
    near = np.argwhere(dirs @ s > math.cos(SUN_DIAMETER / 2 + 3 * texel))
    fine = 32
    for j, i in near:
        theta = (j + (np.arange(fine) + 0.5) / fine) / height * math.pi
        phi = (i + (np.arange(fine) + 0.5) / fine) / width * 2 * math.pi
        T, P = np.meshgrid(theta, phi, indexing="ij")
        sub = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
        w = np.sin(T).ravel()
        cover = float(((sub @ s >= cos_r) * w).sum() / w.sum())
        img[j, i] += cover * sun_rgb()
    # Ground: Lambertian, lit by the sun and the upper hemisphere of the sky.
    omega = texel_solid_angles(width, height)[:, None]
    dz = dirs[..., 2]
    sky_irr = (img * (np.clip(dz, 0, None) * omega)[..., None] * (dz > 0)[..., None]).sum((0, 1))
    img = np.where((dz < 0)[..., None], _GROUND_ALBEDO / math.pi * sky_irr, img)
    return img


# ---------------------------------------------------------------- softbox

def _facing_panel(direction, distance, half, radiance, hot=0.0, soft=0.0) -> Panel:
    """A rectangle at ``distance`` along ``direction`` facing the probe, its
    long side horizontal."""
    n = np.asarray(direction, np.float64)
    n = n / np.linalg.norm(n)
    u = np.cross(np.array([0.0, 0.0, 1.0]), n)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return Panel(tuple(n * distance), tuple(u), tuple(v), half, radiance, hot, soft)


_SOFTBOX_KEY = _facing_panel((-0.6, -0.65, 0.62), 2.5, (1.0, 0.7), (20.0, 19.6, 19.0), hot=0.35, soft=0.12)
_SOFTBOX_FILL = _facing_panel((0.9, -0.4, 0.05), 3.0, (0.7, 0.7), (1.4, 1.4, 1.45), soft=0.2)
_BACKDROP = np.array([0.012, 0.012, 0.013])
_TABLE = np.array([0.03, 0.029, 0.028])


def _softbox_radiance(d: np.ndarray) -> np.ndarray:
    # a backdrop that brightens slightly toward the horizon, a table below it
    above = np.clip(d[:, 2], 0, 1)
    rad = np.where((d[:, 2] >= 0)[:, None], _BACKDROP * (1.6 - 0.6 * above)[:, None], _TABLE)
    t = np.full(len(d), np.inf)
    for panel in (_SOFTBOX_KEY, _SOFTBOX_FILL):
        tp, prad = panel.hit(d)
        closer = tp < t
        t = np.where(closer, tp, t)
        rad = np.where(closer[:, None], prad, rad)
    return rad


# ---------------------------------------------------------------- public

def key_white(img: np.ndarray, n_normals: int = 64) -> float:
    """Luminance a white Lambertian card reads facing the map's brightest
    side: max over normals n of (1/pi) sum L max(0, n.w) dOmega."""
    h, w = img.shape[:2]
    dirs = texel_directions(w, h, 1)[:, :, 0].reshape(-1, 3)
    lum = (img.reshape(-1, 3) @ LUMA) * np.repeat(texel_solid_angles(w, h), w)
    k = np.arange(n_normals) + 0.5  # a Fibonacci sphere of normals
    z = 1 - 2 * k / n_normals
    r = np.sqrt(1 - z * z)
    a = k * math.pi * (3 - math.sqrt(5))
    normals = np.stack([r * np.cos(a), r * np.sin(a), z], -1)
    return float((np.clip(dirs @ normals.T, 0, None) * lum[:, None]).sum(0).max() / math.pi)


def _generate(name: str, width: int, height: int) -> np.ndarray:
    samples = 2
    if name == "studio":
        img = _supersampled(_studio_radiance, width, height, samples, "studio environment")
    elif name == "sky":
        img = _sky(width, height, samples)
    else:
        img = _supersampled(_softbox_radiance, width, height, samples, "softbox environment")
    img = img * (KEY_WHITE / key_white(img))
    return np.ascontiguousarray(np.maximum(img, 1e-6), dtype=np.float32)


def cache_dir() -> Path:
    """Where generated maps are kept: $XDG_CACHE_HOME/nbrdf/environments."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "nbrdf" / "environments"


def make_environment(name: str, width: int = DEFAULT_SIZE[0], height: int = DEFAULT_SIZE[1],
                     cache: bool = True) -> np.ndarray:
    """The preset ``name`` as float32 (H, W, 3) linear radiance, from the cache
    when it is there (an unreadable or unwritable cache is skipped)."""
    if name not in ENV_PRESETS:
        raise NbrdfError(f"environment {name!r}: expected one of {', '.join(ENV_PRESETS)} or an .hdr/.exr file")
    for v, what in ((width, "width"), (height, "height")):
        if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or not 4 <= v <= _MAX_SIZE:
            raise NbrdfError(f"environment {what}: expected an integer in [4, {_MAX_SIZE}], got {v!r}")
    path = cache_dir() / f"{name}-{width}x{height}-v{VERSION}.npy"
    if cache and path.is_file():
        try:
            img = np.load(path, allow_pickle=False)
            if img.shape == (height, width, 3) and img.dtype == np.float32 and np.isfinite(img).all():
                return img
        except (OSError, ValueError):
            pass
    img = _generate(name, int(width), int(height))
    if cache:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(suffix=".npy", dir=path.parent)
            with os.fdopen(fd, "wb") as f:
                np.save(f, img)
            os.replace(tmp, path)
        except OSError:
            pass
    return img


def resolve_environment(spec: str, width: int = DEFAULT_SIZE[0], height: int = DEFAULT_SIZE[1]) -> np.ndarray:
    """``--env`` argument -> radiance: a preset name or an .hdr/.exr path."""
    if not isinstance(spec, str) or not spec:
        raise NbrdfError(f"--env: expected {', '.join(ENV_PRESETS)} or an .hdr/.exr file, got {spec!r}")
    if spec in ENV_PRESETS:
        return make_environment(spec, width, height)
    if Path(spec).suffix.lower() not in (".hdr", ".exr"):
        raise NbrdfError(f"--env {spec}: not a preset ({', '.join(ENV_PRESETS)}) nor an .hdr/.exr file")
    return read_environment(spec)
