"""Issue 14, deliverable 2: a second compiled-walk library measured against Numba.

The per-lane walk of ``training.walk`` ported to NVIDIA Warp (CPU backend)
for the benchmark's stack class only: one rough dielectric top (GGX, VNDF
sampling), a homogeneous medium slab (free flight, isotropic phase), a rough
conductor base (Schlick), next-event estimation toward wo through the top
with MIS, the reciprocal start, Russian roulette as a weight window, and the
same counter-based random numbers (SplitMix64 of (seed, pair * spp + sample,
counter)). The fused kernels of "Walk speed" (docs/RESULTS.md) are ported as
they are, so the two walks run the same arithmetic and can be compared path
for path (they differ only by rounding: the compilers contract and
reassociate differently). The port is built with Numba's fast-math set
(``NUMBA_LIKE_FLAGS``) and, for comparison, with Warp's default flags. To
separate the library from the specialisation, the same specialised walk is
also written in Numba (``_path_std``, the "twin"): library against library
is twin against Warp; ``training.walk.run_walk`` (every stack class) is the
production figure.

Run (not part of the test suite; warp-lang is not a project dependency:
``.venv/bin/pip install warp-lang`` into the virtual environment first):

    nice -n 15 .venv/bin/python tools/bench_walk_warp.py [--quick] [--rounds 2]

It prints one JSON: the compile times (cold: a fresh kernel cache; cached),
the agreement with ``simulate`` (same seed: per-pair relative difference;
other seed: z-test per pair with a Bonferroni limit), the thread count of
each backend, and the alternated speed runs (every variant once per round)
on the inputs of ``nbrdf bench reference`` (4,096 pairs x 256 paths, seed 1),
wall and CPU time of this process. Without Warp it says so in one line and
exits with status 2.
"""
import argparse
import json
import math
import os
import sys
import tempfile
import time

try:
    import warp as wp
except ImportError:
    print("bench_walk_warp: the warp package is not importable (pip install warp-lang into the virtual environment)")
    sys.exit(2)

import numpy as np
from numba import njit, prange

from nbrdf.training import walk as W

wp.config.log_level = wp.LOG_WARNING  # the JSON alone on stdout (building the constants below initialises Warp)

D = wp.float64
INV_PI = wp.constant(D(1.0 / math.pi))
INV_4PI = wp.constant(D(1.0 / (4.0 * math.pi)))
TWO_PI = wp.constant(D(2.0 * math.pi))
PI = wp.constant(D(math.pi))
INV_2_53 = wp.constant(D(1.0 / 9007199254740992.0))
# Taylor coefficients of sin and cos (computed in Python: a literal expression
# inside a Warp kernel is evaluated in float32)
S3, S5, S7, S9 = (wp.constant(D(v)) for v in (-1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0))
S11, S13, S15 = (wp.constant(D(v)) for v in (-1.0 / 39916800.0, 1.0 / 6227020800.0, -1.0 / 1307674368000.0))
C4, C6, C8, C10 = (wp.constant(D(v)) for v in (1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0, -1.0 / 3628800.0))
C12, C14, C16 = (wp.constant(D(v)) for v in (1.0 / 479001600.0, -1.0 / 87178291200.0, 1.0 / 20922789888000.0))
M1 = wp.constant(wp.uint64(0xBF58476D1CE4E5B9))
M2 = wp.constant(wp.uint64(0x94D049BB133111EB))
SEED_OFS = wp.constant(wp.uint64(0x632BE59BD9B4E019))
WEYL = wp.constant(wp.uint64(0x9E3779B97F4A7C15))


# --- counter-based random numbers (training.walk._mix64, _lane_key, _uniform) -------------
@wp.func
def mix64(x: wp.uint64):
    x = (x ^ (x >> wp.uint64(30))) * M1
    x = (x ^ (x >> wp.uint64(27))) * M2
    return x ^ (x >> wp.uint64(31))


@wp.func
def lane_key(seed: wp.uint64, lane: wp.uint64):
    return mix64(mix64(seed + SEED_OFS) ^ lane)


@wp.func
def uniform(key: wp.uint64, counter: wp.int32):
    h = mix64(key + wp.uint64(counter + 1) * WEYL)
    return D(h >> wp.uint64(11)) * INV_2_53


# --- microfacet building blocks ----------------------------------------------------------
@wp.func
def cos_sin_2pi(u: D):
    q = wp.floor(D(4.0) * u + D(0.5))
    x = TWO_PI * (u - D(0.25) * q)
    x2 = x * x
    s = x * (D(1.0) + x2 * (S3 + x2 * (S5 + x2 * (S7 + x2 * (S9 + x2 * (S11 + x2 * (S13 + x2 * S15)))))))
    c = D(1.0) + x2 * (D(-0.5) + x2 * (C4 + x2 * (C6 + x2 * (C8 + x2 * (C10 + x2 * (C12 + x2 * (C14 + x2 * C16)))))))
    qi = wp.int32(q) & 3
    cc = c
    ss = s
    if (qi & 1) == 1:
        cc = s
        ss = c
    if qi == 1 or qi == 2:
        cc = -cc
    if qi >= 2:
        ss = -ss
    return cc, ss


@wp.func
def norm3(x: D, y: D, z: D):
    n = wp.sqrt(x * x + y * y + z * z)
    inv = D(1.0) / wp.max(n, D(1e-30))
    return x * inv, y * inv, z * inv


@wp.func
def ggx_d(mx: D, my: D, mz: D, a: D):
    if mz <= D(0.0):
        return D(0.0)
    a2 = a * a
    den = mx * mx + my * my + mz * mz * a2
    return a2 / (PI * den * den)


@wp.func
def g1_dir(wx: D, wy: D, wz: D, a: D):
    z = wp.abs(wz)
    den = z + wp.sqrt(wz * wz + a * a * (wx * wx + wy * wy))
    if den > D(0.0):
        return D(2.0) * z / den
    return D(0.0)


