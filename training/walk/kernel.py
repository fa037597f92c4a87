"""One path of the walk (``path``) and the CPU entry point over work items
(``run``): the path's start, its free flights, the vertex loop with the
pending copies of a split path, and Russian roulette. The vertices' work is
in ``vertices``; ``training.walk_cuda`` runs the same ``path`` on a GPU."""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from nbrdf.training.walk.ggx import INV_4PI, conductor_f, survival
from nbrdf.training.walk.interfaces import ft_pdf, ft_sample
from nbrdf.training.walk.params import JIT, JIT_INLINE
from nbrdf.training.walk.rng import (
    ENTRY,
    ENTRY_CONNECTION,
    FLIGHT_DIMS,
    ROULETTE_DIMS,
    START_DIMS,
    START_DIMS_CONNECTION,
    lane_key,
    uniform,
)
from nbrdf.training.walk.splitting import UNSPLIT, pop_copy, split_at_top, split_guide
from nbrdf.training.walk.strategies import connection, pair_of, setup_of
from nbrdf.training.walk.vertices import NO_CONNECTION, base_vertex, interior_vertex, scatter_vertex, top_vertex


@njit(**JIT_INLINE)
def enter(ix, iy, iz, s, spp, q, T, M, b_r0, b_f82, key, out):
    """The path's start from wi = (ix, iy, iz): the entry refraction at the
    top (the first uniform stratified by the sample index s of spp) and, with
    the connection, its two strategies from the entry (into ``out``, zeroed
    first). Returns (d, the entry weight, the counter after the start, C4 of d)."""
    u0 = (s + uniform(key, ENTRY)) / spp
    dx, dy, dz, w_entry, _ = ft_sample(T.a0, T.ay0, T.e0, ix, iy, iz, u0, uniform(key, ENTRY + 1))
    for c in range(out.shape[0]):
        out[c] = 0.0
    if not M.conn:
        return dx, dy, dz, w_entry, START_DIMS, NO_CONNECTION
    u = (uniform(key, ENTRY_CONNECTION), uniform(key, ENTRY_CONNECTION + 1), uniform(key, ENTRY_CONNECTION + 2),
         uniform(key, ENTRY_CONNECTION + 3), uniform(key, ENTRY_CONNECTION + 4), uniform(key, ENTRY_CONNECTION + 5),
         uniform(key, ENTRY_CONNECTION + 6), uniform(key, ENTRY_CONNECTION + 7))
    k, x, kd, xd = connection(ix, iy, iz, T, 1.0, False, M.a_wide, M.agw, u, True)
    for c in range(out.shape[0]):
        r0, b = b_r0[q, c], b_f82[q, c]
        out[c] += k * conductor_f(x, r0, b) + kd * conductor_f(xd, r0, b)
    C4 = (ft_pdf(T.a0, T.ay0, T.e0, ix, iy, iz, dx, dy, dz), ft_pdf(T.a0, T.ay0, T.e0, T.ox, T.oy, T.oz, -dx, -dy, dz),
          ft_pdf(M.agw, M.agw, T.e0, T.ox, T.oy, T.oz, -dx, -dy, dz), survival(T.tau0, 1.0, dz))
    return dx, dy, dz, w_entry, START_DIMS_CONNECTION, C4


@njit(**JIT_INLINE)
def flight(tau, slab, depth, dz, u):
    """A free flight from ``depth`` along dz in a slab of optical thickness
    tau: (whether it scatters inside the slab, the depth it reaches if so)."""
    if tau > 0.0:
        if dz < 0.0:
            dist_b = (slab + 1.0 - depth) / max(-dz, 1e-12)
        else:
            dist_b = (depth - slab) / max(dz, 1e-12)
        t = -math.log(1.0 - u) / tau  # 1 - u is exact (u: a multiple of 2^-53); log is 2.5x cheaper than log1p
        if t < dist_b:
            return True, depth - t * dz
    return False, depth


@njit(**JIT_INLINE)
def roulette(M, alive, bounces, kscale, beta, u):
    """Whether the path stops after a vertex: dead, no weight left, or Russian
    roulette from ``rr_depth`` on (forced walk: the weight window on the
    unsplit weight; plain walk: survival min(weight, 0.95)). Survivors'
    weights are divided by their survival probability."""
    if not alive:
        return True
    bmax = 0.0
    for c in range(beta.shape[0]):
        bmax = max(bmax, beta[c])
    if not bmax > 0.0:
        return True
    if bounces >= M.rr_depth:
        qs = min(bmax * kscale / M.rr_weight, 1.0) if M.forced else min(bmax, 0.95)
        if u >= qs:
            return True
        for c in range(beta.shape[0]):
            beta[c] /= qs
    return False


