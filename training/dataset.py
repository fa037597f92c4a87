"""Training and validation sets of single-channel BRDFs (``nbrdf data``).

Each BRDF is drawn from the paper's parameter distributions (SPEC section 9)
in one of five classes; its values are tabulated at direction pairs drawn in
Rusinkiewicz coordinates (isotropy leaves three angles), with extra density
near the specular peak. Single interfaces are closed form, stacks come from
the Monte Carlo simulator (mean and standard error per pair).

On disk: a folder with ``manifest.json`` and one safetensors shard per
(split, class, block of BRDFs). A shard is written atomically and is never
recomputed, so an interrupted run resumes where it stopped; every shard's
random stream derives from (seed, split, class, shard index) alone, so the
result does not depend on interruptions.
"""
from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import sys
from dataclasses import MISSING, asdict, dataclass, field, fields
from pathlib import Path

import numpy as np
import torch
from safetensors.numpy import load_file, save_file
from tqdm import tqdm

from nbrdf.neural.coat import coat_eval
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.geometry import cosine_hemisphere

# The stack classes and the on-disk parameter vector belong to the stack translation
# (neural.stack), the paper's distributions to training.distributions; re-exported here.
from nbrdf.neural.stack import (  # noqa: F401
    CLASSES,
    DIFFUSE_BASED,
    PARAM_NAMES,
    THREE_LAYERED,
    P,
    pad_params,
    params_coats,
    params_to_material,
    params_to_stack,
)
from nbrdf.training.analytic import GGXConductor, GGXDielectric
from nbrdf.training.distributed import run_shards
from nbrdf.training.distributions import (  # noqa: F401
    clear_top_slabs,
    darken_top_slabs,
    lossless_stacks,
    paint_base_coats,
    sample_params,
    sharpen_coats,
)
from nbrdf.training.layered import simulate
from nbrdf.training.reference import MAX_LANES, simulator_params

Tensor = torch.Tensor

FORMAT = "nbrdf-dataset/1"
@dataclass(frozen=True)
class DataConfig:
    """What a data set holds; the manifest records it, and resuming requires it unchanged."""

    counts: dict[str, int]
    val_counts: dict[str, int]
    pairs: int = 1536  # direction pairs per BRDF
    spp: int = 64  # Monte Carlo paths per pair (stacks)
    seed: int = 0
    shard_size: int = 32
    peak_fraction: float = 0.5  # share of pairs drawn near the half-vector pole
    sharp_coats: float = 0.0  # share of stacks redrawn with a coat of roughness 0.01-0.06 over a bright base
    bright_bases: float = 1.0  # share of those sharp-coated stacks whose base is redrawn bright (the rest keep theirs)
    clear_top_slabs: float = 0.0  # share of stacks whose top slab is redrawn clear (sigma_t 0, or U(0, 0.3))
    dark_top_slabs: float = 0.0  # share of stacks whose top slab is redrawn dark and thick (darken_top_slabs)
    paint_base_coats: float = 0.0  # share of three-layered stacks whose lower half is redrawn a car paint's base coat
    lossless: float = 0.0  # share of stacks made lossless (every albedo and the base's r0 or albedo 1)


