"""The walk's estimator strategies beyond its own sampling, each with its
multiple-importance-sampling weight next to it: next-event estimation through
the top, the chains through two interfaces and by way of a sharp base, the
two-bounce connection (C: the mirrored exit lobe, D: the wide guide with
next-event estimation at the base) and the walk's own exit at the top in
closed form. Each weighted function returns its contribution per unit path
weight (0.0: none); the vertex code (``vertices``) adds it. Why each strategy
exists and what it bought: docs/decisions/002-008."""
from __future__ import annotations

from collections import namedtuple

from numba import njit

from nbrdf.training.walk.ggx import INV_4PI, INV_PI, g1_dir, norm3, reflect, sample_vndf, survival
from nbrdf.training.walk.interfaces import (
    CONDUCTOR,
    DIFFUSE,
    base_eval,
    cond_eval,
    cond_geo,
    cond_pdf,
    diel_eval_pdf,
    exit_eval,
    ft_core,
    ft_pdf,
    ft_sample,
    top_eval,
)
from nbrdf.training.walk.params import JIT, JIT_INLINE, MIRROR_CHAIN_P, MIRROR_CHAIN_ROUGHNESS

#: One pair's scalars, read once per path (the vertex code gets no arrays it
#: does not index per channel): wo (ox, oy, oz) with its stretched view
#: direction (sx, sy, sz) and G1 (g1o) for the top, which next-event
#: estimation samples from at every vertex; the top's roughness (alpha_x a0,
#: alpha_y ay0), index and slab 0's optical thickness (e0, tau0); interface 1
#: and slab 1 (a1, ay1, e1, tau1; 0 for one interface); the base's roughness
#: and index (ba, bay, be).
Pair = namedtuple("Pair", ["ox", "oy", "oz", "sx", "sy", "sz", "g1o", "a0", "ay0", "e0", "tau0", "a1", "ay1", "e1",
                           "tau1", "ba", "bay", "be"])
#: A path's settings: the base kind, the forced top reflection, the
#: strategies on (``strategies_on``), the top's mixtures (lam, lam_w, a_wide),
#: the wide guide's roughness (agw), roulette (rr_depth, rr_weight) and
#: splitting (kmax, kstep, ifloor), as ``WalkParams`` names them.
Setup = namedtuple("Setup", ["base", "forced", "conn", "split", "chain", "mirror", "lam", "lam_w", "a_wide", "agw",
                             "rr_depth", "rr_weight", "kmax", "kstep", "ifloor"])


@njit(**JIT_INLINE)
def pair_of(P, q):
    """The ``Pair`` record of pair q."""
    ox, oy, oz = P.wo[q, 0], P.wo[q, 1], P.wo[q, 2]
    a0, ay0 = P.rough[q, 0], P.rough_y[q, 0]
    sx, sy, sz = norm3(a0 * ox, ay0 * oy, oz)
    two = P.rough.shape[1] > 1
    a1 = P.rough[q, 1] if two else 0.0
    ay1 = P.rough_y[q, 1] if two else 0.0
    e1 = P.ior[q, 1] if two else 0.0
    tau1 = P.sigma[q, 1] if two else 0.0
    return Pair(ox, oy, oz, sx, sy, sz, g1_dir(ox, oy, oz, a0, ay0), a0, ay0, P.ior[q, 0], P.sigma[q, 0], a1, ay1, e1,
                tau1, P.b_rough[q], P.b_rough_y[q], P.b_ior[q])


