"""Dr.Jit's two ways of running the plugins inside a render, and which one a
material wants.

Symbolic (Dr.Jit's default): loops and calls are traced once into one
kernel. Wavefront (evaluated): each call runs as kernels of its own, its
inputs evaluated first, which ``nbrdf_reference`` needs to hand a wavefront
to the walk through numpy, and which runs the decoder faster on the LLVM
backend (``wants_wavefront``).
"""
from __future__ import annotations

import contextlib

import drjit as dr
import mitsuba as mi

from nbrdf.mitsuba.kernel import Body

SLOW_SYMBOLIC = ("nbrdf: traced symbolically on the LLVM backend, where Dr.Jit loads every decoder weight inside a "
                 "symbolic call with a gather (about 10x slower); render inside nbrdf.mitsuba.wavefront_mode()")


@contextlib.contextmanager
def wavefront_mode():
    """Dr.Jit's evaluated (wavefront) loops and calls, which ``nbrdf_reference``
    needs to hand each wavefront to the walk; restores the flags after."""
    flags = (dr.JitFlag.SymbolicLoops, dr.JitFlag.SymbolicCalls)
    old = [dr.flag(f) for f in flags]
    try:
        for f in flags:
            dr.set_flag(f, False)
        yield
    finally:
        for f, v in zip(flags, old):
            dr.set_flag(f, v)


def wants_wavefront(body: str = Body.DECODER) -> bool:
    """Whether ``nbrdf`` renders faster in ``wavefront_mode()`` under the
    variant in force: on the LLVM backend, Dr.Jit's cooperative vectors
    turn each weight load inside a symbolic call into a per-lane gather,
    while an evaluated call runs the decoder at the top level of its kernel
    (broadcast loads). CUDA's cooperative vectors have no such cost. A body
    read from a table (``Body.TABLE``) has no weights: symbolic is faster."""
    return body == Body.DECODER and mi.variant() is not None and mi.variant().startswith("llvm")


class SlowSymbolicWarning:
    """Mitsuba's log says once per process (``warned``) that the decoder is
    traced where it runs slowly: symbolically, on the backend that wants the
    wavefront mode."""

    def __init__(self) -> None:
        self.warned = False

    def check(self, body: str) -> None:
        """Warns unless done already, when ``body`` runs inside a symbolic call here."""
        if not self.warned and body == Body.DECODER and dr.flag(dr.JitFlag.SymbolicScope) \
                and dr.flag(dr.JitFlag.SymbolicCalls) and wants_wavefront():
            self.warned = True
            mi.Log(mi.LogLevel.Warn, SLOW_SYMBOLIC)


#: The process's one warning (a test resets ``warned``).
SLOW_WARNING = SlowSymbolicWarning()
