"""Render-space accuracy (SPEC section 9, ``nbrdf report render``).

Lobe PSNR averages over the whole hemisphere and hides what a viewer shows:
a sharp coat's highlight over a coloured body. This module renders what the
viewer renders -- a sphere under an orthographic camera along +z, lit by one
directional light, per pixel f(wi, wo) cos(theta_i) with unit irradiance --
with the ground truth and with the neural paths, and scores the linear images
with HDR-FLIP (NVIDIA's ``flip-evaluator``, default settings) and PSNR on
x / (1 + x).

Methods scored against the reference:

- ``neural``: the full neural path (leaf encoders + layering + decoder, the
  coat in closed form);
- ``projected``: the decoder at a body latent fitted to the reference minus
  the top interface's reflection, plus that coat (its capacity alone, no
  operation networks);
- ``refined``: the network's code refined against the material's own
  simulation within ``refine_budget`` seconds (``training.refine``);
- ``belcour``: Belcour 2018's analytic layered model (``training.belcour``),
  the baseline real-time renderers use.

References are closed form for single interfaces and Monte Carlo for stacks,
rendered as two independent halves (their mean is the reference; their FLIP
against each other bounds the reference's own noise) and cached on disk keyed
by material and settings, so an interrupted report resumes.
"""
from __future__ import annotations

import hashlib
import json
import math
import platform
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from tqdm import tqdm

from nbrdf.imaging.flip import flip
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Conductor, Material, load_material, material_to_dict
from nbrdf.neural.methods import Method
from nbrdf.neural.metrics import compressed_psnr, noise_psnr
from nbrdf.neural.model import default_model, load_model
from nbrdf.training.brdfs import brdf_for
from nbrdf.training.evaluate import heldout_set
from nbrdf.training.plots import _plt
from nbrdf.training.reference import reference_eval

Tensor = torch.Tensor
EvalFn = Callable[[Tensor, Tensor], Tensor]  # (wi (N, 3), wo (N, 3)) local -> f (N, 3)

#: The light direction of SPEC section 9 (view space, before normalisation).
LIGHT = (-0.45, 0.55, 0.70)
#: The package folder of the material sets.
SETS_DIR = Path(__file__).resolve().parent / "sets"
#: The sets of training/sets/ a report names by their folder's name.
NAMED_SETS = ("lookdev", "openpbr", "brushed")
#: Bumped when a change makes cached reference renders stale.
CACHE_VERSION = 1
#: The methods a render report scores (the reference is what they are scored against).
METHODS = (Method.NEURAL, Method.CALIBRATED, Method.PROJECTED, Method.REFINED, Method.BELCOUR)


@dataclass
class RenderReportConfig:
    """Settings of one render-space report."""

    sets: tuple[str, ...] = ("lookdev", "heldout")
    """Material sets: ``lookdev`` (the package's look-development set),
    ``heldout`` (the first ``heldout_per_class`` of each held-out class), or
    paths to material JSON files or folders of them."""
    out: Path = Path("render-report")
    """Folder for render.json and the figures (one PNG per set)."""
    size: int = 96
    """Sphere image size in pixels (square)."""
    spp: int = 384
    """Monte Carlo paths per pixel of a stack's reference (split over two halves)."""
    cache: Path | None = None
    """Folder of cached reference renders (default: ``out / "references"``)."""
    model: str | None = None
    """Neural bundle (.safetensors); None = the shipped weights."""
    methods: tuple[Method, ...] = (Method.NEURAL, Method.PROJECTED)
    """Methods scored, from ``METHODS``."""
    heldout_per_class: int = 3
    """Held-out materials per class in the ``heldout`` set."""
    projection_pairs: int = 4096
    """Reference samples a projection fits to (drawn like the training data)."""
    projection_spp: int = 64
    """Monte Carlo paths per projection sample of a stack."""
    refine_budget: float = 10.0
    """Seconds the ``refined`` method may spend per material."""
    light_azimuths: tuple[float, ...] = (0.0,)
    """The light's turns about the view axis in degrees (SPEC section 9's light at 0): every material is
    scored under each (a row per material and azimuth), what an anisotropic material needs."""
    noise_target: float = 0.1
    """Refine a stack's reference (doubling its paths) while the FLIP between
    its two independent halves exceeds this (0 = a single round of ``spp``)."""
    max_spp: int = 1536
    """Most paths per pixel the refinement may reach."""
    seed: int = 0
    """Seed of the references and the projection samples."""
    figure: bool = True
    """Write the side-by-side figure of every set."""
    figure_dpi: int = 60
    """Resolution of the figures (keeps the PNGs small)."""
    progress: bool = True
    """tqdm progress bars on stderr."""