@njit(**JIT_INLINE)
def setup_of(P, q):
    """The ``Setup`` of pair q's paths. The strategies (all need the forced
    top reflection): conn, the two-bounce connection (one interface over a
    conductor, the top slab empty or the base sharper than
    MIRROR_CHAIN_ROUGHNESS); split, splitting by exit importance (the
    connection over an empty slab); chain, next-event estimation through two
    interfaces; mirror, the chain by way of the base (one interface over a
    medium and a sharp conductor)."""
    L = P.rough.shape[1]
    tau0 = P.sigma[q, 0]
    sharp = P.b_rough[q] < MIRROR_CHAIN_ROUGHNESS  # alpha_x, the larger alpha of an anisotropic base
    one_conductor = P.forced and L == 1 and P.base == CONDUCTOR
    conn = one_conductor and (tau0 == 0.0 or sharp)
    split = conn and P.kmax > 1 and tau0 == 0.0
    chain = P.forced and L == 2
    mirror = one_conductor and tau0 > 0.0 and sharp
    return Setup(P.base, P.forced, conn, split, chain, mirror, P.lam, P.lam_w, P.a_wide, P.agw, P.rr_depth,
                 P.rr_weight, P.kmax, P.kstep, P.ifloor)


# --- samplers of the strategies -------------------------------------------------------------
@njit(**JIT)
def nee(z, sx, sy, sz, g1o, ox, oy, oz, a0, ay0, e0, tau0, u0, u1):
    """Samples the top interface from wo (forced transmission): the direction
    v = (vx, vy, vz) leaving the vertex upward, Tr f_top(-v, wo) / pdf and pdf.
    (sx, sy, sz), g1o: wo's stretched view direction and G1 (per pair).
    f_top(t, wo) / pdf = (1 - F) G1(t) / (eta^2 |t_z|) in closed form (the
    facet's D, G1(wo) and Jacobian cancel)."""
    tx, ty, tz, w, p = ft_core(sx, sy, sz, g1o, a0, ay0, e0, ox, oy, oz, u0, u1)
    if p <= 0.0 or w <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0
    vz = -tz
    tr = survival(tau0, z, vz)
    return -tx, -ty, vz, tr * w / (e0 * e0 * vz), p


@njit(**JIT)
def chain_nee(depth, sx, sy, sz, g1o, ox, oy, oz, a0, ay0, e0, tau0, a1, ay1, e1, tau1, u0, u1, u2, u3):
    """Next-event estimation through the stack for a vertex in slab 1 (at
    ``depth`` in [1, 2]) of a two-interface stack: v0 in slab 0 by forced
    refraction from wo through the top (as ``nee``), then d1 in slab 1 by
    forced refraction of v0 down through interface 1. Returns d1 (up, from
    the vertex), g = Tr1 f_if(-d1, v0) |v0_z| Tr0 f_top(v0, wo) / (pn p1) and
    the three strategies' densities of the segment (d1, v0) without the
    vertex's own density: pn (v0 from wo), p1 (d1 given v0), p_if (v0 given
    d1, the walk's sampling at interface 1), and Tr1, Tr0: the flights'
    survival, which the walk's own densities carry in the MIS weights."""
    v0x, v0y, v0z, sc0, pn = nee(1.0, sx, sy, sz, g1o, ox, oy, oz, a0, ay0, e0, tau0, u0, u1)
    if sc0 <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0
    tx, ty, tz, w1, p1 = ft_sample(a1, ay1, e1, v0x, v0y, v0z, u2, u3)
    if p1 <= 0.0 or w1 <= 0.0 or tz >= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0
    f_if, p_if = diel_eval_pdf(tx, ty, tz, v0x, v0y, v0z, a1, ay1, e1)
    if f_if <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0
    d1z = -tz
    tr1, tr0 = survival(tau1, depth - 1.0, d1z), survival(tau0, 1.0, v0z)
    return -tx, -ty, d1z, tr1 * f_if * v0z * sc0 / p1, pn, p1, p_if, tr1, tr0


