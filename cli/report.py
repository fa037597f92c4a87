"""``nbrdf report representation|operations|interpolation``: accuracy on the
held-out sets and the figures of SPEC section 9."""
from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np

from nbrdf.cli.common import decoder_or_default, model_or_default
from nbrdf.cli.config import Parser, add_arguments, build
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material
from nbrdf.neural.methods import Method
from nbrdf.viewer.options import parse_size


@dataclass
class RepresentationReport:
    """``nbrdf report representation``: projected latents vs converged references."""

    refs: str
    """cache folder of held-out references (made on first use)"""
    out: str
    """folder for representation.json and the figures"""
    decoder: str | None = None
    """decoder weights (default: the shipped ones)"""
    limit: int = 0
    """score only the first N materials (quick looks; 0: all)"""
    record: bool = False
    """write the summary into the decoder file's metadata"""


@dataclass
class OperationsReport:
    """``nbrdf report operations``: full neural path vs projection vs analytic layering; sampling variance."""

    refs: str
    """cache folder of held-out references (made on first use)"""
    out: str
    """folder for operations.json / .md and figures"""
    model: str | None = None
    """bundle (default: the shipped weights)"""
    limit: int = 0
    """score only the first N held-out materials (0: all)"""
    every: int = 7
    """show every N-th stack in the lobe figure"""
    set: str = "heldout"
    """materials scored: heldout (the paper-distribution held-out set), lookdev (the look-development set,
    training/sets/lookdev) or depth (stacks of 2 to 6 layers: how the error grows with depth); keep one
    --refs folder per set"""
    per_depth: int = 8
    """depth: stacks of each depth"""
    noise_target: float = 48.0
    """lobe noise PSNR (dB) new references are refined to (60: the held-out figures of docs/RESULTS.md)"""
    max_spp: int = 256
    """paths per pixel at most while refining a new reference (60 dB needs about 16384)"""
    methods: str = "neural,projected,analytic"
    """comma-separated methods scored: neural (the full neural path), projected (the decoder at a fitted latent,
    the decoder's capacity; a fit per material), analytic (the analytic layering baseline)"""


@dataclass
class InterpolationReport:
    """``nbrdf report interpolation``: latent blend vs linear blend of BRDF values (a figure)."""

    a: str
    """first material JSON (t = 0)"""
    b: str
    """second material JSON (t = 1)"""
    out: str
    """PNG"""
    model: str | None = None
    """bundle (default: the shipped weights)"""


@dataclass
class RenderReport:
    """``nbrdf report render``: lit spheres (SPEC section 9, render-space error), reference vs neural
    paths, scored with HDR-FLIP and PSNR; JSON, tables and a side-by-side figure with error maps."""

    out: str
    """folder for render.json, render.md and the figures"""
    set: str = "lookdev,heldout"
    """comma-separated sets: lookdev (the bundled sharp-coat set), brushed (brushed metals, anisotropic),
    heldout (the paper-distribution held-out set), or paths of material JSON files / folders"""
    methods: str = "neural,projected"
    """comma-separated methods: neural (the full neural path), projected (the decoder at a fitted latent),
    refined (the network's code refined within --budget seconds), belcour (Belcour 2018's analytic layered
    model, a baseline)"""
    budget: float = 10.0
    """seconds the refined method spends per material (a cached refined code that serves it is used at once)"""
    size: int = 96
    """sphere image size in pixels (square)"""
    spp: int = 384
    """Monte Carlo paths per pixel of a stack's reference (first round)"""
    max_spp: int = 1536
    """paths per pixel at most while refining a reference to the noise target"""
    noise_target: float = 0.1
    """a reference is refined until the HDR-FLIP between its two independent halves is below this"""
    cache: str | None = None
    """reference cache folder (default: OUT/references); reruns resume from it"""
    model: str | None = None
    """bundle (default: the shipped weights)"""
    heldout_per_class: int = 3
    """held-out materials scored per class"""
    seed: int = 0
    """seed of the references and projections"""
    light_azimuths: str = "0"
    """comma-separated turns of the light about the view axis in degrees (SPEC section 9's light at 0): every
    material is scored under each, e.g. 0,120,240 for anisotropic materials"""