@wp.func
def vndf_std(vx: D, vy: D, vz: D, a: D, u1: D, u2: D):
    cph, sph = cos_sin_2pi(u2)
    z = (D(1.0) - u1) * (D(1.0) + vz) - vz
    st = wp.sqrt(wp.max(D(1.0) - z * z, D(0.0)))
    return norm3(a * (st * cph + vx), a * (st * sph + vy), wp.max(z + vz, D(1e-12)))


@wp.func
def sample_vndf(wx: D, wy: D, wz: D, a: D, u1: D, u2: D):
    sg = D(1.0)
    if wz < D(0.0):
        sg = D(-1.0)
    vx, vy, vz = norm3(a * sg * wx, a * sg * wy, sg * wz)
    return vndf_std(vx, vy, vz, a, u1, u2)


@wp.func
def fresnel(cos_i: D, eta: D):
    c = wp.min(wp.abs(cos_i), D(1.0))
    sin2_t = (D(1.0) - c * c) / (eta * eta)
    if sin2_t >= D(1.0):
        return D(1.0)
    cos_t = wp.sqrt(wp.max(D(1.0) - sin2_t, D(0.0)))
    rs = (c - eta * cos_t) / (c + eta * cos_t)
    rp = (eta * c - cos_t) / (eta * c + cos_t)
    return D(0.5) * (rs * rs + rp * rp)


@wp.func
def schlick5(c: D):
    t = D(1.0) - wp.min(wp.abs(c), D(1.0))
    t2 = t * t
    return t2 * t2 * t


@wp.func
def ft_core(sx: D, sy: D, sz: D, g1w: D, a: D, er: D, wx: D, wy: D, wz: D, u0: D, u1: D):
    """training.walk._ft_core: forced refraction of w through a VNDF facet,
    (tx, ty, tz, weight (1 - F) G1(t), pdf)."""
    mx, my, mz = vndf_std(sx, sy, sz, a, u0, u1)
    c = wx * mx + wy * my + wz * mz
    ei = D(1.0) / er
    k = D(1.0) - ei * ei * (D(1.0) - c * c)
    if c <= D(0.0) or k <= D(0.0):
        return D(0.0), D(0.0), D(1.0), D(0.0), D(0.0)
    ct = wp.sqrt(k)
    f = ei * c - ct
    tx = f * mx - ei * wx
    ty = f * my - ei * wy
    tz = f * mz - ei * wz
    th = tx * mx + ty * my + tz * mz
    den = c + er * th
    if wz * tz >= D(0.0) or th >= D(0.0) or wp.abs(den) <= D(1e-12):
        return tx, ty, tz, D(0.0), D(0.0)
    p = g1w * c * ggx_d(mx, my, mz, a) / wp.abs(wz) * er * er * (-th) / (den * den)
    if not (p > D(0.0)):
        return tx, ty, tz, D(0.0), D(0.0)
    rs = (c - er * ct) / (c + er * ct)
    rp = (er * c - ct) / (er * c + ct)
    F = D(0.5) * (rs * rs + rp * rp)
    g1t = D(0.0)
    if th * tz > D(0.0):
        g1t = g1_dir(tx, ty, tz, a)
    return tx, ty, tz, (D(1.0) - F) * g1t, p


@wp.func
def ft_sample(a: D, er: D, wx: D, wy: D, wz: D, u0: D, u1: D):
    sx, sy, sz = norm3(a * wx, a * wy, wp.abs(wz))
    return ft_core(sx, sy, sz, g1_dir(wx, wy, wz, a), a, er, wx, wy, wz, u0, u1)


@wp.func
def nee(z: D, sx: D, sy: D, sz: D, g1o: D, ox: D, oy: D, oz: D, a0: D, e0: D, tau0: D, u0: D, u1: D):
    """training.walk._nee: (vx, vy, vz, Tr f_top / pdf, pdf) toward wo."""
    tx, ty, tz, w, p = ft_core(sx, sy, sz, g1o, a0, e0, ox, oy, oz, u0, u1)
    if p <= D(0.0) or w <= D(0.0):
        return D(0.0), D(0.0), D(1.0), D(0.0), D(0.0)
    vz = -tz
    tr = D(1.0)
    if tau0 > D(0.0):
        tr = wp.exp(-tau0 * z / wp.max(vz, D(1e-12)))
    return -tx, -ty, vz, tr * w / (e0 * e0 * vz), p


@wp.func
def exit_eval(wx: D, wy: D, wz: D, ox: D, oy: D, oz: D, g1w: D, g1o: D, a: D, eta: D):
    """training.walk._exit_eval: (f toward wo, its next-event pdf)."""
    if wz == D(0.0) or oz == D(0.0):
        return D(0.0), D(0.0)
    hx, hy, hz = norm3(-(eta * wx + ox), -(eta * wy + oy), -(eta * wz + oz))
    if hz < D(0.0):
        hx = -hx
        hy = -hy
        hz = -hz
    ih = wx * hx + wy * hy + wz * hz
    oh = ox * hx + oy * hy + oz * hz
    if ih * oh >= D(0.0) or oh <= D(0.0) or ih * wz <= D(0.0):
        return D(0.0), D(0.0)
    den = eta * ih + oh
    if wp.abs(den) <= D(1e-12):
        return D(0.0), D(0.0)
    F = fresnel(ih, D(1.0) / eta)
    common = g1o * oh * ggx_d(hx, hy, hz, a) * wp.abs(ih) / (oz * den * den)
    return common * (D(1.0) - F) * g1w / wp.abs(wz), common * eta * eta


