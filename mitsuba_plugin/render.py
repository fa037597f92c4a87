"""Path tracing a scene (``scenes.Scene``) in Mitsuba 3, in chunks of samples
per pixel so that a progress bar can follow it and a caller can stop at a
time budget. Each chunk is an independent render with its own seed; the image
is their average (equal weights: every chunk has the same spp).

Scenes with nbrdf materials render in Dr.Jit's wavefront mode on the LLVM
backend (``modes.wants_wavefront``): the reference needs it, and the neural
decoder runs about ten times faster there than inside a symbolic call. A scene
whose neural materials all read their body from a table (``body: "table"``)
and that has no reference renders in symbolic mode, its fastest."""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, ContextManager

import drjit as dr
import mitsuba as mi
import numpy as np

from nbrdf.mitsuba.modes import wants_wavefront, wavefront_mode
from nbrdf.mitsuba.scenes import Scene, mitsuba_dict, neural_bodies, uses_reference

#: Samples per pixel per ``mi.render`` call unless asked otherwise.
CHUNK_SPP = 4


@dataclass
class RenderResult:
    """A rendered image and what it cost."""

    image: np.ndarray
    """linear RGB (H, W, 3) float32, row 0 at the top"""
    spp: int
    """samples per pixel in the image"""
    seconds: float
    """wall time of the sampling (scene loading excluded), less ``compile_seconds``"""
    chunks: list[np.ndarray]
    """the per-chunk images (kept when asked, for noise estimates), else empty"""
    compile_seconds: float = 0.0
    """LLVM compilation of kernels missing from Dr.Jit's cache during the
    sampling (a one-off cost per kernel, not per sample): excluded from
    ``seconds`` when the render was asked to (``exclude_compile``), else 0"""


def load(scene: Scene, size: tuple[int, int], chunk_spp: int = CHUNK_SPP):
    """The Mitsuba scene object (the package's import registered the plugins)."""
    return mi.load_dict(mitsuba_dict(scene, size, chunk_spp))


def is_wavefront(scene: Scene) -> bool:
    """Whether ``render`` renders ``scene`` in Dr.Jit's wavefront mode (module docstring)."""
    return uses_reference(scene) or any(wants_wavefront(b) for b in neural_bodies(scene))


def render(scene: Scene, size: tuple[int, int], spp: int, seed: int = 0, chunk_spp: int = CHUNK_SPP,
           progress: Callable[[int], None] | None = None, keep_chunks: bool = False, loaded=None,
           max_seconds: float | None = None, exclude_compile: bool = False,
           enter_wavefront: Callable[[], ContextManager] = wavefront_mode) -> RenderResult:
    """Renders ``spp`` samples per pixel (rounded up to whole chunks) in chunks
    of ``chunk_spp``, seeds ``seed * 100003 + k``; ``progress(spp_done)`` after
    each chunk. With ``max_seconds`` it stops after the chunk that crosses it.
    ``exclude_compile``: the time spent compiling kernels that Dr.Jit had not
    cached (its kernel history) is taken out of the time, so that a timing
    measures sampling: in wavefront mode a wavefront that happens to hold one
    lane gets kernels of its own, compiled the first time they occur.
    ``enter_wavefront``: what enters the wavefront mode (``modes.wavefront_mode``;
    a test passes one that records its use)."""
    chunk_spp = max(1, min(chunk_spp, spp))
    n_chunks = -(-spp // chunk_spp)
    mscene = loaded if loaded is not None else load(scene, size, chunk_spp)
    acc = np.zeros((size[1], size[0], 3), np.float64)
    chunks: list[np.ndarray] = []
    done = 0
    t0 = time.perf_counter()
    compile_s = 0.0
    wavefront = is_wavefront(scene)
    history = dr.flag(dr.JitFlag.KernelHistory)
    if exclude_compile:
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        dr.kernel_history()  # drop what came before
    for k in range(n_chunks):
        if wavefront:
            with enter_wavefront():
                img = mi.render(mscene, seed=seed * 100003 + k, spp=chunk_spp)
        else:
            img = mi.render(mscene, seed=seed * 100003 + k, spp=chunk_spp)
        dr.eval(img)
        arr = np.array(img, np.float32).reshape(size[1], size[0], 3)
        if exclude_compile:
            compile_s += sum(e.get("backend_time", 0.0) for e in dr.kernel_history()
                             if e.get("type") == dr.KernelType.JIT and not e.get("cache_hit", True)) / 1000.0
        acc += arr
        if keep_chunks:
            chunks.append(arr)
        done += 1
        if progress is not None:
            progress(done * chunk_spp)
        if max_seconds is not None and time.perf_counter() - t0 - compile_s >= max_seconds:
            break
    seconds = time.perf_counter() - t0 - compile_s
    dr.set_flag(dr.JitFlag.KernelHistory, history)
    return RenderResult((acc / done).astype(np.float32), done * chunk_spp, seconds, chunks, compile_s)