@dataclass
class OpenPbrReport(RenderReport):
    """``nbrdf report openpbr``: the OpenPBR test set (training/sets/openpbr: coated metals and plastics, car paints,
    lacquered wood, uncoated metals and plastics) on the lit sphere against each document's stack's Monte Carlo
    reference: the neural path, the refined codes, Belcour 2018, and OpenPBR as MaterialX's generated GLSL renders
    it (the column an OpenPBR user sees today; where it cannot run, one line says why)."""

    set: str = "openpbr"
    methods: str = "neural,refined,belcour"
    size: int = 64


def method_words(text: str, allowed: Iterable[Method]) -> tuple[Method, ...]:
    """The ``--methods`` words as ``Method`` members, in the order given: the one place a report reads them
    (one-line error for a word outside ``allowed``)."""
    allowed = tuple(allowed)
    words = tuple(w.strip() for w in text.split(",") if w.strip())
    if any(w not in allowed for w in words):
        raise NbrdfError(f"--methods: {text!r} is not a comma-separated list of {', '.join(allowed)}")
    return tuple(Method(w) for w in words)


def azimuth_words(text: str) -> tuple[float, ...]:
    """The ``--light-azimuths`` words as finite degrees (one-line error otherwise)."""
    try:
        out = tuple(float(w) for w in text.split(",") if w.strip())
    except ValueError:
        out = ()
    if not out or not all(math.isfinite(a) for a in out):
        raise NbrdfError(f"--light-azimuths: {text!r} is not a comma-separated list of angles in degrees")
    return out


def cmd_report_render(ns: argparse.Namespace, cls: type = RenderReport, extra: dict | None = None) -> int:
    from nbrdf.training import render_report  # late: torch costs ~1 s, --help needs none

    c: RenderReport = build(cls, ns)
    methods = method_words(c.methods, render_report.METHODS)
    sets = tuple(w.strip() for w in c.set.split(",") if w.strip())
    cfg = render_report.RenderReportConfig(sets=sets, out=Path(c.out), size=c.size, spp=c.spp, max_spp=c.max_spp,
                                           noise_target=c.noise_target,
                                           cache=Path(c.cache) if c.cache else None, model=c.model,
                                           methods=methods, heldout_per_class=c.heldout_per_class, seed=c.seed,
                                           refine_budget=c.budget, light_azimuths=azimuth_words(c.light_azimuths))
    result = render_report.run_render_report(cfg, extra)
    print(render_report.markdown_tables(result, (*render_report.METHODS, *(extra or {}))))
    for entry in result["sets"].values():
        for reason in dict.fromkeys(v for row in entry["rows"] for k, v in row.items() if k.endswith("_error")):
            print(f"not shown: {reason}")
    return 0


def cmd_report_openpbr(ns: argparse.Namespace) -> int:
    """The OpenPBR report: the render report over the OpenPBR set with MaterialX's own GLSL as a column."""
    from nbrdf.neural.mtlx import openpbr_from_record, write_mtlx  # late: MaterialX, as above
    from nbrdf.viewer.gpu.gl import offscreen_context  # late: GL for this column only
    from nbrdf.viewer.gpu.materialx_glsl import render_materialx  # late: moderngl and MaterialX's generators

    ctx, folder = None, Path(tempfile.mkdtemp(prefix="nbrdf-mtlx-"))

    def materialx(m, geo):
        nonlocal ctx
        if m.openpbr is None:
            raise NbrdfError(f"{m.name}: not an OpenPBR material (MaterialX's column needs its inputs)")
        if ctx is None:
            ctx = offscreen_context()
        doc = folder / "m.mtlx"
        write_mtlx(openpbr_from_record(dict(m.openpbr)), m.name or "material", doc)
        return render_materialx(ctx, doc, geo)

    return cmd_report_render(ns, OpenPbrReport, {"materialx": materialx})


def cmd_report_representation(ns: argparse.Namespace) -> int:
    from nbrdf.training.evaluate import build_references, projected_method, report_figures, score  # late: torch

    c: RepresentationReport = build(RepresentationReport, ns)
    dec = decoder_or_default(c.decoder)
    refs = build_references(c.refs, limit=c.limit)
    result = score(refs, projected_method(dec))
    result["decoder_id"] = dec.weights_id()
    out = Path(c.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "representation.json").write_text(json.dumps(result, indent=1))
    report_figures(refs, projected_method(dec), result, out)
    if c.record:
        from nbrdf.neural.decoder import DEFAULT_WEIGHTS, record_accuracy  # late: torch, --help needs none

        record_accuracy(c.decoder or DEFAULT_WEIGHTS, {"heldout_projected": result["summary"]})
    print(json.dumps(result["summary"], indent=1))
    return 0