PRESETS: dict[str, DataConfig] = {
    "tiny": DataConfig(counts=dict(conductor=6, dielectric=6, two_layer=8, three_layer=3, diffuse_base=3),
                       val_counts=dict(conductor=2, dielectric=2, two_layer=2, three_layer=1, diffuse_base=1),
                       pairs=256, spp=16, shard_size=8),
    # the decoder's data: a dielectric's body is black under the coat split, so few of them;
    # 40 % of the stacks carry look-development coats (sharp, over bright bases)
    "cpu": DataConfig(counts=dict(conductor=200, dielectric=40, two_layer=800, three_layer=200, diffuse_base=150,
                                  three_layer_diffuse=100),
                      val_counts=dict(conductor=16, dielectric=8, two_layer=32, three_layer=16, diffuse_base=16,
                                      three_layer_diffuse=8),
                      pairs=1536, spp=64, sharp_coats=0.4),
    # stacks with their parameters, for the layering network (many BRDFs, fewer pairs each)
    "layering": DataConfig(counts=dict(conductor=0, dielectric=0, two_layer=2496, three_layer=640,
                                       diffuse_base=640, three_layer_diffuse=320),
                           val_counts=dict(conductor=0, dielectric=0, two_layer=64, three_layer=32, diffuse_base=32,
                                           three_layer_diffuse=16),
                           pairs=768, spp=32, seed=1, sharp_coats=0.4, clear_top_slabs=0.3),
    # the same stacks without the clear top slab redraw: the shipped bundle's first
    # layering set (the layering preset as it was before that redraw)
    "layering_open": DataConfig(counts=dict(conductor=0, dielectric=0, two_layer=2496, three_layer=640,
                                            diffuse_base=640, three_layer_diffuse=320),
                                val_counts=dict(conductor=0, dielectric=0, two_layer=64, three_layer=32,
                                                diffuse_base=32, three_layer_diffuse=16),
                                pairs=768, spp=32, seed=1, sharp_coats=0.4),
    # look-development stacks for fine-tuning the layering network: most carry
    # a sharp coat over a clear (or thin) top slab -- clear-coated metals,
    # lacquers and three-layer car paints (issue 16)
    "coats": DataConfig(counts=dict(conductor=0, dielectric=0, two_layer=768, three_layer=768, diffuse_base=256,
                                    three_layer_diffuse=256),
                        val_counts=dict(conductor=0, dielectric=0, two_layer=32, three_layer=32, diffuse_base=16,
                                        three_layer_diffuse=16),
                        pairs=768, spp=32, seed=2, sharp_coats=0.7, bright_bases=0.6, clear_top_slabs=0.8),
    # the same look-development range with more dark, thick coloured coatings
    # (black and tinted lacquers) and cleaner values, for the layering network's
    # last stage
    "lacquers": DataConfig(counts=dict(conductor=0, dielectric=0, two_layer=512, three_layer=256, diffuse_base=512,
                                       three_layer_diffuse=256),
                           val_counts=dict(conductor=0, dielectric=0, two_layer=32, three_layer=16, diffuse_base=32,
                                           three_layer_diffuse=16),
                           pairs=768, spp=128, seed=5, sharp_coats=0.7, bright_bases=0.5, clear_top_slabs=0.4,
                           dark_top_slabs=0.4),
    # car paints and coated metals, the look-development stacks the other presets
    # rarely draw: a sharp clear coat over a rough low-index inner interface and
    # a coloured, often dark, thick base coat (paint_base_coats)
    "paints": DataConfig(counts=dict(conductor=0, dielectric=0, two_layer=128, three_layer=256, diffuse_base=0,
                                     three_layer_diffuse=256),
                         val_counts=dict(conductor=0, dielectric=0, two_layer=16, three_layer=16, diffuse_base=0,
                                         three_layer_diffuse=16),
                         pairs=768, spp=64, seed=11, sharp_coats=0.9, bright_bases=0.5, clear_top_slabs=0.9,
                         paint_base_coats=0.8),
    # deep stacks (3 and 4 coats over a conductor) for training the recursion past the paper's depth
    # (issue 40: the error jumped at 4 layers, the first depth absent from training)
    "deep": DataConfig(counts=dict(conductor=0, dielectric=0, two_layer=0, three_layer=0, diffuse_base=0,
                                   four_layer=640, five_layer=512),
                       val_counts=dict(conductor=0, dielectric=0, two_layer=0, three_layer=0, diffuse_base=0,
                                       four_layer=32, five_layer=32),
                       pairs=768, spp=32, seed=13, sharp_coats=0.4, clear_top_slabs=0.3),
    # white-furnace stacks of every depth: most lossless (media, conductor r0 and diffuse albedo 1), which
    # the paper's distributions never draw, and whose long paths the energy term needs to see (issue 40)
    "lossless": DataConfig(counts=dict(conductor=0, dielectric=0, two_layer=320, three_layer=192, diffuse_base=192,
                                       three_layer_diffuse=96, four_layer=128, five_layer=64),
                           val_counts=dict(conductor=0, dielectric=0, two_layer=16, three_layer=16, diffuse_base=16,
                                           three_layer_diffuse=16, four_layer=16, five_layer=16),
                           pairs=768, spp=32, seed=17, sharp_coats=0.3, clear_top_slabs=0.3, lossless=0.7),
    "paper": DataConfig(counts=dict(conductor=300, dielectric=300, two_layer=12720, three_layer=1800,
                                    diffuse_base=1200),
                        val_counts=dict(conductor=32, dielectric=32, two_layer=128, three_layer=64, diffuse_base=32),
                        pairs=4096, spp=128),
}