# --- geometry ----------------------------------------------------------------------------
@dataclass
class SphereGeometry:
    """Pixels of the lit sphere: the disk mask and per-pixel local directions."""

    mask: Tensor
    """(H, W) bool, True inside the disk; row 0 is the top of the image (+y)."""
    frame: Tensor
    """(P, 3, 3) per disk pixel, rows x, y, z (= the normal) of the local frame, view space."""
    wi: Tensor
    """(P, 3) the light direction in the local frames."""
    wo: Tensor
    """(P, 3) the view direction (+z) in the local frames."""
    light: tuple[float, float, float] = LIGHT
    """The light direction (view space, before normalisation): SPEC section 9's, or it turned about the view axis."""


def turned_light(azimuth: float) -> tuple[float, float, float]:
    """SPEC section 9's light turned by ``azimuth`` degrees about the view axis (0: ``LIGHT`` itself)."""
    if azimuth == 0:
        return LIGHT
    c, s = math.cos(math.radians(azimuth)), math.sin(math.radians(azimuth))
    return (c * LIGHT[0] - s * LIGHT[1], s * LIGHT[0] + c * LIGHT[1], LIGHT[2])


def light_direction(dtype: torch.dtype = torch.float64, light: tuple[float, float, float] = LIGHT) -> Tensor:
    v = torch.tensor(light, dtype=dtype)
    return v / v.norm()


def sphere_geometry(size: int, light_azimuth: float = 0.0) -> SphereGeometry:
    """Pixel centres of an orthographic view of the unit sphere, SPEC section 9:
    z = n, x = normalize(cross((0, 1, 0), n)), y = cross(n, x); the light turned by ``light_azimuth``
    degrees about the view axis."""
    if size < 2:
        raise NbrdfError(f"size: {size} is too small for a sphere image (at least 2 pixels)")
    c = (torch.arange(size, dtype=torch.float64) + 0.5) / size * 2 - 1
    y, x = torch.meshgrid(-c, c, indexing="ij")  # row 0 at the top: y = +1
    r2 = x * x + y * y
    mask = r2 < 1.0
    n = torch.stack([x[mask], y[mask], torch.sqrt(1.0 - r2[mask])], -1)
    up = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64).expand_as(n)
    tx = torch.linalg.cross(up, n)
    tx = tx / tx.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    ty = torch.linalg.cross(n, tx)
    frame = torch.stack([tx, ty, n], 1)
    to_local = lambda v: frame @ v  # (P, 3, 3) @ (3,) -> (P, 3)
    light = turned_light(light_azimuth)
    wi = to_local(light_direction(light=light))
    wo = to_local(torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64))
    return SphereGeometry(mask, frame, wi, wo, light)


def to_image(values: Tensor, geo: SphereGeometry) -> np.ndarray:
    """Per-pixel values (P, 3) -> a float32 (H, W, 3) image, zeros outside the disk."""
    img = torch.zeros(*geo.mask.shape, 3, dtype=torch.float64)
    img[geo.mask] = values.detach().double()
    return img.numpy().astype(np.float32)


def shade(fn: EvalFn, geo: SphereGeometry) -> np.ndarray:
    """The lit sphere of a BRDF: f(wi, wo) cos(theta_i) with unit irradiance,
    zero where either direction is below the horizon."""
    wi, wo = geo.wi.float(), geo.wo.float()
    up = (geo.wi[:, 2] > 0) & (geo.wo[:, 2] > 0)
    with torch.no_grad():
        f = fn(wi, wo).double()
    v = torch.where(up[:, None], f * geo.wi[:, 2:3], torch.zeros_like(f))
    return to_image(v, geo)


# --- scores -----------------------------------------------------------------------------
def material_class(m: Material) -> str:
    """A look-development class from the stack's structure."""
    n = len(m.interfaces)
    base = type(m.base).__name__.lower()
    if n == 0:
        return base
    if n == 1:
        return "coated_metal" if isinstance(m.base, Conductor) else f"coated_{base}"
    return "car_paint" if n == 2 else f"{n + 1}_layer"