def cmd_report_operations(ns: argparse.Namespace) -> int:
    from nbrdf.training import evaluate, render_report  # late: torch and the walk, --help needs neither

    c: OperationsReport = build(OperationsReport, ns)
    model = model_or_default(c.model)
    if c.set not in ("heldout", "lookdev", "depth"):
        raise NbrdfError(f"--set: {c.set!r} is not heldout, lookdev or depth")
    if c.per_depth < 1 or c.max_spp < 1 or not c.noise_target > 0:
        raise NbrdfError("--per-depth, --max-spp and --noise-target must be positive")
    makers = {Method.NEURAL: lambda: evaluate.neural_method(model),
              Method.PROJECTED: lambda: evaluate.projected_method(model.decoder),
              Method.ANALYTIC: evaluate.analytic_method}
    names = tuple(dict.fromkeys(method_words(c.methods, makers)))
    if not names:
        raise NbrdfError(f"--methods: {c.methods!r} is not a comma-separated list of {', '.join(makers)}")
    items = None
    if c.set == "lookdev":
        items = render_report.load_set("lookdev")
    elif c.set == "depth":
        items = evaluate.depth_set(c.per_depth)
    refs = evaluate.build_references(c.refs, limit=c.limit, items=items, noise_target=c.noise_target,
                                     max_spp=c.max_spp)
    out = Path(c.out)
    out.mkdir(parents=True, exist_ok=True)
    methods = {n: makers[n]() for n in names}
    stacks = [x for x in refs if x[1].interfaces]  # single layers: the analytic model is the reference itself
    results = {name: evaluate.score(stacks if name is Method.ANALYTIC else refs, m) for name, m in methods.items()}
    glossy = evaluate.glossy_stacks(refs)
    variances = [dict(name=m.name, **evaluate.sampling_variance(model, m, seed=i))
                 for i, (_, m, _) in enumerate(glossy)]
    ratio = lambda k: float(np.median([v[k] / max(v["proxy"], 1e-30) for v in variances])) if variances else None
    sampling = {"glossy_stacks": len(variances), "median_variance_reduction_vs_cosine": ratio("cosine"),
                "median_variance_reduction_vs_top_ggx": ratio("top_ggx"), "per_material": variances}
    report = {"summary": {k: r["summary"] for k, r in results.items()}, "sampling": sampling,
              "rows": {k: r["rows"] for k, r in results.items()}}
    (out / "operations.json").write_text(json.dumps(report, indent=1))
    (out / "operations.md").write_text(evaluate.comparison_table(results) + "\n")
    shown = [(k, m, r) for k, m, r in refs if k in ("two_layer", "three_layer") or c.set != "heldout"]
    shown = shown[:: max(1, c.every)][:6]
    evaluate.comparison_figure(shown, methods, out / "operations_lobes.png")
    print(evaluate.comparison_table(results))
    print(json.dumps({k: v for k, v in sampling.items() if k != "per_material"}))
    return 0