@njit(**JIT)
def mirror_chain_nee(depth, sx, sy, sz, g1o, ox, oy, oz, a0, ay0, e0, tau0, ba, bay, u0, u1, u2, u3):
    """Next-event estimation by way of a sharp conductor base for a
    scattering in slab 0 (one interface): v0 by forced refraction from wo
    through the top, then u (= -d, d the direction down to the base) by the
    base's VNDF reflection of v0. Returns g = Tr(d) f_base(u, v0) |v0_z| Tr0
    f_top(v0, wo) / pn (F = 1; Schlick's x for the caller), pn, pb (the walk's
    density of v0 given u), p_rev (the chain's density of u given v0), x."""
    v0x, v0y, v0z, sc0, pn = nee(1.0, sx, sy, sz, g1o, ox, oy, oz, a0, ay0, e0, tau0, u0, u1)
    if sc0 <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    mx, my, mz = sample_vndf(v0x, v0y, v0z, ba, bay, u2, u3)
    ux, uy, uz = reflect(v0x, v0y, v0z, mx, my, mz)
    if uz <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    f, pb, x = cond_eval(ux, uy, uz, v0x, v0y, v0z, ba, bay, g1_dir(ux, uy, uz, ba, bay))
    p_rev = cond_pdf(v0x, v0y, v0z, ux, uy, uz, ba, bay)
    if f <= 0.0 or p_rev <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    tr = survival(tau0, 1.0 - depth, uz)
    return tr * f * v0z * sc0 / p_rev, pn, pb, p_rev, x


@njit(**JIT)
def first_vertex(wx, wy, wz, gx, gy, gz, a0, ay0, e0, lam, wide, a_wide, ox, oy, oz, entry):
    """The top vertex of the two-bounce connection toward the downward g: (its
    f |g_z|, the walk's density of g there). ``entry``: w is wi above the
    stack and the vertex is the forced refraction into it; else the internal
    reflection with the walk's mixture (lam, wide, a_wide)."""
    if entry:
        fr, _ = diel_eval_pdf(wx, wy, wz, gx, gy, gz, a0, ay0, e0)
        return fr * abs(gz), ft_pdf(a0, ay0, e0, wx, wy, wz, gx, gy, gz)
    return top_eval(wx, wy, wz, gx, gy, gz, a0, ay0, e0, lam, wide, a_wide, ox, oy, oz)


@njit(**JIT)
def mirror_connection(wx, wy, wz, a0, ay0, e0, ba, bay, lam, wide, a_wide, agw, ox, oy, oz, u0, u1, u2, u3, entry,
                      tau0):
    """Strategy C of the two-bounce connection (top reflection -> base ->
    exit toward wo) for an empty top slab over a conductor: draws the
    reflected direction g from the exit lobe toward wo mirrored about the
    plane (the guide), the base's direction u from its VNDF, and evaluates
    the exit in closed form. Returns (value without Fresnel and beta:
    f_r |g_z| / p_g * f_c u_z / p_c * f_exit * MIS weight, Schlick's x at the
    base); the MIS weight is C's share of the balance heuristic over A (walk:
    p_mix(g) p_c(u)), B (next-event at the base: p_mix(g) p_n(u)), C
    (p_g(g) p_c(u)) and D (the wide guide and next-event estimation:
    p_w(g) p_n(u), ``wide_connection``; agw: its roughness). ``entry``: w
    is wi above the stack and the first vertex is the forced refraction into
    it instead of the internal reflection. tau0: the top slab's optical
    thickness (the path crosses it twice unscattered). The wide guide is isotropic (agw on both axes)."""
    tx, ty, tz, _, pg = ft_sample(a0, ay0, e0, ox, oy, oz, u0, u1)
    if pg <= 0.0:
        return 0.0, 0.0
    gx, gy, gz = -tx, -ty, tz
    fr, pm = first_vertex(wx, wy, wz, gx, gy, gz, a0, ay0, e0, lam, wide, a_wide, ox, oy, oz, entry)
    if fr <= 0.0:
        return 0.0, 0.0
    mx, my, mz = sample_vndf(-gx, -gy, -gz, ba, bay, u2, u3)
    ux, uy, uz = reflect(-gx, -gy, -gz, mx, my, mz)
    fc, pc, x = cond_geo(-gx, -gy, -gz, ux, uy, uz, ba, bay)
    if fc <= 0.0 or pc <= 0.0:
        return 0.0, 0.0
    fe, _ = diel_eval_pdf(-ux, -uy, -uz, ox, oy, oz, a0, ay0, e0)
    if fe <= 0.0:
        return 0.0, 0.0
    pn = ft_pdf(a0, ay0, e0, ox, oy, oz, -ux, -uy, -uz)
    pw = ft_pdf(agw, agw, e0, ox, oy, oz, -gx, -gy, gz)
    tg, tu = survival(tau0, 1.0, gz), survival(tau0, 1.0, uz)
    w = pg * pc / (pm * tg * tu * pc + pm * tg * pn + pg * pc + pw * pn)
    return fr / pg * fc * uz / pc * fe * w * tg * tu, x


