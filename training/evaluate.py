"""Held-out accuracy per SPEC section 9 (``nbrdf report representation``).

A held-out set is drawn with a fixed seed from the paper's distributions,
disjoint from training by its seed stream. For every material it caches
the converged reference lobes at the standard incidences (with standard
errors), the reference directional albedos, and the samples a projection
fits to; then any neural method is scored against them: lobe PSNR (median
and 10th percentile per class) and albedo error.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from safetensors.numpy import load_file, save_file
from tqdm import tqdm

from nbrdf.neural.geometry import cosine_hemisphere, incidence
from nbrdf.neural.latent_texture import blend
from nbrdf.neural.layer_kinds import CONDUCTOR, DIELECTRIC, DIFFUSE, MEDIUM
from nbrdf.neural.material import FORMAT as MATERIAL_FORMAT
from nbrdf.neural.material import Material, parse_material
from nbrdf.neural.methods import Method
from nbrdf.neural.metrics import THETAS, albedo_error, directional_albedo, is_converged, lobe_image, lobe_psnr
from nbrdf.neural.neural_brdf import latent_brdf
from nbrdf.training import distributions as D
from nbrdf.training.analytic import GGXConductor
from nbrdf.training.brdfs import brdf_for
from nbrdf.training.plots import _plt, save_lobe_comparison, save_lobe_grid
from nbrdf.training.project import Samples, fit, material_coat, material_samples
from nbrdf.training.reference import converged_lobe, reference_eval

Tensor = torch.Tensor
HELDOUT_SEED = 20_221_122  # never a training seed
CLASS_COUNTS = {"conductor": 20, "dielectric": 20, "two_layer": 50, "three_layer": 20, "three_layer_diffuse": 10}


def _u(g: np.random.Generator, n: int | None = None):
    return g.uniform(0, 1, n)


def heldout_material(cls: str, g: np.random.Generator, name: str) -> Material:
    """An RGB material of a class: colours drawn per channel, shared parameters once."""
    r6 = lambda x: float(round(x, 6))
    rough = lambda: r6(D.roughness(_u(g)))
    ior = lambda: r6(D.ior(_u(g)))
    alb = lambda: [r6(D.medium_albedo(x)) for x in _u(g, 3)]
    sig = lambda: r6(D.sigma_t(_u(g)))
    colour = lambda: [r6(D.colour(x)) for x in _u(g, 3)]
    diel = lambda: {"type": DIELECTRIC, "roughness": rough(), "ior": ior()}
    med = lambda: {"type": MEDIUM, "albedo": alb(), "sigma_t": sig()}
    cond = lambda: {"type": CONDUCTOR, "roughness": rough(), "r0": colour()}
    layers = {"conductor": lambda: [cond()], "dielectric": lambda: [diel()],
              "two_layer": lambda: [diel(), med(), cond()],
              "three_layer": lambda: [diel(), med(), diel(), med(), cond()],
              "three_layer_diffuse": lambda: [diel(), med(), diel(), med(),
                                              {"type": DIFFUSE, "albedo": colour()}],
              }[cls]()
    return parse_material({"format": MATERIAL_FORMAT, "name": name, "layers": layers})


def heldout_set(counts: dict[str, int] = CLASS_COUNTS, seed: int = HELDOUT_SEED) -> list[tuple[str, Material]]:
    out = []
    for k, (cls, n) in enumerate(counts.items()):
        g = np.random.default_rng([seed, k])
        out += [(cls, heldout_material(cls, g, f"{cls}-{i:03d}")) for i in range(n)]
    return out


DEPTH_SEED = 20_221_123  # never a training seed, not the held-out set's
DEPTHS = (2, 3, 4, 5, 6)
#: Depths whose coats come from the first stream (the set as it was first drawn); deeper coats have their own.
FIRST_DEPTHS = 4


def depth_set(per_depth: int = 8, seed: int = DEPTH_SEED) -> list[tuple[str, Material]]:
    """Stacks of 2 to 6 layers (1 to 5 coats, each an interface and a
    medium, over a conductor), ``per_depth`` of each, drawn from the paper's
    distributions: how the recursive layering's error grows with depth (each
    extra layer is one more call of the network on its own output). Classes
    ``depth2`` .. ``depth6``; the k-th stack of depth d+1 is the k-th of
    depth d with one more coat just above its base (same draws), so the
    depths differ by the extra layer only. The coats of depths 5 and 6 come
    from a second stream, so the stacks of 2 to 4 layers are those the set
    had before it grew (earlier figures stay comparable)."""
    g = np.random.default_rng([seed])
    deep = np.random.default_rng([seed, 1])
    r6 = lambda x: float(round(x, 6))
    out = []
    for i in range(per_depth):
        base = {"type": CONDUCTOR, "roughness": r6(D.roughness(_u(g))), "r0": [r6(D.colour(x)) for x in _u(g, 3)]}
        coats = [[{"type": DIELECTRIC, "roughness": r6(D.roughness(_u(g))), "ior": r6(D.ior(_u(g)))},
                  {"type": MEDIUM, "albedo": [r6(D.medium_albedo(x)) for x in _u(g, 3)],
                   "sigma_t": r6(D.sigma_t(_u(g)))}] for _ in range(FIRST_DEPTHS - 1)]
        coats += [[{"type": DIELECTRIC, "roughness": r6(D.roughness(_u(deep))), "ior": r6(D.ior(_u(deep)))},
                   {"type": MEDIUM, "albedo": [r6(D.medium_albedo(x)) for x in _u(deep, 3)],
                    "sigma_t": r6(D.sigma_t(_u(deep)))}] for _ in range(max(DEPTHS) - FIRST_DEPTHS)]
        for d in DEPTHS:
            layers = [x for c in coats[: d - 1] for x in c] + [base]
            out.append((f"depth{d}", parse_material({"format": MATERIAL_FORMAT, "name": f"depth{d}-{i:03d}",
                                                     "layers": layers})))
    return sorted(out, key=lambda x: x[0])


@dataclass
class Reference:
    """Cached reference of one held-out material."""

    lobes: np.ndarray  # (4, 64, 64, 3)
    lobe_stderr: np.ndarray  # (4, 64, 64, 3)
    albedo: np.ndarray  # (4, 3)
    wi: np.ndarray  # projection samples (n, 3)
    wo: np.ndarray
    f: np.ndarray  # (n, 3)


def make_reference(material: Material, noise_target: float = 48.0, max_spp: int = 256, seed: int = 0) -> Reference:
    """Lobes are refined until their noise PSNR reaches ``noise_target`` (10 dB
    above the strictest target, 38 dB) or ``max_spp`` paths per pixel."""
    lobes, ses, albs = [], [], []
    for k, th in enumerate(THETAS):
        img, se, _ = converged_lobe(material, th, target_noise_psnr=noise_target, start_spp=64, max_spp=max_spp,
                                    seed=seed + k)
        lobes.append(img)
        ses.append(se)
        albs.append(directional_albedo(lambda wi, wo: reference_eval(material, wi, wo, spp=16, seed=seed + 101 + k)[0],
                                       th))
    s = material_samples(material, n=2048, spp=64, seed=seed + 1)
    return Reference(np.stack(lobes), np.stack(ses), np.stack(albs).astype(np.float32), s.wi.numpy(), s.wo.numpy(),
                     s.f.numpy())


def build_references(folder: str | Path, progress: bool = True, limit: int = 0, noise_target: float = 48.0,
                     max_spp: int = 256, items: list[tuple[str, Material]] | None = None
                     ) -> list[tuple[str, Material, Reference]]:
    """Makes (or resumes) the cached references of the held-out set (or of
    ``items``, (class, material) pairs) in ``folder`` (the first ``limit``
    materials only, when given); ``noise_target`` and ``max_spp`` go to
    ``make_reference`` (60 dB needs a larger ``max_spp``)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    items = (heldout_set() if items is None else items)[: limit or None]
    for i, (cls, m) in enumerate(tqdm(items, desc="held-out references", unit="material", file=sys.stderr,
                                      disable=not progress or None)):
        path = folder / f"{m.name}.safetensors"
        if not path.exists():
            r = make_reference(m, noise_target=noise_target, max_spp=max_spp, seed=1000 * i)
            tmp = path.with_suffix(".tmp")
            save_file({k: np.ascontiguousarray(v, dtype=np.float32) for k, v in r.__dict__.items()}, str(tmp))
            tmp.replace(path)
        arrays = load_file(str(path))
        out.append((cls, m, Reference(**arrays)))
    return out


