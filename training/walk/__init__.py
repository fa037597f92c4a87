"""The compiled per-lane random walk behind ``training.layered.simulate``.

One path per lane, written as scalar code and compiled by Numba (``kernel``:
``parallel=True``, ``cache=True``; on a GPU ``training.walk_cuda`` runs the
same code): work items are (pair, block of paths), spread over the threads.
Random numbers are counter based (``rng``), so a result depends on the seed
and the batch only, never on the number of threads or on how work is split.

The parts, each a module:

- ``params``: the tuning constants and ``WalkParams``, the one record the
  CPU and CUDA entry points take;
- ``rng``: the hash and the named random dimensions of each vertex kind;
- ``ggx``, ``interfaces``: the interface kinds (rough dielectric, conductor,
  diffuse, isotropic medium), each with its eval / sample / pdf kernels;
- ``strategies``: next-event estimation, the chains, the two-bounce
  connection and the closed-form exit, each with its MIS weight;
- ``splitting``: splitting by exit importance;
- ``vertices``: what happens at a scattering, the top, an interior
  interface and the base;
- ``kernel``: one path (start, flights, vertices, roulette) and ``run``.

Physics: SPEC section 5 and ``training.layered``; anisotropic interfaces (SPEC
section 10): every roughness is a pair (alpha_x, alpha_y) and the pairs come
in the material's rotated tangent frame (``training.layered._walk_frame``). The estimator's design and
its measurements: docs/decisions/001-009 and 061.
"""
from nbrdf.training.walk.params import BLOCK, RR_WEIGHT, WalkParams, walk_params

__all__ = ["BLOCK", "RR_WEIGHT", "WalkParams", "walk_params"]