@njit(**JIT)
def wide_connection(wx, wy, wz, a0, ay0, e0, ba, bay, lam, wide, a_wide, agw, ox, oy, oz, sx, sy, sz, g1o, u0, u1,
                    u2, u3, entry, tau0):
    """Strategy D of the two-bounce connection (the path of
    ``mirror_connection``): the reflected direction g from the wide guide
    (the exit lobe toward wo of a coat of roughness agw, mirrored about the
    plane), next-event estimation toward wo at the base, and the base's BRDF
    evaluated: its GGX tail bridges the ring around the exit lobe that neither
    the narrow guide (C) nor the walk's own reflection samples well. Weighted
    by the balance heuristic over A (p_mix p_c), B (p_mix p_n), C (p_g p_c)
    and D (p_w p_n). Returns (value per unit beta without the base's Fresnel,
    Schlick's x at the base)."""
    tx, ty, tz, _, pw = ft_sample(agw, agw, e0, ox, oy, oz, u0, u1)
    if pw <= 0.0:
        return 0.0, 0.0
    gx, gy, gz = -tx, -ty, tz
    fr, pm = first_vertex(wx, wy, wz, gx, gy, gz, a0, ay0, e0, lam, wide, a_wide, ox, oy, oz, entry)
    if fr <= 0.0:
        return 0.0, 0.0
    vx, vy, vz, sc, pn = nee(1.0, sx, sy, sz, g1o, ox, oy, oz, a0, ay0, e0, tau0, u2, u3)
    if sc <= 0.0:
        return 0.0, 0.0
    fc, pb, x = cond_geo(-gx, -gy, -gz, vx, vy, vz, ba, bay)
    if fc <= 0.0:
        return 0.0, 0.0
    pg = ft_pdf(a0, ay0, e0, ox, oy, oz, -gx, -gy, gz)
    tg, tv = survival(tau0, 1.0, gz), survival(tau0, 1.0, vz)  # the flights down and up; sc has the one up
    return fr * fc * vz * sc * pn * tg / (pm * tg * tv * pb + pm * tg * pn + pg * pb + pw * pn), x


# --- MIS-weighted contributions per unit path weight (0.0: none) ---------------------------
@njit(**JIT_INLINE)
def scatter_nee(depth, T, u0, u1):
    """Next-event estimation through the top from a scattering in slab 0 (at
    ``depth``), balance heuristic against the phase function's own sample."""
    vx, vy, vz, sc, pn = nee(depth, T.sx, T.sy, T.sz, T.g1o, T.ox, T.oy, T.oz, T.a0, T.ay0, T.e0, T.tau0, u0, u1)
    if sc > 0.0:
        return INV_4PI * sc * pn / (pn + INV_4PI)
    return 0.0


@njit(**JIT_INLINE)
def scatter_mirror_chain(depth, T, u0, u1, u2, u3):
    """The chain by way of a sharp base from a scattering (drawn with
    probability MIRROR_CHAIN_P): (value, Schlick's x at the base); balance
    heuristic over the segment's strategies (the walk, next-event estimation
    at the base, the chain)."""
    g, pn, pb, p_rev, x = mirror_chain_nee(depth, T.sx, T.sy, T.sz, T.g1o, T.ox, T.oy, T.oz, T.a0, T.ay0, T.e0, T.tau0,
                                           T.ba, T.bay, u0, u1, u2, u3)
    if g > 0.0:
        return INV_4PI * g * pn * p_rev / (INV_4PI * pb + INV_4PI * pn + MIRROR_CHAIN_P * pn * p_rev), x
    return 0.0, 0.0


