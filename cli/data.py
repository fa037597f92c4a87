"""``nbrdf data``: generate a training / validation data set (sharded,
resumable). A new option is one field of :class:`DataArgs` plus its use in
:func:`cmd_data`."""
from __future__ import annotations

import argparse
from dataclasses import dataclass, replace

from nbrdf.cli.config import add_arguments, build
from nbrdf.neural.errors import NbrdfError


@dataclass
class DataArgs:
    """``nbrdf data``: which preset, where, and overrides of the preset."""

    out: str
    """folder for the shards and manifest.json"""
    preset: str = "tiny"
    """tiny (seconds), cpu (the shipped decoder), layering (stacks for the layering network), layering_open (the
    same without clear top slabs), coats (look-development stacks to fine-tune it), lacquers (dark thick coatings),
    paints (car paints and coated metals), paper; albedo: walk albedos of drawn stacks for the albedo network
    (``training.albedo_data``; --seed applies, --spp and --ray do not)"""
    seed: int | None = None
    """random seed (default: the preset's)"""
    spp: int | None = None
    """Monte Carlo paths per direction pair (default: the preset's); cleaner targets for the layering network,
    e.g. the shipped bundle's second coats set: --preset coats --seed 7 --spp 128"""
    overwrite: bool = False
    """replace a data set made with other settings"""
    ray: str | None = None
    """run the shards as Ray tasks: auto (the cluster found on this machine), local (a private
    instance) or a cluster address HOST:PORT / ray://HOST:PORT; shards are identical to a local run"""


def cmd_data(a: argparse.Namespace) -> int:
    from nbrdf.training.dataset import PRESETS, generate  # late: torch and the walk, --help needs neither

    c: DataArgs = build(DataArgs, a)
    if c.preset == "albedo":
        from nbrdf.training import albedo_data  # late: as above

        cfg_a = albedo_data.AlbedoDataConfig()
        print(f"data set ready: {albedo_data.generate(c.out, replace(cfg_a, seed=c.seed or cfg_a.seed))}")
        return 0
    if c.preset not in PRESETS:
        raise NbrdfError(f"--preset: {c.preset!r} is not one of {', '.join(PRESETS)}")
    cfg = PRESETS[c.preset]
    if c.seed is not None:
        cfg = replace(cfg, seed=c.seed)
    if c.spp is not None:
        if c.spp < 1:
            raise NbrdfError(f"--spp: {c.spp} paths per pair; at least 1")
        cfg = replace(cfg, spp=c.spp)
    man = generate(c.out, cfg, preset=c.preset, overwrite=c.overwrite, ray=c.ray)
    print(f"data set ready: {man}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Adds ``data`` to the ``nbrdf`` subcommands."""
    p = sub.add_parser("data", help="generate a training / validation data set (sharded, resumable)",
                       description=DataArgs.__doc__)
    add_arguments(p, DataArgs)
    p.set_defaults(fn=cmd_data)