def load_set(spec: str, heldout_per_class: int = 3) -> list[tuple[str, Material]]:
    """(class, material) pairs of a set name or a path (file or folder of JSON or .mtlx materials). The
    ``openpbr`` set (training/sets/openpbr/, written by tools/openpbr_set.py) is OpenPBR documents, each file's
    class the part of its name before "-"."""
    if spec == "heldout":
        out, seen = [], {}
        for cls, m in heldout_set():
            if seen.get(cls, 0) < heldout_per_class:
                seen[cls] = seen.get(cls, 0) + 1
                out.append((cls, m))
        return out
    path = SETS_DIR / spec if spec in NAMED_SETS else Path(spec)
    if path.is_dir():
        files = sorted([*path.glob("*.json"), *path.glob("*.mtlx")])
        if not files:
            raise NbrdfError(f"{spec}: no material .json or .mtlx files in this folder")
    elif path.is_file():
        files = [path]
    else:
        raise NbrdfError(f"{spec}: not a set name ({', '.join(NAMED_SETS)}, heldout), a material file or a folder")
    out = []
    for f in files:
        notes: list[str] = []
        m = load_material(f, notes)
        for note in notes:  # what a document's stack cannot hold is said, not dropped
            print(note, file=sys.stderr)
        if m.is_textured:
            raise NbrdfError(f"{f}: texture-mapped materials have no single render-space reference")
        out.append((f.stem.split("-")[0] if f.suffix == ".mtlx" else material_class(m), m))
    return out


def set_label(spec: str) -> str:
    return spec if spec in (*NAMED_SETS, "heldout") else Path(spec).stem


# --- references ---------------------------------------------------------------------------
@dataclass
class ReferenceRender:
    """A reference sphere and its noise."""

    image: np.ndarray  # (H, W, 3), the mean of the two halves
    stderr: np.ndarray  # (H, W, 3)
    half_flip: float  # FLIP of one half against the other (0 for closed forms)
    spp: int  # paths per pixel in all (0 = closed form)
    seconds: float


