"""The walk's vertices by kind: a scattering in a medium, the top seen from
below, an interior interface, the base. Each adds its strategies'
contributions to ``out`` (per channel, times the path weight ``beta``), draws
the walk's next direction through its interface kind's kernels, and returns
the counter after its block of random numbers (``rng``'s named dimensions).

``C4`` = (pm, pg, pw, tg): the densities of the current downward direction
under the walk's top mixture, the connection's guide (C) and wide guide (D),
and its flight's survival (``NO_CONNECTION``: no top vertex before it)."""
from __future__ import annotations

from numba import njit

from nbrdf.training.walk.ggx import conductor_f, g1_dir, survival
from nbrdf.training.walk.interfaces import (
    CONDUCTOR,
    DIFFUSE,
    cond_sample,
    diel_sample,
    diffuse_sample,
    phase_sample,
    top_reflection,
)
from nbrdf.training.walk.params import JIT_INLINE, MIRROR_CHAIN_P
from nbrdf.training.walk.rng import (
    BASE_CHAIN,
    BASE_CHAIN_DIMS,
    BASE_DIMS,
    BASE_NEE,
    BASE_SAMPLE,
    INTERIOR_DIMS,
    INTERIOR_NEE,
    INTERIOR_SAMPLE,
    PHASE_DIMS,
    SCATTER_CHAIN,
    SCATTER_DIMS,
    SCATTER_DIMS_CHAIN,
    SCATTER_DIMS_MIRROR,
    SCATTER_MIRROR,
    SCATTER_MIRROR_PICK,
    SCATTER_NEE,
    TOP_CONNECTION,
    TOP_DIMS,
    TOP_DIMS_CONNECTION,
    TOP_SAMPLE,
    uniform,
)
from nbrdf.training.walk.strategies import (
    base_chain,
    base_nee,
    connection,
    connection_densities,
    interior_nee,
    nee,
    scatter_chain,
    scatter_mirror_chain,
    scatter_nee,
    top_exit,
)

NO_CONNECTION = (1.0, 0.0, 0.0, 1.0)


@njit(**JIT_INLINE)
def scatter_vertex(q, T, M, alb, b_r0, b_f82, slab, depth, key, ctr, out, beta):
    """A scattering at ``depth`` in ``slab``: next-event estimation (slab 0),
    the chain by way of the base (``mirror``) or through both interfaces
    (slab 1, ``chain``), the albedo into beta and the phase function's
    direction. Returns (d, counter). T: the pair's ``Pair``, M: the path's
    ``Setup``; alb, b_r0, b_f82: the slabs' albedos, the base's r0 and F82 coefficient (all pairs)."""
    C = out.shape[0]
    dims = SCATTER_DIMS
    if slab == 0:
        k = scatter_nee(depth, T, uniform(key, ctr + SCATTER_NEE), uniform(key, ctr + SCATTER_NEE + 1))
        if k != 0.0:
            for c in range(C):
                out[c] += beta[c] * alb[q, slab, c] * k
        if M.mirror and uniform(key, ctr + SCATTER_MIRROR_PICK) < MIRROR_CHAIN_P:
            k, x = scatter_mirror_chain(depth, T, uniform(key, ctr + SCATTER_MIRROR),
                                        uniform(key, ctr + SCATTER_MIRROR + 1), uniform(key, ctr + SCATTER_MIRROR + 2),
                                        uniform(key, ctr + SCATTER_MIRROR + 3))
            if k != 0.0:
                for c in range(C):
                    out[c] += beta[c] * alb[q, slab, c] * k * conductor_f(x, b_r0[q, c], b_f82[q, c])
        if M.mirror:
            dims = SCATTER_DIMS_MIRROR
    elif M.chain and slab == 1:
        k = scatter_chain(depth, T, uniform(key, ctr + SCATTER_CHAIN),
                          uniform(key, ctr + SCATTER_CHAIN + 1), uniform(key, ctr + SCATTER_CHAIN + 2),
                          uniform(key, ctr + SCATTER_CHAIN + 3))
        if k != 0.0:
            for c in range(C):
                out[c] += beta[c] * alb[q, slab, c] * k
        dims = SCATTER_DIMS_CHAIN
    for c in range(C):
        beta[c] *= alb[q, slab, c]
    ctr += dims
    dx, dy, dz = phase_sample(uniform(key, ctr), uniform(key, ctr + 1))
    return dx, dy, dz, ctr + PHASE_DIMS


