"""Per-pair means of the Monte Carlo walk on fixed stacks and seeds, recorded
and compared: the check that a change to the walk's code keeps its estimates
(the same seeds must give the same numbers up to floating-point rounding).

    python tools/walk_means.py record OUT.npz [--pairs 32] [--spp 32]
    python tools/walk_means.py compare OLD.npz NEW.npz [--rtol 1e-12]

The stacks: every held-out material with a layer stack (training.evaluate's
``heldout_set``), and synthetic stacks that switch on each of the walk's
strategies (the two-bounce connection and splitting, the chain through two
interfaces, the chain by way of a sharp base, a dielectric base, the walk
without the forced top reflection). ``compare`` prints the largest relative
difference of the means and of the standard errors, the number of pairs that
differ beyond ``--rtol`` and the vertex counts; exit status 1 when any differ.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import torch

SEEDS = (3, 1234)


def _dirs(n: int, seed: int) -> torch.Tensor:
    g = np.random.default_rng(seed)
    u = g.random((n, 2))
    r = np.sqrt(u[:, 0])
    return torch.from_numpy(np.stack([r * np.cos(2 * np.pi * u[:, 1]), r * np.sin(2 * np.pi * u[:, 1]),
                                      np.sqrt(1 - u[:, 0])], -1))


def _stacks(n: int) -> dict:
    """Name -> (StackParams, forced_top_reflection)."""
    from nbrdf.neural.errors import NbrdfError
    from nbrdf.training.evaluate import heldout_set
    from nbrdf.training.layered import StackParams
    from nbrdf.training.reference import stack_params

    f = lambda v, *shape: torch.full(shape, float(v), dtype=torch.float64)
    out = {
        "standard": (StackParams(f(0.1, n, 1), f(1.5, n, 1), f(0.9, n, 1, 3), f(1.0, n, 1), "conductor", f(0.3, n),
                                 base_r0=f(0.9, n, 3)), True),
        "trapping": (StackParams(f(0.15, n, 1), f(1.5, n, 1), f(0.0, n, 1, 3), f(0.0, n, 1), "conductor", f(0.02, n),
                                 base_r0=torch.tensor([[1.0, 0.7, 0.4]], dtype=torch.float64).expand(n, 3)), True),
        "two_interface": (StackParams(f(0.3, n, 2), f(1.4, n, 2), f(0.7, n, 2, 3), f(0.5, n, 2), "diffuse", f(1.0, n),
                                      base_albedo=f(0.6, n, 3)), True),
        "sharp_base": (StackParams(f(0.05, n, 1), f(1.5, n, 1), f(0.9, n, 1, 3), f(1.0, n, 1), "conductor",
                                   f(0.02, n), base_r0=f(0.9, n, 3)), True),
        "dielectric_base": (StackParams(f(0.2, n, 1), f(1.5, n, 1), f(0.8, n, 1, 3), f(0.7, n, 1), "dielectric",
                                        f(0.3, n), base_ior=f(1.3, n)), True),
        "unforced": (StackParams(f(0.1, n, 1), f(1.5, n, 1), f(0.9, n, 1, 3), f(1.0, n, 1), "conductor", f(0.3, n),
                                 base_r0=f(0.9, n, 3)), False),
    }
    for _cls, m in heldout_set():
        try:
            out[m.name] = (stack_params(m, n), True)
        except NbrdfError:
            continue  # single layers and bases without a Monte Carlo reference
    return out


def record(path: str, pairs: int, spp: int) -> None:
    from nbrdf.training.layered import SimStats, simulate

    arrays = {}
    for name, (st, forced) in _stacks(pairs).items():
        for seed in SEEDS:
            stats = SimStats()
            m, e = simulate(st, _dirs(pairs, seed), _dirs(pairs, seed + 1), spp=spp, seed=seed, dtype=torch.float64,
                            include_top_reflection=False, forced_top_reflection=forced, stats=stats, device="cpu")
            arrays[f"{name}/{seed}/mean"] = m.numpy()
            arrays[f"{name}/{seed}/se"] = e.numpy()
            arrays[f"{name}/{seed}/vertices"] = np.array([stats.vertices, stats.dropped])
    np.savez(path, **arrays)
    print(f"{len(arrays) // 3} runs ({pairs} pairs x {spp} paths) -> {path}")


def compare(old: str, new: str, rtol: float) -> int:
    a, b = np.load(old), np.load(new)
    if sorted(a.files) != sorted(b.files):
        print("the two files hold different runs")
        return 1
    worst = {"mean": 0.0, "se": 0.0}
    off = verts = 0
    pairs = 0
    for k in a.files:
        kind = k.rsplit("/", 1)[1]
        if kind == "vertices":
            verts += int(not np.array_equal(a[k], b[k]))
            continue
        x, y = a[k], b[k]
        rel = np.abs(x - y) / np.maximum(np.abs(x), 1e-300)
        rel = np.where((x == 0) & (y == 0), 0.0, rel)
        worst[kind] = max(worst[kind], float(rel.max()))
        off += int((rel > rtol).any(-1).sum()) if kind == "mean" else 0
        pairs += x.shape[0] if kind == "mean" else 0
    print(f"pairs compared: {pairs}; largest relative difference: means {worst['mean']:.3g}, "
          f"standard errors {worst['se']:.3g}; pairs beyond {rtol:g}: {off}; runs with other vertex counts: {verts}")
    return int(off > 0 or verts > 0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record")
    r.add_argument("out")
    r.add_argument("--pairs", type=int, default=32)
    r.add_argument("--spp", type=int, default=32)
    c = sub.add_parser("compare")
    c.add_argument("old")
    c.add_argument("new")
    c.add_argument("--rtol", type=float, default=1e-12)
    a = ap.parse_args(argv)
    if a.cmd == "record":
        record(a.out, a.pairs, a.spp)
        return 0
    return compare(a.old, a.new, a.rtol)


if __name__ == "__main__":
    sys.exit(main())
