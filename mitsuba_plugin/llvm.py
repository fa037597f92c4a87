"""Where Dr.Jit finds LLVM for the ``llvm_*`` variants.

Dr.Jit's LLVM back end loads ``libLLVM`` at run time and needs a recent one
(the system's LLVM 15 aborts in code generation with "Cannot select:
fminimum"); Debian's ``libllvm19`` works. ``point_drjit_at_llvm`` sets
``DRJIT_LIBLLVM_PATH`` to it when the user has not chosen a library, and must
run before Dr.Jit is imported.
"""
from __future__ import annotations

import glob
import os

ENV = "DRJIT_LIBLLVM_PATH"
#: Newest first: the first that exists is used.
CANDIDATES = ("/usr/lib/x86_64-linux-gnu/libLLVM-19.so", "/usr/lib/aarch64-linux-gnu/libLLVM-19.so",
              "/usr/lib/llvm-19/lib/libLLVM-19.so", "/usr/lib/llvm-19/lib/libLLVM.so.1")


def find_libllvm() -> str | None:
    """Path of an LLVM 19 shared library on this machine, or None."""
    for p in CANDIDATES:
        if os.path.isfile(p):
            return p
    hits = sorted(glob.glob("/usr/lib/*/libLLVM-19.so*") + glob.glob("/usr/lib/*/libLLVM.so.19*"))
    return hits[0] if hits else None


def point_drjit_at_llvm() -> str | None:
    """Sets ``DRJIT_LIBLLVM_PATH`` to LLVM 19 when it is unset; returns the
    path in force (None: Dr.Jit searches on its own)."""
    if os.environ.get(ENV):
        return os.environ[ENV]
    path = find_libllvm()
    if path is not None:
        os.environ[ENV] = path
    return path