@wp.func
def top_reflect_vndf(wx: D, wy: D, wz: D, a: D, eta: D, u0: D, u1: D, u2: D, lam: D, aw: D, g1a: D):
    """training.walk._top_reflect_vndf: the forced internal reflection at the
    top, facet from VNDF(a) w.p. lam else VNDF(aw); (d, f |cos| / p, p)."""
    a_s = aw
    if u2 < lam or aw <= a:
        a_s = a
    sg = D(1.0)
    if wz < D(0.0):
        sg = D(-1.0)
    vx, vy, vz = norm3(sg * a_s * wx, sg * a_s * wy, sg * wz)
    mx, my, mz = vndf_std(vx, vy, vz, a_s, u0, u1)
    wm = sg * (wx * mx + wy * my + wz * mz)
    dd = D(2.0) * (wx * mx + wy * my + wz * mz)
    dx = dd * mx - wx
    dy = dd * my - wy
    dz = dd * mz - wz
    if wz * dz <= D(0.0) or wm <= D(0.0):
        return dx, dy, dz, D(0.0), D(0.0)
    d_a = ggx_d(mx, my, mz, a)
    iz4 = D(1.0) / (D(4.0) * wp.abs(wz))
    pa = g1a * d_a * iz4
    p = pa
    if lam < D(1.0):
        alt = pa
        if aw > a:
            alt = g1_dir(wx, wy, wz, aw) * ggx_d(mx, my, mz, aw) * iz4
        p = lam * pa + (D(1.0) - lam) * alt
    if not (p > D(0.0)):
        return dx, dy, dz, D(0.0), D(0.0)
    e = eta
    if not (wz > D(0.0)):
        e = D(1.0) / eta
    F = fresnel(wm, e)
    g1d = D(0.0)
    if (dx * mx + dy * my + dz * mz) * dz > D(0.0):
        g1d = g1_dir(dx, dy, dz, a)
    return dx, dy, dz, F * d_a * g1a * g1d * iz4 / p, p


@wp.func
def cond_eval(ix: D, iy: D, iz: D, ox: D, oy: D, oz: D, a: D, g1i: D):
    """training.walk._cond_eval: (f with F = 1, pdf, Schlick's x)."""
    if iz <= D(0.0) or oz <= D(0.0):
        return D(0.0), D(0.0), D(0.0)
    hx, hy, hz = norm3(ix + ox, iy + oy, iz + oz)
    ih = ix * hx + iy * hy + iz * hz
    if ih <= D(0.0):
        return D(0.0), D(0.0), D(0.0)
    p = g1i * ggx_d(hx, hy, hz, a) / (D(4.0) * iz)
    return p * g1_dir(ox, oy, oz, a) / oz, p, schlick5(ih)


# --- the walk: training.walk._path for its medium branch ----------------------------------
@wp.func
def path(q: wp.int32, s: wp.int32, spp: wp.int32, seed: wp.uint64, wi: wp.vec3d, wo: wp.vec3d, a0: D, e0: D,
         tau0: D, alb: wp.vec3d, ba: D, r0: wp.vec3d, rr_depth: wp.int32, max_depth: wp.int32, rr_weight: D,
         a_wide: D, lam_w: D):
    """One path on a stack of one interface over a medium slab (tau0 > 0) and
    a conductor base, forced top reflection (the v2 estimator): returns its
    RGB contribution and its number of vertices. With one slab, no
    connection and no splitting, ``_path``'s MIS weights reduce exactly
    (pm = 1, pg = pw = 0)."""
    key = lane_key(seed, wp.uint64(q * spp + s))
    ix = wi[0]
    iy = wi[1]
    iz = wi[2]
    ox = wo[0]
    oy = wo[1]
    oz = wo[2]
    sx, sy, sz = norm3(a0 * ox, a0 * oy, oz)
    g1o = g1_dir(ox, oy, oz, a0)
    u0 = (D(s) + uniform(key, 0)) / D(spp)
    u1 = uniform(key, 1)
    ctr = wp.int32(2)
    dx, dy, dz, w_entry, pe = ft_sample(a0, e0, ix, iy, iz, u0, u1)
    out = wp.vec3d(D(0.0), D(0.0), D(0.0))
    vertices = wp.int32(0)
    if w_entry <= D(0.0):
        return out, vertices
    beta = wp.vec3d(w_entry, w_entry, w_entry)
    depth = D(0.0)
    pdf_last = D(0.0)
    bounces = wp.int32(0)
    while True:
        if bounces >= max_depth:
            break
        bounces += 1
        vertices += 1
        # free flight in the slab (the only one: slab 0 between interface 0 and the base)
        down = dz < D(0.0)
        dist_b = depth / wp.max(dz, D(1e-12))
        if down:
            dist_b = (D(1.0) - depth) / wp.max(-dz, D(1e-12))
        u = uniform(key, ctr)
        ctr += 1
        scatter = False
        t = -wp.log(D(1.0) - u) / tau0
        if t < dist_b:
            scatter = True
            depth = depth - t * dz
        alive = True
        nx = dx
        ny = dy
        nz = dz
        p = D(0.0)
        if scatter:
            vx, vy, vz, sc, pn = nee(depth, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0, uniform(key, ctr),
                                     uniform(key, ctr + 1))
            if sc > D(0.0):
                k = INV_4PI * sc * pn / (pn + INV_4PI)
                out = out + wp.cw_mul(beta, alb) * k
            ctr += 2
            beta = wp.cw_mul(beta, alb)
            zz = D(1.0) - D(2.0) * uniform(key, ctr)
            ph = uniform(key, ctr + 1)
            ctr += 2
            r = wp.sqrt(wp.max(D(1.0) - zz * zz, D(0.0)))
            cph, sph = cos_sin_2pi(ph)
            nx = r * cph
            ny = r * sph
            nz = zz
            p = INV_4PI
        else:
            wx = -dx
            wy = -dy
            wz = -dz
            if not down:
                # the top from below: exit toward wo in closed form, MIS vs next-event estimation
                depth = D(0.0)
                g1w = g1_dir(wx, wy, wz, a0)
                f, pn = exit_eval(wx, wy, wz, ox, oy, oz, g1w, g1o, a0, e0)
                if f > D(0.0):
                    k = f * pdf_last / (pdf_last + pn)
                    out = out + beta * k
                lm = D(1.0)
                aw = a0
                if (D(1.0) - wz * wz) * e0 * e0 < D(1.0):  # below the critical angle: the wide mixture
                    lm = lam_w
                    aw = wp.max(a0, a_wide)
                nx, ny, nz, wgt, p = top_reflect_vndf(wx, wy, wz, a0, e0, uniform(key, ctr), uniform(key, ctr + 1),
                                                      uniform(key, ctr + 2), lm, aw, g1w)
                ctr += 3
                alive = p > D(0.0) and nz < D(0.0) and wgt > D(0.0)
                beta = beta * wgt
            else:
                # the conductor base: next-event estimation toward wo through the top, then its VNDF sample
                depth = D(1.0)
                vx, vy, vz, sc, pn = nee(D(1.0), sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0, uniform(key, ctr),
                                         uniform(key, ctr + 1))
                ctr += 2
                g1w = g1_dir(wx, wy, wz, ba)
                if sc > D(0.0):
                    f, pb, x = cond_eval(wx, wy, wz, vx, vy, vz, ba, g1w)
                    k = f * wp.abs(vz) * sc * pn / (pn + pb)
                    out = out + wp.cw_mul(beta * k, wp.vec3d(x, x, x) + r0 * (D(1.0) - x))
                mx, my, mz = sample_vndf(wx, wy, wz, ba, uniform(key, ctr), uniform(key, ctr + 1))
                wm = wx * mx + wy * my + wz * mz
                dd = D(2.0) * wm
                nx = dd * mx - wx
                ny = dd * my - wy
                nz = dd * mz - wz
                if wz > D(0.0) and nz > D(0.0) and wm > D(0.0):
                    p = g1w * ggx_d(mx, my, mz, ba) / (D(4.0) * wz)
                wgt = D(0.0)
                if p > D(0.0):
                    wgt = g1_dir(nx, ny, nz, ba)
                alive = p > D(0.0) and wgt > D(0.0)
                x = schlick5(wm)
                beta = wp.cw_mul(beta, (wp.vec3d(x, x, x) + r0 * (D(1.0) - x)) * wgt)
                ctr += 3
        dx = nx
        dy = ny
        dz = nz
        pdf_last = p
        u = uniform(key, ctr)
        ctr += 1
        if not alive:
            break
        bmax = wp.max(beta[0], wp.max(beta[1], beta[2]))
        if not (bmax > D(0.0)):
            break
        if bounces >= rr_depth:
            qs = wp.min(bmax / rr_weight, D(1.0))
            if u >= qs:
                break
            beta = beta / qs
    return out, vertices