@njit(**JIT_INLINE)
def scatter_chain(depth, T, u0, u1, u2, u3):
    """Next-event estimation through both interfaces from a scattering in
    slab 1; balance heuristic over the segment (d1, v0): the walk (whose
    densities carry its flights' survival t1, t0: it passes them by chance),
    next-event estimation at interface 1, the chain."""
    _, _, _, g, pn, p1, p_if, t1, t0 = chain_nee(depth, T.sx, T.sy, T.sz, T.g1o, T.ox, T.oy, T.oz, T.a0, T.ay0, T.e0,
                                                 T.tau0, T.a1, T.ay1, T.e1, T.tau1, u0, u1, u2, u3)
    if g > 0.0:
        return INV_4PI * g * pn * p1 / (INV_4PI * t1 * t0 * p_if + INV_4PI * t1 * pn + pn * p1)
    return 0.0


@njit(**JIT_INLINE)
def interior_nee(wx, wy, wz, T, a, ay, e, pdf_last, chain_from_below, t1, u0, u1):
    """Next-event estimation through the top from interface 1 (w toward
    where the light came from); ``chain_from_below`` (a two-interface stack,
    w from slab 1): the chain's density of d1 = -w enters the weight, with
    the walk's density of d1 times its flight's survival t1; else the balance
    heuristic against the interface's own sample."""
    vx, vy, vz, sc, pn = nee(1.0, T.sx, T.sy, T.sz, T.g1o, T.ox, T.oy, T.oz, T.a0, T.ay0, T.e0, T.tau0, u0, u1)
    if not sc > 0.0:
        return 0.0
    f, pb = diel_eval_pdf(wx, wy, wz, vx, vy, vz, a, ay, e)
    if chain_from_below:
        p1 = ft_pdf(a, ay, e, vx, vy, vz, wx, wy, wz)
        pw1 = pdf_last * t1
        return f * abs(vz) * sc * pw1 * pn / (pw1 * survival(T.tau0, 1.0, vz) * pb + pw1 * pn + pn * p1)
    return f * abs(vz) * sc * pn / (pn + pb)


@njit(**JIT_INLINE)
def base_chain(base, wx, wy, wz, depth, T, g1w, u0, u1, u2, u3):
    """Next-event estimation through both interfaces from the base under
    slab 1: (value, Schlick's x of a conductor base); balance heuristic over
    the segment (d1, v0) as ``scatter_chain``, the base's density of d1 for
    the walk's."""
    d1x, d1y, d1z, g, pn, p1, p_if, t1, t0 = chain_nee(depth, T.sx, T.sy, T.sz, T.g1o, T.ox, T.oy, T.oz, T.a0, T.ay0,
                                                       T.e0, T.tau0, T.a1, T.ay1, T.e1, T.tau1, u0, u1, u2, u3)
    if g > 0.0:
        fb, pb, x = base_eval(base, wx, wy, wz, d1x, d1y, d1z, T.ba, T.bay, T.be, g1w)
        if fb > 0.0:
            return fb * d1z * g * pn * p1 / (pb * t1 * t0 * p_if + pb * t1 * pn + pn * p1), x
    return 0.0, 0.0


@njit(**JIT_INLINE)
def base_nee(base, wx, wy, wz, vx, vy, vz, sc, pn, ba, bay, be, g1w, pdf_last, seg, C4, conn, tau0):
    """Next-event estimation through the top at the base (v, sc, pn from
    ``nee``): (value, Schlick's x of a conductor). A conductor's segment
    ``seg`` (after a scattering over a sharp base: the chain made it too) is
    weighted over (the walk, next-event estimation, the chain); otherwise over
    the walk, next-event estimation and the two-bounce connection's C and D,
    whose densities of the direction down C4 = (pm, pg, pw, tg) carry; the
    diffuse and dielectric bases against their own sample."""
    if base == CONDUCTOR:
        f, pb, x = cond_eval(wx, wy, wz, vx, vy, vz, ba, bay, g1w)
        if seg:
            p_rev = cond_pdf(vx, vy, vz, wx, wy, wz, ba, bay)
            return f * abs(vz) * sc * pdf_last * pn / (pdf_last * pb + pdf_last * pn + MIRROR_CHAIN_P * pn * p_rev), x
        pm, pg, pw, tg = C4
        tv = survival(tau0, 1.0, vz) if conn else 1.0
        return f * abs(vz) * sc * pm * tg * pn / (pm * tg * pn + pm * tg * tv * pb + pg * pb + pw * pn), x
    if base == DIFFUSE:
        if wz > 0.0:
            return max(vz, 0.0) * INV_PI * sc * pn / (pn + max(vz, 0.0) * INV_PI), 0.0
        return 0.0, 0.0
    f, pb = diel_eval_pdf(wx, wy, wz, vx, vy, vz, ba, bay, be)
    return f * abs(vz) * sc * pn / (pn + pb), 0.0