@njit(**JIT_INLINE)
def top_vertex(q, T, M, b_r0, b_f82, wx, wy, wz, pdf_last, C4, seg_in, seg, scat_prev, resume, key, ctr, out, beta):
    """The top seen from below (w toward where the light came from): the exit
    toward wo (unless ``resume``: a split copy, whose vertex was evaluated),
    the walk's reflection (forced) or its Fresnel-chosen sample (plain walk),
    and the two-bounce connection from here. Returns (n, the weight factor, its
    density, counter, the new C4); beta is left for the caller (splitting
    comes first)."""
    C = out.shape[0]
    g1w = g1_dir(wx, wy, wz, T.a0, T.ay0)
    if not resume:
        tu = survival(T.tau0, 1.0, wz) if M.conn and not scat_prev else 1.0  # the walk's flight up (its density)
        k = top_exit(wx, wy, wz, T, g1w, pdf_last, C4, tu, seg_in, M.mirror, seg[0], seg[1], seg[2], seg[3], seg[4])
        if k != 0.0:
            for c in range(C):
                out[c] += beta[c] * k
    u0, u1, u2 = uniform(key, ctr + TOP_SAMPLE), uniform(key, ctr + TOP_SAMPLE + 1), uniform(key, ctr + TOP_SAMPLE + 2)
    if not M.forced:
        nx, ny, nz, wgt, p = diel_sample(wx, wy, wz, T.a0, T.ay0, T.e0, u0, u1, u2)
        return nx, ny, nz, wgt, p, ctr + TOP_DIMS, C4
    nx, ny, nz, wgt, p, lm, wide = top_reflection(wx, wy, wz, T.a0, T.ay0, T.e0, T.tau0, M.conn, M.lam, M.lam_w,
                                                  M.a_wide, g1w, T.ox, T.oy, T.oz, u0, u1, u2)
    if not M.conn:
        return nx, ny, nz, wgt, p, ctr + TOP_DIMS, C4
    if not resume:
        u = (uniform(key, ctr + TOP_CONNECTION), uniform(key, ctr + TOP_CONNECTION + 1),
             uniform(key, ctr + TOP_CONNECTION + 2), uniform(key, ctr + TOP_CONNECTION + 3),
             uniform(key, ctr + TOP_CONNECTION + 4), uniform(key, ctr + TOP_CONNECTION + 5),
             uniform(key, ctr + TOP_CONNECTION + 6), uniform(key, ctr + TOP_CONNECTION + 7))
        k, x, kd, xd = connection(wx, wy, wz, T, lm, wide, M.a_wide, M.agw, u, False)
        for c in range(C):
            r0, b = b_r0[q, c], b_f82[q, c]
            out[c] += beta[c] * (k * conductor_f(x, r0, b) + kd * conductor_f(xd, r0, b))
    C4 = connection_densities(T.a0, T.ay0, T.e0, M.agw, T.tau0, T.ox, T.oy, T.oz, p, nx, ny, nz)
    return nx, ny, nz, wgt, p, ctr + TOP_DIMS_CONNECTION, C4


@njit(**JIT_INLINE)
def interior_vertex(T, k_if, a, ay, e, wx, wy, wz, dz, z0, pdf_last, chain, key, ctr, out, beta):
    """Interface ``k_if`` (> 0; roughness (a, ay), index e), reached along d (dz) from depth z0: next-event
    estimation through the top (interface 1) and the interface's sample.
    Returns (n, weight factor, density, t1, counter); t1: the survival of the
    walk's flight from slab 1 (the chain's segment starts with it)."""
    below = chain and wz < 0.0
    t1 = 1.0
    if k_if == 1:
        t1 = survival(T.tau1, z0 - 1.0, dz) if below else 1.0
        k = interior_nee(wx, wy, wz, T, a, ay, e, pdf_last, below, t1, uniform(key, ctr + INTERIOR_NEE),
                         uniform(key, ctr + INTERIOR_NEE + 1))
        if k != 0.0:
            for c in range(out.shape[0]):
                out[c] += beta[c] * k
    nx, ny, nz, wgt, p = diel_sample(wx, wy, wz, a, ay, e, uniform(key, ctr + INTERIOR_SAMPLE),
                                     uniform(key, ctr + INTERIOR_SAMPLE + 1), uniform(key, ctr + INTERIOR_SAMPLE + 2))
    return nx, ny, nz, wgt, p, t1, ctr + INTERIOR_DIMS