# --- directions ----------------------------------------------------------------------
def sample_pairs(n: int, g: torch.Generator, peak_fraction: float = 0.5) -> tuple[Tensor, Tensor]:
    """n (wi, wo) pairs, both above the horizon, float64 (n, 3) each.

    A ``peak_fraction`` of them has theta_h = (pi/2) u^2 (dense near the
    specular peak, where lobes are sharp); the rest is cosine-distributed in
    wi and wo independently (the whole domain, weighted as the lobe metric)."""
    out_i, out_o, have = [], [], 0
    while have < n:
        m = 2 * (n - have) + 16
        u = torch.rand(m, 6, generator=g, dtype=torch.float64)
        peak = u[:, 5] < peak_fraction
        # Peak pairs: half vector near the pole, difference vector anywhere.
        th, ph = 0.5 * math.pi * u[:, 0] ** 2, 2 * math.pi * u[:, 1]
        td, pd = torch.acos(1 - u[:, 2]), 2 * math.pi * u[:, 3]  # uniform over the hemisphere of d
        h = torch.stack([th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()], -1)
        d = torch.stack([td.sin() * pd.cos(), td.sin() * pd.sin(), td.cos()], -1)
        # rotate d from the frame where h is the pole: by theta_h about y, then phi_h about z
        ct, st, cp, sp = th.cos(), th.sin(), ph.cos(), ph.sin()
        x1 = ct * d[:, 0] + st * d[:, 2]
        z1 = -st * d[:, 0] + ct * d[:, 2]
        wi_p = torch.stack([cp * x1 - sp * d[:, 1], sp * x1 + cp * d[:, 1], z1], -1)
        wo_p = 2 * (wi_p * h).sum(-1, keepdim=True) * h - wi_p
        # Cosine pairs.
        wi_c, wo_c = cosine_hemisphere(u[:, 0], u[:, 1]), cosine_hemisphere(u[:, 2], u[:, 3])
        wi = torch.where(peak[:, None], wi_p, wi_c)
        wo = torch.where(peak[:, None], wo_p, wo_c)
        ok = (wi[:, 2] > 1e-4) & (wo[:, 2] > 1e-4)
        out_i.append(wi[ok])
        out_o.append(wo[ok])
        have += int(ok.sum())
    wi, wo = torch.cat(out_i)[:n], torch.cat(out_o)[:n]
    return wi / wi.norm(dim=-1, keepdim=True), wo / wo.norm(dim=-1, keepdim=True)


