"""The lit preview's noise: relative standard deviation across independent
renders, where it comes from, and the bias of the firefly clamp.

Relative noise (issue 13) = per pixel on the object, the standard deviation
of the luminance across K renders that differ only in their random numbers
(``LitSampling.seed``), over the mean of the K renders; averaged over the
object's pixels. The renderer's random numbers are deterministic per pixel,
pass and seed, so every figure here is reproducible.

``python -m nbrdf.viewer.gpu.noise`` prints the default render's figures as JSON
(``--size``, ``--spp``, ``--renders``, ``--terms``, ``--coat-samples``, ``--clamp``),
``--material`` another material's, ``--brdf`` another BRDF (belcour), ``--target proxy`` with the decoder resampled
by the proxy target instead of the body's table (``LitSampling.table_target``), ``--still-window map|no-map`` the
window's still view on software OpenGL (``--against N``: the error of its first render against N passes without
the map).
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from nbrdf.imaging.environment import LUMA
from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.gpu.body_source import table_sampling
from nbrdf.viewer.gpu.body_table_gpu import STILL, BodyTables
from nbrdf.viewer.gpu.env_prefilter import PrefilterSettings
from nbrdf.viewer.gpu.gl import offscreen_context
from nbrdf.viewer.gpu.lit_sampling import Term
from nbrdf.viewer.gpu.renderer import make_renderer
from nbrdf.viewer.options import ViewOptions


@dataclass
class NoiseConfig:
    """What a noise measurement renders."""

    size: tuple[int, int] = (64, 64)
    """Image size (w, h): small renders iterate fast; the figure holds at 256 x 256 (docs/RESULTS.md)."""
    spp: int = 16
    """Passes per render (the offscreen preview's default)."""
    renders: int = 8
    """Independent renders (seeds 1..renders) the standard deviation is taken over."""
    terms: bool = False
    """Also measure each estimator term alone (``Term``): where the variance comes from."""


@dataclass
class NoiseReport:
    """A noise measurement's figures (fractions, not per cent)."""

    relative_noise: float
    """Mean over the object's pixels of std / mean of the luminance."""
    median: float
    """Median of the per-pixel relative noise."""
    p99: float
    """99th percentile of the per-pixel relative noise."""
    worst: float
    """The largest per-pixel relative noise (a firefly shows here)."""
    seconds_per_render: float
    """Wall time of one render (median after the first, which compiles shaders)."""
    cpu_seconds_per_render: float
    """CPU time of one render, all threads (llvmpipe: less sensitive to a loaded machine than wall time)."""
    pixels: int
    """Pixels on the object."""
    by_term: dict[str, float] = field(default_factory=dict)
    """Per estimator term rendered alone: mean over the object of the term's std over the full mean."""

    def as_dict(self) -> dict:
        out = {k: (round(v, 5) if isinstance(v, float) else v) for k, v in self.__dict__.items() if k != "by_term"}
        if self.by_term:
            out["by_term"] = {k: round(v, 5) for k, v in self.by_term.items()}
        return out


def default_setup(ctx, material: Path | None = None, brdf: str = "auto"):
    """The default offscreen preview's renderer and state (``nbrdf-view --offscreen``:
    ``material``, default the default material, shaded by ``brdf`` (``--brdf``),
    studio environment, the framed three-quarter camera), object only."""
    opts = ViewOptions(brdf=brdf) if material is None else ViewOptions(material=material, brdf=brdf)
    r = make_renderer(ctx, opts.load_material()[0], opts)
    state = replace(opts.state, background=False)
    return r, state


def render_seeds(renderer, state, size: tuple[int, int], spp: int, seeds, progress: bool = False
                 ) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    """Linear renders (K, H, W, 3) of ``state``, one per seed, the (H, W) mask of
    object pixels, and the median (wall, CPU) seconds per render (without the first)."""
    w, h = size
    imgs, times = [], []
    old = renderer.sampling.seed
    try:
        for seed in tqdm(list(seeds), desc="renders", unit="render", disable=not progress, leave=False):
            renderer.sampling.seed = seed
            t0, c0 = time.perf_counter(), time.process_time()
            tex = renderer.accumulate(state, w, h, 0, spp, slot="noise")
            acc = np.frombuffer(tex.read(), np.float32).reshape(h, w, 4)[::-1]
            times.append((time.perf_counter() - t0, time.process_time() - c0))
            imgs.append(acc[..., :3] / spp)
    finally:
        renderer.sampling.seed = old
    mask = acc[..., 3] > 0
    kept = np.asarray(times[1:] if len(times) > 1 else times)
    return np.stack(imgs), mask, (float(np.median(kept[:, 0])), float(np.median(kept[:, 1])))


def per_pixel_noise(images: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Per object pixel, the luminance's std across renders (ddof 1) over its mean."""
    lum = images @ LUMA.astype(np.float64)
    mean = lum.mean(0)[mask]
    std = lum.std(0, ddof=1)[mask]
    return std / np.maximum(mean, 1e-12)


def measure_noise(renderer, state, config: NoiseConfig | None = None, progress: bool = False) -> NoiseReport:
    """The relative noise of ``renderer``'s image of ``state`` (its ``sampling``
    settings as they are), over ``config.renders`` independent seeds
    (default: ``NoiseConfig()``)."""
    config = config or NoiseConfig()
    seeds = range(1, config.renders + 1)
    imgs, mask, dt = render_seeds(renderer, state, config.size, config.spp, seeds, progress)
    rel = per_pixel_noise(imgs, mask)
    report = NoiseReport(float(rel.mean()), float(np.median(rel)), float(np.quantile(rel, 0.99)),
                         float(rel.max()), dt[0], dt[1], int(mask.sum()))
    if config.terms:
        lum = imgs @ LUMA.astype(np.float64)
        mean = np.maximum(lum.mean(0)[mask], 1e-12)
        old = renderer.sampling.terms
        try:
            for term in (t for t in Term if t != Term.ALL):
                renderer.sampling.terms = term
                part, _, _ = render_seeds(renderer, state, config.size, config.spp, seeds)
                std = (part @ LUMA.astype(np.float64)).std(0, ddof=1)[mask]
                report.by_term[term.name.lower()] = float((std / mean).mean())
        finally:
            renderer.sampling.terms = old
    return report


def clamp_bias(renderer, state, clamp: float, size: tuple[int, int] = (64, 64), spp: int = 16,
               reference_spp: int = 1024, progress: bool = False) -> dict:
    """The firefly clamp's bias: the mean of a ``spp``-pass render with the clamp
    at ``clamp`` against a ``reference_spp``-pass render without it, both over
    the object: relative difference of the mean luminance and mean per-pixel
    relative difference (luminance)."""
    old = (renderer.sampling.clamp, renderer.sampling.seed)
    w, h = size
    try:
        renderer.sampling.seed = 7
        renderer.sampling.clamp = 0.0
        chunk = 64
        for first in tqdm(range(0, reference_spp, chunk), desc="reference", disable=not progress, leave=False):
            tex = renderer.accumulate(state, w, h, first, min(chunk, reference_spp - first), slot="bias")
        acc = np.frombuffer(tex.read(), np.float32).reshape(h, w, 4)[::-1]
        ref = acc[..., :3] / reference_spp
        mask = acc[..., 3] > 0
        renderer.sampling.clamp = clamp
        # The clamped estimator's mean: the same long render with the clamp on.
        for first in range(0, reference_spp, chunk):
            tex = renderer.accumulate(state, w, h, first, min(chunk, reference_spp - first), slot="bias")
        clamped = np.frombuffer(tex.read(), np.float32).reshape(h, w, 4)[::-1][..., :3] / reference_spp
    finally:
        renderer.sampling.clamp, renderer.sampling.seed = old
    a, b = clamped @ LUMA, ref @ LUMA
    return {"clamp": clamp, "reference_spp": reference_spp,
            "mean_bias": float(a[mask].sum() / b[mask].sum() - 1.0),
            "pixel_bias_mean": float((np.abs(a - b)[mask] / np.maximum(b[mask], 1e-12)).mean()),
            "pixel_bias_max": float((np.abs(a - b)[mask] / np.maximum(b[mask], 1e-12)).max())}


def main(argv: list[str] | None = None) -> int:
    """Prints the default render's noise report as one JSON object."""
    ap = argparse.ArgumentParser(prog="python -m nbrdf.viewer.gpu.noise", description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=64, help="square image side, pixels")
    ap.add_argument("--spp", type=int, default=16, help="passes per render")
    ap.add_argument("--renders", type=int, default=8, help="independent renders")
    ap.add_argument("--terms", action="store_true", help="also each estimator term alone")
    ap.add_argument("--coat-samples", type=int, default=None, help="coat samples per pass (default: the renderer's)")
    ap.add_argument("--ris", type=int, default=None, help="resampled body samples per pass (0: off)")
    ap.add_argument("--candidates", type=int, default=None, help="candidates per resampled sample")
    ap.add_argument("--clamp", type=float, default=None, help="firefly clamp (default: the renderer's)")
    ap.add_argument("--strategies", type=int, choices=(3, 4), default=None)
    ap.add_argument("--bias", action="store_true", help="also the clamp's bias against a long unclamped render")
    ap.add_argument("--material", type=Path, default=None, help="material file (default: the default material)")
    ap.add_argument("--brdf", default="auto", help="the BRDF shaded (nbrdf-view --brdf; default auto)")
    ap.add_argument("--target", choices=("table", "proxy"), default=None,
                    help="the decoder's resampling target: the body's baked table or the proxy pdf "
                         "(default: the renderer's)")
    ap.add_argument("--still-window", choices=("map", "no-map"), default=None,
                    help="the window's still view on software OpenGL: the body baked into the still table, the "
                         "table's sampling, with or without the body environment map (viewer/gpu/env_prefilter.py)")
    ap.add_argument("--against", type=int, default=0,
                    help="also the mean relative error and bias of the first render against this many passes "
                         "of the still view without the map (with --still-window)")
    args = ap.parse_args(argv)
    try:
        ctx = offscreen_context()
        r, state = default_setup(ctx, args.material, args.brdf)
        if args.still_window is not None:
            r.brdf = BodyTables(ctx).brdf(r.brdf, STILL)
            r.sampling = table_sampling(r.sampling)
    except (NbrdfError, OSError) as e:
        ap.exit(2, f"{ap.prog}: {e}\n")
    reference = None
    if args.still_window is not None and args.against > 0:
        reference = r.render_linear(state, (args.size, args.size), args.against)
    if args.still_window == "map":
        r.settings.prefilter = PrefilterSettings()
    if args.target is not None:
        r.sampling.table_target = args.target == "table"
    if args.coat_samples is not None:
        r.sampling.coat_samples = args.coat_samples
    if args.ris is not None:
        r.sampling.ris_samples = args.ris
    if args.candidates is not None:
        r.sampling.ris_candidates = args.candidates
    if args.clamp is not None:
        r.sampling.clamp = args.clamp
    if args.strategies is not None:
        r.sampling.strategies = args.strategies
    cfg = NoiseConfig(size=(args.size, args.size), spp=args.spp, renders=args.renders, terms=args.terms)
    out = measure_noise(r, state, cfg, progress=True).as_dict()
    out.update(size=f"{args.size}x{args.size}", spp=args.spp, renders=args.renders,
               ris=r.sampling.ris_samples, candidates=r.sampling.ris_candidates,
               coat_samples=r.sampling.coat_samples, clamp=r.sampling.clamp, strategies=r.sampling.strategies,
               target="table" if r.sampling.table_target else "proxy",
               material=str(args.material) if args.material else "default", brdf=args.brdf)
    if args.still_window is not None:
        out["still_window"] = args.still_window
    if reference is not None:
        img = r.render_linear(state, (args.size, args.size), args.spp)
        on = reference.sum(-1) > 0
        out["against_passes"] = args.against
        out["mean_relative_error"] = float(np.abs(img - reference)[on].sum() / reference[on].sum())
        out["bias"] = float(img[on].sum() / reference[on].sum() - 1.0)
    if args.bias:
        out["clamp_bias"] = clamp_bias(r, state, r.sampling.clamp, (args.size, args.size), args.spp, progress=True)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
