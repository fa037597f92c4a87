"""``nbrdf``: the entry point and its subcommand registry (SPEC section 8).

Each command family (a module of this package) registers its subcommands;
every subcommand parses its flags from one dataclass, calls the library and
writes files. Bad input of any kind ends with one line on stderr and exit
status 2; an internal failure ends with one line and exit status 1
(``NBRDF_DEBUG=1`` shows the traceback).
"""
from __future__ import annotations

import os
import sys
from typing import Callable, Sequence

from nbrdf.cli import bench, data, evaluate, export, project, render, report, train
from nbrdf.cli.config import Parser
from nbrdf.neural.errors import NbrdfError

PROG = "nbrdf"
#: The command families, in the order ``nbrdf --help`` lists them.
FAMILIES = (evaluate, data, train, project, render, report, bench, export)


def run_guarded(prog: str, fn: Callable[[], int]) -> int:
    """Runs ``fn``; turns bad input into one line + exit 2, a crash into one line + exit 1."""
    try:
        return fn()
    except NbrdfError as e:
        msg = str(e)  # a usage error already names its program ("nbrdf eval: ...")
        print(msg if msg.split(":", 1)[0].split(" ")[0] == prog else f"{prog}: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # noqa: BLE001 - the last line of defence
        if os.environ.get("NBRDF_DEBUG"):
            raise
        print(f"{prog}: internal error: {type(e).__name__}: {e} (set NBRDF_DEBUG=1 for details)", file=sys.stderr)
        return 1


def build_parser() -> Parser:
    """The whole ``nbrdf`` parser: every family's subcommands."""
    p = Parser(prog=PROG, description="Neural layered BRDFs: ground truth, representation, operations.",
               epilog="environment: NBRDF_WALK_DEVICE=auto|cpu|cuda chooses where the Monte Carlo walk runs "
                      "(auto: an NVIDIA GPU when the cuda extra finds one); NBRDF_DEBUG=1 shows tracebacks")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    for family in FAMILIES:
        family.register(sub)
    return p


def nbrdf_main(argv: Sequence[str] | None = None) -> int:
    """The ``nbrdf`` console script."""
    def go() -> int:
        args = build_parser().parse_args(argv)
        return args.fn(args)

    return run_guarded(PROG, go)


if __name__ == "__main__":
    sys.exit(nbrdf_main())