@functools.cache
def _peak_acceptance() -> float:
    """The share of ``sample_pairs``' peak-branch draws with both directions above the horizon (a fixed
    2^21-draw estimate: the same number every run)."""
    g = torch.Generator().manual_seed(12_345)
    u = torch.rand(1 << 21, 4, generator=g, dtype=torch.float64)
    th, ph = 0.5 * math.pi * u[:, 0] ** 2, 2 * math.pi * u[:, 1]
    td, pd = torch.acos(1 - u[:, 2]), 2 * math.pi * u[:, 3]
    h = torch.stack([th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()], -1)
    d = torch.stack([td.sin() * pd.cos(), td.sin() * pd.sin(), td.cos()], -1)
    z_i = -th.sin() * d[:, 0] + th.cos() * d[:, 2]  # wi's z after the rotation of sample_pairs
    z_o = 2 * d[:, 2] * h[:, 2] - z_i  # wo = 2 (wi.h) h - wi, and wi.h = d_z
    return float(((z_i > 1e-4) & (z_o > 1e-4)).double().mean())


def pair_pdf(wi: Tensor, wo: Tensor, peak_fraction: float = 0.5) -> Tensor:
    """The density (per solid angle of wi and of wo) of ``sample_pairs``' pairs at (wi, wo) (..., 3):
    the peak branch's half vector (theta_h = (pi/2) u^2) and uniform difference vector, with the
    reflection's Jacobian 1 / (4 wi.h), mixed with the cosine pairs, both over the accepted share. With
    it, sums over a data set's pairs weighted by cos_i cos_o / pdf estimate integrals (the energy term)."""
    h = wi + wo
    h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    th = torch.acos(h[..., 2].clamp(-1.0, 1.0)).clamp_min(1e-9)
    p_h = 1.0 / (2 * math.pi * th.sin().clamp_min(1e-12) * torch.sqrt(2 * math.pi * th))
    peak = torch.where(th < 0.5 * math.pi, p_h / (2 * math.pi) / (4 * (wi * h).sum(-1).clamp_min(1e-9)),
                       torch.zeros_like(th))
    cos = wi[..., 2].clamp_min(0) * wo[..., 2].clamp_min(0) / math.pi ** 2
    return (peak_fraction * peak + (1 - peak_fraction) * cos) / (peak_fraction * _peak_acceptance()
                                                                 + (1 - peak_fraction))


# --- values ------------------------------------------------------------------------
def _stack_params(params: Tensor, pairs: int):
    """Simulator parameters for K single-channel stacks of one class, each
    repeated over its pairs (K * pairs rows)."""
    return simulator_params(params_to_stack(params).repeat_interleave(pairs))