@njit(**JIT)
def path(q, s, P, out, beta, stk):
    """Path s of pair q: writes its contribution per channel to ``out`` and
    returns the number of vertices (``beta``: scratch of C weights; ``stk``:
    scratch of the pending copies of a split path, (kmax - 1, 7 + C))."""
    rough, ior, sigma, alb, b_r0, b_f82, b_alb = P.rough, P.ior, P.sigma, P.alb, P.b_r0, P.b_f82, P.b_alb
    L = rough.shape[1]
    key = key0 = lane_key(P.seed, q * P.spp + s)
    T, M = pair_of(P, q), setup_of(P, q)
    dx, dy, dz, w_entry, ctr, C4 = enter(P.wi[q, 0], P.wi[q, 1], P.wi[q, 2], s, P.spp, q, T, M, b_r0, b_f82, key, out)
    if w_entry <= 0.0:
        return 0
    for c in range(beta.shape[0]):
        beta[c] = w_entry
    guide = split_guide(T, M.a_wide) if M.split else (0.0, 0.0, 0.0, 0.0)
    sp = UNSPLIT
    depth, slab, pdf_last, vertices, bounces = 0.0, 0, 0.0, 0, 0
    scat = seg_on = resume = False
    seg = (0.0, 0.0, 0.0, 0.0, 1.0)  # the walk's segment toward the top: its first direction, density, survival
    while True:
        if bounces >= P.max_depth:
            if sp[3] == 0:
                break
            dx, dy, dz, bounces, sp, key = pop_copy(stk, sp, key0, beta)
            ctr, resume, slab, depth = 0, True, 0, 0.0
        bounces += 1
        vertices += 1
        z0 = depth
        scatter, depth = flight(sigma[q, slab], slab, depth, dz, uniform(key, ctr))
        ctr += FLIGHT_DIMS
        alive = True
        seg_in, seg_on = seg_on, False  # the segment reaches the top only without a vertex between
        scat_prev, scat = scat, scatter
        if scatter:
            C4 = NO_CONNECTION  # the connection makes only unscattered segments
            dx, dy, dz, ctr = scatter_vertex(q, T, M, alb, b_r0, b_f82, slab, depth, key, ctr, out, beta)
            pdf_last = INV_4PI
        else:
            k_if = slab + 1 if dz < 0.0 else slab
            depth = slab + 1.0 if dz < 0.0 else float(slab)
            wx, wy, wz = -dx, -dy, -dz
            if k_if == 0:
                nx, ny, nz, wgt, p, ctr, C4n = top_vertex(q, T, M, b_r0, b_f82, wx, wy, wz, pdf_last, C4, seg_in, seg,
                                                          scat_prev, resume, key, ctr, out, beta)
                if M.split and not resume:
                    sp = split_at_top(wx, wy, wz, T, guide, M.a_wide, M.kmax, M.kstep, M.ifloor, bounces, sp, beta,
                                      stk)
                C4 = C4n
                alive = p > 0.0 and nz < 0.0 and wgt > 0.0
                for c in range(beta.shape[0]):
                    beta[c] *= wgt
            elif k_if < L:
                nx, ny, nz, wgt, p, t1, ctr = interior_vertex(T, k_if, rough[q, k_if], P.rough_y[q, k_if], ior[q, k_if],
                                                              wx, wy, wz, dz, z0, pdf_last, M.chain, key, ctr, out,
                                                              beta)
                alive = p > 0.0 and wgt > 0.0
                if M.chain and alive and wz < 0.0 and nz > 0.0:  # up through interface 1: the segment starts
                    seg_on, seg = True, (-wx, -wy, -wz, pdf_last, t1)
                if alive and wz * nz < 0.0:  # crossed: down into slab k, up into slab k - 1
                    slab = k_if if dz < 0.0 else k_if - 1
                for c in range(beta.shape[0]):
                    beta[c] *= wgt
            else:
                nx, ny, nz, p, alive, starts, ctr = base_vertex(q, T, M, b_r0, b_f82, b_alb, L, wx, wy, wz, depth, pdf_last,
                                                                C4, scat_prev, key, ctr, out, beta)
                if starts:
                    seg_on, seg = True, (wx, wy, wz, pdf_last, seg[4])
            dx, dy, dz, pdf_last = nx, ny, nz, p
        stop = roulette(M, alive, bounces, sp[0], beta, uniform(key, ctr))
        ctr += ROULETTE_DIMS
        if stop:
            if sp[3] == 0:
                break
            bounces = P.max_depth  # the next pending copy of a split path
        else:
            resume = False
    return vertices


@njit(**JIT)
def add_path(out, s1, s2, it):
    """Adds a path's contribution to work item ``it``'s sums; 1 if it was
    dropped (a non-finite channel), else 0."""
    C = out.shape[0]
    for c in range(C):
        if not math.isfinite(out[c]):
            return 1
    for c in range(C):
        s1[it, c] += out[c]
        s2[it, c] += out[c] * out[c]
    return 0


@njit(parallel=True, **JIT)
def run(P):
    """Per work item (pair, block of ``P.block`` paths): the sum and the sum of
    squares of the path contributions per channel, the number of vertices and
    of dropped (non-finite) paths."""
    N = P.wi.shape[0]
    C = P.alb.shape[2]
    nb = (P.spp + P.block - 1) // P.block
    items = N * nb
    s1 = np.zeros((items, C))
    s2 = np.zeros((items, C))
    verts = np.zeros(items, dtype=np.int64)
    dropped = np.zeros(items, dtype=np.int64)
    for it in prange(items):
        q = it // nb
        b = it - q * nb
        out = np.empty(C)
        beta = np.empty(C)
        stk = np.empty((max(P.kmax - 1, 1), 7 + C))
        for s in range(b * P.block, min(P.spp, (b + 1) * P.block)):
            verts[it] += path(q, s, P, out, beta, stk)
            dropped[it] += add_path(out, s1, s2, it)
    return s1, s2, verts, dropped