def cmd_report_interpolation(ns: argparse.Namespace) -> int:
    from nbrdf.training.evaluate import interpolation_figure  # late: torch costs ~1 s, --help needs none

    c: InterpolationReport = build(InterpolationReport, ns)
    model = model_or_default(c.model)
    out = Path(c.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    res = interpolation_figure(model, load_material(c.a), load_material(c.b), out)
    print(json.dumps(res))
    return 0


@dataclass
class GalleryReport:
    """``nbrdf report gallery``: every bundled preset on the sphere, offscreen, under the previewer's default
    environment and look, in one labelled image grid."""

    out: str = "docs/figures/gallery.png"
    """the grid PNG"""
    tile: int = 160
    """pixels per side of one material's tile"""
    spp: int = 32
    """passes per pixel of each tile"""
    columns: int = 4
    """tiles per row"""


def cmd_report_gallery(ns: argparse.Namespace) -> int:
    from nbrdf.viewer.gallery import GalleryConfig, render_gallery  # late: the previewer (GL, torch)

    c: GalleryReport = build(GalleryReport, ns)
    print(render_gallery(GalleryConfig(Path(c.out), c.tile, c.spp, c.columns)))
    return 0


@dataclass
class FurnaceReport:
    """``nbrdf report furnace``: directional albedo (per channel, 8 incidences) and reciprocity of the neural and
    refined paths against the walk, on 20 fixed held-out stacks (10 lossless, 10 absorbing, 2 to 4 layers).
    Usage: nbrdf report furnace --out runs/furnace [--model BUNDLE] [--ref-max-paths 262144 --ref-target 0.002];
    writes furnace.json (every albedo with its standard error, the summary), furnace.md and furnace.png."""

    out: str
    """folder for furnace.json, furnace.md and furnace.png"""
    model: str | None = None
    """bundle (default: the shipped weights)"""
    methods: str = "neural,refined"
    """comma-separated methods scored against the walk: neural (the full neural path), refined (its code refined
    within --budget seconds)"""
    per_class: int = 10
    """lossless and absorbing stacks each (the set is fixed; fewer: its first ones)"""
    samples: int = 1024
    """Sobol points per replicate of a neural or refined albedo"""
    replicates: int = 8
    """independent scrambles of a neural or refined albedo (its standard error comes from their spread)"""
    ref_paths: int = 16384
    """walk paths per incidence in the reference's first round (rounds double the total)"""
    ref_max_paths: int = 262144
    """walk paths per incidence at most"""
    ref_target: float = 0.002
    """relative standard error the reference albedo is refined to (or --ref-max-paths)"""
    budget: float = 3.0
    """seconds of refinement per stack (refined)"""
    pairs: int = 64
    """random (wi, wo) pairs of the reciprocity figure, per stack"""
    pair_spp: int = 256
    """walk paths per pair and order of the reference's reciprocity (its noise level)"""
    seed: int = 0
    """seed of the estimators (the stacks have their own fixed seed)"""
    cache: str = ""
    """folder keeping the references between runs (bundles then compare on the same references; empty: none)"""


@dataclass
class AnisotropyReport:
    """``nbrdf report anisotropy``: the held-out anisotropic materials (issue 39: lone brushed conductors, their
    reference the closed form, and brushed conductors under a coat and a medium, their reference the walk) scored by
    lobe PSNR at the standard incidences and 4 incident azimuths; references cached per material, so a build
    resumes. Usage: nbrdf report anisotropy --refs runs/aniso_refs [--build] [--per-class 20]."""

    refs: str
    """folder of the cached reference lobes (one file per material)"""
    build: bool = False
    """compute the missing references first (the coated ones take minutes each at 60 dB)"""
    per_class: int = 20
    """materials per class (the set is fixed; fewer: its first ones)"""
    noise_target: float = 60.0
    """noise PSNR (dB) a walk reference is refined to"""
    model: str | None = None
    """bundle (default: the shipped weights)"""


def cmd_report_anisotropy(ns: argparse.Namespace) -> int:
    from nbrdf.neural.neural_brdf import neural_brdf  # late: torch and the walk, --help needs neither
    from nbrdf.training import anisotropy_report as ar  # late: as above

    c: AnisotropyReport = build(AnisotropyReport, ns)
    if c.per_class < 1 or not 20.0 <= c.noise_target <= 90.0:
        raise NbrdfError("report anisotropy: --per-class must be at least 1 and --noise-target in [20, 90] dB")
    if c.build:
        ar.build_references(c.refs, c.per_class, c.noise_target)
    elif not Path(c.refs).is_dir():
        raise NbrdfError(f"--refs {c.refs}: no such folder (add --build to compute the references)")
    model = model_or_default(c.model)
    rows = ar.score(c.refs, lambda m: neural_brdf(m, model).eval, c.per_class)
    if not rows:
        raise NbrdfError(f"--refs {c.refs}: holds no reference of this set (add --build)")
    print(json.dumps({"summary": ar.summary(rows), "rows": [{k: v for k, v in r.items() if k != "psnrs"}
                                                           for r in rows]}, indent=1))
    return 0


def cmd_report_furnace(ns: argparse.Namespace) -> int:
    from nbrdf.training import furnace_report  # late: torch and the walk, --help needs neither

    c: FurnaceReport = build(FurnaceReport, ns)
    if min(c.per_class, c.samples, c.pairs, c.pair_spp) < 1 or c.replicates < 2 or c.ref_paths < 2 \
            or c.ref_max_paths < c.ref_paths or not (c.ref_target > 0 and c.budget > 0):
        raise NbrdfError("report furnace: --per-class, --samples, --pairs and --pair-spp must be at least 1, "
                         "--replicates at least 2, --ref-paths at least 2, --ref-max-paths at least --ref-paths, "
                         "--ref-target and --budget positive")
    methods = tuple(dict.fromkeys(method_words(c.methods, furnace_report.FURNACE_METHODS)))
    if not methods:
        raise NbrdfError(f"--methods: {c.methods!r} names no method")
    cfg = furnace_report.FurnaceConfig(out=Path(c.out), methods=methods, model=model_or_default(c.model),
                                       per_class=c.per_class, samples=c.samples, replicates=c.replicates,
                                       ref_paths=c.ref_paths, ref_max_paths=c.ref_max_paths, ref_target=c.ref_target,
                                       budget=c.budget, pairs=c.pairs, pair_spp=c.pair_spp, seed=c.seed,
                                       cache=Path(c.cache) if c.cache else None)
    result = furnace_report.run_furnace_report(cfg, log=lambda s: print(s, file=sys.stderr))
    print(furnace_report.table(result))
    return 0


#: ``nbrdf report`` subcommands: name -> (config, command, one-line help).
@dataclass
class ScenesReport:
    """``nbrdf report scenes``: the paper's Table 3 on the project's scenes: the neural material vs its Monte Carlo
    ground truth (nbrdf_reference) at equal time in Mitsuba 3, MSE and HDR-FLIP against a converged reference."""

    out: str
    """folder for scenes.json, scenes.md, scenes.png and the images"""
    scenes: str = "still_life,teapot"
    """comma-separated scene presets or scene JSON files"""
    size: tuple[int, int] = field(default=(96, 72), metadata={"parse": parse_size, "metavar": "WxH", "shown": "96x72"})
    """image size in pixels"""
    time_budget: float = 20.0
    """seconds of the neural render: the equal time both methods get"""
    ref_spp: int = 512
    """samples per pixel of the converged Monte Carlo reference (cached)"""
    chunk: int = 16
    """samples per pixel of the first and smallest Mitsuba pass (larger passes amortise the wavefront mode's per-pass cost)"""
    max_chunk: int = 256
    """largest pass: a method's passes double from --chunk while one takes at most 1/8 of the budget"""
    cache: str | None = None
    """cache folder of the converged references (default: OUT/cache)"""
    figure: str | None = None
    """the figure's path (default: OUT/scenes.png)"""
    seed: int = 0
    """seed of the renders"""
    neural_body: str = field(default="decoder", metadata={"choices": ("decoder", "table")})
    """the neural material's body: decoder (per query, wavefront mode) or table (baked once per uniform material,
    symbolic mode; a texture-mapped material varying at most two albedos gets a parametric table, others keep
    the decoder)"""


def cmd_report_scenes(ns: argparse.Namespace) -> int:
    c: ScenesReport = build(ScenesReport, ns)
    if c.time_budget <= 0 or c.ref_spp < 2 or c.chunk < 1 or c.max_chunk < c.chunk:
        raise NbrdfError(f"report scenes: --time-budget must be positive, --ref-spp at least 2, --chunk at least 1 "
                         f"and --max-chunk at least --chunk (got {c.time_budget}, {c.ref_spp}, {c.chunk}, "
                         f"{c.max_chunk})")
    try:
        from nbrdf.mitsuba import scene_report, scenes  # optional: mitsuba
    except ImportError as e:
        raise NbrdfError(f"report scenes: Mitsuba 3 is unusable ({e}); pip install -e '.[mitsuba]'") from None

    names = tuple(w.strip() for w in c.scenes.split(",") if w.strip())
    if not names:
        raise NbrdfError("report scenes: --scenes is empty")
    for n in names:
        scenes.load_scene(n)  # bad scenes fail before minutes of rendering
    cfg = scene_report.SceneReportConfig(out=Path(c.out), scenes=names, size=c.size, time_budget=c.time_budget,
                                         ref_spp=c.ref_spp, chunk=c.chunk, max_chunk=c.max_chunk,
                                         cache=Path(c.cache) if c.cache else None, seed=c.seed,
                                         figure=Path(c.figure) if c.figure else None, neural_body=c.neural_body)
    print(scene_report.markdown(scene_report.run_scene_report(cfg, log=lambda s: print(s, file=sys.stderr))))
    return 0


@dataclass
class MisReport:
    """``nbrdf report mis``: the paper's MIS figure: direct lighting of two neural materials with light sampling only,
    BSDF sampling only and MIS at equal spp (Mitsuba 3), each scored by MSE against a high-spp MIS render."""

    out: str
    """the figure (PNG); its MSEs go to a .json beside it"""
    spp: int = 8
    """samples per pixel of every strategy"""
    ref_factor: int = 32
    """the reference render has this many times the spp"""
    size: tuple[int, int] = field(default=(128, 72), metadata={"parse": parse_size, "metavar": "WxH", "shown": "128x72"})
    """image size in pixels"""
    seed: int = 0
    """seed of the renders"""


def cmd_report_mis(ns: argparse.Namespace) -> int:
    c: MisReport = build(MisReport, ns)
    if c.spp < 1 or c.ref_factor < 2 or not c.out.lower().endswith(".png"):
        raise NbrdfError(f"report mis: --spp must be at least 1, --ref-factor at least 2 and the output a .png "
                         f"(got {c.spp}, {c.ref_factor}, {c.out})")
    try:
        from nbrdf.mitsuba.mis_figure import MisFigureConfig, mis_figure  # optional: mitsuba
    except ImportError as e:
        raise NbrdfError(f"report mis: Mitsuba 3 is unusable ({e}); pip install -e '.[mitsuba]'") from None

    res = mis_figure(MisFigureConfig(out=Path(c.out), size=c.size, spp=c.spp, ref_factor=c.ref_factor, seed=c.seed),
                     log=lambda s: print(s, file=sys.stderr))
    for name, r in res["strategies"].items():
        print(f"{name:15s} {c.spp} spp: MSE {r['mse']:.2e} ({r['seconds']:.1f} s)")
    return 0


REPORTS = {
    "representation": (RepresentationReport, cmd_report_representation,
                       "projected latents vs converged references"),
    "operations": (OperationsReport, cmd_report_operations,
                   "full neural path vs projection vs analytic layering; sampling variance"),
    "interpolation": (InterpolationReport, cmd_report_interpolation,
                      "latent blend vs linear blend of BRDF values (a figure)"),
    "render": (RenderReport, cmd_report_render,
               "render-space error: lit spheres, HDR-FLIP and PSNR (SPEC section 9)"),
    "openpbr": (OpenPbrReport, cmd_report_openpbr,
                "the OpenPBR set: neural, refined, Belcour and MaterialX's own GLSL against each stack's reference"),
    "gallery": (GalleryReport, cmd_report_gallery,
                "every preset rendered with the previewer's defaults, one image grid"),
    "scenes": (ScenesReport, cmd_report_scenes,
               "neural vs Monte Carlo material at equal time in Mitsuba 3 scenes (the paper's Table 3)"),
    "furnace": (FurnaceReport, cmd_report_furnace,
                "directional albedo and reciprocity of the neural and refined paths against the walk"),
    "mis": (MisReport, cmd_report_mis, "light vs BSDF sampling vs MIS for neural materials in Mitsuba 3 (a figure)"),
    "anisotropy": (AnisotropyReport, cmd_report_anisotropy,
                   "held-out brushed conductors, bare and coated: lobe PSNR at 4 incidences x 4 azimuths"),
}


def register(sub: argparse._SubParsersAction) -> None:
    """Adds ``report`` and its subcommands to the ``nbrdf`` subcommands."""
    rp = sub.add_parser("report", help="accuracy on the held-out sets (SPEC section 9)")
    rsub = rp.add_subparsers(dest="what", required=True, parser_class=Parser)
    for name, (cls, fn, help_) in REPORTS.items():
        p = rsub.add_parser(name, help=help_, description=cls.__doc__)
        add_arguments(p, cls)
        p.set_defaults(fn=fn)
