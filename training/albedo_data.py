"""Walk albedos of drawn stacks: what the albedo network learns (issue 40, record 122).

Each entry is an RGB stack drawn like the furnace set's (``training.furnace``) but from a seed of its own and
over a wider range -- 2 to 5 layers, lossless and absorbing, conductor and diffuse bases, a share of sharp top
coats and of clear top slabs -- with its directional albedo from the walk (``furnace.reference_albedo``) at the
incidences the code's energy check uses (``neural.energy.EnergySettings.thetas``).

On disk: a folder of chunk files, ``chunk-NNNN.safetensors`` (``mean`` and ``se``, (n, T, 3)) beside
``chunk-NNNN.json`` (the n materials); a chunk is written atomically and never recomputed, so an interrupted run
resumes where it stopped, and every stack's draw and walk seed derive from its index alone (so a set may be
stopped early, or grown by asking for more stacks, and its chunks stay valid).
"""
from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from safetensors.numpy import load_file, save_file
from tqdm import tqdm

from nbrdf.neural.energy import EnergySettings
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import CONDUCTOR, DIELECTRIC, DIFFUSE, MEDIUM
from nbrdf.neural.material import FORMAT as MATERIAL_FORMAT
from nbrdf.neural.material import Material, material_to_dict, parse_material
from nbrdf.training import distributions as D
from nbrdf.training.furnace import reference_albedo

ALBEDO_DATA_SEED = 40_122  # neither a training seed nor the furnace, held-out or depth sets'


@dataclass(frozen=True)
class AlbedoDataConfig:
    """What an albedo data set holds; the folder's ``config.json`` records it and resuming requires it unchanged."""

    stacks: int = 2400
    """stacks drawn (entries: stacks x 3 channels x incidences)"""
    seed: int = ALBEDO_DATA_SEED
    """seed of the draws and the walks"""
    lossless: float = 0.4
    """share of lossless stacks (every medium albedo and the base's colour 1)"""
    sharp_tops: float = 0.3
    """share of stacks whose top interface is redrawn sharp (roughness 0.01-0.06, a look-development coat)"""
    clear_tops: float = 0.3
    """share of stacks whose top slab is redrawn clear (sigma_t U(0, 0.3))"""
    max_layers: int = 5
    """layers at most (a stack has 2 to this many: coats over a base)"""
    paths: int = 2048
    """walk paths per incidence in the first round"""
    max_paths: int = 8192
    """walk paths per incidence at most"""
    target: float = 0.01
    """relative standard error the walk is refined to (the training averages the rest)"""
    chunk: int = 50
    """stacks per chunk file"""


def draw_stack(i: int, cfg: AlbedoDataConfig) -> Material:
    """Stack ``i`` of the set: its draw depends on (seed, i) alone."""
    g = np.random.default_rng([cfg.seed, i])
    r6 = lambda x: float(round(float(x), 6))
    lossless = g.uniform() < cfg.lossless
    depth = int(g.integers(2, cfg.max_layers + 1))
    coats = []
    for k in range(depth - 1):
        rough = D.roughness(g.uniform())
        if k == 0 and g.uniform() < cfg.sharp_tops:
            rough = g.uniform(0.01, 0.06)
        sigma = D.sigma_t(g.uniform())
        if k == 0 and g.uniform() < cfg.clear_tops:
            sigma = g.uniform(0.0, 0.3)
        alb = [1.0] * 3 if lossless else [r6(D.medium_albedo(x)) for x in g.uniform(0, 1, 3)]
        coats += [{"type": DIELECTRIC, "roughness": r6(rough), "ior": r6(D.ior(g.uniform()))},
                  {"type": MEDIUM, "albedo": alb, "sigma_t": r6(sigma)}]
    colour = [1.0] * 3 if lossless else [r6(D.colour(x)) for x in g.uniform(0, 1, 3)]
    base = ({"type": CONDUCTOR, "roughness": r6(D.roughness(g.uniform())), "r0": colour} if g.uniform() < 0.5
            else {"type": DIFFUSE, "albedo": colour})
    name = f"{'lossless' if lossless else 'absorbing'}-d{depth}-{i:05d}"
    return parse_material({"format": MATERIAL_FORMAT, "name": name, "layers": coats + [base]})


def _chunk_path(folder: Path, c: int, ext: str) -> Path:
    return folder / f"chunk-{c:04d}.{ext}"


def _stacks_in(folder: Path, c: int) -> int:
    """How many stacks chunk ``c`` holds (0 when it is not finished): a set grown past a short last chunk
    recomputes that chunk whole."""
    if not _chunk_path(folder, c, "safetensors").exists():
        return 0
    return len(json.loads(_chunk_path(folder, c, "json").read_text()))


def generate(folder: str | Path, cfg: AlbedoDataConfig = AlbedoDataConfig(), progress: bool = True) -> Path:
    """Writes (or completes) the set under ``folder``; returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    conf = folder / "config.json"
    want = asdict(cfg) | {"thetas": list(EnergySettings().thetas)}
    same = lambda d: {k: v for k, v in d.items() if k != "stacks"}  # noqa: E731  (a set may grow or stop early)
    if conf.exists() and same(json.loads(conf.read_text())) != same(want):
        raise NbrdfError(f"{folder}: holds an albedo set with other settings; choose another folder")
    conf.write_text(json.dumps(want, indent=1))
    thetas = EnergySettings().thetas
    chunks = range((cfg.stacks + cfg.chunk - 1) // cfg.chunk)
    todo = [c for c in chunks if _stacks_in(folder, c) < min(cfg.chunk, cfg.stacks - c * cfg.chunk)]
    with tqdm(total=cfg.stacks, initial=cfg.stacks - sum(min(cfg.chunk, cfg.stacks - c * cfg.chunk) for c in todo),
              desc="albedo stacks", unit="stack", disable=not progress) as bar:
        for c in todo:
            idx = range(c * cfg.chunk, min(cfg.stacks, (c + 1) * cfg.chunk))
            mats, means, ses = [], [], []
            for i in idx:
                m = draw_stack(i, cfg)
                a = reference_albedo(m, thetas, paths=cfg.paths, max_paths=cfg.max_paths, target=cfg.target,
                                     seed=cfg.seed * 7 + i)
                mats.append(material_to_dict(m))
                means.append(a.mean)
                ses.append(a.se)
                bar.update(1)
            tmp = _chunk_path(folder, c, "tmp")
            _chunk_path(folder, c, "json").write_text(json.dumps(mats))
            save_file({"mean": np.stack(means).astype(np.float32), "se": np.stack(ses).astype(np.float32)}, str(tmp))
            os.replace(tmp, _chunk_path(folder, c, "safetensors"))
    return folder


def load(folder: str | Path) -> tuple[list[Material], np.ndarray, np.ndarray]:
    """(materials, walk albedo (N, T, 3), its standard error (N, T, 3)) of every finished chunk."""
    folder = Path(folder)
    files = sorted(folder.glob("chunk-*.safetensors"))
    if not files:
        raise NbrdfError(f"{folder}: no albedo data (make it with `nbrdf data --preset albedo --out {folder}`)")
    mats, means, ses = [], [], []
    for f in files:
        d = load_file(str(f))
        docs = json.loads(f.with_suffix(".json").read_text())
        if len(docs) != len(d["mean"]):
            raise NbrdfError(f"{f}: {len(docs)} materials for {len(d['mean'])} albedos; remove the chunk")
        mats += [parse_material(x) for x in docs]
        means.append(d["mean"])
        ses.append(d["se"])
    return mats, np.concatenate(means), np.concatenate(ses)
