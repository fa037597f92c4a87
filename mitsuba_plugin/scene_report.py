"""``nbrdf report scenes``: the paper's Table 3 on this project's scenes.

Per scene: the neural material (``nbrdf``) and its Monte Carlo ground truth
(``nbrdf_reference``, a fresh unbiased estimate of f per query, as Guo et al.
2018) rendered at EQUAL TIME, each scored against a converged reference (the
Monte Carlo at high spp, cached) by MSE and HDR-FLIP. The time: after one
untimed chunk each (kernel compilation), the two renders take turns, a chunk
of spp at a time, the one with less time spent going next, until each has
spent the budget: on a machine whose load drifts both meet the same
conditions. Both render with the same path tracer, each in its fastest Dr.Jit
mode on this backend (``render.is_wavefront``): the Monte Carlo always in the
wavefront mode (the walk needs it), the neural material there too when its
body is the decoder, in symbolic mode when every uniform material reads its
body from a baked table (``neural_body="table"``; a texture-mapped material
whose maps vary at most two albedos reads a parametric table, ``param_table``;
any other keeps the decoder, and the wavefront mode with it). The LLVM compilation of any kernel met later for the first time (a
wavefront of one lane gets kernels of its own) is taken out of both times
and stated.

The converged reference is two independent halves (even and odd chunks): the
MSE between them estimates its own noise (the full average's noise variance is
a quarter of it), which is stated and subtracted from the scores' noise
floor. The crossover extrapolates the unbiased Monte Carlo's MSE as
(MSE at equal time) x t_eq / t: the render time at which it would reach the
neural material's error. An extrapolation, stated as one.
"""
from __future__ import annotations

import hashlib
import json
import math
import platform
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nbrdf.imaging.flip import flip
from nbrdf.imaging.image_io import tonemap
from nbrdf.mitsuba.render import RenderResult, is_wavefront, load, render
from nbrdf.mitsuba.scenes import Scene, load_scene, neural_bodies, with_method
from nbrdf.neural.errors import NbrdfError
from nbrdf.training.plots import _plt

#: The paper's Table 3: equal-time MSE, (neural, Guo et al. Monte Carlo), at 1024 x 1024.
#: Samples per pixel per pass of the converged reference (its cache does not depend on ``--chunk``).
REF_CHUNK = 16
#: A method's passes grow (doubling from ``chunk``) while one takes at most this share of the time budget.
PASS_SHARE = 1 / 8
PAPER_TABLE3 = {"still_life": (1.0e-3, 2.0e-3), "globe": (9.3e-4, 2.3e-3), "teapot": (6.0e-4, 5.4e-3)}


@dataclass
class SceneReportConfig:
    """What ``run_scene_report`` renders and where it writes."""

    out: Path
    """folder for scenes.json, scenes.md, the figure and the images"""
    scenes: tuple[str, ...] = ("still_life", "teapot")
    """preset names or scene JSON files"""
    size: tuple[int, int] = (96, 72)
    """image size (w, h)"""
    time_budget: float = 20.0
    """seconds of the neural render (the equal time)"""
    ref_spp: int = 512
    """samples per pixel of the converged Monte Carlo reference"""
    chunk: int = 16
    """samples per pixel of the first pass and the smallest (the wavefront mode's per-pass cost, tracing and
    launches per bounce, is amortised over a pass)"""
    max_chunk: int = 256
    """largest pass: each method's passes double from ``chunk`` while one takes at most ``PASS_SHARE`` of
    the budget at its warm-up pace (the same rule for both; ``chunk``: fixed passes)"""
    cache: Path | None = None
    """converged references are cached here (default: OUT/cache)"""
    seed: int = 0
    """seed of the renders (the converged reference uses seed + 1000)"""
    figure: Path | None = field(default=None)
    """the figure's path (default: OUT/scenes.png)"""
    neural_body: str = "decoder"
    """the ``nbrdf`` plugin's ``body``: "decoder" (per query) or "table" (baked once, ``kernel.TableBody``, or
    ``param_table`` for a texture-mapped material that fits one: noise-free, its interpolation error a bias;
    renders in symbolic mode)"""


def mse(a: np.ndarray, b: np.ndarray) -> float:
    """Mean squared error over pixels and channels."""
    return float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))


