"""``nbrdf report furnace`` (issue 40): directional albedo and reciprocity of the neural and refined paths
against the walk, on the furnace set (``training.furnace.furnace_set``): JSON, a table and a figure."""
from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from nbrdf.neural.material import material_to_dict
from nbrdf.neural.methods import Method
from nbrdf.training import furnace
from nbrdf.training.brdfs import brdf_for
from nbrdf.training.furnace import FURNACE_THETAS, Albedo
from nbrdf.training.plots import _plt
from nbrdf.training.reference import reference_eval

#: Methods the report can score against the reference.
FURNACE_METHODS = (Method.NEURAL, Method.CALIBRATED, Method.REFINED)


@dataclass
class FurnaceConfig:
    """What ``run_furnace_report`` measures and where it writes."""

    out: Path
    """folder for furnace.json, furnace.md and furnace.png"""
    methods: tuple[Method, ...] = FURNACE_METHODS
    """methods scored against the reference"""
    model: object = None
    """neural bundle (None: the shipped one)"""
    per_class: int = 10
    """lossless and absorbing stacks each"""
    samples: int = 1024
    """Sobol points per replicate of a sampled (neural, refined) albedo"""
    replicates: int = 8
    """independent scrambles of a sampled albedo (its standard error comes from them)"""
    ref_paths: int = 1 << 14
    """walk paths per incidence in the reference's first round"""
    ref_max_paths: int = 1 << 18
    """walk paths per incidence at most"""
    ref_target: float = 0.002
    """relative standard error the reference is refined to"""
    budget: float = 3.0
    """seconds of refinement per material (refined)"""
    pairs: int = 64
    """(wi, wo) pairs of the reciprocity figure"""
    pair_spp: int = 256
    """walk paths per pair and order of the reference's reciprocity"""
    seed: int = 0
    """seed of the estimators (the set has its own fixed seed)"""
    cache: Path | None = None
    """folder keeping each stack's reference (albedo and reciprocity values) by its material and settings, so
    bundles are compared on the same references (None: none kept)"""


def _rel(a: Albedo, ref: Albedo) -> np.ndarray:
    return np.abs(a.mean - ref.mean) / np.maximum(ref.mean, 1e-12)


def _cached(cfg: FurnaceConfig, what: str, material, compute: Callable[[], dict]) -> dict:
    """``compute()`` (a dict of lists), or what an earlier run with the same material and reference settings
    kept in ``cfg.cache``."""
    if cfg.cache is None:
        return compute()
    key = json.dumps([what, material_to_dict(material), FURNACE_THETAS, cfg.ref_paths, cfg.ref_max_paths,
                      cfg.ref_target, cfg.pairs, cfg.pair_spp, cfg.seed], sort_keys=True)
    path = Path(cfg.cache) / f"{material.name}-{what}-{hashlib.sha256(key.encode()).hexdigest()[:16]}.json"
    if path.is_file():
        return json.loads(path.read_text())
    out = compute()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(out))
    tmp.replace(path)
    return out


def _reference_albedo(m, cfg: FurnaceConfig) -> Albedo:
    def compute() -> dict:
        a = furnace.reference_albedo(m, FURNACE_THETAS, cfg.ref_paths, cfg.ref_max_paths, cfg.ref_target, cfg.seed)
        return {"mean": a.mean.tolist(), "se": a.se.tolist(), "samples": a.samples.tolist()}

    d = _cached(cfg, "albedo", m, compute)
    return Albedo(np.array(d["mean"]), np.array(d["se"]), np.array(d["samples"]))