def _run_items(wi: wp.array(dtype=wp.vec3d), wo: wp.array(dtype=wp.vec3d), a0: wp.array(dtype=D),
               e0: wp.array(dtype=D), tau0: wp.array(dtype=D), alb: wp.array(dtype=wp.vec3d),
               ba: wp.array(dtype=D), r0: wp.array(dtype=wp.vec3d), spp: wp.int32, seed: wp.uint64,
               block: wp.int32, nb: wp.int32, rr_depth: wp.int32, max_depth: wp.int32, rr_weight: D, a_wide: D,
               lam_w: D, s1: wp.array(dtype=wp.vec3d), s2: wp.array(dtype=wp.vec3d),
               verts: wp.array(dtype=wp.int64), dropped: wp.array(dtype=wp.int32), it0: wp.int32):
    """training.walk._run: per work item (pair, block of paths) the sums of
    the path contributions and of their squares, vertices, dropped paths
    (items it0, it0 + 1, ...: a launch can run a slice of them)."""
    it = wp.tid() + it0
    q = it // nb
    b = it - q * nb
    acc1 = wp.vec3d(D(0.0), D(0.0), D(0.0))
    acc2 = wp.vec3d(D(0.0), D(0.0), D(0.0))
    nv = wp.int64(0)
    nd = wp.int32(0)
    for s in range(b * block, wp.min(spp, (b + 1) * block)):
        o, v = path(q, s, spp, seed, wi[q], wo[q], a0[q], e0[q], tau0[q], alb[q], ba[q], r0[q], rr_depth,
                    max_depth, rr_weight, a_wide, lam_w)
        nv += wp.int64(v)
        if wp.isfinite(o):
            acc1 = acc1 + o
            acc2 = acc2 + wp.cw_mul(o, o)
        else:
            nd += 1
    s1[it] = acc1
    s2[it] = acc2
    verts[it] = nv
    dropped[it] = nd


#: Numba's fast-math flags (``training.walk._JIT``: contract, arcp, nsz,
#: reassoc) as clang cc1 options, added to Warp's default CPU flags: the like
#: for like build. Warp's own default contracts within an expression only.
NUMBA_LIKE_FLAGS = " -ffp-contract=fast -freciprocal-math -fno-signed-zeros -mreassociate"
run_kernel = wp.kernel(_run_items, name="walk_numba_flags", module="unique", enable_backward=False,
                       module_options={"cpu_compiler_flags": wp.config.cpu_compiler_flags + NUMBA_LIKE_FLAGS})
run_kernel_default = wp.kernel(_run_items, name="walk_default_flags", module="unique", enable_backward=False)


