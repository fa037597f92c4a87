"""The ``nbrdf`` command line (SPEC section 8).

Each subcommand parses its arguments, calls the library, and writes files.
Bad input of any kind ends with one line on stderr and exit status 2; an
internal failure ends with one line and exit status 1 (``NBRDF_DEBUG=1``
shows the traceback).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from nbrdf.neural.errors import NbrdfError

PROG = "nbrdf"
METHODS = ("reference", "neural", "projected")


class _Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line and exit status 2."""

    def error(self, message: str):  # type: ignore[override]
        raise NbrdfError(f"{self.prog}: {message}")


def run_guarded(prog: str, fn: Callable[[], int]) -> int:
    """Runs ``fn``; turns bad input into one line + exit 2, a crash into one line + exit 1."""
    try:
        return fn()
    except NbrdfError as e:
        print(f"{prog}: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # noqa: BLE001 - the last line of defence
        if os.environ.get("NBRDF_DEBUG"):
            raise
        print(f"{prog}: internal error: {type(e).__name__}: {e} (set NBRDF_DEBUG=1 for details)", file=sys.stderr)
        return 1


# --- input helpers ----------------------------------------------------------------
def load_pairs(path: str) -> tuple["np.ndarray", "np.ndarray"]:
    """(wi, wo) float32 (N, 3) each from an (N, 6) .npy, checked."""
    p = Path(path)
    if not p.is_file():
        raise NbrdfError(f"{path}: no such file")
    try:
        arr = np.load(p, allow_pickle=False)
    except Exception as e:  # noqa: BLE001 - any unreadable file is bad input
        raise NbrdfError(f"{path}: not a readable .npy file ({e})") from None
    if arr.ndim != 2 or arr.shape[1] != 6:
        raise NbrdfError(f"{path}: expected an (N, 6) array of wi.xyz, wo.xyz, got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.floating):
        raise NbrdfError(f"{path}: expected float32 values, got {arr.dtype}")
    arr = arr.astype(np.float32)
    bad = ~np.isfinite(arr).all(1)
    if bad.any():
        raise NbrdfError(f"{path}: row {int(np.argmax(bad))} holds a NaN or infinite value")
    for name, sl in (("wi", slice(0, 3)), ("wo", slice(3, 6))):
        n = np.linalg.norm(arr[:, sl], axis=1)
        off = np.abs(n - 1) > 1e-3
        if off.any():
            i = int(np.argmax(off))
            raise NbrdfError(f"{path}: row {i}: {name} is not a unit vector (length {n[i]:.4g})")
    return arr[:, :3], arr[:, 3:]


def out_path(path: str, suffixes: Sequence[str]) -> Path:
    p = Path(path)
    if p.suffix.lower() not in suffixes:
        raise NbrdfError(f"{path}: the output must end in {' or '.join(suffixes)}")
    if p.parent and not p.parent.exists():
        raise NbrdfError(f"{path}: the folder {p.parent} does not exist")
    return p


def stderr_path(p: Path) -> Path:
    """F.npy -> F.stderr.npy"""
    return p.with_name(p.stem + ".stderr" + p.suffix)


def _progress(total: int, desc: str):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="pair", disable=None, leave=False, file=sys.stderr)


# --- evaluation back ends ------------------------------------------------------------
def make_evaluator(material, method: str, spp: int, seed: int, want_stderr: bool = False):
    """fn(wi, wo) -> (f (N,3), stderr (N,3) or None) for a method of SPEC section 8."""
    import torch

    if method == "reference":
        from nbrdf.training.reference import reference_eval

        def ref(wi: torch.Tensor, wo: torch.Tensor):
            with _progress(wi.shape[0], "reference") as bar:
                return reference_eval(material, wi, wo, spp=spp, seed=seed, progress=bar.update)

        return ref
    if method == "neural":
        from nbrdf.neural.model import neural_evaluator

        fn = neural_evaluator(material)
        return lambda wi, wo: (fn(wi, wo), None)
    if method == "projected":
        from nbrdf.training.project import projected_evaluator

        fn = projected_evaluator(material, seed=seed)
        return lambda wi, wo: (fn(wi, wo), None)
    raise NbrdfError(f"unknown method {method!r}")


def _model(a: argparse.Namespace):
    """The bundle of ``--model``, or the shipped one."""
    from nbrdf.neural.model import default_model, load_model

    return load_model(a.model) if a.model else default_model()


def _load_material(path: str):
    from nbrdf.neural.material import load_material

    return load_material(path)


# --- subcommands -----------------------------------------------------------------------
def cmd_eval(a: argparse.Namespace) -> int:
    import torch

    material = _load_material(a.material)
    wi, wo = load_pairs(a.pairs)
    out = out_path(a.out, (".npy",))
    fn = _guard_method(material, a.method, a.spp, a.seed)
    f, se = fn(torch.from_numpy(wi), torch.from_numpy(wo))
    np.save(out, f.detach().numpy().astype(np.float32))
    if a.method == "reference":
        np.save(stderr_path(out), se.detach().numpy().astype(np.float32))
    return 0


def cmd_lobe(a: argparse.Namespace) -> int:
    import torch

    from nbrdf.neural.metrics import lobe_image

    material = _load_material(a.material)
    out = out_path(a.out, (".npy", ".png"))
    if not (0.0 <= a.theta_i < 90.0):
        raise NbrdfError(f"--theta-i: {a.theta_i} is outside [0, 90)")
    fn = _guard_method(material, a.method, a.spp, a.seed)
    errs: list = []

    def values(wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
        f, se = fn(wi, wo)
        errs.append(se)
        return f

    img = lobe_image(values, a.theta_i)
    npy = out.with_suffix(".npy") if out.suffix.lower() == ".png" else out
    np.save(npy, img)
    if a.method == "reference" and errs[0] is not None:
        se_img = lobe_image(lambda wi, wo: errs[0] / wo[:, 2:3].clamp_min(1e-12), a.theta_i)
        np.save(stderr_path(npy), se_img)
    if out.suffix.lower() == ".png":
        from nbrdf.training.plots import save_lobe_png

        save_lobe_png(img, out, title=f"{material.name}  theta_i={a.theta_i:g}  ({a.method})")
    return 0


def _guard_method(material, method: str, spp: int, seed: int):
    if spp < 1:
        raise NbrdfError(f"--spp: {spp} must be at least 1")
    try:
        return make_evaluator(material, method, spp, seed)
    except ModuleNotFoundError as e:
        if e.name and e.name.split(".")[0] in ("neural", "training"):
            raise NbrdfError(f"--method {method}: not available in this version ({e.name} is missing)") from None
        raise


def cmd_bench_reference(a: argparse.Namespace) -> int:
    from nbrdf.training.bench import bench_reference

    print(json.dumps(bench_reference(quick=a.quick), indent=2))
    return 0


def cmd_data(a: argparse.Namespace) -> int:
    from dataclasses import replace

    from nbrdf.training.dataset import PRESETS, generate

    if a.preset not in PRESETS:
        raise NbrdfError(f"--preset: {a.preset!r} is not one of {', '.join(PRESETS)}")
    cfg = PRESETS[a.preset]
    if a.seed is not None:
        cfg = replace(cfg, seed=a.seed)
    man = generate(a.out, cfg, preset=a.preset, overwrite=a.overwrite)
    print(f"data set ready: {man}")
    return 0


def cmd_train_representation(a: argparse.Namespace) -> int:
    from nbrdf.neural.decoder import DecoderSpec
    from nbrdf.training.train_representation import TrainConfig, train

    spec = DecoderSpec(width=a.width, depth=a.depth, activation=a.activation, loss_scale=a.loss_scale)
    for name in ("epochs", "batch"):
        if getattr(a, name) < 1:
            raise NbrdfError(f"--{name}: must be at least 1")
    cfg = TrainConfig(data=a.data, out=a.out, spec=spec, epochs=a.epochs, batch=a.batch, lr=a.lr,
                      seed=a.seed, device=a.device)
    if a.loss_scale <= 0:
        raise NbrdfError(f"--loss-scale: {a.loss_scale} must be positive")
    bundle = train(cfg, stop_after=a.stop_after)
    print(f"decoder written: {bundle}" if bundle else f"stopped after {a.stop_after} epochs; run the same command to resume")
    return 0


def cmd_train_operation(a: argparse.Namespace) -> int:
    from nbrdf.neural.decoder import DEFAULT_WEIGHTS
    from nbrdf.training import train_operations as to

    for name in ("steps", "batch", "pairs"):
        if getattr(a, name) < 1:
            raise NbrdfError(f"--{name}: must be at least 1")
    cfg = to.OpsConfig(decoder=a.decoder or str(DEFAULT_WEIGHTS), out=a.out, steps=a.steps, batch=a.batch,
                       pairs=a.pairs, lr=a.lr, seed=a.seed, data=getattr(a, "data", None),
                       recursion_steps=getattr(a, "recursion_steps", 0), width=getattr(a, "width", 0))
    train = {"leaf": to.train_leaf, "layering": to.train_layering, "sampler": to.train_sampler}[a.what]
    print(f"bundle written: {train(cfg)}")
    return 0


def cmd_project(a: argparse.Namespace) -> int:
    from nbrdf.neural.decoder import default_decoder, load_decoder, save_decoder
    from nbrdf.neural.latent import save_latent
    from nbrdf.neural.projection import ProjectionConfig
    from nbrdf.training import project as pj

    out = out_path(a.out, (".safetensors",))
    given = [x for x in (a.material, a.samples, a.merl) if x]
    if len(given) != 1:
        raise NbrdfError("give exactly one of --material, --samples, --merl")
    if a.steps < 1:
        raise NbrdfError(f"--steps: {a.steps} must be at least 1")
    dec = load_decoder(a.decoder) if a.decoder else default_decoder()
    if a.material:
        s = pj.material_samples(_load_material(a.material), n=a.pairs, spp=a.spp, seed=a.seed)
        source = {"material": str(a.material), "spp": a.spp, "pairs": a.pairs}
    elif a.samples:
        s = pj.npy_samples(a.samples)
        source = {"samples": str(a.samples)}
    else:
        s = pj.merl_samples(a.merl, n=a.pairs, seed=a.seed)
        source = {"merl": str(a.merl), "pairs": a.pairs}
    if a.finetune and not a.merl:
        raise NbrdfError("--finetune: only for measured (--merl) files")
    lat, secs = pj.project_to_latent(dec, s, source, ProjectionConfig(steps=a.steps, seed=a.seed))
    report = {"out": str(out), "decoder_id": lat.decoder_id, "sample_seconds": round(s.seconds, 3),
              "projection_seconds": round(secs, 3)}
    if a.finetune:
        t0 = time.perf_counter()
        tuned, z = pj.finetune(dec, s, lat.z)
        dec_path = out.with_name(out.stem + ".decoder.safetensors")
        lat.decoder_id = save_decoder(tuned, dec_path, trained_on={"finetuned_from": dec.weights_id(),
                                                                   "merl": str(a.merl)})
        lat.z = z
        lat.source["finetuned_decoder"] = dec_path.name
        report.update(finetune_seconds=round(time.perf_counter() - t0, 3), decoder=str(dec_path),
                      decoder_id=lat.decoder_id)
    save_latent(out, lat)
    print(json.dumps(report))
    return 0


def cmd_report_representation(a: argparse.Namespace) -> int:
    from nbrdf.neural.decoder import default_decoder, load_decoder
    from nbrdf.training.evaluate import build_references, projected_method, report_figures, score

    dec = load_decoder(a.decoder) if a.decoder else default_decoder()
    refs = build_references(a.refs, limit=a.limit)
    result = score(refs, projected_method(dec))
    result["decoder_id"] = dec.weights_id()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "representation.json").write_text(json.dumps(result, indent=1))
    report_figures(refs, projected_method(dec), result, out)
    if a.record:
        from nbrdf.neural.decoder import DEFAULT_WEIGHTS, record_accuracy

        record_accuracy(a.decoder or DEFAULT_WEIGHTS, {"heldout_projected": result["summary"]})
    print(json.dumps(result["summary"], indent=1))
    return 0


def cmd_report_operations(a: argparse.Namespace) -> int:
    from nbrdf.training import evaluate as ev
    from nbrdf.training.plots import save_lobe_grid

    model = _model(a)
    refs = ev.build_references(a.refs, limit=a.limit)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    methods = {"neural": ev.neural_method(model), "projected": ev.projected_method(model.decoder),
               "analytic": ev.analytic_method()}
    stacks = [x for x in refs if x[1].interfaces]  # single layers: the analytic model is the reference itself
    results = {name: ev.score(stacks if name == "analytic" else refs, m) for name, m in methods.items()}
    glossy = ev.glossy_stacks(refs)
    variances = [dict(name=m.name, **ev.sampling_variance(model, m, seed=i)) for i, (_, m, _) in enumerate(glossy)]
    ratio = lambda k: float(np.median([v[k] / max(v["proxy"], 1e-30) for v in variances])) if variances else None
    sampling = {"glossy_stacks": len(variances), "median_variance_reduction_vs_cosine": ratio("cosine"),
                "median_variance_reduction_vs_top_ggx": ratio("top_ggx"), "per_material": variances}
    report = {"summary": {k: r["summary"] for k, r in results.items()}, "sampling": sampling,
              "rows": {k: r["rows"] for k, r in results.items()}}
    (out / "operations.json").write_text(json.dumps(report, indent=1))
    (out / "operations.md").write_text(ev.comparison_table(results) + "\n")
    from nbrdf.neural.metrics import lobe_image

    shown = [(c, m, r) for c, m, r in refs if c in ("two_layer", "three_layer")][:: max(1, a.every)][:6]
    rows = []
    for c, m, r in shown:
        imgs = [r.lobes[1]] + [lobe_image(fn(m, r), ev.THETAS[1]) for fn in methods.values()]
        rows.append((m.name, imgs))
    if rows:
        save_lobe_grid(rows, ["reference"] + list(methods), out / "operations_lobes.png")
    print(ev.comparison_table(results))
    print(json.dumps({k: v for k, v in sampling.items() if k != "per_material"}))
    return 0


def cmd_report_interpolation(a: argparse.Namespace) -> int:
    from nbrdf.training.evaluate import interpolation_figure

    model = _model(a)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    res = interpolation_figure(model, _load_material(a.a), _load_material(a.b), out)
    print(json.dumps(res))
    return 0


def cmd_sample(a: argparse.Namespace) -> int:
    import torch

    from nbrdf.neural.geometry import incidence
    from nbrdf.neural.sampling import proxy_sample

    if a.n < 1:
        raise NbrdfError(f"--n: {a.n} must be at least 1")
    if not 0 <= a.theta_i < 90:
        raise NbrdfError(f"--theta-i: {a.theta_i} must lie in [0, 90)")
    model = _model(a)
    z = model.material_latent(_load_material(a.material))
    sigma, w = model.proxy(z)
    wi = incidence(a.theta_i).expand(a.n, 3).contiguous()
    u = torch.rand(a.n, 3, generator=torch.Generator().manual_seed(a.seed))
    wo, pdf = proxy_sample(wi, u, sigma, w)
    pdf = torch.where(wo[:, 2] > 0, pdf, torch.zeros_like(pdf))  # below the horizon: a failed sample
    np.save(out_path(a.out, (".npy",)), torch.cat([wo, pdf[:, None]], 1).numpy().astype(np.float32))
    print(json.dumps({"sigma": sigma, "w": w, "failed": int((pdf == 0).sum())}))
    return 0


def cmd_bench_operations(a: argparse.Namespace) -> int:
    from nbrdf.neural.bench import bench_operations

    print(json.dumps(bench_operations(_model(a), a.repeats), indent=2))
    return 0


def cmd_bench_app(a: argparse.Namespace) -> int:
    from nbrdf.viewer.bench import bench_app
    from nbrdf.viewer.view_cli import _size, has_display

    if not has_display():
        raise NbrdfError("bench app: no display (run it under xvfb-run on a headless machine)")
    if a.edits < 1:
        raise NbrdfError(f"--edits: {a.edits} must be at least 1")
    print(json.dumps(bench_app(_size(a.size), a.edits), indent=2))
    return 0


def cmd_bench_render(a: argparse.Namespace) -> int:
    from nbrdf.viewer.bench import bench_render
    from nbrdf.viewer.view_cli import _size

    print(json.dumps(bench_render(_size(a.size), repeats=a.repeats), indent=2))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog=PROG, description="Neural layered BRDFs: ground truth, representation, operations.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    e = sub.add_parser("eval", help="evaluate a material's BRDF on direction pairs")
    e.add_argument("--material", required=True, help="material JSON (SPEC section 4)")
    e.add_argument("--pairs", required=True, help="float32 (N, 6) .npy: wi.xyz, wo.xyz in the local frame")
    e.add_argument("--out", required=True, help="float32 (N, 3) .npy of RGB BRDF values (no cosine)")
    e.add_argument("--method", choices=METHODS, default="reference")
    e.add_argument("--spp", type=int, default=256, help="Monte Carlo paths per pair (reference of a stack)")
    e.add_argument("--seed", type=int, default=0)
    e.set_defaults(fn=cmd_eval)

    lo = sub.add_parser("lobe", help="the standard 64x64 lobe image (SPEC section 9)")
    lo.add_argument("--material", required=True)
    lo.add_argument("--theta-i", type=float, required=True, help="incidence angle in degrees (phi_i = 0)")
    lo.add_argument("--method", choices=METHODS, default="reference")
    lo.add_argument("--out", required=True, help=".npy (the array) or .png (a picture, plus the .npy beside it)")
    lo.add_argument("--spp", type=int, default=1024)
    lo.add_argument("--seed", type=int, default=0)
    lo.set_defaults(fn=cmd_lobe)

    d = sub.add_parser("data", help="generate a training / validation data set (sharded, resumable)")
    d.add_argument("--preset", default="tiny", help="tiny (seconds), cpu (the shipped decoder), layering (stacks for the layering network), paper")
    d.add_argument("--out", required=True, help="folder for the shards and manifest.json")
    d.add_argument("--seed", type=int, default=None)
    d.add_argument("--overwrite", action="store_true", help="replace a data set made with other settings")
    d.set_defaults(fn=cmd_data)

    t = sub.add_parser("train", help="train networks")
    tsub = t.add_subparsers(dest="what", required=True, parser_class=_Parser)
    tr = tsub.add_parser("representation", help="auto-decoder: the shared decoder and training latents")
    tr.add_argument("--data", required=True, help="a folder made by `nbrdf data`")
    tr.add_argument("--out", required=True, help="run folder (checkpoint, decoder.safetensors, curves.png)")
    tr.add_argument("--epochs", type=int, default=40)
    tr.add_argument("--batch", type=int, default=8192)
    tr.add_argument("--lr", type=float, default=2e-3)
    tr.add_argument("--width", type=int, default=64)
    tr.add_argument("--depth", type=int, default=3)
    tr.add_argument("--activation", default="relu", choices=("relu", "silu"))
    tr.add_argument("--loss-scale", type=float, default=0.01, help="s in the loss log(1 + f cos / s)")
    tr.add_argument("--stop-after", type=int, default=None, help="end this run after N epochs (resume later)")
    tr.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"))
    tr.add_argument("--seed", type=int, default=0)
    tr.set_defaults(fn=cmd_train_representation)
    ops = {"leaf": ("leaf encoders, through the frozen decoder against closed-form layers", 6000, 32, 128, 2e-3),
           "layering": ("layering network, through the decoder against Monte Carlo stacks", 5000, 48, 192, 1e-3),
           "sampler": ("proxy-pdf network, by KL divergence to decoded lobes", 3000, 64, 256, 3e-3)}
    for what, (help_, steps, batch, pairs, lr) in ops.items():
        to = tsub.add_parser(what, help=help_)
        to.add_argument("--decoder", help="bundle to build on (default: the shipped weights); a network of the "
                                          "same shape already in it is fine-tuned")
        to.add_argument("--out", required=True, help="run folder (checkpoint, curves, model.safetensors)")
        to.add_argument("--steps", type=int, default=steps)
        to.add_argument("--batch", type=int, default=batch, help="BRDFs per step")
        to.add_argument("--pairs", type=int, default=pairs, help="direction pairs per BRDF per step")
        to.add_argument("--lr", type=float, default=lr)
        to.add_argument("--seed", type=int, default=0)
        if what == "layering":
            to.add_argument("--data", required=True, help="a folder made by `nbrdf data --preset layering`")
            to.add_argument("--recursion-steps", type=int, default=2000,
                            help="final steps that mix in three-layer stacks (recursive layering)")
            to.add_argument("--width", type=int, default=256)
        to.set_defaults(fn=cmd_train_operation)

    pr = sub.add_parser("project", help="fit a latent (3 x 32) to a material, samples or a MERL table")
    pr.add_argument("--material", help="material JSON (fitted through its reference)")
    pr.add_argument("--samples", help="float (N, 9) .npy: wi.xyz, wo.xyz, f.rgb")
    pr.add_argument("--merl", help="MERL .binary file")
    pr.add_argument("--out", required=True, help="latent .safetensors")
    pr.add_argument("--decoder", help="decoder weights (default: the shipped ones)")
    pr.add_argument("--finetune", action="store_true", help="measured files: also adapt a copy of the decoder")
    pr.add_argument("--pairs", type=int, default=2048, help="samples drawn from the material or table")
    pr.add_argument("--spp", type=int, default=64, help="Monte Carlo paths per pair for a stack's reference")
    pr.add_argument("--steps", type=int, default=200)
    pr.add_argument("--seed", type=int, default=0)
    pr.set_defaults(fn=cmd_project)

    rp = sub.add_parser("report", help="accuracy on the held-out sets (SPEC section 9)")
    rsub = rp.add_subparsers(dest="what", required=True, parser_class=_Parser)
    rr = rsub.add_parser("representation", help="projected latents vs converged references")
    rr.add_argument("--refs", required=True, help="cache folder of held-out references (made on first use)")
    rr.add_argument("--decoder", help="decoder weights (default: the shipped ones)")
    rr.add_argument("--out", required=True, help="folder for representation.json and the figures")
    rr.add_argument("--limit", type=int, default=0, help="score only the first N materials (quick looks)")
    rr.add_argument("--record", action="store_true", help="write the summary into the decoder file's metadata")
    rr.set_defaults(fn=cmd_report_representation)

    ro = rsub.add_parser("operations", help="full neural path vs projection vs analytic layering; sampling variance")
    ro.add_argument("--refs", required=True, help="cache folder of held-out references (made on first use)")
    ro.add_argument("--out", required=True, help="folder for operations.json / .md and figures")
    ro.add_argument("--model", help="bundle (default: the shipped weights)")
    ro.add_argument("--limit", type=int, default=0, help="score only the first N held-out materials")
    ro.add_argument("--every", type=int, default=7, help="show every N-th stack in the lobe figure")
    ro.set_defaults(fn=cmd_report_operations)
    ri = rsub.add_parser("interpolation", help="latent blend vs linear blend of BRDF values (a figure)")
    ri.add_argument("--a", required=True, help="first material JSON (t = 0)")
    ri.add_argument("--b", required=True, help="second material JSON (t = 1)")
    ri.add_argument("--out", required=True, help="PNG")
    ri.add_argument("--model", help="bundle (default: the shipped weights)")
    ri.set_defaults(fn=cmd_report_interpolation)

    sa = sub.add_parser("sample", help="importance-sample wo through the learned proxy pdf")
    sa.add_argument("--material", required=True)
    sa.add_argument("--theta-i", type=float, required=True, help="incidence angle in degrees (phi_i = 0)")
    sa.add_argument("--n", type=int, required=True)
    sa.add_argument("--out", required=True, help="float32 (N, 4) .npy: wo.xyz, pdf (0 = failed sample)")
    sa.add_argument("--model", help="bundle (default: the shipped weights)")
    sa.add_argument("--seed", type=int, default=0)
    sa.set_defaults(fn=cmd_sample)

    b = sub.add_parser("bench", help="speed benchmarks, printed as JSON")
    bsub = b.add_subparsers(dest="what", required=True, parser_class=_Parser)
    br = bsub.add_parser("reference", help="Monte Carlo paths per second and time to a converged lobe")
    br.add_argument("--quick", action="store_true", help="a short run (for tests)")
    br.set_defaults(fn=cmd_bench_reference)
    bd = bsub.add_parser("render", help="GLSL decoder and full shading frame times, GLSL vs torch throughput")
    bd.add_argument("--size", default="1920x1080", help="WxH of the timed frames")
    bd.add_argument("--repeats", type=int, default=3)
    bd.set_defaults(fn=cmd_bench_render)
    ba = bsub.add_parser("app", help="the window's frame time and slider-to-frame latency (needs a display)")
    ba.add_argument("--size", default="1000x620", help="WxH of the window")
    ba.add_argument("--edits", type=int, default=8)
    ba.set_defaults(fn=cmd_bench_app)
    bo = bsub.add_parser("operations", help="CPU latency of leaf encoders and layering (what a slider runs)")
    bo.add_argument("--model", help="bundle (default: the shipped weights)")
    bo.add_argument("--repeats", type=int, default=1000)
    bo.set_defaults(fn=cmd_bench_operations)
    return p


def nbrdf_main(argv: Sequence[str] | None = None) -> int:
    def go() -> int:
        args = build_parser().parse_args(argv)
        return args.fn(args)

    return run_guarded(PROG, go)


if __name__ == "__main__":
    sys.exit(nbrdf_main())