def tabulate(params: Tensor, wi: Tensor, wo: Tensor, spp: int, seed: int) -> tuple[Tensor, Tensor]:
    """Values and standard errors (K, n) of K BRDFs of one class at their pairs (K, n, 3)."""
    K, n = wi.shape[:2]
    cls = CLASSES[int(params[0, 0])]
    fi, fo = wi.reshape(-1, 3), wo.reshape(-1, 3)
    if cls in ("conductor", "dielectric"):
        st = params_to_stack(params).repeat_interleave(n)
        f = (GGXConductor(st.base_roughness, st.base_r0[:, 0]) if cls == "conductor"
             else GGXDielectric(st.base_roughness, st.base_ior)).eval(fi, fo)
        return f.reshape(K, n), torch.zeros(K, n, dtype=f.dtype)
    per_call = max(1, MAX_LANES // (n * spp))
    means, errs = [], []
    for s in range(0, K, per_call):
        sl = slice(s, s + per_call)
        k = params[sl].shape[0]
        m, e = simulate(_stack_params(params[sl], n), wi[sl].reshape(-1, 3).float(), wo[sl].reshape(-1, 3).float(),
                        spp=spp, seed=seed * 7_919 + s)
        means.append(m.double().reshape(k, n))
        errs.append(e.double().reshape(k, n))
    return torch.cat(means), torch.cat(errs)


# --- shards and manifest -------------------------------------------------------------
def _stream_seed(seed: int, *parts: object) -> int:
    h = hashlib.sha256(repr((seed,) + parts).encode()).digest()
    return int.from_bytes(h[:8], "little") & ((1 << 62) - 1)


@dataclass
class Shard:
    file: str
    split: str
    cls: str
    index: int
    count: int


def plan(cfg: DataConfig) -> list[Shard]:
    shards = []
    for split, counts in (("train", cfg.counts), ("val", cfg.val_counts)):
        for cls in CLASSES:
            total = counts.get(cls, 0)
            for i, s in enumerate(range(0, total, cfg.shard_size)):
                shards.append(Shard(f"{split}-{cls}-{i:04d}.safetensors", split, cls, i,
                                    min(cfg.shard_size, total - s)))
    return shards


def make_shard(cfg: DataConfig, shard: Shard) -> dict[str, np.ndarray]:
    g = torch.Generator().manual_seed(_stream_seed(cfg.seed, shard.split, shard.cls, shard.index))
    params = sample_params(shard.cls, shard.count, g)
    # the look-development redraws, in this order, each from its own stream
    redraws = (("coats", cfg.sharp_coats, lambda p, share, g: sharpen_coats(p, share, g, cfg.bright_bases)),
               ("slabs", cfg.clear_top_slabs, clear_top_slabs), ("dark", cfg.dark_top_slabs, darken_top_slabs),
               ("paint", cfg.paint_base_coats, paint_base_coats), ("lossless", cfg.lossless, lossless_stacks))
    for stream, share, redraw in redraws:
        if share > 0:
            redraw(params, share, torch.Generator().manual_seed(
                _stream_seed(cfg.seed, stream, shard.split, shard.cls, shard.index)))
    wi, wo = zip(*(sample_pairs(cfg.pairs, g, cfg.peak_fraction) for _ in range(shard.count)))
    wi, wo = torch.stack(wi), torch.stack(wo)
    f, se = tabulate(params, wi, wo, cfg.spp, seed=_stream_seed(cfg.seed, "mc", shard.split, shard.cls, shard.index)
                     % (1 << 31))
    return {"params": params.float().numpy(), "wi": wi.float().numpy(), "wo": wo.float().numpy(),
            "f": f.float().numpy(), "stderr": se.float().numpy()}


def _config_dict(cfg: DataConfig) -> dict:
    return json.loads(json.dumps(asdict(cfg)))


def _same_config(old: dict | None, new: dict) -> bool:
    """Whether a manifest's config equals ``new``; fields added to
    ``DataConfig`` since the manifest was written count at their defaults
    (they reproduce the old draws), so older data sets still resume."""
    defaults = {f.name: f.default for f in fields(DataConfig) if f.default is not MISSING}
    return old is not None and json.loads(json.dumps({**defaults, **old})) == new


def generate(out: str | Path, cfg: DataConfig, preset: str = "custom", overwrite: bool = False,
             progress: bool = True, ray: str | None = None) -> Path:
    """Creates (or resumes) a data set in ``out``; returns the manifest path.
    ``ray``: None computes the shards here; "auto", "local" or a cluster
    address runs them as Ray tasks (``training.distributed``), same shards."""
    out = Path(out)
    man_path = out / "manifest.json"
    shards = plan(cfg)
    manifest = {"format": FORMAT, "preset": preset, "config": _config_dict(cfg), "param_names": list(PARAM_NAMES),
                "shards": [asdict(s) for s in shards]}
    if man_path.exists():
        old = json.loads(man_path.read_text())
        if not _same_config(old.get("config"), manifest["config"]):
            if not overwrite:
                raise NbrdfError(f"{out}: holds a data set made with other settings; "
                                 "pass --overwrite to replace it or choose another folder")
            for s in old.get("shards", []):
                (out / s["file"]).unlink(missing_ok=True)
    elif out.exists() and any(out.iterdir()):
        raise NbrdfError(f"{out}: exists and is not an nbrdf data set; choose an empty or new folder")
    out.mkdir(parents=True, exist_ok=True)
    man_path.write_text(json.dumps(manifest, indent=1))
    todo = [s for s in shards if not (out / s.file).exists()]
    total = sum(s.count for s in shards)
    with tqdm(total=total, initial=total - sum(s.count for s in todo), desc="BRDFs", unit="brdf",
              disable=not progress or None, file=sys.stderr) as bar:
        def write(s: Shard, arrays: dict[str, np.ndarray]) -> None:
            tmp = out / (s.file + ".tmp")
            save_file(arrays, str(tmp), metadata={"class": s.cls, "split": s.split})
            os.replace(tmp, out / s.file)
            bar.update(s.count)

        if ray is not None:
            run_shards(make_shard, cfg, todo, ray, write)
        else:
            for s in todo:
                write(s, make_shard(cfg, s))
    return man_path


# --- reading ------------------------------------------------------------------------
@dataclass
class BRDFSet:
    """All BRDFs of a split in memory: params (K, 19), wi/wo (K, n, 3), f/stderr (K, n)."""

    params: Tensor
    wi: Tensor
    wo: Tensor
    f: Tensor
    stderr: Tensor
    classes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return self.params.shape[0]


def body_values(data: "BRDFSet") -> Tensor:
    """The values (K, n) without the top interface's closed-form reflection:
    what a coat-split decoder represents (the simulator adds that reflection
    analytically, so the difference carries no extra noise)."""
    c = params_coats(data.params).to(data.f.dtype)[:, None, :]
    return (data.f - coat_eval(c, data.wi.to(data.f.dtype), data.wo.to(data.f.dtype))).clamp_min(0.0)


def data_folders(spec: str) -> list[str]:
    """The folders of a ``--data`` value: one data set, or several joined by commas."""
    folders = [f.strip() for f in str(spec).split(",") if f.strip()]
    if not folders:
        raise NbrdfError("--data: no data folder given")
    return folders


def load_manifest(folder: str | Path) -> dict:
    man = Path(folder) / "manifest.json"
    if not man.is_file():
        raise NbrdfError(f"{folder}: no manifest.json (make a data set with `nbrdf data`)")
    try:
        m = json.loads(man.read_text())
    except json.JSONDecodeError as e:
        raise NbrdfError(f"{man}: not valid JSON ({e.msg})") from None
    if m.get("format") != FORMAT:
        raise NbrdfError(f"{man}: format {m.get('format')!r} is not {FORMAT}")
    return m


def load_split(folder: str | Path, split: str = "train") -> BRDFSet:
    """Reads every finished shard of a split (an unfinished data set is an error)."""
    folder = Path(folder)
    m = load_manifest(folder)
    parts: dict[str, list] = {k: [] for k in ("params", "wi", "wo", "f", "stderr")}
    for s in m["shards"]:
        if s["split"] != split:
            continue
        path = folder / s["file"]
        if not path.is_file():
            raise NbrdfError(f"{path}: missing; the data set is unfinished (run the same `nbrdf data` again)")
        arrays = load_file(str(path))
        for k in parts:
            parts[k].append(torch.from_numpy(arrays[k]) if k != "params" else pad_params(torch.from_numpy(arrays[k])))
    if not parts["params"]:
        raise NbrdfError(f"{folder}: no BRDFs in split {split!r}")
    cat = {k: torch.cat(v) for k, v in parts.items()}
    finite = torch.isfinite(cat["f"]).all(1) & torch.isfinite(cat["params"]).all(1)
    if not bool(finite.all()):  # data made before the simulator dropped round-off failures
        print(f"{folder}: skipping {int((~finite).sum())} BRDF(s) of split {split!r} with non-finite values",
              file=sys.stderr)
        cat = {k: v[finite] for k, v in cat.items()}
    classes = [CLASSES[int(c)] for c in cat["params"][:, 0]]
    return BRDFSet(classes=classes, **cat)

