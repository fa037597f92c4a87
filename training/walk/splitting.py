"""Splitting by exit importance (the two-bounce connection's stacks over an
empty slab): at the top seen from below a path's level is its weight times
I(w), the coat's reflection density from its state w toward the centre g* of
the mirrored exit lobe. Each time the level doubles against the one the path
started at, the path splits into copies of weight beta / k (unbiased: a split
divides the weight by the number of copies); roulette keeps using the
unsplit weight (beta times ``kscale``, the product of the split factors).

The split state is the tuple (kscale, lref, ntot, nstk): lref the level the
path started at times kscale, ntot the copies made so far, nstk the pending
ones, kept as rows of ``stk`` (w, bounces, kscale, lref, copy number, then the
weights per channel)."""
from __future__ import annotations

import math

from numba import njit

from nbrdf.training.walk.interfaces import top_eval
from nbrdf.training.walk.params import JIT
from nbrdf.training.walk.rng import split_key

#: The split state of a path that has not split.
UNSPLIT = (1.0, 0.0, 1, 0)


@njit(**JIT)
def split_guide(T, a_wide):
    """(g*, I at the state a flat facet turns into g*): g* the centre of the
    mirrored exit lobe toward wo, I's peak the floor's reference."""
    gsx, gsy = T.ox / T.e0, T.oy / T.e0
    gsz = -math.sqrt(max(1.0 - gsx * gsx - gsy * gsy, 0.0))
    i_peak, _ = top_eval(-gsx, -gsy, gsz, gsx, gsy, gsz, T.a0, T.ay0, T.e0, 1.0, False, a_wide, T.ox, T.oy, T.oz)
    return gsx, gsy, gsz, i_peak


@njit(**JIT)
def split_at_top(wx, wy, wz, T, guide, a_wide, kmax, kstep, ifloor, bounces, state, beta, stk):
    """At the top seen from below (w toward where the light came from, before
    the reflection is sampled): splits the path when its level has doubled,
    at most ``kstep`` ways here and ``kmax`` copies in all; pending copies are
    this vertex before its reflection. Returns the new split state."""
    gsx, gsy, gsz, i_peak = guide
    kscale, lref, ntot, nstk = state
    iv, _ = top_eval(wx, wy, wz, gsx, gsy, gsz, T.a0, T.ay0, T.e0, 1.0, False, a_wide, T.ox, T.oy, T.oz)
    C = beta.shape[0]
    bmax = 0.0
    for c in range(C):
        bmax = max(bmax, beta[c])
    lv = bmax * kscale * max(iv, ifloor * i_peak)
    if lref <= 0.0:
        lref = lv
    elif lv >= 2.0 * lref and ntot < kmax:
        ks = min(int(lv / lref), kstep, kmax - ntot + 1)
        kscale *= ks
        lref *= ks
        for _j in range(ks - 1):
            stk[nstk, 0], stk[nstk, 1], stk[nstk, 2] = wx, wy, wz
            stk[nstk, 3], stk[nstk, 4], stk[nstk, 5], stk[nstk, 6] = bounces - 1, kscale, lref, ntot
            for c in range(C):
                stk[nstk, 7 + c] = beta[c] / ks
            nstk += 1
            ntot += 1
        for c in range(C):
            beta[c] /= ks
    return kscale, lref, ntot, nstk


@njit(**JIT)
def pop_copy(stk, state, key0, beta):
    """The last pending copy: its direction d (toward the top), bounces, new
    split state and random-number key (``key0``: the path's); its weights
    into ``beta``."""
    kscale, lref, ntot, nstk = state
    nstk -= 1
    for c in range(beta.shape[0]):
        beta[c] = stk[nstk, 7 + c]
    key = split_key(key0, int(stk[nstk, 6]))
    return (-stk[nstk, 0], -stk[nstk, 1], -stk[nstk, 2], int(stk[nstk, 3]), (stk[nstk, 4], stk[nstk, 5], ntot, nstk),
            key)