# --- the same specialised walk in Numba (like for like with the port) -----------------------
# The Warp port's ``path`` / ``run_kernel`` written line for line in Numba
# (same flags and building blocks as ``training.walk``; RGB as three scalars,
# as Warp keeps them in a vec3d): separates what the library does from what
# specialising the walk to one stack class does.
@njit(**W._JIT)
def _path_std(q, s, spp, seed, wi, wo, a0, e0, tau0, alb, ba, r0, rr_depth, max_depth, rr_weight, a_wide, lam_w):
    key = W._lane_key(seed, q * spp + s)
    ix, iy, iz = wi[q, 0], wi[q, 1], wi[q, 2]
    ox, oy, oz = wo[q, 0], wo[q, 1], wo[q, 2]
    al0, al1, al2 = alb[q, 0], alb[q, 1], alb[q, 2]
    r00, r01, r02 = r0[q, 0], r0[q, 1], r0[q, 2]
    sx, sy, sz = W._norm3(a0 * ox, a0 * oy, oz)
    g1o = W._g1_dir(ox, oy, oz, a0)
    u0 = (s + W._uniform(key, 0)) / spp
    u1 = W._uniform(key, 1)
    ctr = 2
    dx, dy, dz, w_entry, _ = W._ft_sample(a0, e0, ix, iy, iz, u0, u1)
    o0 = o1 = o2 = 0.0
    vertices = 0
    if w_entry <= 0.0:
        return o0, o1, o2, vertices
    b0 = b1 = b2 = w_entry
    depth = 0.0
    pdf_last = 0.0
    bounces = 0
    while True:
        if bounces >= max_depth:
            break
        bounces += 1
        vertices += 1
        down = dz < 0.0
        dist_b = (1.0 - depth) / max(-dz, 1e-12) if down else depth / max(dz, 1e-12)
        u = W._uniform(key, ctr)
        ctr += 1
        scatter = False
        t = -math.log(1.0 - u) / tau0
        if t < dist_b:
            scatter = True
            depth = depth - t * dz
        alive = True
        p = 0.0
        if scatter:
            vx, vy, vz, sc, pn = W._nee(depth, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0, W._uniform(key, ctr),
                                        W._uniform(key, ctr + 1))
            if sc > 0.0:
                k = W.INV_4PI * sc * pn / (pn + W.INV_4PI)
                o0 += b0 * al0 * k
                o1 += b1 * al1 * k
                o2 += b2 * al2 * k
            ctr += 2
            b0 *= al0
            b1 *= al1
            b2 *= al2
            zz = 1.0 - 2.0 * W._uniform(key, ctr)
            ph = W._uniform(key, ctr + 1)
            ctr += 2
            r = math.sqrt(max(1.0 - zz * zz, 0.0))
            cph, sph = W._cos_sin_2pi(ph)
            nx, ny, nz = r * cph, r * sph, zz
            p = W.INV_4PI
        else:
            wx, wy, wz = -dx, -dy, -dz
            if not down:
                depth = 0.0
                g1w = W._g1_dir(wx, wy, wz, a0)
                f, pn = W._exit_eval(wx, wy, wz, ox, oy, oz, g1w, g1o, a0, e0)
                if f > 0.0:
                    k = f * pdf_last / (pdf_last + pn)
                    o0 += b0 * k
                    o1 += b1 * k
                    o2 += b2 * k
                lm, aw = 1.0, a0
                if (1.0 - wz * wz) * e0 * e0 < 1.0:
                    lm, aw = lam_w, max(a0, a_wide)
                nx, ny, nz, wgt, p = W._top_reflect_vndf(wx, wy, wz, a0, e0, W._uniform(key, ctr),
                                                         W._uniform(key, ctr + 1), W._uniform(key, ctr + 2), lm,
                                                         aw, g1w)
                ctr += 3
                alive = p > 0.0 and nz < 0.0 and wgt > 0.0
                b0 *= wgt
                b1 *= wgt
                b2 *= wgt
            else:
                depth = 1.0
                vx, vy, vz, sc, pn = W._nee(1.0, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0,
                                            W._uniform(key, ctr), W._uniform(key, ctr + 1))
                ctr += 2
                bq = ba[q]
                g1w = W._g1_dir(wx, wy, wz, bq)
                if sc > 0.0:
                    f, pb, x = W._cond_eval(wx, wy, wz, vx, vy, vz, bq, g1w)
                    k = f * abs(vz) * sc * pn / (pn + pb)
                    o0 += b0 * k * (x + r00 * (1.0 - x))
                    o1 += b1 * k * (x + r01 * (1.0 - x))
                    o2 += b2 * k * (x + r02 * (1.0 - x))
                mx, my, mz = W._sample_vndf(wx, wy, wz, bq, W._uniform(key, ctr), W._uniform(key, ctr + 1))
                nx, ny, nz = W._reflect(wx, wy, wz, mx, my, mz)
                wm = wx * mx + wy * my + wz * mz
                if wz > 0.0 and nz > 0.0 and wm > 0.0:
                    p = g1w * W._ggx_d(mx, my, mz, bq) / (4.0 * wz)
                wgt = W._g1_dir(nx, ny, nz, bq) if p > 0.0 else 0.0
                alive = p > 0.0 and wgt > 0.0
                x = W._schlick5(wm)
                b0 *= wgt * (x + r00 * (1.0 - x))
                b1 *= wgt * (x + r01 * (1.0 - x))
                b2 *= wgt * (x + r02 * (1.0 - x))
                ctr += 3
        dx, dy, dz, pdf_last = nx, ny, nz, p
        u = W._uniform(key, ctr)
        ctr += 1
        if not alive:
            break
        bmax = max(b0, max(b1, b2))
        if not bmax > 0.0:
            break
        if bounces >= rr_depth:
            qs = min(bmax / rr_weight, 1.0)
            if u >= qs:
                break
            b0 /= qs
            b1 /= qs
            b2 /= qs
    return o0, o1, o2, vertices

@njit(parallel=True, **W._JIT)
def _run_std(wi, wo, spp, seed, a0, e0, tau0, alb, ba, r0, rr_depth, max_depth, rr_weight, a_wide, lam_w,
            block):
    N = wi.shape[0]
    nb = (spp + block - 1) // block
    items = N * nb
    s1 = np.zeros((items, 3))
    s2 = np.zeros((items, 3))
    verts = np.zeros(items, dtype=np.int64)
    dropped = np.zeros(items, dtype=np.int64)
    for it in prange(items):
        q = it // nb
        b = it - q * nb
        for s in range(b * block, min(spp, (b + 1) * block)):
            o0, o1, o2, v = _path_std(q, s, spp, seed, wi, wo, a0[q], e0[q], tau0[q], alb, ba, r0, rr_depth,
                                     max_depth, rr_weight, a_wide, lam_w)
            verts[it] += v
            if not (math.isfinite(o0) and math.isfinite(o1) and math.isfinite(o2)):
                dropped[it] += 1
                continue
            s1[it, 0] += o0
            s1[it, 1] += o1
            s1[it, 2] += o2
            s2[it, 0] += o0 * o0
            s2[it, 1] += o1 * o1
            s2[it, 2] += o2 * o2
    return s1, s2, verts, dropped