#: A method makes a material's value function from the material and its cached
#: reference: the ``eval`` of an ``RGBBRDF`` (``training.brdfs.brdf_for``).
MethodFn = Callable[[Material, Reference], Callable[[Tensor, Tensor], Tensor]]


def score(refs: list[tuple[str, Material, Reference]], method: MethodFn, progress: bool = True) -> dict:
    """Per-material lobe PSNR (mean over the 4 incidences) and albedo error,
    summarised per class."""
    rows = []
    for cls, m, r in tqdm(refs, desc="scoring", unit="material", file=sys.stderr, disable=not progress or None):
        fn = method(m, r)
        psnrs, errs, conv = [], [], []
        for k, th in enumerate(THETAS):
            img = lobe_image(fn, th)
            p = lobe_psnr(img, r.lobes[k])
            psnrs.append(p)
            conv.append(is_converged(r.lobes[k], r.lobe_stderr[k], p))
            a = directional_albedo(fn, th)
            errs.append(albedo_error(a, r.albedo[k]))
        rows.append({"class": cls, "name": m.name, "psnr": psnrs, "albedo_error": np.concatenate(errs).tolist(),
                     "converged": all(conv)})
    return {"rows": rows, "summary": summarise(rows)}


def summarise(rows: list[dict]) -> dict:
    """Per class (the held-out classes first, then any other in order of
    appearance) and over all rows: lobe PSNR median / p10, albedo error."""
    out = {}
    seen = list(dict.fromkeys(r["class"] for r in rows))
    for cls in [c for c in CLASS_COUNTS if c in seen] + [c for c in seen if c not in CLASS_COUNTS] + ["all"]:
        sel = [r for r in rows if cls == "all" or r["class"] == cls]
        if not sel:
            continue
        ps = np.array([p for r in sel for p in r["psnr"]])
        ae = np.array([e for r in sel for e in r["albedo_error"]])
        out[cls] = {"materials": len(sel), "psnr_median": float(np.median(ps)),
                    "psnr_p10": float(np.percentile(ps, 10)), "albedo_error_median": float(np.median(ae)),
                    "albedo_error_p90": float(np.percentile(ae, 90)),
                    "references_converged": f"{sum(r['converged'] for r in sel)}/{len(sel)}"}
    return out


