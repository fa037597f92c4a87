"""Counter-based random numbers and the walk's named random dimensions.

The k-th uniform of path (pair, sample) is a hash of (seed, pair * spp +
sample, k), so a result depends on the seed and the batch only, never on the
number of threads or on how work is split. A path reads its numbers in a
fixed order: the start's dimensions, then per vertex its flight's, the
vertex's own (by kind, below) and the roulette's. Each constant is an offset
from the first counter of its block; ``*_DIMS`` is the size of the block."""
from __future__ import annotations

import numpy as np
from numba import njit

from nbrdf.training.walk.params import JIT

# --- the path's start -------------------------------------------------------------------------
#: The entry refraction at the top (2: the first stratified by the path's index).
ENTRY = 0
#: The two-bounce connection from the entry: strategy C (4), then D (4).
ENTRY_CONNECTION = 2
START_DIMS = 2
START_DIMS_CONNECTION = 10

# --- every vertex -----------------------------------------------------------------------------
#: The free flight that reaches the vertex (1), before the vertex's own block.
FLIGHT_DIMS = 1
#: Russian roulette after the vertex (1).
ROULETTE_DIMS = 1

# --- a scattering in a medium -----------------------------------------------------------------
#: Next-event estimation through the top (2; in slab 0).
SCATTER_NEE = 0
#: The chain through both interfaces (4; a scattering in slab 1 of a
#: two-interface stack, in place of SCATTER_NEE).
SCATTER_CHAIN = 0
#: The chain by way of a sharp base (4), then the choice to draw it (1).
SCATTER_MIRROR = 2
SCATTER_MIRROR_PICK = 6
SCATTER_DIMS = 2
SCATTER_DIMS_CHAIN = 4
SCATTER_DIMS_MIRROR = 7
#: The phase function's direction (2), after the scattering's block.
PHASE_DIMS = 2

# --- the top interface seen from below --------------------------------------------------------
#: The reflection (or the plain walk's Fresnel-chosen sample): 3.
TOP_SAMPLE = 0
#: The two-bounce connection from this vertex: strategy C (4), then D (4).
TOP_CONNECTION = 3
TOP_DIMS = 3
TOP_DIMS_CONNECTION = 11

# --- an interior interface --------------------------------------------------------------------
#: Next-event estimation through the top (2), then the interface's sample (3).
INTERIOR_NEE = 0
INTERIOR_SAMPLE = 2
INTERIOR_DIMS = 5

# --- the base ---------------------------------------------------------------------------------
#: The chain through both interfaces (4; a two-interface stack): its block comes
#: first and moves the rest by BASE_CHAIN_DIMS.
BASE_CHAIN = 0
BASE_CHAIN_DIMS = 2
#: Next-event estimation through the top (2; one-interface stacks), then the
#: base's sample (3).
BASE_NEE = 0
BASE_SAMPLE = 2
BASE_DIMS = 5


@njit(**JIT)
def mix64(x):
    """SplitMix64's finaliser (a bijective 64-bit hash)."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@njit(**JIT)
def lane_key(seed, lane):
    """The key of a path (lane = pair * spp + sample)."""
    return mix64(mix64(np.uint64(seed) + np.uint64(0x632BE59BD9B4E019)) ^ np.uint64(lane))


@njit(**JIT)
def uniform(key, counter):
    """The counter-th uniform in [0, 1) of the lane with this key: SplitMix64
    of a Weyl sequence started at the key (53 random bits)."""
    h = mix64(key + np.uint64(counter + 1) * np.uint64(0x9E3779B97F4A7C15))
    return float(h >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(**JIT)
def split_key(key0, copy):
    """The random-number key of copy ``copy`` (>= 1) of a split path."""
    return mix64(key0 ^ (np.uint64(copy) * np.uint64(0xD1B54A32D192ED03)))