@njit(**JIT_INLINE)
def base_vertex(q, T, M, b_r0, b_f82, b_alb, L, wx, wy, wz, depth, pdf_last, C4, scat_prev, key, ctr, out, beta):
    """The base (w toward where the light came from): next-event estimation
    through the top (one interface) or through both (two), and the base's
    sample with its weight into beta. Returns (n, density, alive, whether the
    walk's segment by way of the base starts here, counter)."""
    C = out.shape[0]
    base, ba, bay, be = M.base, T.ba, T.bay, T.be
    sc = pn = vx = vy = vz = 0.0
    if L == 1:
        vx, vy, vz, sc, pn = nee(1.0, T.sx, T.sy, T.sz, T.g1o, T.ox, T.oy, T.oz, T.a0, T.ay0, T.e0, T.tau0,
                                 uniform(key, ctr + BASE_NEE), uniform(key, ctr + BASE_NEE + 1))
    g1w = g1_dir(wx, wy, wz, ba, bay) if base == CONDUCTOR else 0.0
    if M.chain and wz > 0.0:
        k, x = base_chain(base, wx, wy, wz, depth, T, g1w, uniform(key, ctr + BASE_CHAIN), uniform(key, ctr + BASE_CHAIN + 1),
                          uniform(key, ctr + BASE_CHAIN + 2), uniform(key, ctr + BASE_CHAIN + 3))
        if k != 0.0:
            for c in range(C):
                col = conductor_f(x, b_r0[q, c], b_f82[q, c]) if base == CONDUCTOR else (
                    b_alb[q, c] if base == DIFFUSE else 1.0)
                out[c] += beta[c] * k * col
        ctr += BASE_CHAIN_DIMS
    seg = base == CONDUCTOR and M.mirror and scat_prev and wz > 0.0  # the chain made this segment too
    if sc > 0.0:
        k, x = base_nee(base, wx, wy, wz, vx, vy, vz, sc, pn, ba, bay, be, g1w, pdf_last, seg, C4, M.conn, T.tau0)
        if k != 0.0:
            for c in range(C):
                if base == CONDUCTOR:
                    out[c] += beta[c] * k * conductor_f(x, b_r0[q, c], b_f82[q, c])
                elif base == DIFFUSE:
                    out[c] += beta[c] * b_alb[q, c] * k
                else:
                    out[c] += beta[c] * k
    u0, u1 = uniform(key, ctr + BASE_SAMPLE), uniform(key, ctr + BASE_SAMPLE + 1)
    if base == CONDUCTOR:
        nx, ny, nz, wgt, p, x = cond_sample(wx, wy, wz, ba, bay, g1w, u0, u1)
        alive = p > 0.0 and wgt > 0.0
        for c in range(C):
            beta[c] *= wgt * conductor_f(x, b_r0[q, c], b_f82[q, c])
    elif base == DIFFUSE:
        nx, ny, nz, p = diffuse_sample(u0, u1)
        alive = wz > 0.0 and p > 0.0
        for c in range(C):
            beta[c] *= b_alb[q, c] if alive else 0.0
    else:
        nx, ny, nz, wgt, p = diel_sample(wx, wy, wz, ba, bay, be, u0, u1, uniform(key, ctr + BASE_SAMPLE + 2))
        alive = p > 0.0 and nz > 0.0 and wgt > 0.0  # what is transmitted leaves the stack
        for c in range(C):
            beta[c] *= wgt if alive else 0.0
    return nx, ny, nz, p, alive, seg and alive, ctr + BASE_DIMS