def numba_twin_walk(wi, wo, spp: int, seed: int, st: dict):
    """The specialised Numba twin on the inputs of ``warp_walk``: (s1, s2, vertices, dropped)."""
    from nbrdf.training.walk import BLOCK, RR_WEIGHT, WIDE_LAM, WIDE_ROUGHNESS

    check_class(st)
    swap = (wo[:, 2] < wi[:, 2])[:, None]
    wi, wo = np.where(swap, wo, wi), np.where(swap, wi, wo)
    c = lambda x: np.ascontiguousarray(x, dtype=np.float64)
    N = wi.shape[0]
    s1, s2, verts, dropped = _run_std(c(wi), c(wo), int(spp), int(seed) & 0x7FFFFFFFFFFFFFFF,
                                      c(st["roughness"][:, 0]), c(st["ior"][:, 0]), c(st["sigma_t"][:, 0]),
                                      c(st["albedo"][:, 0, :]), c(st["base_roughness"]), c(st["base_r0"]), RR_DEPTH,
                                      MAX_DEPTH, RR_WEIGHT, WIDE_ROUGHNESS, WIDE_LAM, BLOCK)
    nb = s1.shape[0] // N
    return s1.reshape(N, nb, 3).sum(1), s2.reshape(N, nb, 3).sum(1), int(verts.sum()), int(dropped.sum())


# --- driver ---------------------------------------------------------------------------------
#: ``run_walk``'s defaults (as ``simulate`` calls it): roulette from the 4th vertex, no depth cap in practice.
RR_DEPTH = 4
MAX_DEPTH = 100_000


def check_class(st: dict) -> None:
    """The ports cover the benchmark's stack class only."""
    if st["base"] != "conductor" or st["roughness"].shape[1] != 1 or st["albedo"].shape[2] != 3 \
            or not bool((st["sigma_t"][:, 0] > 0).all()):
        raise ValueError("the ports cover one interface over a medium slab and a conductor base, RGB")


def standard_inputs(n_pairs: int):
    """The benchmark's pairs (``training.bench.bench_reference``: torch
    generator seed 0, cosine-distributed wi and wo) and its standard stack,
    as float64 numpy arrays with explicit channels."""
    import torch

    from nbrdf.neural.material import parse_material
    from nbrdf.training.bench import STANDARD_STACK
    from nbrdf.training.reference import stack_params

    g = torch.Generator().manual_seed(0)
    u = torch.rand(2, n_pairs, 2, generator=g)
    z = torch.sqrt(1 - u[..., 0])
    r = torch.sqrt(u[..., 0])
    d = torch.stack([r * torch.cos(6.2832 * u[..., 1]), r * torch.sin(6.2832 * u[..., 1]), z], -1)
    sp, _ = stack_params(parse_material(STANDARD_STACK), n_pairs).normalized(torch.float64)
    npy = lambda t: t.detach().cpu().numpy().astype(np.float64)
    stack = {k: npy(getattr(sp, k)) for k in ("roughness", "ior", "sigma_t", "albedo", "base_roughness",
                                               "base_r0", "base_ior", "base_albedo")}
    stack["base"] = sp.base
    return npy(d[0].double()), npy(d[1].double()), stack


def numba_walk(wi, wo, spp: int, seed: int, st: dict):
    """``training.walk.run_walk`` (the walk behind ``simulate``): (s1, s2, vertices, dropped)."""
    from nbrdf.training.walk import run_walk

    s1, s2, _, verts, dropped = run_walk(wi, wo, spp, seed, st["roughness"], st["ior"], st["sigma_t"],
                                         st["albedo"], st["base"], st["base_roughness"], st["base_r0"],
                                         st["base_ior"], st["base_albedo"])
    return s1, s2, verts, dropped