def projected_method(dec) -> MethodFn:
    """The decoder at latents fitted to the cached projection samples."""

    def make(m: Material, r: Reference):
        z = fit(dec, Samples(torch.from_numpy(r.wi), torch.from_numpy(r.wo), torch.from_numpy(r.f),
                             coat=material_coat(m)))
        return latent_brdf(dec, z, m).eval

    return make


def report_figures(refs: list[tuple[str, Material, Reference]], method: MethodFn, result: dict, out: Path,
                   per_class: int = 2) -> None:
    """Reference vs neural lobes (theta_i 30) with difference maps, a few per
    class, and PSNR histograms per class."""
    rows = []
    for cls in CLASS_COUNTS:
        picked = [(c, m, r) for c, m, r in refs if c == cls][:per_class]
        for _c, m, r in picked:
            row = next(x for x in result["rows"] if x["name"] == m.name)
            img = lobe_image(method(m, r), THETAS[1])
            rows.append((f"{m.name} {row['psnr'][1]:.1f} dB", r.lobes[1], img))
    if rows:
        save_lobe_comparison(rows, out / "lobes.png")
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 3.5), dpi=100)
    for cls in CLASS_COUNTS:
        ps = [p for x in result["rows"] if x["class"] == cls for p in x["psnr"]]
        if ps:
            ax.hist(ps, bins=30, alpha=0.5, label=cls)
    ax.set_xlabel("lobe PSNR (dB)")
    ax.set_ylabel("lobes")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "psnr_hist.png")
    plt.close(fig)


# --- the operations: the full neural path against its baselines ---------------------------
def neural_method(model) -> MethodFn:
    """Leaf encoders -> recursive layering -> decoder (nothing fitted)."""
    return lambda m, r: brdf_for(m, Method.NEURAL, model=model).eval


def analytic_method() -> MethodFn:
    """The analytic layering baseline (``training.analytic_layering``)."""
    return lambda m, r: brdf_for(m, Method.ANALYTIC).eval