def crossover_seconds(mse_mc: float, seconds_mc: float, mse_target: float) -> float:
    """Render time at which an unbiased Monte Carlo render with ``mse_mc``
    after ``seconds_mc`` reaches ``mse_target`` (MSE ~ 1 / time)."""
    if mse_target <= 0:
        return math.inf
    return seconds_mc * mse_mc / mse_target


def _cache_key(scene: Scene, size: tuple[int, int], spp: int, chunk: int, seed: int) -> str:
    """The converged reference's cache key: the scene with its materials' file
    names (their contents are hashed, so the key does not depend on where the
    checkout lies), the image size, spp, pass and seed."""
    files = sorted({next(iter(s["material"].values())) for s in scene.spec["shapes"]
                    if "diffuse" not in s["material"]})
    shapes = [{**s, "material": {k: Path(v).name for k, v in s["material"].items()}}
              if "diffuse" not in s["material"] else s for s in scene.spec["shapes"]]
    blob = json.dumps({"spec": {**scene.spec, "shapes": shapes}, "size": size, "spp": spp, "chunk": chunk,
                       "seed": seed, "v": 2, "materials": [Path(f).read_text() for f in files]}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def converged_reference(scene: Scene, cfg: SceneReportConfig, progress=None) -> dict:
    """The Monte Carlo reference at ``cfg.ref_spp``: image, halves, its noise,
    from the cache when there (``cached`` says which)."""
    cache = cfg.cache or cfg.out / "cache"
    ref_scene = with_method(scene, "reference")
    seed = cfg.seed + 1000
    chunk = max(1, min(REF_CHUNK, cfg.ref_spp // 2))
    path = cache / f"{scene.name}-{cfg.size[0]}x{cfg.size[1]}-{_cache_key(ref_scene, cfg.size, cfg.ref_spp, chunk, seed)}.npz"
    if path.is_file():
        z = np.load(path)
        res = {k: z[k] for k in ("half_a", "half_b")}
        res.update(spp=int(z["spp"]), seconds=float(z["seconds"]), cached=True)
    else:
        r = render(ref_scene, cfg.size, cfg.ref_spp, seed=seed, chunk_spp=chunk, keep_chunks=True, progress=progress)
        if len(r.chunks) < 2:
            raise NbrdfError(f"--ref-spp {cfg.ref_spp}: the converged reference needs at least two chunks of {chunk}")
        n = len(r.chunks) // 2 * 2
        res = {"half_a": np.mean(r.chunks[0:n:2], 0), "half_b": np.mean(r.chunks[1:n:2], 0),
               "spp": n * chunk, "seconds": r.seconds, "cached": False}
        cache.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez_compressed(tmp, half_a=res["half_a"], half_b=res["half_b"], spp=res["spp"], seconds=res["seconds"])
        tmp.replace(path)
    res["image"] = (0.5 * (res["half_a"] + res["half_b"])).astype(np.float32)
    # the full average's noise variance: a quarter of the halves' squared difference
    res["noise_mse"] = mse(res["half_a"], res["half_b"]) / 4
    res["path"] = str(path)
    return res


def pass_spp(seconds_per_spp: float, cfg: SceneReportConfig) -> int:
    """Samples per pixel of a method's passes at its measured pace: ``cfg.chunk``
    doubled while a pass stays within ``cfg.max_chunk`` and ``PASS_SHARE`` of
    the budget. At 96 x 72 a pass of 16 spp is 110 k paths, and the wavefront
    mode's per-pass cost (kernel tracing and launches per bounce) is a large
    part of a fast method's pass; at the paper's 1024 x 1024 one spp is 1 M
    paths and it is negligible."""
    spp = cfg.chunk
    while spp * 2 <= cfg.max_chunk and spp * 2 * seconds_per_spp <= cfg.time_budget * PASS_SHARE:
        spp *= 2
    return spp


def equal_time(scenes: dict[str, Scene], cfg: SceneReportConfig, seeds: dict[str, int],
               log=print) -> dict[str, RenderResult]:
    """Renders of ``scenes`` (by key) at equal time: one untimed pass each
    (kernel compilation; its pace sizes the method's passes, ``pass_spp``),
    then passes in turn, always of the render with the least time spent,
    until each has spent ``cfg.time_budget`` and has two passes (so the times
    differ by at most a pass, and both renders share the machine's load)."""
    loaded = {k: load(sc, cfg.size, cfg.chunk) for k, sc in scenes.items()}
    sizes = {}
    for k, sc in scenes.items():
        w = render(sc, cfg.size, cfg.chunk, seed=seeds[k] + 777, chunk_spp=cfg.chunk, loaded=loaded[k],
                   exclude_compile=True)
        sizes[k] = pass_spp(w.seconds / w.spp, cfg) if w.seconds > 0 else cfg.chunk
    chunks: dict[str, list[np.ndarray]] = {k: [] for k in scenes}
    spent = {k: 0.0 for k in scenes}
    compiled = {k: 0.0 for k in scenes}
    while True:
        # at least two passes each: their halves give the render's own noise
        pending = [k for k in scenes if spent[k] < cfg.time_budget or len(chunks[k]) < 2]
        if not pending:
            break
        k = min(pending, key=spent.__getitem__)
        r = render(scenes[k], cfg.size, sizes[k], seed=seeds[k] * 10007 + len(chunks[k]), chunk_spp=sizes[k],
                   loaded=loaded[k], exclude_compile=True)
        chunks[k].append(r.image)
        spent[k] += r.seconds
        compiled[k] += r.compile_seconds
    log("  " + ", ".join(f"{k}: {len(c) * sizes[k]} spp in {spent[k]:.1f} s (passes of {sizes[k]})"
                         for k, c in chunks.items()))
    return {k: RenderResult(np.mean(c, 0).astype(np.float32), len(c) * sizes[k], spent[k], c, compiled[k])
            for k, c in chunks.items()}


def own_noise_mse(chunks: list[np.ndarray]) -> float:
    """The noise variance of a render's average, from its even and odd chunks
    (a quarter of the halves' squared difference); NaN with fewer than two."""
    n = len(chunks) // 2 * 2
    if n < 2:
        return math.nan
    return mse(np.mean(chunks[0:n:2], 0), np.mean(chunks[1:n:2], 0)) / 4


def score_scene(name: str, cfg: SceneReportConfig, log=print) -> tuple[dict, dict]:
    """One scene's row of the table and its images."""
    scene = load_scene(name)
    log(f"[{scene.name}] converged reference ({cfg.ref_spp} spp)")
    ref = converged_reference(scene, cfg)
    log(f"[{scene.name}] neural and Monte Carlo at {cfg.time_budget:g} s each, interleaved")
    methods = {"neural": with_method(scene, "neural", cfg.neural_body), "mc": with_method(scene, "reference")}
    res = equal_time(methods, cfg, {"neural": cfg.seed, "mc": cfg.seed + 2}, log)
    neural, mc = res["neural"], res["mc"]
    row: dict = {"scene": scene.name, "size": list(cfg.size), "neural_body": sorted(neural_bodies(methods["neural"])),
                 "mode": {k: "wavefront" if is_wavefront(sc) else "symbolic" for k, sc in methods.items()},
                 "reference": {"spp": ref["spp"], "seconds": round(ref["seconds"], 2), "cached": ref["cached"],
                               "noise_mse": ref["noise_mse"],
                               "half_flip": flip(ref["half_a"], ref["half_b"])[0]}}
    images = {"reference": ref["image"]}
    for key, r in (("neural", neural), ("mc", mc)):
        fl, fmap = flip(ref["image"], r.image)
        m = mse(ref["image"], r.image)
        row[key] = {"spp": r.spp, "seconds": round(r.seconds, 2), "seconds_per_spp": r.seconds / r.spp,
                    "compile_seconds_excluded": round(r.compile_seconds, 2), "pass_spp": r.spp // len(r.chunks),
                    "mse": m, "mse_minus_ref_noise": max(m - ref["noise_mse"], 0.0), "flip": fl,
                    "noise_mse": own_noise_mse(r.chunks)}
        # what is left of the error once both renders' noise is taken out: the bias (0 for the unbiased MC,
        # up to its own noise estimate's error)
        row[key]["bias_mse"] = max(m - ref["noise_mse"] - row[key]["noise_mse"], 0.0)
        images[key], images[f"err_{key}"], images[f"flip_{key}"] = r.image, np.mean((r.image - ref["image"]) ** 2, 2), fmap
    row["mse_ratio_mc_over_neural"] = row["mc"]["mse"] / max(row["neural"]["mse"], 1e-30)
    # against the true image: the reference's own noise (independent of both renders) taken out of both
    row["mse_ratio_mc_over_neural_ref_noise_removed"] = (row["mc"]["mse_minus_ref_noise"]
                                                         / max(row["neural"]["mse_minus_ref_noise"], 1e-30))
    for key in ("neural", "mc"):  # noise variance of one sample per pixel: what a method's spp buy
        row[key]["noise_per_spp"] = row[key]["noise_mse"] * row[key]["spp"]
    # the equal time is only as equal as a loaded machine allows: the MC's MSE moved to the neural's time by
    # MSE ~ 1/t (its noise part; the reference's noise stays)
    mc_at_t = row["mc"]["mse_minus_ref_noise"] * mc.seconds / neural.seconds + ref["noise_mse"]
    row["mse_ratio_mc_over_neural_time_matched"] = mc_at_t / max(row["neural"]["mse"], 1e-30)
    # the crossover: MC's noise-corrected MSE ~ 1/t reaching the neural's noise-corrected MSE
    mc_m, nn_m = row["mc"]["mse_minus_ref_noise"], row["neural"]["mse_minus_ref_noise"]
    row["crossover_seconds"] = crossover_seconds(mc_m, max(mc.seconds, 1e-9), nn_m)
    row["crossover_is_extrapolated"] = True
    return row, images


def markdown(result: dict) -> str:
    """The table beside the paper's."""
    w, h = result["config"]["size"]
    lines = [f"Equal-time MSE against the converged Monte Carlo reference ({w}x{h}, path tracer max depth 8; "
             "this machine). Paper (Table 3, 1024x1024, Mitsuba on a workstation): neural vs Guo et al.",
             "",
             "| scene | neural body (mode) | neural spp (pass) | MC spp (pass) | time/frame (s) | MSE neural | MSE MC | MC/neural (time-matched) | "
             "MC/neural, ref. noise removed | FLIP neural | "
             "FLIP MC | neural noise / bias MSE | MC noise / bias MSE | ref spp (noise MSE) | crossover (s, extrapolated) | "
             "paper neural / MC |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["scenes"]:
        p = PAPER_TABLE3.get(r["scene"])
        paper = f"{p[0]:.1e} / {p[1]:.1e} ({p[1] / p[0]:.1f}x)" if p else "-"
        cross = r["crossover_seconds"]
        lines.append(
            f"| {r['scene']} | {'+'.join(r.get('neural_body', ['decoder']))} ({r.get('mode', {}).get('neural', 'wavefront')}) "
            f"| {r['neural']['spp']} ({r['neural'].get('pass_spp', '-')}) | {r['mc']['spp']} "
            f"({r['mc'].get('pass_spp', '-')}) | {r['neural']['seconds']:.1f} / "
            f"{r['mc']['seconds']:.1f} | {r['neural']['mse']:.2e} | {r['mc']['mse']:.2e} | "
            f"{r['mse_ratio_mc_over_neural']:.2f}x ({r['mse_ratio_mc_over_neural_time_matched']:.2f}x) | "
            f"{r['mse_ratio_mc_over_neural_ref_noise_removed']:.2f}x | "
            f"{r['neural']['flip']:.3f} | {r['mc']['flip']:.3f} | "
            f"{r['neural']['noise_mse']:.1e} / {r['neural']['bias_mse']:.1e} | "
            f"{r['mc']['noise_mse']:.1e} / {r['mc']['bias_mse']:.1e} | "
            f"{r['reference']['spp']} ({r['reference']['noise_mse']:.1e}) | "
            f"{'never' if math.isinf(cross) else f'{cross:.0f}'} | {paper} |")
    lines += ["", "MSE ~ 1/time for the unbiased Monte Carlo: the crossover is the time at which it would reach the "
              "neural material's error (both corrected for the reference's own noise). An extrapolation. The MSE against "
              "the true image is the MSE against the reference less the reference's own noise (independent of both "
              "renders): the ratio of those is the column 'ref. noise removed'. Passes: each method's grow from "
              "--chunk while one takes at most 1/8 of the budget at its warm-up pace (same rule for both). Times: "
              "sampling only, the same path tracer, each method in its fastest Dr.Jit mode (column 'mode'; the Monte "
              "Carlo always wavefront: the walk needs it; a neural body read from a baked table renders symbolic, the "
              "decoder wavefront: its weights are per-lane gathers in a symbolic call on LLVM); the LLVM compilation "
              "of kernels not yet in Dr.Jit's cache is excluded from both (scenes.json: compile_seconds_excluded). "
              "Noise: each "
              "render's own, from its even and odd chunks; bias: the MSE left after both renders' noise (the neural "
              "material's representation error; about 0 for the Monte Carlo)."]
    return "\n".join(lines) + "\n"


def save_figure(rows: list[dict], images: list[dict], path: Path) -> None:
    """Per scene: converged reference, neural, MC at equal time, a 2x crop of
    each, and their per-pixel squared-error maps (shared scale per scene)."""
    plt = _plt()
    cols = ["reference", "neural", "mc", "crop reference", "crop neural", "crop mc", "err_neural", "err_mc"]
    fig, axes = plt.subplots(len(rows), len(cols), figsize=(1.7 * len(cols), 1.6 * len(rows) + 0.3), dpi=80,
                             squeeze=False)
    for i, (row, im) in enumerate(zip(rows, images)):
        h, w = im["reference"].shape[:2]
        # the crop: the quarter of the image where the two errors differ most
        diff = im["err_mc"] - im["err_neural"]
        ch, cw = h // 2, w // 2
        best, y0, x0 = -np.inf, 0, 0
        for y in range(0, h - ch + 1, max(1, h // 8)):
            for x in range(0, w - cw + 1, max(1, w // 8)):
                s = diff[y:y + ch, x:x + cw].sum()
                if s > best:
                    best, y0, x0 = s, y, x
        vmax = float(np.percentile(np.concatenate([im["err_neural"].ravel(), im["err_mc"].ravel()]), 99)) or 1.0
        for j, c in enumerate(cols):
            ax = axes[i, j]
            ax.set_xticks([])
            ax.set_yticks([])
            if c.startswith("err_"):
                ax.imshow(im[c], cmap="magma", vmin=0, vmax=vmax, interpolation="nearest")
                k = c[4:]
                ax.set_title(f"sq. err {k}: MSE {row[k]['mse']:.1e}\n(noise {row[k]['noise_mse']:.1e}, "
                             f"bias {row[k]['bias_mse']:.1e})", fontsize=6)
            else:
                key = c.split()[-1]
                img = im[key][y0:y0 + ch, x0:x0 + cw] if c.startswith("crop") else im[key]
                ax.imshow(tonemap(img), interpolation="nearest")
                label = {"reference": f"reference {row['reference']['spp']} spp",
                         "neural": f"neural {row['neural']['spp']} spp", "mc": f"MC {row['mc']['spp']} spp"}[key]
                ax.set_title(("crop " if c.startswith("crop") else "") + label, fontsize=7)
                if c == "reference":
                    ax.add_patch(plt.Rectangle((x0 - 0.5, y0 - 0.5), cw, ch, fill=False, ec="c", lw=0.8))
            if j == 0:
                ax.set_ylabel(row["scene"], fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def run_scene_report(cfg: SceneReportConfig, log=print) -> dict:
    """All scenes: scenes.json, scenes.md, the figure, and the images (.npy)."""
    cfg.out.mkdir(parents=True, exist_ok=True)
    rows, images = [], []
    for name in cfg.scenes:
        row, im = score_scene(name, cfg, log)
        rows.append(row)
        images.append(im)
        for k in ("reference", "neural", "mc"):
            np.save(cfg.out / f"{row['scene']}-{k}.npy", im[k])
    result = {"config": {"scenes": list(cfg.scenes), "size": list(cfg.size), "time_budget": cfg.time_budget,
                         "ref_spp": cfg.ref_spp, "chunk": cfg.chunk, "seed": cfg.seed, "neural_body": cfg.neural_body},
              "machine": {"platform": platform.platform(), "processor": platform.processor() or platform.machine()},
              "paper_table3": {k: {"neural": v[0], "mc": v[1]} for k, v in PAPER_TABLE3.items()},
              "scenes": rows}
    (cfg.out / "scenes.json").write_text(json.dumps(result, indent=2, default=float))
    (cfg.out / "scenes.md").write_text(markdown(result))
    save_figure(rows, images, cfg.figure or cfg.out / "scenes.png")
    return result