@njit(**JIT_INLINE)
def top_exit(wx, wy, wz, T, g1w, pdf_last, C4, tu, seg_in, mirror, chx, chy, chz, chp, cht1):
    """The top seen from below: the exit toward wo in closed form, weighted
    against the strategies that make the same last segment. After the walk's
    segment by way of the base (``seg_in`` and ``mirror``): (the walk,
    next-event estimation at the base, the chain); after its segment from
    slab 1 (``seg_in``): (the walk, whose densities carry survival, next-event
    estimation at interface 1, the chain); otherwise the walk against
    next-event estimation and the connection's C and D (C4 = (pm, pg, pw, tg),
    tu the survival of the flight up, which the connection evaluates)."""
    f, pn = exit_eval(wx, wy, wz, T.ox, T.oy, T.oz, g1w, T.g1o, T.a0, T.ay0, T.e0)
    if not f > 0.0:
        return 0.0
    if seg_in and mirror:
        p_rev = cond_pdf(-wx, -wy, -wz, chx, chy, chz, T.ba, T.bay)
        return f * chp * pdf_last / (chp * pdf_last + chp * pn + MIRROR_CHAIN_P * pn * p_rev)
    if seg_in:
        p1 = ft_pdf(T.a1, T.ay1, T.e1, -wx, -wy, -wz, -chx, -chy, -chz)
        t0 = survival(T.tau0, 1.0, wz)
        return f * chp * cht1 * t0 * pdf_last / (chp * cht1 * t0 * pdf_last + chp * cht1 * pn + pn * p1)
    pm, pg, pw, tg = C4
    pa = pm * tg * tu * pdf_last
    return f * pa / (pa + pm * tg * pn + pg * pdf_last + pw * pn)


@njit(**JIT_INLINE)
def connection(wx, wy, wz, T, lam, wide, a_wide, agw, u, entry):
    """Both strategies of the two-bounce connection from a top vertex (C, then
    D; ``u``: their 8 uniforms): (C's value, its Schlick x, D's value, its x)."""
    k, x = mirror_connection(wx, wy, wz, T.a0, T.ay0, T.e0, T.ba, T.bay, lam, wide, a_wide, agw, T.ox, T.oy, T.oz, u[0],
                             u[1], u[2], u[3], entry, T.tau0)
    kd, xd = wide_connection(wx, wy, wz, T.a0, T.ay0, T.e0, T.ba, T.bay, lam, wide, a_wide, agw, T.ox, T.oy, T.oz, T.sx,
                             T.sy, T.sz, T.g1o, u[4], u[5], u[6], u[7], entry, T.tau0)
    return k, x, kd, xd


@njit(**JIT_INLINE)
def connection_densities(a0, ay0, e0, agw, tau0, ox, oy, oz, p, nx, ny, nz):
    """(pm, pg, pw, tg) of a downward direction n that the walk drew with
    density p: the densities the connection's C and D give it and the
    survival of its flight (all neutral when p = 0)."""
    tg = survival(tau0, 1.0, nz) if p > 0.0 else 1.0
    pg = ft_pdf(a0, ay0, e0, ox, oy, oz, -nx, -ny, nz) if p > 0.0 else 0.0
    pw = ft_pdf(agw, agw, e0, ox, oy, oz, -nx, -ny, nz) if p > 0.0 else 0.0
    return p, pg, pw, tg