def _cache_key(m: Material, size: int, spp: int, seed: int, light: tuple[float, float, float] = LIGHT) -> str:
    d = material_to_dict(m)
    d.pop("name", None)
    blob = json.dumps({"m": d, "size": size, "spp": spp, "seed": seed, "light": light, "v": CACHE_VERSION},
                      sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def reference_render(m: Material, geo: SphereGeometry, spp: int, seed: int = 0, cache: Path | None = None,
                     progress: bool = True, noise_target: float = 0.0, max_spp: int = 0) -> ReferenceRender:
    """The ground-truth sphere; stacks by Monte Carlo in two independent halves
    of spp/2 paths each. While the halves' FLIP against each other exceeds
    ``noise_target`` (0 = off) the paths are doubled, up to ``max_spp``. Every
    round is cached in ``cache`` (resumable per material and round)."""
    size = geo.mask.shape[0]
    if not m.interfaces:
        return _cached(cache, m, size, 0, seed, lambda prev: _closed_round(m, geo), light=geo.light)[0]
    per, prev = max(1, spp // 2), None
    while True:
        ref, prev = _cached(cache, m, size, 2 * per, seed,
                            lambda p: _mc_round(m, geo, per if p is None else per // 2, seed, p, progress), prev,
                            light=geo.light)
        if noise_target <= 0 or ref.half_flip <= noise_target or 4 * per > max(max_spp, 2 * per):
            return ref
        per *= 2


def _closed_round(m: Material, geo: SphereGeometry) -> tuple[ReferenceRender, dict]:
    t0 = time.perf_counter()
    f, _ = reference_eval(m, geo.wi.float(), geo.wo.float())
    img = to_image(f.double() * geo.wi[:, 2:3].clamp_min(0), geo)
    return ReferenceRender(img, np.zeros_like(img), 0.0, 0, time.perf_counter() - t0), {}


def _mc_round(m: Material, geo: SphereGeometry, n: int, seed: int, prev: dict | None,
              progress: bool) -> tuple[ReferenceRender, dict]:
    """Adds n paths per pixel to each half (pooled with ``prev``'s halves by path count)."""
    t0 = time.perf_counter()
    wi, wo = geo.wi.float(), geo.wo.float()
    cos_i = geo.wi[:, 2:3].clamp_min(0)
    n_prev = int(prev["n_half"]) if prev is not None else 0
    rnd = 0 if prev is None else int(prev["round"]) + 1
    up = int(((geo.wi[:, 2] > 0) & (geo.wo[:, 2] > 0)).sum())
    halves = {}
    with tqdm(total=2 * up, desc=f"reference {m.name} ({2 * (n_prev + n)} spp)", unit="px", file=sys.stderr,
              leave=False, disable=not progress or None) as bar:
        for k in "ab":
            sd = seed * 2 + (k == "b") + 1 + 7919 * rnd
            f, e = reference_eval(m, wi, wo, spp=n, seed=sd, progress=bar.update)
            img, se = to_image(f.double() * cos_i, geo), to_image(e.double() * cos_i, geo)
            if prev is not None:
                w = n_prev + n
                img = (prev[f"half_{k}"] * n_prev + img * n) / w
                se = np.sqrt((prev[f"se_{k}"] * n_prev) ** 2 + (se * n) ** 2) / w
            halves[f"half_{k}"], halves[f"se_{k}"] = img.astype(np.float32), se.astype(np.float32)
    image = 0.5 * (halves["half_a"] + halves["half_b"])
    stderr = 0.5 * np.sqrt(halves["se_a"] ** 2 + halves["se_b"] ** 2)
    secs = time.perf_counter() - t0 + (float(prev["total_seconds"]) if prev is not None else 0.0)
    ref = ReferenceRender(image, stderr.astype(np.float32), flip(halves["half_a"], halves["half_b"])[0],
                          2 * (n_prev + n), secs)
    return ref, {**halves, "n_half": n_prev + n, "round": rnd, "total_seconds": secs}


def _cached(cache: Path | None, m: Material, size: int, spp: int, seed: int, make, prev: dict | None = None,
            light: tuple[float, float, float] = LIGHT) -> tuple[ReferenceRender, dict | None]:
    """A cached round, or ``make(prev)`` saved under the key of its total spp."""
    path = None
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
        path = cache / f"{_slug(m.name)}-{_cache_key(m, size, spp, seed, light)}.npz"
        if path.is_file():
            z = dict(np.load(path))
            ref = ReferenceRender(z["image"], z["stderr"], float(z["half_flip"]), int(z["spp"]), float(z["seconds"]))
            if spp == 0 or "half_a" in z or prev is None:
                return ref, (z if "half_a" in z else None)
    ref, extra = make(prev)
    if path is not None:
        tmp = path.with_suffix(".tmp.npz")
        np.savez_compressed(tmp, image=ref.image, stderr=ref.stderr, half_flip=ref.half_flip, spp=ref.spp,
                            seconds=ref.seconds, **extra)
        tmp.replace(path)
    return ref, extra


def _slug(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "-" for ch in name.lower()) or "material"


# --- methods ------------------------------------------------------------------------------
def method_evaluators(m: Material, model, methods: tuple[Method, ...], pairs: int, spp: int,
                      seed: int, budget: float | None = None) -> dict:
    """The BRDF of every method for one material, from the one BRDF factory
    (``training.brdfs.brdf_for``); the projection fits ``pairs`` reference
    values of ``spp`` paths under the material's own coat (``neural.coat``);
    the refinement spends ``budget`` seconds (or reads the per-user cache of refined codes)."""
    return {name: brdf_for(m, name, seed=seed + 1, model=model, projection_pairs=pairs, projection_spp=spp,
                           budget=budget)
            for name in METHODS if name in methods}


# --- the report ---------------------------------------------------------------------------
def summarise(rows: list[dict], methods: tuple[Method, ...]) -> dict:
    """Median and worst FLIP / PSNR per class and over the whole set, per method."""
    classes = list(dict.fromkeys(r["class"] for r in rows)) + ["all"]
    out = {}
    for cls in classes:
        sel = [r for r in rows if cls == "all" or r["class"] == cls]
        entry = {"materials": len(sel)}
        for meth in methods:
            fl = [r[meth]["flip"] for r in sel if meth in r]
            ps = [r[meth]["psnr"] for r in sel if meth in r]
            if fl:
                entry[meth] = {"flip_median": float(np.median(fl)), "flip_worst": float(np.max(fl)),
                               "psnr_median": float(np.median(ps)), "psnr_worst": float(np.min(ps)),
                               "materials": len(fl)}
        noise = [r["reference"]["half_flip"] for r in sel]
        entry["reference_half_flip_worst"] = float(np.max(noise))
        out[cls] = entry
    return out


#: An extra column of a render report: a material and the sphere's pixels -> its linear image (or ``NbrdfError``,
#: recorded as the column's one line); e.g. OpenPBR as MaterialX's generated GLSL renders it (the previewer's
#: ``viewer.gpu.materialx_glsl``, handed in by the command line: this package never imports the previewer).
ExtraColumn = Callable[[Material, SphereGeometry], np.ndarray]


def run_render_report(config: RenderReportConfig, extra: dict[str, ExtraColumn] | None = None) -> dict:
    """Renders and scores every set; writes render.json and one figure per set
    into ``config.out``. Returns the JSON's content. ``extra``: further columns by name (scored like a method;
    a material a column cannot render gets that column's one-line reason in its row instead)."""
    extra = extra or {}
    unknown = [x for x in config.methods if x not in METHODS]
    if unknown:
        raise NbrdfError(f"methods: {unknown[0]!r} is not one of {', '.join(METHODS)}")
    if Method.REFINED in config.methods and not (math.isfinite(config.refine_budget) and config.refine_budget > 0):
        raise NbrdfError(f"budget: {config.refine_budget} seconds must be positive")
    if config.spp < 2:
        raise NbrdfError(f"spp: {config.spp} is too few (at least 2: two independent halves)")
    model = load_model(config.model) if config.model else default_model()
    if Method.NEURAL in config.methods:
        model.require("leaf")
        model.require("layering")
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    cache = Path(config.cache) if config.cache is not None else out / "references"
    if not config.light_azimuths or not all(math.isfinite(a) for a in config.light_azimuths):
        raise NbrdfError(f"light azimuths: {config.light_azimuths} must be one or more finite angles")
    geos = [sphere_geometry(config.size, a) for a in config.light_azimuths]
    sets = {set_label(s): load_set(s, config.heldout_per_class) for s in config.sets}
    result = {"config": {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(config).items()},
              "light": [float(x) for x in light_direction()], "machine": _machine(), "sets": {}}
    turns = len(geos) > 1
    for label, items in sets.items():
        rows, images = [], []
        for cls, m in tqdm(items, desc=f"render {label}", unit="material", file=sys.stderr,
                           disable=not config.progress or None):
            t0 = time.perf_counter()
            brdfs = method_evaluators(m, model, config.methods, config.projection_pairs, config.projection_spp,
                                      config.seed, config.refine_budget)
            made = time.perf_counter() - t0  # the methods' making, counted in the material's first row
            for az, geo in zip(config.light_azimuths, geos):
                row, imgs = _scored_row(config, cache, cls, m, brdfs, extra, geo, az if turns else None)
                row["method_seconds"] = round(row["method_seconds"] + made, 2)
                made = 0.0
                rows.append(row)
                images.append(imgs)
        columns = (*config.methods, *extra)
        entry = {"rows": rows, "summary": summarise(rows, columns)}
        if config.figure and rows:
            fig = out / f"render_{label}.png"
            save_render_figure(rows, images, columns, fig, config.figure_dpi)
            entry["figure"] = str(fig)
        result["sets"][label] = entry
    (out / "render.json").write_text(json.dumps(result, indent=1, default=_json_default) + "\n")
    (out / "render.md").write_text(markdown_tables(result, (*METHODS, *extra)))
    return result


def _scored_row(config: RenderReportConfig, cache: Path, cls: str, m: Material, brdfs: dict,
                extra: dict[str, ExtraColumn], geo: SphereGeometry, azimuth: float | None) -> tuple[dict, dict]:
    """One material under one light (``azimuth``: its turn, named in the row; None: the one light): the
    reference, every method's and extra column's image, FLIP and PSNR."""
    mask = geo.mask.numpy()
    ref = reference_render(m, geo, config.spp, config.seed, cache, config.progress, config.noise_target,
                           config.max_spp)
    row = {"name": m.name if azimuth is None else f"{m.name} @ {azimuth:g} deg", "class": cls,
           "layers": len(m.layers), "light_azimuth": 0.0 if azimuth is None else azimuth,
           "reference": {"spp": ref.spp, "noise_psnr": noise_psnr(ref.image, ref.stderr, mask),
                         "half_flip": ref.half_flip, "seconds": round(ref.seconds, 2)}}
    t0 = time.perf_counter()
    imgs = {"reference": ref.image}
    for meth, brdf in brdfs.items():
        img = shade(brdf.eval, geo)
        fl, fmap = flip(ref.image, img)
        row[meth] = {"flip": fl, "flip_disk": float(fmap[mask].mean()), "psnr": compressed_psnr(img, ref.image, mask)}
        imgs[meth], imgs[f"flip_{meth}"] = img, fmap
        how = getattr(brdf, "refinement", None)
        if how is not None:  # what the refinement spent (a shared machine gives it less processor time)
            row[meth]["refinement"] = {k: getattr(how, k) for k in ("seconds", "cpu_seconds", "rounds", "pairs",
                                                                    "converged", "error", "network_error")
                                       if hasattr(how, k)}
    for name, render in extra.items():
        try:
            img = render(m, geo)
        except NbrdfError as e:
            row[f"{name}_error"] = str(e)
            continue
        fl, fmap = flip(ref.image, img)
        row[name] = {"flip": fl, "flip_disk": float(fmap[mask].mean()), "psnr": compressed_psnr(img, ref.image, mask)}
        imgs[name], imgs[f"flip_{name}"] = img, fmap
    row["method_seconds"] = time.perf_counter() - t0
    return row, imgs


def markdown_tables(result: dict, columns: tuple[str, ...] = METHODS) -> str:
    """Per set: one row per class (and all), median / worst FLIP and PSNR per method (and extra column)."""
    lines = []
    for label, entry in result["sets"].items():
        summ = entry["summary"]
        meths = [m for m in columns if any(m in v for v in summ.values())]
        lines += [f"**{label}**", "",
                  "| class | n | " + " | ".join(f"{m} FLIP median / worst | {m} PSNR median / worst (dB)"
                                                 for m in meths) + " | reference noise (half-FLIP, worst) |",
                  "|---|---|" + "---|---|" * len(meths) + "---|"]
        for cls, v in summ.items():
            cells = []
            for m in meths:
                s = v.get(m)
                cells += ([f"{s['flip_median']:.3f} / {s['flip_worst']:.3f}",
                           f"{s['psnr_median']:.1f} / {s['psnr_worst']:.1f}"] if s else ["—", "—"])
            name = f"**{cls}**" if cls == "all" else cls
            lines.append(f"| {name} | {v['materials']} | " + " | ".join(cells)
                         + f" | {v['reference_half_flip_worst']:.3f} |")
        lines.append("")
    return "\n".join(lines)


def _json_default(x):
    if isinstance(x, float) and math.isinf(x):
        return "inf"
    return str(x)


def _machine() -> dict:
    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "torch": torch.__version__, "threads": torch.get_num_threads()}


# --- figure -------------------------------------------------------------------------------
def display(img: np.ndarray) -> np.ndarray:
    """Linear image -> sRGB-ish [0, 1] through x / (1 + x) and gamma 2.2 (display only)."""
    x = np.maximum(img, 0.0)
    return np.clip(x / (1.0 + x), 0, 1) ** (1 / 2.2)


def save_render_figure(rows: list[dict], images: list[dict], methods: tuple[Method, ...], path: Path,
                       dpi: int = 60) -> None:
    """Rows: materials; columns: reference, each method, then each method's
    FLIP error map (magma, 0..1, with a colour bar)."""
    plt = _plt()
    meths = [m for m in methods if any(m in im for im in images)]
    cols = ["reference"] + meths + [f"flip_{m}" for m in meths]
    cell = 1.6
    fig, axes = plt.subplots(len(rows), len(cols), figsize=(cell * len(cols) + 0.8, cell * len(rows) + 0.4),
                             dpi=dpi, squeeze=False)
    mappable = None
    for i, (row, im) in enumerate(zip(rows, images)):
        for j, c in enumerate(cols):
            ax = axes[i, j]
            ax.set_xticks([])
            ax.set_yticks([])
            if c not in im:
                ax.axis("off")
                continue
            if c.startswith("flip_"):
                mappable = ax.imshow(im[c], cmap="magma", vmin=0, vmax=1, interpolation="nearest")
                r = row[c[5:]]
                ax.set_title(f"FLIP {r['flip']:.3f}  {r['psnr']:.1f} dB", fontsize=7)
            else:
                ax.imshow(display(im[c]), interpolation="nearest")
                ax.set_title(c if i == 0 else "", fontsize=8)
            if j == 0:
                ax.set_ylabel(row["name"], fontsize=7)
    fig.tight_layout(rect=(0, 0, 0.93, 1))
    if mappable is not None:
        cax = fig.add_axes((0.945, 0.3, 0.015, 0.4))
        fig.colorbar(mappable, cax=cax).ax.tick_params(labelsize=7)
    fig.savefig(path)
    plt.close(fig)