def warp_walk(wi, wo, spp: int, seed: int, st: dict, launches: int = 1, default_flags: bool = False):
    """The Warp port on the same inputs as ``numba_walk`` (benchmark stack
    class only: one interface, a medium slab, a conductor base, RGB).
    ``launches`` > 1 splits the work items into that many slices launched
    from as many Python threads (Warp's CPU backend runs a launch on the
    calling thread). ``default_flags``: the kernel built with Warp's default
    CPU flags instead of Numba's fast-math set. Returns (s1, s2, vertices,
    dropped)."""
    from concurrent.futures import ThreadPoolExecutor

    from nbrdf.training.walk import BLOCK, RR_WEIGHT, WIDE_LAM, WIDE_ROUGHNESS

    N = wi.shape[0]
    check_class(st)
    swap = (wo[:, 2] < wi[:, 2])[:, None]  # the reciprocal start of run_walk
    wi, wo = np.where(swap, wo, wi), np.where(swap, wi, wo)
    dev = "cpu"
    arr = lambda x, t: wp.array(np.ascontiguousarray(x, dtype=np.float64), dtype=t, device=dev)
    nb = (spp + BLOCK - 1) // BLOCK
    items = N * nb
    s1 = wp.zeros(items, dtype=wp.vec3d, device=dev)
    s2 = wp.zeros(items, dtype=wp.vec3d, device=dev)
    verts = wp.zeros(items, dtype=wp.int64, device=dev)
    dropped = wp.zeros(items, dtype=wp.int32, device=dev)
    args = [arr(wi, wp.vec3d), arr(wo, wp.vec3d), arr(st["roughness"][:, 0], D), arr(st["ior"][:, 0], D),
            arr(st["sigma_t"][:, 0], D), arr(st["albedo"][:, 0, :], wp.vec3d), arr(st["base_roughness"], D),
            arr(st["base_r0"], wp.vec3d), int(spp), int(seed) & 0x7FFFFFFFFFFFFFFF, BLOCK, nb, RR_DEPTH, MAX_DEPTH,
            RR_WEIGHT, WIDE_ROUGHNESS, WIDE_LAM, s1, s2, verts, dropped]
    cuts = [items * i // launches for i in range(launches + 1)]

    def launch(i: int) -> None:
        kernel = run_kernel_default if default_flags else run_kernel
        wp.launch(kernel, dim=cuts[i + 1] - cuts[i], inputs=args + [cuts[i]], device=dev)

    if launches == 1:
        launch(0)
    else:
        with ThreadPoolExecutor(launches) as ex:
            list(ex.map(launch, range(launches)))
    wp.synchronize_device(dev)
    return (s1.numpy().reshape(N, nb, 3).sum(1), s2.numpy().reshape(N, nb, 3).sum(1), int(verts.numpy().sum()),
            int(dropped.numpy().sum()))


def mean_se(s1, s2, spp: int):
    mean = s1 / spp
    var = np.maximum(s2 / spp - mean * mean, 0.0) * spp / (spp - 1)
    return mean, np.sqrt(var / spp)


def agreement(n_pairs: int, spp: int) -> dict:
    """The Warp walk against ``simulate`` (walk only, the closed-form top
    reflection left out: it is the same term for both): with the same seed
    (the random numbers line up: equal up to rounding), and with independent
    seeds (z-test per pair and channel, Bonferroni at alpha = 0.01)."""
    import torch
    from scipy.stats import norm

    from nbrdf.training.layered import simulate, StackParams

    rng = np.random.default_rng(7)
    # random pairs over the hemisphere (cosine-distributed), the standard stack
    _, _, st = standard_inputs(n_pairs)
    u = rng.random((2, n_pairs, 2))
    r = np.sqrt(u[..., 0])
    d = np.stack([r * np.cos(2 * np.pi * u[..., 1]), r * np.sin(2 * np.pi * u[..., 1]), np.sqrt(1 - u[..., 0])], -1)
    wi, wo = d[0], d[1]
    t = lambda k: torch.from_numpy(st[k])
    sp = StackParams(roughness=t("roughness"), ior=t("ior"), albedo=t("albedo"), sigma_t=t("sigma_t"),
                     base=st["base"], base_roughness=t("base_roughness"), base_r0=t("base_r0"),
                     base_ior=t("base_ior"), base_albedo=t("base_albedo"))
    out = {"pairs": n_pairs, "paths_per_pair": spp}
    m_n, se_n = (x.numpy() for x in simulate(sp, torch.from_numpy(wi), torch.from_numpy(wo), spp=spp, seed=11,
                                             dtype=torch.float64, include_top_reflection=False))
    m_w, se_w = mean_se(*warp_walk(wi, wo, spp, 11, st)[:2], spp)
    rel = np.abs(m_w - m_n) / np.maximum(np.abs(m_n), 1e-300)
    out["same_seed"] = {"max_rel_diff": float(rel.max()), "median_rel_diff": float(np.median(rel)),
                        "bit_identical_fraction": float((m_w == m_n).mean()),
                        "max_z": float((np.abs(m_w - m_n) / np.sqrt(se_w ** 2 + se_n ** 2)).max())}
    m_t, _ = mean_se(*numba_twin_walk(wi, wo, spp, 11, st)[:2], spp)
    rel_t = np.abs(m_t - m_n) / np.maximum(np.abs(m_n), 1e-300)
    out["numba_twin_same_seed"] = {"max_rel_diff": float(rel_t.max()),
                                   "bit_identical_fraction": float((m_t == m_n).mean())}
    m_w2, se_w2 = mean_se(*warp_walk(wi, wo, spp, 12, st)[:2], spp)
    z = (m_w2 - m_n) / np.sqrt(se_w2 ** 2 + se_n ** 2)
    limit = float(norm.isf(0.01 / 2 / z.size))
    out["independent_seeds"] = {"tests": int(z.size), "max_abs_z": float(np.abs(z).max()),
                                "bonferroni_limit": limit, "z_mean": float(z.mean()), "z_sd": float(z.std()),
                                "pass": bool(np.abs(z).max() < limit)}
    return out


def thread_independence(n_pairs: int, spp: int) -> dict:
    """Warp: one launch (one thread) against the items split over two
    launches on two Python threads; Numba: 1 against 2 threads."""
    import numba

    wi, wo, st = standard_inputs(n_pairs)
    a = warp_walk(wi, wo, spp, 3, st, launches=1)
    b = warp_walk(wi, wo, spp, 3, st, launches=2)
    nt = numba.get_num_threads()
    numba.set_num_threads(1)
    c = numba_walk(wi, wo, spp, 3, st)
    numba.set_num_threads(nt)
    e = numba_walk(wi, wo, spp, 3, st)
    return {"warp_1_vs_2_launch_threads_identical": bool(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])),
            "numba_1_vs_%d_threads_identical" % nt: bool(np.array_equal(c[0], e[0]) and np.array_equal(c[1], e[1]))}


def compile_probe(lib: str) -> dict:
    """Seconds to build the inputs, initialise and run the first (tiny) walk
    of ``lib`` in this process ("numba": ``training.walk``, every stack
    class; "numba_twin": the specialised twin of the port; "warp": the
    port): the first call compiles or loads the cached kernels."""
    t0 = time.perf_counter()
    wi, wo, st = standard_inputs(8)
    t1 = time.perf_counter()
    if lib == "warp":
        wp.init()
        t2 = time.perf_counter()
        warp_walk(wi, wo, 4, 0, st)
    else:
        t2 = time.perf_counter()
        (numba_walk if lib == "numba" else numba_twin_walk)(wi, wo, 4, 0, st)
    t3 = time.perf_counter()
    return {"inputs_s": round(t1 - t0, 3), "init_s": round(t2 - t1, 3), "first_call_s": round(t3 - t2, 3)}


