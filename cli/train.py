"""``nbrdf train representation|leaf|layering|sampler|albedo``: the flags are the
training code's own config dataclasses (``TrainConfig`` with the decoder's
``DecoderSpec``; ``LeafConfig``, ``LayeringConfig``, ``SamplerConfig``, ``AlbedoTrainConfig``), so
``--help`` shows the defaults the code uses."""
from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Callable

from nbrdf.cli.common import at_least, in_range
from nbrdf.cli.config import Parser, add_arguments, build, values

#: Operation-only fields that the leaf and sampler commands do not take.
LAYERING_ONLY = ("data", "recursion_steps", "width", "depth", "medium", "medium_lr_scale", "loss", "loss_scale", "relative_scale")
#: The decoder architecture fields set from the command line, with their help
#: (``DecoderSpec`` lives in the library; its other fields are fixed).
SPEC_HELP = {"width": "hidden units per decoder layer", "depth": "hidden layers of the decoder",
             "activation": "hidden-layer activation",
             "encoding": "direction features (rusink5: five of the Rusinkiewicz angles; lobes11: and GGX-like bumps "
                         "of the half vector, outside and inside a coat)",
             "loss_scale": "s in the loss log(1 + f cos / s)",
             "coat": "the coat split (--no-coat: decode whole BRDFs, not bodies under the top interface's closed-form reflection; neural.coat)"}


@dataclass
class RunArgs:
    """Options of a representation run that are not part of its configuration."""

    stop_after: int | None = None
    """end this run after N epochs (resume later)"""


def _representation():
    """The decoder and representation-training modules, imported on first use."""
    from nbrdf.neural import decoder  # late: torch costs ~1 s, --help needs none
    from nbrdf.training import train_representation  # late: torch, as above

    return decoder, train_representation


def cmd_train_representation(a: argparse.Namespace) -> int:
    decoder, tr = _representation()
    for name in ("epochs", "batch", "val_every"):
        at_least("--" + name.replace("_", "-"), getattr(a, name))
    for name in ("lr", "latent_lr", "loss_scale"):
        in_range("--" + name.replace("_", "-"), getattr(a, name), 0.0, low_open=True)
    in_range("--latent-reg", a.latent_reg, 0.0)
    spec = build(decoder.DecoderSpec, a, SPEC_HELP)
    cfg = build(tr.TrainConfig, a, spec=spec)
    run: RunArgs = build(RunArgs, a)
    bundle = tr.train(cfg, stop_after=run.stop_after)
    print(f"decoder written: {bundle}" if bundle else f"stopped after {run.stop_after} epochs; run the same command to resume")
    return 0


def cmd_train_operation(a: argparse.Namespace) -> int:
    from nbrdf.training import train_operations as to  # late: torch costs ~1 s, --help needs none
    from nbrdf.training import train_sampler as ts  # late: as above

    cls, train = {"leaf": (to.LeafConfig, to.train_leaf), "layering": (to.LayeringConfig, to.train_layering),
                  "sampler": (ts.SamplerConfig, ts.train_sampler)}[a.what]
    for name in ("steps", "batch", "pairs"):
        at_least("--" + name, getattr(a, name))
    in_range("--lr", a.lr, 0.0, low_open=True)
    in_range("--ema", a.ema, 0.0, 1.0)
    for name in ("loss_scale", "relative_scale"):
        if hasattr(a, name):
            in_range("--" + name.replace("_", "-"), getattr(a, name), 0.0)
    kw = values(cls, a)
    if not kw.get("decoder"):  # --decoder not given: the dataclass default (the shipped weights)
        kw.pop("decoder", None)
    print(f"bundle written: {train(cls(**kw))}")
    return 0


@dataclass
class RouteDepthArgs:
    """A bundle whose deep stacks (3 interfaces or more) take another run's layering network
    (``training.train_operations.route_depth``, docs/decisions/112)."""

    base: str
    """the bundle kept for the shallow stacks (and its sampler)"""
    deep: str
    """a layering fine-tune of --base (same decoder and leaf encoders) whose layering network takes the deep stacks"""
    out: str
    """the bundle written"""


def cmd_route_depth(a: argparse.Namespace) -> int:
    from nbrdf.training import train_operations as to  # late: torch costs ~1 s, --help needs none

    r: RouteDepthArgs = build(RouteDepthArgs, a)
    print(f"bundle written: {to.route_depth(r.base, r.deep, r.out)}")
    return 0


def cmd_train_albedo(a: argparse.Namespace) -> int:
    from nbrdf.training import train_albedo as ta  # late: torch costs ~1 s, --help needs none

    cfg = build(ta.AlbedoTrainConfig, a)
    at_least("--steps", cfg.steps)
    in_range("--lr", cfg.lr, 0.0, low_open=True)
    in_range("--val-share", cfg.val_share, 0.0, 0.5, low_open=True)
    ta.train_albedo(cfg)
    return 0


def _albedo_flags(p: Parser) -> None:
    from nbrdf.training import train_albedo as ta  # late: flags added on first use (torch)

    p.description = ta.AlbedoTrainConfig.__doc__
    add_arguments(p, ta.AlbedoTrainConfig)


def _representation_flags(p: Parser) -> None:
    decoder, tr = _representation()
    p.description = tr.TrainConfig.__doc__
    add_arguments(p, tr.TrainConfig, exclude=("spec",))
    add_arguments(p, decoder.DecoderSpec, only=SPEC_HELP, help=SPEC_HELP)
    add_arguments(p, RunArgs)


def _operation_flags(what: str) -> Callable[[Parser], None]:
    def populate(p: Parser) -> None:
        from nbrdf.training import train_operations as to  # late: flags added on first use (torch)
        from nbrdf.training import train_sampler as ts  # late: as above

        cls = {"leaf": to.LeafConfig, "layering": to.LayeringConfig, "sampler": ts.SamplerConfig}[what]
        p.description = cls.__doc__
        add_arguments(p, cls, exclude=() if what == "layering" else LAYERING_ONLY,
                      required=("data",) if what == "layering" else (), defaults={"decoder": None})

    return populate


#: ``nbrdf train`` subcommands: name -> one-line help (the flags are added on
#: first use, so that ``nbrdf`` does not import torch to parse other commands).
TRAINERS = {
    "leaf": "leaf encoders, through the frozen decoder against closed-form layers",
    "layering": "layering network, through the decoder against Monte Carlo stacks",
    "sampler": "proxy-pdf network, by KL divergence to decoded lobes",
}


def register(sub: argparse._SubParsersAction) -> None:
    """Adds ``train``, its four training subcommands and ``route-depth`` to the ``nbrdf`` subcommands."""
    t = sub.add_parser("train", help="train networks")
    tsub = t.add_subparsers(dest="what", required=True, parser_class=Parser)
    tr = tsub.add_parser("representation", help="auto-decoder: the shared decoder and training latents",
                         populate=_representation_flags)
    tr.set_defaults(fn=cmd_train_representation)
    for what, help_ in TRAINERS.items():
        to = tsub.add_parser(what, help=help_, populate=_operation_flags(what))
        to.set_defaults(fn=cmd_train_operation)
    al = tsub.add_parser("albedo", help="albedo network: a layered code's walk albedo, which its code is "
                         "settled to (neural.energy.settle)", populate=_albedo_flags)
    al.set_defaults(fn=cmd_train_albedo)
    rd = tsub.add_parser("route-depth", help="a bundle whose deep stacks (3 interfaces or more) take another "
                         "run's layering network (docs/decisions/112)",
                         populate=lambda p: add_arguments(p, RouteDepthArgs))
    rd.set_defaults(fn=cmd_route_depth)
