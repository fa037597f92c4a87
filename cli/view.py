"""``nbrdf-view``: the previewer's command line (SPEC section 8).

The flags are the fields of :class:`nbrdf.viewer.options.ViewOptions`. With a
display it opens the window; with ``--offscreen`` (or when no display can be
opened) it renders the same view through EGL to an image.
"""
from __future__ import annotations

import sys
from typing import Sequence

from nbrdf.cli.config import Parser, add_arguments, build
from nbrdf.cli.main import run_guarded
from nbrdf.viewer.options import ViewOptions

PROG = "nbrdf-view"


def build_parser() -> Parser:
    """The ``nbrdf-view`` parser, one flag per ``ViewOptions`` field."""
    p = Parser(prog=PROG, description="Real-time neural BRDF previewer.")
    add_arguments(p, ViewOptions)
    return p


def parse_args(argv: Sequence[str] | None) -> ViewOptions:
    """Checked options from the command line (one-line ``NbrdfError`` otherwise)."""
    ns = build_parser().parse_args(argv)
    return build(ViewOptions, ns).check()


def main(argv: Sequence[str] | None = None) -> int:
    """The ``nbrdf-view`` console script."""
    def go() -> int:
        from nbrdf.viewer.offscreen import has_display, render_offscreen  # late: EGL, torch; --help needs neither

        opts = parse_args(argv)
        if opts.offscreen:
            render_offscreen(opts)
            return 0
        if not has_display():
            render_offscreen(opts, fallback="no display found")
            return 0
        from nbrdf.viewer.ui.app import App, WindowUnavailable  # late: glfw and imgui, only with a display

        try:
            app = App(opts)
        except WindowUnavailable as e:
            render_offscreen(opts, fallback=f"cannot open a window ({e})")
            return 0
        app.run()
        return 0

    return run_guarded(PROG, go)


if __name__ == "__main__":
    sys.exit(main())