def compile_times() -> dict:
    """Cold (an empty cache directory) and cached (the same directory, a new
    process) first-call times of each library, each in a subprocess;
    ``process_s``: the whole subprocess (interpreter, imports, Warp's
    initialisation at import, the call)."""
    import subprocess

    from tqdm import tqdm

    out = {}
    bar = tqdm(total=6, desc="compile probes", file=sys.stderr)
    for lib in ("numba", "numba_twin", "warp"):
        with tempfile.TemporaryDirectory() as cache:
            env = dict(os.environ, NUMBA_CACHE_DIR=cache, WARP_CACHE_PATH=cache)
            for kind in ("cold", "cached"):
                t0 = time.perf_counter()
                r = subprocess.run([sys.executable, __file__, "--probe", lib], env=env, capture_output=True,
                                   text=True, check=True)
                out[f"{lib}_{kind}"] = json.loads(r.stdout.strip().splitlines()[-1])
                out[f"{lib}_{kind}"]["process_s"] = round(time.perf_counter() - t0, 3)
                bar.update()
    bar.close()
    return out


def cuda_ptx(arch: int = 90) -> dict:
    """The same kernel source compiled for CUDA (NVRTC, to PTX for compute
    capability ``arch``; 90 = H100) ahead of time: needs no GPU or driver,
    proves the port builds for ``device="cuda"`` (it is not run here)."""
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        try:
            paths = wp.compile_aot_module(run_kernel.module, arch=arch, module_dir=d, use_ptx=True)
        except Exception as e:  # reported, not fatal: the CPU figures stand alone
            return {"arch": arch, "error": f"{type(e).__name__}: {e}"[:300]}
        return {"arch": arch, "seconds": round(time.perf_counter() - t0, 3),
                "ptx_bytes": sum(os.path.getsize(p) for p in paths)}


def speed(rounds: int, n_pairs: int, spp: int, numba_threads: list[int]) -> dict:
    """Alternated runs (``training.walk`` and its specialised twin at each
    thread count, the Warp port in one launch, in two launch threads, and
    built with Warp's default flags) on the benchmark's inputs (seed 1), after a warm-up:
    RGB paths per second (wall) and per CPU-second of this process."""
    import numba

    wi, wo, st = standard_inputs(n_pairs)
    numba_walk(wi[:64], wo[:64], 16, 0, st_slice(st, 64))
    numba_twin_walk(wi[:64], wo[:64], 16, 0, st_slice(st, 64))
    warp_walk(wi[:64], wo[:64], 16, 0, st_slice(st, 64))
    warp_walk(wi[:64], wo[:64], 16, 0, st_slice(st, 64), default_flags=True)
    nt0 = numba.get_num_threads()
    variants = [(f"numba_{n}_threads", lambda n=n: (numba.set_num_threads(n), numba_walk(wi, wo, spp, 1, st))[1])
                for n in numba_threads]
    variants += [(f"numba_twin_{n}_threads",
                  lambda n=n: (numba.set_num_threads(n), numba_twin_walk(wi, wo, spp, 1, st))[1])
                 for n in numba_threads]
    variants += [("warp_1_launch", lambda: warp_walk(wi, wo, spp, 1, st, 1)),
                 ("warp_2_launch_threads", lambda: warp_walk(wi, wo, spp, 1, st, 2)),
                 ("warp_default_flags_1_launch", lambda: warp_walk(wi, wo, spp, 1, st, 1, default_flags=True))]
    runs = []
    paths = n_pairs * spp
    from tqdm import tqdm

    for r in tqdm(range(rounds), desc="A/B rounds", file=sys.stderr):
        for name, fn in variants:
            load = os.getloadavg()[0]
            c0, w0 = time.process_time(), time.perf_counter()
            res = fn()
            w, c = time.perf_counter() - w0, time.process_time() - c0
            runs.append({"round": r, "walk": name, "paths_per_second": round(paths / w),
                         "paths_per_cpu_second": round(paths / c), "wall_s": round(w, 3), "cpu_s": round(c, 3),
                         "vertices_per_path": round(res[2] / paths, 3), "load_1min": round(load, 2)})
    numba.set_num_threads(nt0)
    summary = {}
    for name, _ in variants:
        rs = [x for x in runs if x["walk"] == name]
        summary[name] = {"paths_per_second": [x["paths_per_second"] for x in rs],
                         "paths_per_cpu_second": [x["paths_per_cpu_second"] for x in rs]}
    return {"pairs": n_pairs, "paths_per_pair": spp, "seed": 1, "runs": runs, "summary": summary}


def st_slice(st: dict, n: int) -> dict:
    return {k: (v if k == "base" else v[:n]) for k, v in st.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (a smoke run, figures not meaningful)")
    ap.add_argument("--rounds", type=int, default=2, help="A/B rounds (each runs every variant once)")
    ap.add_argument("--skip", default="", help="comma list of parts to skip: compile,agreement,threads,cuda,speed")
    ap.add_argument("--probe", choices=("numba", "numba_twin", "warp"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.probe:
        print(json.dumps(compile_probe(a.probe)))
        return 0
    import numba

    wp.init()
    skip = set(a.skip.split(",")) if a.skip else set()
    res = {"machine": {"cores": os.cpu_count(), "numba": numba.__version__, "numba_threads": numba.get_num_threads(),
                       "warp": wp.config.version, "warp_cpu_threads_per_launch": 1,
                       "load_1min_start": round(os.getloadavg()[0], 2)}}
    if "compile" not in skip:
        res["compile"] = compile_times()
    if "agreement" not in skip:
        res["agreement"] = agreement(*((32, 512) if a.quick else (256, 4096)))
    if "threads" not in skip:
        res["thread_independence"] = thread_independence(*((16, 64) if a.quick else (256, 256)))
    if "cuda" not in skip:
        res["cuda_ptx"] = cuda_ptx()
    if "speed" not in skip:
        nt = numba.get_num_threads()
        res["speed"] = speed(a.rounds, *((256, 64) if a.quick else (4096, 256)), sorted({1, nt}))
    res["machine"]["load_1min_end"] = round(os.getloadavg()[0], 2)
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