def _reciprocity(material, brdfs: dict, cfg: FurnaceConfig) -> dict:
    """Median and p90 of the relative asymmetry per method over fixed pairs; the reference's is its noise, shown
    with the median that pure noise of its standard errors would give (0.674 sigma)."""
    wi, wo = furnace.reciprocity_pairs(cfg.pairs)

    def compute() -> dict:
        f1, e1 = reference_eval(material, wi, wo, spp=cfg.pair_spp, seed=cfg.seed * 2 + 1, dtype=torch.float64)
        f2, e2 = reference_eval(material, wo, wi, spp=cfg.pair_spp, seed=cfg.seed * 2 + 2, dtype=torch.float64)
        return {k: v.tolist() for k, v in (("f1", f1), ("e1", e1), ("f2", f2), ("e2", e2))}

    d = {k: torch.tensor(v, dtype=torch.float64) for k, v in _cached(cfg, "reciprocity", material, compute).items()}
    f1, e1, f2, e2 = d["f1"], d["e1"], d["f2"], d["e2"]
    mean = 0.5 * (f1 + f2).numpy().ravel()
    noise = 0.674 * np.sqrt((e1 * e1 + e2 * e2).numpy().ravel())
    out = {"reference": furnace.spread(furnace.asymmetry(f1.numpy(), f2.numpy())),
           "reference_noise_median": float(np.median(noise[mean > 1e-6] / mean[mean > 1e-6]))}
    for name, b in brdfs.items():
        with torch.no_grad():
            out[str(name)] = furnace.spread(furnace.asymmetry(b.eval(wi.float(), wo.float()).numpy(),
                                              b.eval(wo.float(), wi.float()).numpy()))
    return out


def _stack_row(cls: str, depth: int, m, cfg: FurnaceConfig, log: Callable[[str], None]) -> dict:
    """Every method's albedo at every incidence of one stack, and its reciprocity."""
    t0 = time.perf_counter()
    ref = _reference_albedo(m, cfg)
    brdfs = {k: brdf_for(m, k, model=cfg.model, budget=cfg.budget, seed=cfg.seed) for k in cfg.methods}
    alb = {Method.REFERENCE: ref}
    alb.update({k: furnace.sampled_albedo(b, FURNACE_THETAS, cfg.samples, cfg.replicates, cfg.seed) for k, b in brdfs.items()})
    row = {"name": m.name, "class": cls, "depth": depth, "layers": material_to_dict(m)["layers"],
           "albedo": {str(k): {"mean": a.mean.tolist(), "se": a.se.tolist(), "samples": a.samples.tolist()}
                      for k, a in alb.items()},
           "reciprocity": _reciprocity(m, brdfs, cfg)}
    row["rel_error"] = {str(k): _rel(alb[k], ref).tolist() for k in cfg.methods}
    log(f"{m.name}: {time.perf_counter() - t0:.0f} s, reference rel. se <= {float((ref.se / ref.mean).max()):.4f}")
    return row


def _group(rows: list[dict], method: str) -> dict:
    """Summary figures of one method over rows: max / median relative albedo error, max albedo, and how far
    the reference itself is from converged (its worst relative standard error)."""
    err = np.concatenate([np.ravel(r["rel_error"][method]) for r in rows])
    alb = np.concatenate([np.ravel(r["albedo"][method]["mean"]) for r in rows])
    ref = [(np.array(r["albedo"]["reference"]["se"]) / np.array(r["albedo"]["reference"]["mean"])).max() for r in rows]
    signed = np.concatenate([(np.array(r["albedo"][method]["mean"]) - np.array(r["albedo"]["reference"]["mean"]))
                             .ravel() / np.array(r["albedo"]["reference"]["mean"]).ravel() for r in rows])
    return {"stacks": len(rows), "max_rel_error": float(err.max()), "median_rel_error": float(np.median(err)),
            "mean_signed_rel_error": float(signed.mean()), "max_albedo": float(alb.max()),
            "above_one": int((alb > 1).sum()), "reference_max_rel_se": float(max(ref))}


