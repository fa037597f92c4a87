"""nbrdf materials in Mitsuba 3 (optional extra ``mitsuba``).

``import nbrdf.mitsuba`` registers two BSDF plugins for the Mitsuba variant
in force (``llvm_ad_rgb`` when none is set):

- ``{"type": "nbrdf", "material": PATH}``: the neural material (a material
  JSON, or a code file from ``nbrdf project``), evaluated in Mitsuba's kernel;
- ``{"type": "nbrdf_reference", "material": PATH}``: its Monte Carlo ground
  truth, a stochastic estimate per query (render inside ``wavefront_mode()``).

After ``mi.set_variant`` to another variant, call ``register()`` again.
Dr.Jit is pointed at LLVM 19 (``llvm.point_drjit_at_llvm``) before it loads.

This module is the package's one entry point to Mitsuba: importing any
``nbrdf.mitsuba.*`` module runs it first, so the variant is set before the
other modules run, and they import mitsuba and drjit at their top.
"""
from __future__ import annotations

from nbrdf.mitsuba.llvm import point_drjit_at_llvm

point_drjit_at_llvm()

import mitsuba as mi  # noqa: E402

#: Variants the plugins are made for: ``cuda_ad_rgb`` runs the same code but is not tested here.
VARIANTS = ("llvm_ad_rgb", "cuda_ad_rgb")
DEFAULT_VARIANT = "llvm_ad_rgb"


def _ensure_variant() -> str:
    if mi.variant() is None:
        try:
            mi.set_variant(DEFAULT_VARIANT)
        except Exception as e:  # noqa: BLE001 - Dr.Jit reports a missing LLVM in its own words
            raise ImportError(f"nbrdf.mitsuba: Mitsuba's {DEFAULT_VARIANT} variant is unusable ({e}); install "
                              "LLVM 19 (apt-get install libllvm19) or set DRJIT_LIBLLVM_PATH") from None
    return mi.variant()


# every plugin module may import mitsuba and drjit at its top: they run after this line
_ensure_variant()

from nbrdf.mitsuba import bsdf  # noqa: E402
from nbrdf.mitsuba.bsdf import NbrdfBSDF, NbrdfReferenceBSDF  # noqa: E402
from nbrdf.mitsuba.errors import PluginError  # noqa: E402
from nbrdf.mitsuba.modes import wavefront_mode  # noqa: E402


def register() -> str:
    """Registers ``nbrdf`` and ``nbrdf_reference`` for the current variant
    (``llvm_ad_rgb`` when none is set); returns the variant."""
    variant = _ensure_variant()
    mi.register_bsdf("nbrdf", lambda props: bsdf.NbrdfBSDF(props))
    mi.register_bsdf("nbrdf_reference", lambda props: bsdf.NbrdfReferenceBSDF(props))
    return variant


register()

__all__ = ["register", "NbrdfBSDF", "NbrdfReferenceBSDF", "PluginError", "wavefront_mode", "VARIANTS"]