def comparison_table(results: dict[Method, dict]) -> str:
    """Markdown: one row per class, median / p10 PSNR and median albedo error per method."""
    methods = list(results)
    classes = list(dict.fromkeys(c for r in results.values() for c in r["summary"]))
    head = "| class | " + " | ".join(f"{m}: PSNR median / p10 (dB), albedo err" for m in methods) + " |"
    lines = [head, "|---" * (len(methods) + 1) + "|"]
    for c in classes:
        cells = []
        for m in methods:
            s = results[m]["summary"].get(c)
            cells.append("n/a" if s is None else
                         f"{s['psnr_median']:.1f} / {s['psnr_p10']:.1f}, {100 * s['albedo_error_median']:.1f} %")
        n = next(r["summary"][c]["materials"] for r in results.values() if c in r["summary"])
        lines.append(f"| {c} ({n}) | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def comparison_figure(refs: list[tuple[str, Material, Reference]], methods: dict[Method, MethodFn],
                      path: Path) -> None:
    """One row per material: its reference lobe (theta_i 30) and each method's; no rows, no figure."""
    rows = [(m.name, [r.lobes[1]] + [lobe_image(fn(m, r), THETAS[1]) for fn in methods.values()])
            for _c, m, r in refs]
    if rows:
        save_lobe_grid(rows, ["reference"] + list(methods), path)


def glossy_stacks(refs: list[tuple[str, Material, Reference]], max_roughness: float = 0.1):
    """Held-out stacks whose top interface is glossy (roughness below ``max_roughness``)."""
    return [(c, m, r) for c, m, r in refs
            if m.interfaces and float(m.interfaces[0][0].roughness) < max_roughness]


def sampling_variance(model, material: Material, n: int = 8192, seed: int = 0) -> dict[str, float]:
    """Variance of the directional-albedo estimator f cos / pdf of the neural
    BRDF (channel mean), averaged over the standard incidences, for its own
    sampler (the coat's visible normals mixed with the learned proxy, key
    "proxy"), cosine sampling, and sampling the top interface's GGX lobe."""
    z = model.material_latent(material)
    brdf = latent_brdf(model.decoder, z, material, model.sampler)
    top = float(material.interfaces[0][0].roughness) if material.interfaces else 0.3
    g = torch.Generator().manual_seed(seed)
    out = {"proxy": 0.0, "cosine": 0.0, "top_ggx": 0.0}
    for th in THETAS:
        wi = incidence(th).expand(n, 3).contiguous()
        u = torch.rand(n, 3, generator=g)
        sp = brdf.sample(wi, u)
        wo_p, pdf_p = sp.w, sp.pdf
        wo_c = cosine_hemisphere(u[:, 1], u[:, 2])
        pdf_c = wo_c[:, 2] / math.pi
        s = GGXConductor(top, 1.0).sample(wi, u)
        for name, wo, pdf in (("proxy", wo_p, pdf_p), ("cosine", wo_c, pdf_c), ("top_ggx", s.w, s.pdf)):
            ok = (wo[:, 2] > 0) & (pdf > 0)
            with torch.no_grad():
                f = model.decoder.eval_rgb(z, wi, torch.where(ok[:, None], wo, wi)).mean(-1)
            est = torch.where(ok, f * wo[:, 2] / torch.where(ok, pdf, torch.ones_like(pdf)), torch.zeros_like(f))
            out[name] += float(est.var()) / len(THETAS)
    return out


def interpolation_figure(model, smooth: Material, rough: Material, path: Path, steps: int = 5,
                         theta_i: float = 30.0) -> dict:
    """The paper's interpolation figure: lobes of the latent blend (1 - t) z_a
    + t z_b against the linear blend of the two BRDFs' values, for t from 0 to 1.
    Returns the lobe peak values per row (a latent blend moves the highlight's
    width; a value blend stacks two highlights)."""
    za, zb = model.material_latent(smooth), model.material_latent(rough)
    dec = model.decoder
    ts = [k / (steps - 1) for k in range(steps)]

    def lobe_of(z: Tensor) -> np.ndarray:
        return lobe_image(lambda wi, wo: dec.eval_rgb(z, wi.float(), wo.float()).detach(), theta_i)

    la, lb = lobe_of(za), lobe_of(zb)
    latent_row = [lobe_of(blend([za, zb], [1 - t, t])) for t in ts]
    linear_row = [(1 - t) * la + t * lb for t in ts]
    save_lobe_grid([("latent blend", latent_row), ("linear blend of values", linear_row)],
                   [f"t = {t:.2f}" for t in ts], path)
    return {"t": ts, "latent_peak": [float(x.max()) for x in latent_row],
            "linear_peak": [float(x.max()) for x in linear_row]}