def summary(rows: list[dict], methods: tuple[Method, ...]) -> dict:
    """Per method: the figures of ``_group`` over all stacks, lossless, absorbing and each depth."""
    out = {}
    for k in map(str, methods):
        groups = {"all": rows}
        for key in ("class", "depth"):
            for v in sorted({r[key] for r in rows}):
                groups[f"depth{v}" if key == "depth" else v] = [r for r in rows if r[key] == v]
        out[k] = {g: _group(rs, k) for g, rs in groups.items()}
        rec = [r["reciprocity"][k]["median"] for r in rows if r["reciprocity"][k]["median"] is not None]
        out[k]["reciprocity_median"] = float(np.median(rec)) if rec else None
    rec = [r["reciprocity"]["reference"]["median"] for r in rows if r["reciprocity"]["reference"]["median"]]
    out["reference_reciprocity_median"] = float(np.median(rec)) if rec else None
    out["reference_noise_median"] = float(np.median([r["reciprocity"]["reference_noise_median"] for r in rows]))
    return out


def table(result: dict) -> str:
    """A markdown table of the summary: one row per method and group."""
    lines = ["| method | group | stacks | max rel. error | median rel. error | mean signed | max albedo | "
             "reference max rel. se |", "|---|---|---|---|---|---|---|---|"]
    for k, groups in result["summary"].items():
        if not isinstance(groups, dict):
            continue
        for g, s in groups.items():
            if isinstance(s, dict):
                lines.append(f"| {k} | {g} | {s['stacks']} | {s['max_rel_error']:.2%} | {s['median_rel_error']:.2%} | "
                             f"{s['mean_signed_rel_error']:+.2%} | {s['max_albedo']:.4f} | "
                             f"{s['reference_max_rel_se']:.2%} |")
    s = result["summary"]
    recs = ", ".join(f"{k} {s[k]['reciprocity_median']:.2e}" for k in s if isinstance(s[k], dict))
    lines.append(f"\nreciprocity (median relative asymmetry over stacks): {recs}; reference "
                 f"{s['reference_reciprocity_median']:.2e} (its noise alone: {s['reference_noise_median']:.2e})")
    return "\n".join(lines)


def figure(rows: list[dict], path: Path) -> None:
    """One panel per stack: albedo (mean of the channels) vs theta_i, reference with a 2-sigma band."""
    plt = _plt()
    cols = 5
    fig, axes = plt.subplots((len(rows) + cols - 1) // cols, cols, figsize=(3 * cols, 2.4 * ((len(rows) + 4) // cols)),
                             squeeze=False)
    th = np.array(FURNACE_THETAS)
    for ax, r in zip(axes.ravel(), rows):
        for k, a in r["albedo"].items():
            m, se = np.array(a["mean"]).mean(1), np.sqrt((np.array(a["se"]) ** 2).mean(1) / 3)
            ax.plot(th, m, "k-" if k == "reference" else "-", label=k, lw=1.2)
            if k == "reference":
                ax.fill_between(th, m - 2 * se, m + 2 * se, color="0.7")
        ax.set_title(r["name"], fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[len(rows):]:
        ax.axis("off")
    axes.ravel()[0].legend(fontsize=7)
    fig.supxlabel("theta_i (degrees)")
    fig.supylabel("directional albedo (RGB mean)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def run_furnace_report(cfg: FurnaceConfig, log: Callable[[str], None] = print) -> dict:
    """Measures every stack of the furnace set, writes furnace.json / .md / .png under ``cfg.out``."""
    cfg.out.mkdir(parents=True, exist_ok=True)
    rows = [_stack_row(cls, d, m, cfg, log) for cls, d, m in furnace.furnace_set(cfg.per_class, furnace.FURNACE_SEED)]
    conf = {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items() if k != "model"}
    conf["methods"] = [str(k) for k in cfg.methods]
    result = {"config": conf, "thetas": list(FURNACE_THETAS), "summary": summary(rows, cfg.methods), "stacks": rows}
    (cfg.out / "furnace.json").write_text(json.dumps(result, indent=1))
    (cfg.out / "furnace.md").write_text(table(result) + "\n")
    figure(rows, cfg.out / "furnace.png")
    return result
