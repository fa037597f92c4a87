"""The compiled per-lane random walk behind ``training.layered.simulate``.

One path per lane, written as scalar code and compiled by Numba
(``parallel=True``, ``cache=True``): work items are (pair, block of paths),
spread over the threads by ``prange``. Random numbers are counter based: the
k-th number of path ``(pair, sample)`` is a hash of (seed, pair * spp +
sample, k), so a result depends on the seed and the batch only, never on the
number of threads or on how work is split.

Physics (SPEC section 5) and the estimator are described in
``training.layered``; the one change against the batched torch walk it
replaces ("ground truth v2") is at the top interface seen from below:

- the walk no longer *samples* leaving the stack there. The exit toward
  ``wo`` is already counted in closed form at every such vertex (evaluation
  with MIS against next-event estimation), so a sampled exit only ended the
  path. The walk now always reflects (weight F G1, the Fresnel factor moved
  from a random choice into the weight), and
- Russian roulette is a weight window: a path survives with probability
  min(1, max_c beta / RR_WEIGHT) instead of min(0.95, max_c beta).

Together they make the paths that get trapped between the base and the
underside of the coat by total internal reflection about 1/F(entry) times
more frequent with 1/F(entry) times less weight: those paths carried the rare
large contributions (docs/RESULTS.md, "Ground truth v2"). Both changes keep
the estimator unbiased (a weight moved out of a random choice; roulette with
any survival probability > 0 divided out).

Two more changes for that light:

- for an empty top slab over a conductor, a two-bounce connection at the entry and at every internal reflection at
  the top: the reflected direction is drawn from the exit lobe toward wo
  mirrored about the plane, the base's from its VNDF, and the exit is
  evaluated in closed form (C); a fourth strategy (D) draws the reflected
  direction from a wider copy of that lobe and connects at the base by
  next-event estimation, where the base's GGX tail bridges the ring around
  the exit lobe; the four (walk, next-event at the base, C, D) sample the
  same three-vertex path and are combined by the balance heuristic, so the
  product of the coat's exit lobe and a near-mirror base is no longer found
  by chance;
- for the same stacks, splitting by exit importance (estimator v5): at the
  top seen from below a path's level is its weight times the coat's
  reflection density from its state toward the centre of the mirrored exit
  lobe; each time the level doubles against the one the path started at,
  the path splits into copies of weight beta / k (at most ``SPLIT_MAX`` per
  path; roulette keeps using the unsplit weight), so the paths that drift
  toward the states that feed the exit are followed more often with less
  weight (unbiased: a split divides the weight by the number of copies);
- for two-interface stacks, next-event estimation through the stack
  (estimator v6): a vertex in slab 1 (a scattering or the base) connects to
  wo through both interfaces (v0 drawn from wo through the top, d1 from v0
  through the interior interface), and the segment (d1, v0) is weighted by
  the balance heuristic over the three strategies that make it (the walk
  with the closed-form exit, next-event estimation at the interior interface,
  the chain), so a sharp top over a near-index-matched interior interface
  (two sharp lobes in series) is no longer met by chance; likewise, for one
  interface over a medium and a sharp conductor base, a scattering connects
  to wo by way of the base (v0 drawn from wo through the top, the direction
  down to the base from the base's reflection of v0), weighted against the
  walk and the base's next-event estimation;
- estimator v7, for one interface over a medium and a conductor sharper
  than ``MIRROR_CHAIN_ROUGHNESS``: the two-bounce connection (C, D) also runs
  through the medium, its flights' transmittance in closed form, because the
  unscattered chain coat -> base -> coat carries the base's sharp reflection
  and the walk passed the medium twice only by chance (1 % at the worst
  pairs of a thick slab); in the MIS weights of that connection and of the
  chain through a two-interface stack, the walk's densities carry its
  flights' survival probability (the other strategies evaluate it), so where
  a flight is unlikely to pass the strategies that evaluate it take over;
- on every stack, reciprocity: the walk starts from the more grazing of
  (wi, wo) (a stack reflects into the air it is lit from), whose light
  refracts nearer the critical angle, so the trapped state is reached often
  (on the benchmark's stack this also lowers variance x vertices by 15 %).

Speed: a vertex costs chains of square roots and divisions, not
transcendentals (libm was ~15 % of the time), so the hot kernels are fused
where the sampled facet is known: next-event estimation's f_top / pdf is
(1 - F) G1(t) / (eta^2 |t_z|) in closed form (D, G1(wo) and the Jacobian
cancel) with wo's stretched view direction and G1 computed once per path;
the exit toward wo and its next-event pdf share one half vector; the top's
mixture reflection and the conductor base evaluate f and pdf from the sampled
facet; VNDF facets come from spherical caps (Dupuy and Benyoub 2023, exact);
(cos, sin)(2 pi u) is a polynomial; the free flight uses log(1 - u). Each
fused kernel equals the generic one it replaces
(tests/training/test_walk_kernels.py); 2.2x paths per CPU-second on the
benchmark's stack (docs/RESULTS.md, "Walk speed").
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

INV_PI = 1.0 / math.pi
INV_4PI = 1.0 / (4.0 * math.pi)
TWO_PI = 2.0 * math.pi
#: Russian roulette weight window: paths whose largest channel weight is below
#: this survive with probability weight / RR_WEIGHT (and are divided by it).
RR_WEIGHT = 0.2
#: Top interface seen from below, below the critical angle (the vertices
#: that feed total internal reflection): the reflected facet comes from VNDF(a)
#: with probability WIDE_LAM, else from VNDF(WIDE_ROUGHNESS) (one-sample
#: mixture, weighted by the mixture pdf).
WIDE_ROUGHNESS = 0.4
WIDE_LAM = 0.5
#: Beyond the critical angle (trapped light, only without a medium in the top
#: slab): VNDF(a) with probability GUIDE_LAM, else the mirror guide toward wo.
GUIDE_LAM = 0.8
#: Roughness of the wide guide (strategy D of the connection, empty top slab
#: over a conductor): the exit lobe toward wo of a rougher copy of the coat,
#: mirrored. It covers the ring around the narrow guide's lobe, where the
#: near-mirror base's GGX tail bridges to the exit lobe (next-event estimation
#: at the base); the walk found those directions by chance and they carried
#: its heaviest contributions (docs/RESULTS.md, Ground truth v2).
WIDE_GUIDE_ROUGHNESS = 0.5
#: Splitting by exit importance (estimator v5; empty top slab over a conductor,
#: the connection's stacks): at the top seen from below a path's importance is
#: its weight times I(w), the coat's reflection density from its state w
#: toward the centre of the mirrored exit lobe (where the two-bounce
#: connection gathers its value). Each time it doubles against the level the
#: path started at, the path is split (copies of weight beta / k), at most
#: SPLIT_STEP ways per vertex and SPLIT_MAX copies per path in all (1: off).
SPLIT_MAX = 8
SPLIT_STEP = 2
#: Floor of I(w) as a fraction of its peak (a state's future value is never
#: only its immediate connection value: trapped light drifts).
SPLIT_FLOOR = 1e-3
#: Next-event estimation by way of the base (estimator v6) for one interface
#: over a medium and a conductor base sharper than this roughness (rougher
#: bases: the walk's own sampling of the base lobe suffices, and the benchmark's
#: stack, base 0.3, keeps its estimates and speed).
MIRROR_CHAIN_ROUGHNESS = 0.1
#: Probability that a scattering draws that chain (its contribution divided by
#: it, its density times it in the MIS weights): half the cost per scattering.
MIRROR_CHAIN_P = 0.5
#: Paths per work item (a block of one pair's paths run by one thread).
BLOCK = 32

#: Compiler flags: fastmath without "nnan" / "ninf" (the non-finite checks
#: stay valid); contraction into FMAs and reassociation change results only by
#: rounding, identically on every thread (8 % faster, docs/RESULTS.md).
_JIT = dict(cache=True, fastmath={"contract", "arcp", "nsz", "reassoc"}, nogil=True)


# --- counter-based random numbers ---------------------------------------------------------
@njit(**_JIT)
def _mix64(x):
    """SplitMix64's finaliser (a bijective 64-bit hash)."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@njit(**_JIT)
def _lane_key(seed, lane):
    return _mix64(_mix64(np.uint64(seed) + np.uint64(0x632BE59BD9B4E019)) ^ np.uint64(lane))


@njit(**_JIT)
def _uniform(key, counter):
    """The counter-th uniform in [0, 1) of the lane with this key: SplitMix64
    of a Weyl sequence started at the key (53 random bits)."""
    h = _mix64(key + np.uint64(counter + 1) * np.uint64(0x9E3779B97F4A7C15))
    return float(h >> np.uint64(11)) * (1.0 / 9007199254740992.0)


# --- microfacet building blocks (scalar twins of training.microfacet) ----------------------
@njit(**_JIT)
def _cos_sin_2pi(u):
    """(cos 2 pi u, sin 2 pi u) for u in [0, 1]: reduction to a quarter turn
    (exact in binary) and Taylor polynomials; absolute error < 1e-15, about
    2.5x cheaper than libm's sincos (one pair per sampled direction)."""
    q = math.floor(4.0 * u + 0.5)
    x = TWO_PI * (u - 0.25 * q)  # [-pi/4, pi/4]
    x2 = x * x
    s = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362880.0 + x2 * (
        -1.0 / 39916800.0 + x2 * (1.0 / 6227020800.0 + x2 * (-1.0 / 1307674368000.0))))))))
    c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0 + x2 * (
        -1.0 / 3628800.0 + x2 * (1.0 / 479001600.0 + x2 * (-1.0 / 87178291200.0 + x2 * (1.0 / 20922789888000.0))))))))
    qi = int(q) & 3
    odd = (qi & 1) == 1
    cc = s if odd else c
    ss = c if odd else s
    if qi == 1 or qi == 2:
        cc = -cc
    if qi >= 2:
        ss = -ss
    return cc, ss


@njit(**_JIT)
def _norm3(x, y, z):
    n = math.sqrt(x * x + y * y + z * z)
    inv = 1.0 / max(n, 1e-30)
    return x * inv, y * inv, z * inv


@njit(**_JIT)
def _ggx_d(mx, my, mz, a):
    if mz <= 0.0:
        return 0.0
    a2 = a * a
    den = mx * mx + my * my + mz * mz * a2
    return a2 / (math.pi * den * den)


@njit(**_JIT)
def _g1_dir(wx, wy, wz, a):
    """Smith G1 = 2 / (1 + sqrt(1 + a^2 tan^2)), written with one division."""
    z = abs(wz)
    den = z + math.sqrt(wz * wz + a * a * (wx * wx + wy * wy))
    return 2.0 * z / den if den > 0.0 else 0.0


@njit(**_JIT)
def _g1(wx, wy, wz, mx, my, mz, a):
    if (wx * mx + wy * my + wz * mz) * wz > 0.0:
        return _g1_dir(wx, wy, wz, a)
    return 0.0


@njit(**_JIT)
def _sample_vndf(wx, wy, wz, a, u1, u2):
    """A VNDF facet normal for w (which may lie below: it is mirrored up)."""
    if wz < 0.0:
        wx, wy, wz = -wx, -wy, -wz
    vx, vy, vz = _norm3(a * wx, a * wy, wz)
    return _vndf_std(vx, vy, vz, a, u1, u2)


@njit(**_JIT)
def _vndf_std(vx, vy, vz, a, u1, u2):
    """A VNDF facet normal from the stretched, normalised view direction
    v = (a wx, a wy, wz) / |.| (vz >= 0; per pair for next-event estimation):
    Dupuy and Benyoub 2023 (exact; a point of the spherical cap below v, one
    square root fewer than Heitz's disk mapping and no frame)."""
    cph, sph = _cos_sin_2pi(u2)
    z = (1.0 - u1) * (1.0 + vz) - vz
    st = math.sqrt(max(1.0 - z * z, 0.0))
    return _norm3(a * (st * cph + vx), a * (st * sph + vy), max(z + vz, 1e-12))


@njit(**_JIT)
def _vndf_pdf(wx, wy, wz, mx, my, mz, a):
    if wz < 0.0:
        wx, wy, wz = -wx, -wy, -wz
    wm = wx * mx + wy * my + wz * mz
    if wm <= 0.0:
        return 0.0
    return _g1_dir(wx, wy, wz, a) * wm * _ggx_d(mx, my, mz, a) / max(abs(wz), 1e-30)


@njit(**_JIT)
def _fresnel(cos_i, eta):
    c = min(abs(cos_i), 1.0)
    sin2_t = (1.0 - c * c) / (eta * eta)
    if sin2_t >= 1.0:
        return 1.0
    cos_t = math.sqrt(max(1.0 - sin2_t, 0.0))
    rs = (c - eta * cos_t) / (c + eta * cos_t)
    rp = (eta * c - cos_t) / (eta * c + cos_t)
    return 0.5 * (rs * rs + rp * rp)


@njit(**_JIT)
def _reflect(wx, wy, wz, mx, my, mz):
    d = 2.0 * (wx * mx + wy * my + wz * mz)
    return d * mx - wx, d * my - wy, d * mz - wz


@njit(**_JIT)
def _refract(wx, wy, wz, mx, my, mz, er):
    """Returns (tx, ty, tz, ok); er = eta_incident / eta_transmitted."""
    c = wx * mx + wy * my + wz * mz
    if c < 0.0:
        mx, my, mz, c = -mx, -my, -mz, -c
    k = 1.0 - er * er * (1.0 - c * c)
    f = er * c - math.sqrt(max(k, 0.0))
    tx, ty, tz = _norm3(f * mx - er * wx, f * my - er * wy, f * mz - er * wz)
    return tx, ty, tz, k > 0.0


# --- rough dielectric interface (Walter et al. 2007), eta = index below / above -----------
@njit(**_JIT)
def _diel_setup(ix, iy, iz, ox, oy, oz, eta):
    above_i = iz > 0.0
    refl = iz * oz > 0.0
    eta_i = 1.0 if above_i else eta
    eta_o = eta_i if refl else (eta if above_i else 1.0)
    if refl:
        hx, hy, hz = _norm3(ix + ox, iy + oy, iz + oz)
    else:
        hx, hy, hz = _norm3(-(eta_i * ix + eta_o * ox), -(eta_i * iy + eta_o * oy), -(eta_i * iz + eta_o * oz))
    if hz < 0.0:
        hx, hy, hz = -hx, -hy, -hz
    eta_rel = eta if above_i else 1.0 / eta
    return eta_i, eta_o, hx, hy, hz, refl, eta_rel


@njit(**_JIT)
def _diel_eval_pdf(ix, iy, iz, ox, oy, oz, a, eta):
    """(f(wi, wo), pdf of sampling wo from wi)."""
    if iz == 0.0 or oz == 0.0:
        return 0.0, 0.0
    eta_i, eta_o, hx, hy, hz, refl, eta_rel = _diel_setup(ix, iy, iz, ox, oy, oz, eta)
    ih = ix * hx + iy * hy + iz * hz
    oh = ox * hx + oy * hy + oz * hz
    F = _fresnel(ih, eta_rel)
    dg = _ggx_d(hx, hy, hz, a) * _g1(ix, iy, iz, hx, hy, hz, a) * _g1(ox, oy, oz, hx, hy, hz, a)
    cos_io = max(abs(iz * oz), 1e-30)
    pm = _vndf_pdf(ix, iy, iz, hx, hy, hz, a)
    if refl:
        f = F * dg / (4.0 * cos_io)
        p = F * pm / (4.0 * abs(ih)) if ih != 0.0 else 0.0
        return f, p
    if ih * oh >= 0.0:
        return 0.0, 0.0
    den = eta_i * ih + eta_o * oh
    den2 = den * den
    if den2 == 0.0:
        return 0.0, 0.0
    f = abs(ih * oh) * eta_o * eta_o * (1.0 - F) * dg / (cos_io * den2)
    p = (1.0 - F) * pm * eta_o * eta_o * abs(oh) / den2
    return f, p


@njit(**_JIT)
def _diel_sample(wx, wy, wz, a, eta, u0, u1, u2):
    """Walter sampling (Fresnel picks reflection or refraction).
    Returns (ox, oy, oz, weight = f |cos| / pdf, pdf)."""
    mx, my, mz = _sample_vndf(wx, wy, wz, a, u0, u1)
    above = wz > 0.0
    eta_i = 1.0 if above else eta
    eta_t = eta if above else 1.0
    F = _fresnel(wx * mx + wy * my + wz * mz, eta_t / eta_i)
    tx, ty, tz, ok_t = _refract(wx, wy, wz, mx, my, mz, eta_i / eta_t)
    if u2 < F or not ok_t:
        ox, oy, oz = _reflect(wx, wy, wz, mx, my, mz)
        if wz * oz <= 0.0:
            return ox, oy, oz, 0.0, 0.0
    else:
        ox, oy, oz = tx, ty, tz
        if wz * oz >= 0.0:
            return ox, oy, oz, 0.0, 0.0
    f, p = _diel_eval_pdf(wx, wy, wz, ox, oy, oz, a, eta)
    if p <= 0.0:
        return ox, oy, oz, 0.0, 0.0
    return ox, oy, oz, f * abs(oz) / p, p


@njit(**_JIT)
def _top_reflect(wx, wy, wz, a, eta, u0, u1, u2, lam, wide, a_wide, ox, oy, oz):
    """Internal reflection at the top (no Fresnel choice: F goes into the
    weight), the direction drawn from the one-sample mixture
    lam p_refl + (1 - lam) p_alt. p_refl: the interface's own VNDF reflection.
    p_alt (``wide``): the VNDF reflection of a rougher copy (``a_wide``), or
    (not ``wide``) the guide: a direction that an ideal mirror below turns
    into a next-event direction toward wo. Returns (dx, dy, dz, weight =
    f_r |cos| / p_mix, p_mix); lam = 1 is the plain forced reflection."""
    aw = max(a, a_wide)
    if u2 < lam or (wide and aw <= a):
        mx, my, mz = _sample_vndf(wx, wy, wz, a, u0, u1)
        dx, dy, dz = _reflect(wx, wy, wz, mx, my, mz)
    elif wide:
        mx, my, mz = _sample_vndf(wx, wy, wz, aw, u0, u1)
        dx, dy, dz = _reflect(wx, wy, wz, mx, my, mz)
    else:
        tx, ty, tz, w, pg = _ft_sample(a, eta, ox, oy, oz, u0, u1)
        if pg <= 0.0:
            return tx, ty, tz, 0.0, 0.0
        dx, dy, dz = -tx, -ty, tz  # -t goes up; mirrored about the plane it goes down
    fc, p = _top_eval(wx, wy, wz, dx, dy, dz, a, eta, lam, wide, a_wide, ox, oy, oz)
    if p <= 0.0:
        return dx, dy, dz, 0.0, 0.0
    return dx, dy, dz, fc / p, p


@njit(**_JIT)
def _top_reflect_vndf(wx, wy, wz, a, eta, u0, u1, u2, lam, aw, g1a):
    """``_top_reflect`` without the guide: the facet from VNDF(a) with
    probability lam, else from VNDF(aw) (aw > a; lam = 1: the plain forced
    reflection). The sampled facet is the half vector, so f and the mixture
    pdf share D(m) and G1(w) (g1a, for roughness a) instead of recomputing
    them (``_top_eval``)."""
    a_s = a if (u2 < lam or aw <= a) else aw
    sg = -1.0 if wz < 0.0 else 1.0  # w mirrored up for the VNDF
    vx, vy, vz = _norm3(sg * a_s * wx, sg * a_s * wy, sg * wz)
    mx, my, mz = _vndf_std(vx, vy, vz, a_s, u0, u1)
    wm = sg * (wx * mx + wy * my + wz * mz)
    dx, dy, dz = _reflect(wx, wy, wz, mx, my, mz)
    if wz * dz <= 0.0 or wm <= 0.0:
        return dx, dy, dz, 0.0, 0.0
    d_a = _ggx_d(mx, my, mz, a)
    iz4 = 1.0 / (4.0 * abs(wz))
    pa = g1a * d_a * iz4
    p = pa
    if lam < 1.0:
        alt = _g1_dir(wx, wy, wz, aw) * _ggx_d(mx, my, mz, aw) * iz4 if aw > a else pa
        p = lam * pa + (1.0 - lam) * alt
    if not p > 0.0:
        return dx, dy, dz, 0.0, 0.0
    F = _fresnel(wm, eta if wz > 0.0 else 1.0 / eta)
    g1d = _g1_dir(dx, dy, dz, a) if (dx * mx + dy * my + dz * mz) * dz > 0.0 else 0.0
    return dx, dy, dz, F * d_a * g1a * g1d * iz4 / p, p


@njit(**_JIT)
def _top_eval(wx, wy, wz, dx, dy, dz, a, eta, lam, wide, a_wide, ox, oy, oz):
    """(f_r(w, d) |d_z|, the density ``_top_reflect`` draws d with) for the
    internal reflection at the top seen from below."""
    if wz * dz <= 0.0:
        return 0.0, 0.0
    aw = max(a, a_wide)
    hx, hy, hz = _norm3(wx + dx, wy + dy, wz + dz)
    if hz < 0.0:
        hx, hy, hz = -hx, -hy, -hz
    wm = abs(wx * hx + wy * hy + wz * hz)
    if wm == 0.0:
        return 0.0, 0.0
    pa = _vndf_pdf(wx, wy, wz, hx, hy, hz, a) / (4.0 * wm)
    p = pa
    if lam < 1.0:
        if wide:
            alt = _vndf_pdf(wx, wy, wz, hx, hy, hz, aw) / (4.0 * wm) if aw > a else pa
        else:
            alt = _ft_pdf(a, eta, ox, oy, oz, -dx, -dy, dz)
        p = lam * pa + (1.0 - lam) * alt
    F = _fresnel(wm, eta if wz > 0.0 else 1.0 / eta)
    f = (F * _ggx_d(hx, hy, hz, a) * _g1(wx, wy, wz, hx, hy, hz, a) * _g1(dx, dy, dz, hx, hy, hz, a)
         / max(4.0 * abs(wz * dz), 1e-30))
    return f * abs(dz), p


@njit(**_JIT)
def _ft_pdf(a, er, wx, wy, wz, tx, ty, tz):
    """Density of drawing t by refracting w through a VNDF-sampled facet (no
    Fresnel choice); er = index on t's side / index on w's side."""
    if wz * tz >= 0.0:
        return 0.0
    hx, hy, hz = _norm3(-(wx + er * tx), -(wy + er * ty), -(wz + er * tz))
    if hz < 0.0:
        hx, hy, hz = -hx, -hy, -hz
    wh = wx * hx + wy * hy + wz * hz
    th = tx * hx + ty * hy + tz * hz
    den = wh + er * th
    if wh * th >= 0.0 or abs(den) <= 1e-12:
        return 0.0
    return _vndf_pdf(wx, wy, wz, hx, hy, hz, a) * er * er * abs(th) / (den * den)


@njit(**_JIT)
def _ft_sample(a, er, wx, wy, wz, u0, u1):
    """Forced refraction of w (above the interface): (tx, ty, tz, weight =
    (1 - F) G1(t), pdf)."""
    sx, sy, sz = _norm3(a * wx, a * wy, abs(wz))
    return _ft_core(sx, sy, sz, _g1_dir(wx, wy, wz, a), a, er, wx, wy, wz, u0, u1)


@njit(**_JIT)
def _ft_core(sx, sy, sz, g1w, a, er, wx, wy, wz, u0, u1):
    """``_ft_sample`` given w's stretched view direction (sx, sy, sz) and
    G1(w) (constant per pair for next-event estimation). The facet m is
    known, so the Fresnel factor reuses the refraction's cos_t and the pdf
    (that of ``_ft_pdf``) is written with m instead of a recomputed half
    vector."""
    mx, my, mz = _vndf_std(sx, sy, sz, a, u0, u1)
    c = wx * mx + wy * my + wz * mz
    ei = 1.0 / er
    k = 1.0 - ei * ei * (1.0 - c * c)
    if c <= 0.0 or k <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0
    ct = math.sqrt(k)
    f = ei * c - ct
    tx, ty, tz = f * mx - ei * wx, f * my - ei * wy, f * mz - ei * wz
    th = tx * mx + ty * my + tz * mz
    den = c + er * th
    if wz * tz >= 0.0 or th >= 0.0 or abs(den) <= 1e-12:
        return tx, ty, tz, 0.0, 0.0
    p = g1w * c * _ggx_d(mx, my, mz, a) / abs(wz) * er * er * (-th) / (den * den)
    if not p > 0.0:
        return tx, ty, tz, 0.0, 0.0
    rs = (c - er * ct) / (c + er * ct)
    rp = (er * c - ct) / (er * c + ct)
    F = 0.5 * (rs * rs + rp * rp)
    g1t = _g1_dir(tx, ty, tz, a) if th * tz > 0.0 else 0.0
    return tx, ty, tz, (1.0 - F) * g1t, p


# --- conductor base: geometric part (F = 1); Schlick per channel applied by the caller -----
@njit(**_JIT)
def _schlick5(c):
    """Schlick's (1 - |c|)^5."""
    t = 1.0 - min(abs(c), 1.0)
    t2 = t * t
    return t2 * t2 * t


@njit(**_JIT)
def _cond_eval(ix, iy, iz, ox, oy, oz, a, g1i):
    """``_cond_geo`` given G1(i) (shared by the base's next-event evaluation
    and its own sample at one vertex)."""
    if iz <= 0.0 or oz <= 0.0:
        return 0.0, 0.0, 0.0
    hx, hy, hz = _norm3(ix + ox, iy + oy, iz + oz)
    ih = ix * hx + iy * hy + iz * hz
    if ih <= 0.0:
        return 0.0, 0.0, 0.0
    p = g1i * _ggx_d(hx, hy, hz, a) / (4.0 * iz)
    return p * _g1_dir(ox, oy, oz, a) / oz, p, _schlick5(ih)


@njit(**_JIT)
def _cond_pdf(ix, iy, iz, ox, oy, oz, a):
    """The density with which the base's VNDF sampling from i gives o (the
    reversed-chain densities of estimator v6)."""
    return _cond_eval(ix, iy, iz, ox, oy, oz, a, _g1_dir(ix, iy, iz, a))[1]


@njit(**_JIT)
def _cond_geo(ix, iy, iz, ox, oy, oz, a):
    """(f with F = 1, pdf, Schlick's (1 - |i.h|)^5)."""
    if iz <= 0.0 or oz <= 0.0:
        return 0.0, 0.0, 0.0
    hx, hy, hz = _norm3(ix + ox, iy + oy, iz + oz)
    ih = ix * hx + iy * hy + iz * hz
    f = (_ggx_d(hx, hy, hz, a) * _g1(ix, iy, iz, hx, hy, hz, a) * _g1(ox, oy, oz, hx, hy, hz, a)
         / max(4.0 * iz * oz, 1e-30))
    p = _vndf_pdf(ix, iy, iz, hx, hy, hz, a) / (4.0 * abs(ih)) if ih != 0.0 else 0.0
    return f, p, _schlick5(ih)


@njit(**_JIT)
def _first_vertex(wx, wy, wz, gx, gy, gz, a0, e0, lam, wide, a_wide, ox, oy, oz, entry):
    """The top vertex of the two-bounce connection toward the downward g: (its
    f |g_z|, the walk's density of g there). ``entry``: w is wi above the
    stack and the vertex is the forced refraction into it; else the internal
    reflection with the walk's mixture (lam, wide, a_wide)."""
    if entry:
        fr, _ = _diel_eval_pdf(wx, wy, wz, gx, gy, gz, a0, e0)
        return fr * abs(gz), _ft_pdf(a0, e0, wx, wy, wz, gx, gy, gz)
    return _top_eval(wx, wy, wz, gx, gy, gz, a0, e0, lam, wide, a_wide, ox, oy, oz)


@njit(**_JIT)
def _mirror_connection(wx, wy, wz, a0, e0, ba, lam, wide, a_wide, agw, ox, oy, oz, u0, u1, u2, u3, entry, tau0):
    """Strategy C of the two-bounce connection (top reflection -> base ->
    exit toward wo) for an empty top slab over a conductor: draws the
    reflected direction g from the exit lobe toward wo mirrored about the
    plane (the guide), the base's direction u from its VNDF, and evaluates
    the exit in closed form. Returns (value without Fresnel and beta:
    f_r |g_z| / p_g * f_c u_z / p_c * f_exit * MIS weight, Schlick's x at the
    base); the MIS weight is C's share of the balance heuristic over A (walk:
    p_mix(g) p_c(u)), B (next-event at the base: p_mix(g) p_n(u)), C
    (p_g(g) p_c(u)) and D (the wide guide and next-event estimation:
    p_w(g) p_n(u), ``_wide_connection``; agw: its roughness). ``entry``: w
    is wi above the stack and the first vertex is the forced refraction into
    it instead of the internal reflection. tau0: the top slab's optical
    thickness (the path crosses it twice unscattered)."""
    tx, ty, tz, _, pg = _ft_sample(a0, e0, ox, oy, oz, u0, u1)
    if pg <= 0.0:
        return 0.0, 0.0
    gx, gy, gz = -tx, -ty, tz
    fr, pm = _first_vertex(wx, wy, wz, gx, gy, gz, a0, e0, lam, wide, a_wide, ox, oy, oz, entry)
    if fr <= 0.0:
        return 0.0, 0.0
    mx, my, mz = _sample_vndf(-gx, -gy, -gz, ba, u2, u3)
    ux, uy, uz = _reflect(-gx, -gy, -gz, mx, my, mz)
    fc, pc, x = _cond_geo(-gx, -gy, -gz, ux, uy, uz, ba)
    if fc <= 0.0 or pc <= 0.0:
        return 0.0, 0.0
    fe, _ = _diel_eval_pdf(-ux, -uy, -uz, ox, oy, oz, a0, e0)
    if fe <= 0.0:
        return 0.0, 0.0
    pn = _ft_pdf(a0, e0, ox, oy, oz, -ux, -uy, -uz)
    pw = _ft_pdf(agw, e0, ox, oy, oz, -gx, -gy, gz)
    tg, tu = _survival(tau0, 1.0, gz), _survival(tau0, 1.0, uz)
    w = pg * pc / (pm * tg * tu * pc + pm * tg * pn + pg * pc + pw * pn)
    return fr / pg * fc * uz / pc * fe * w * tg * tu, x


@njit(**_JIT)
def _wide_connection(wx, wy, wz, a0, e0, ba, lam, wide, a_wide, agw, ox, oy, oz, sx, sy, sz, g1o, u0, u1, u2, u3,
                     entry, tau0):
    """Strategy D of the two-bounce connection (the path of
    ``_mirror_connection``): the reflected direction g from the wide guide
    (the exit lobe toward wo of a coat of roughness agw, mirrored about the
    plane), next-event estimation toward wo at the base, and the base's BRDF
    evaluated: its GGX tail bridges the ring around the exit lobe that neither
    the narrow guide (C) nor the walk's own reflection samples well. Weighted
    by the balance heuristic over A (p_mix p_c), B (p_mix p_n), C (p_g p_c)
    and D (p_w p_n). Returns (value per unit beta without the base's Fresnel,
    Schlick's x at the base)."""
    tx, ty, tz, _, pw = _ft_sample(agw, e0, ox, oy, oz, u0, u1)
    if pw <= 0.0:
        return 0.0, 0.0
    gx, gy, gz = -tx, -ty, tz
    fr, pm = _first_vertex(wx, wy, wz, gx, gy, gz, a0, e0, lam, wide, a_wide, ox, oy, oz, entry)
    if fr <= 0.0:
        return 0.0, 0.0
    vx, vy, vz, sc, pn = _nee(1.0, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0, u2, u3)
    if sc <= 0.0:
        return 0.0, 0.0
    fc, pb, x = _cond_geo(-gx, -gy, -gz, vx, vy, vz, ba)
    if fc <= 0.0:
        return 0.0, 0.0
    pg = _ft_pdf(a0, e0, ox, oy, oz, -gx, -gy, gz)
    tg, tv = _survival(tau0, 1.0, gz), _survival(tau0, 1.0, vz)  # the flights down and up; sc has the one up
    return fr * fc * vz * sc * pn * tg / (pm * tg * tv * pb + pm * tg * pn + pg * pb + pw * pn), x


# --- the walk -----------------------------------------------------------------------------
@njit(**_JIT)
def _survival(tau, length, cz):
    """Tr = exp(-tau length / |cz|): the probability that a flight through
    ``length`` (in slab thicknesses) of a slab of optical thickness ``tau``
    along a direction of z component ``cz`` passes unscattered; 1 for an
    empty slab."""
    return math.exp(-tau * length / max(abs(cz), 1e-12)) if tau > 0.0 else 1.0


@njit(**_JIT)
def _nee(z, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0, u0, u1):
    """Samples the top interface from wo (forced transmission): the direction
    v = (vx, vy, vz) leaving the vertex upward, Tr f_top(-v, wo) / pdf and pdf.
    (sx, sy, sz), g1o: wo's stretched view direction and G1 (per pair).
    f_top(t, wo) / pdf = (1 - F) G1(t) / (eta^2 |t_z|) in closed form (the
    facet's D, G1(wo) and Jacobian cancel)."""
    tx, ty, tz, w, p = _ft_core(sx, sy, sz, g1o, a0, e0, ox, oy, oz, u0, u1)
    if p <= 0.0 or w <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0
    vz = -tz
    tr = _survival(tau0, z, vz)
    return -tx, -ty, vz, tr * w / (e0 * e0 * vz), p


@njit(**_JIT)
def _chain_nee(depth, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0, a1, e1, tau1, u0, u1, u2, u3):
    """Next-event estimation through the stack for a vertex in slab 1 (at
    ``depth`` in [1, 2]) of a two-interface stack: v0 in slab 0 by forced
    refraction from wo through the top (as ``_nee``), then d1 in slab 1 by
    forced refraction of v0 down through interface 1. Returns d1 (up, from
    the vertex), g = Tr1 f_if(-d1, v0) |v0_z| Tr0 f_top(v0, wo) / (pn p1) and
    the three strategies' densities of the segment (d1, v0) without the
    vertex's own density: pn (v0 from wo), p1 (d1 given v0), p_if (v0 given
    d1, the walk's sampling at interface 1), and Tr1, Tr0: the flights'
    survival, which the walk's own densities carry in the MIS weights."""
    v0x, v0y, v0z, sc0, pn = _nee(1.0, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0, u0, u1)
    if sc0 <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0
    tx, ty, tz, w1, p1 = _ft_sample(a1, e1, v0x, v0y, v0z, u2, u3)
    if p1 <= 0.0 or w1 <= 0.0 or tz >= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0
    f_if, p_if = _diel_eval_pdf(tx, ty, tz, v0x, v0y, v0z, a1, e1)
    if f_if <= 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0
    d1z = -tz
    tr1, tr0 = _survival(tau1, depth - 1.0, d1z), _survival(tau0, 1.0, v0z)
    return -tx, -ty, d1z, tr1 * f_if * v0z * sc0 / p1, pn, p1, p_if, tr1, tr0


@njit(**_JIT)
def _mirror_chain_nee(depth, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0, ba, u0, u1, u2, u3):
    """Next-event estimation by way of a sharp conductor base for a
    scattering in slab 0 (one interface): v0 by forced refraction from wo
    through the top, then u (= -d, d the direction down to the base) by the
    base's VNDF reflection of v0. Returns g = Tr(d) f_base(u, v0) |v0_z| Tr0
    f_top(v0, wo) / pn (F = 1; Schlick's x for the caller), pn, pb (the walk's
    density of v0 given u), p_rev (the chain's density of u given v0), x."""
    v0x, v0y, v0z, sc0, pn = _nee(1.0, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0, u0, u1)
    if sc0 <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    mx, my, mz = _sample_vndf(v0x, v0y, v0z, ba, u2, u3)
    ux, uy, uz = _reflect(v0x, v0y, v0z, mx, my, mz)
    if uz <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    f, pb, x = _cond_eval(ux, uy, uz, v0x, v0y, v0z, ba, _g1_dir(ux, uy, uz, ba))
    p_rev = _cond_pdf(v0x, v0y, v0z, ux, uy, uz, ba)
    if f <= 0.0 or p_rev <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    tr = _survival(tau0, 1.0 - depth, uz)
    return tr * f * v0z * sc0 / p_rev, pn, pb, p_rev, x


@njit(**_JIT)
def _exit_eval(wx, wy, wz, ox, oy, oz, g1w, g1o, a, eta):
    """At the top seen from below (w points down into the stack): (f(w, wo) of
    the transmission toward wo, the density ``_ft_pdf`` gives w when sampled
    from wo); the two share the half vector, D and G1(wo) (g1o, per pair;
    g1w = G1(w), shared with the reflection sampled at the same vertex)."""
    if wz == 0.0 or oz == 0.0:
        return 0.0, 0.0
    hx, hy, hz = _norm3(-(eta * wx + ox), -(eta * wy + oy), -(eta * wz + oz))
    if hz < 0.0:
        hx, hy, hz = -hx, -hy, -hz
    ih = wx * hx + wy * hy + wz * hz
    oh = ox * hx + oy * hy + oz * hz
    if ih * oh >= 0.0 or oh <= 0.0 or ih * wz <= 0.0:
        return 0.0, 0.0
    den = eta * ih + oh
    if abs(den) <= 1e-12:
        return 0.0, 0.0
    F = _fresnel(ih, 1.0 / eta)
    common = g1o * oh * _ggx_d(hx, hy, hz, a) * abs(ih) / (oz * den * den)
    return common * (1.0 - F) * g1w / abs(wz), common * eta * eta


@njit(**_JIT)
def _split_key(key0, copy):
    """The random-number key of copy ``copy`` (>= 1) of a split path."""
    return _mix64(key0 ^ (np.uint64(copy) * np.uint64(0xD1B54A32D192ED03)))


@njit(**_JIT)
def _path(q, s, spp, seed, wi, wo, rough, ior, sigma, alb, base, b_rough, b_r0, b_ior, b_alb,
          rr_depth, max_depth, forced, rr_weight, a_wide, lam, lam_w, agw, kmax, kstep, ifloor, out, beta, stk):
    """One path; writes its contribution per channel to ``out`` and returns
    the number of vertices (``beta``: scratch of C weights; ``stk``: scratch
    of the pending copies of a split path, (kmax - 1, 7 + C))."""
    C = out.shape[0]
    L = rough.shape[1]
    key = _lane_key(seed, q * spp + s)
    key0 = key
    ctr = 0
    ix, iy, iz = wi[q, 0], wi[q, 1], wi[q, 2]
    ox, oy, oz = wo[q, 0], wo[q, 1], wo[q, 2]
    a0, e0, tau0 = rough[q, 0], ior[q, 0], sigma[q, 0]
    # wo's stretched view direction and G1 for the top: next-event estimation samples from wo at every vertex
    sx, sy, sz = _norm3(a0 * ox, a0 * oy, oz)
    g1o = _g1_dir(ox, oy, oz, a0)
    u0 = (s + _uniform(key, 0)) / spp
    u1 = _uniform(key, 1)
    ctr = 2
    dx, dy, dz, w_entry, _ = _ft_sample(a0, e0, ix, iy, iz, u0, u1)
    for c in range(C):
        out[c] = 0.0
    # the same through a medium over a sharp conductor (roughness < MIRROR_CHAIN_ROUGHNESS): the
    # unscattered chain top -> base -> exit joins two lobes through a near-mirror (estimator v7)
    conn = forced and L == 1 and base == 0 and (tau0 == 0.0 or b_rough[q] < MIRROR_CHAIN_ROUGHNESS)
    if conn:  # strategies C and D from the entry (independent of the walk's first sample)
        k, x = _mirror_connection(ix, iy, iz, a0, e0, b_rough[q], 1.0, False, a_wide, agw, ox, oy, oz,
                                  _uniform(key, 2), _uniform(key, 3), _uniform(key, 4), _uniform(key, 5), True, tau0)
        kd, xd = _wide_connection(ix, iy, iz, a0, e0, b_rough[q], 1.0, False, a_wide, agw, ox, oy, oz, sx, sy, sz,
                                  g1o, _uniform(key, 6), _uniform(key, 7), _uniform(key, 8), _uniform(key, 9), True,
                                  tau0)
        for c in range(C):
            r0 = b_r0[q, c]
            out[c] += k * (x + r0 * (1.0 - x)) + kd * (xd + r0 * (1.0 - xd))
    if w_entry <= 0.0:
        return 0
    for c in range(C):
        beta[c] = w_entry
    depth = 0.0
    slab = 0
    pdf_last = 0.0
    vertices = 0
    bounces = 0
    vx = vy = vz = pn = p = 0.0
    nx, ny, nz = dx, dy, dz
    # the two-bounce connection (strategies C and D) is on for an empty top
    # slab over a conductor; (pm, pg, pw): densities of the current downward
    # direction from the walk's mixture, the guide and the wide guide (pg = pw
    # = 0: no top vertex before it)
    pm, pg, pw, tg = 1.0, 0.0, 0.0, 1.0
    if conn:
        ctr = 10
        pm = _ft_pdf(a0, e0, ix, iy, iz, dx, dy, dz)
        tg = _survival(tau0, 1.0, dz)
        pg = _ft_pdf(a0, e0, ox, oy, oz, -dx, -dy, dz)
        pw = _ft_pdf(agw, e0, ox, oy, oz, -dx, -dy, dz)
    # splitting by exit importance (v5): g* = centre of the mirrored exit lobe,
    # i_peak = I of the state a flat facet turns into g*; kscale = product of
    # the split factors (beta * kscale = the unsplit weight), lref = the
    # importance level (unsplit weight x I) the path started at x kscale
    split = conn and kmax > 1 and tau0 == 0.0
    # next-event estimation through the stack (two interfaces): at vertices in
    # slab 1, with MIS over the segment (d1, v0) against the walk (exit in
    # closed form at the top) and next-event estimation at interface 1;
    # (chx, chy, chz, chp): d1 and its density while the walk's segment is on
    chain = forced and L == 2
    # the same through the base for one interface over a medium and a sharp
    # conductor (roughness < MIRROR_CHAIN_ROUGHNESS): a scattering in slab 0
    # connects to wo by way of the base's reflection (segment (d, v0): d down
    # to the base, v0 up to the top)
    mirror = forced and L == 1 and base == 0 and tau0 > 0.0 and b_rough[q] < MIRROR_CHAIN_ROUGHNESS
    scat = False
    ch_on = False
    chx = chy = chz = chp = 0.0
    cht1 = 1.0  # the survival of the walk's flight d1 in slab 1
    gsx = gsy = gsz = i_peak = lref = 0.0
    kscale = 1.0
    ntot = 1
    nstk = 0
    resume = False  # a popped copy: its vertex was evaluated, only its reflection is left to sample
    if split:
        gsx, gsy = ox / e0, oy / e0
        gsz = -math.sqrt(max(1.0 - gsx * gsx - gsy * gsy, 0.0))
        i_peak, _ = _top_eval(-gsx, -gsy, gsz, gsx, gsy, gsz, a0, e0, 1.0, False, a_wide, ox, oy, oz)
    while True:
        if bounces >= max_depth:
            if nstk == 0:
                break
            nstk -= 1
            dx, dy, dz = -stk[nstk, 0], -stk[nstk, 1], -stk[nstk, 2]
            bounces, kscale, lref = int(stk[nstk, 3]), stk[nstk, 4], stk[nstk, 5]
            key, ctr, resume, slab, depth = _split_key(key0, int(stk[nstk, 6])), 0, True, 0, 0.0
            for c in range(C):
                beta[c] = stk[nstk, 7 + c]
        bounces += 1
        vertices += 1
        z0 = depth  # where the flight starts
        # free flight in the current slab
        tau = sigma[q, slab]
        down = dz < 0.0
        if down:
            dist_b = (slab + 1.0 - depth) / max(-dz, 1e-12)
        else:
            dist_b = (depth - slab) / max(dz, 1e-12)
        u = _uniform(key, ctr)
        ctr += 1
        scatter = False
        if tau > 0.0:
            t = -math.log(1.0 - u) / tau  # 1 - u is exact (u: a multiple of 2^-53); log is 2.5x cheaper than log1p
            if t < dist_b:
                scatter = True
                depth = depth - t * dz
        alive = True
        ch_prev = ch_on  # the walk's segment (d1, v0) reaches the top only without a vertex between
        ch_on = False
        scat_prev = scat  # the vertex before this one was a scattering
        scat = scatter
        if scatter:
            pm, pg, pw, tg = 1.0, 0.0, 0.0, 1.0  # the connection makes only unscattered segments
            if slab == 0:
                vx, vy, vz, sc, pn = _nee(depth, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0, _uniform(key, ctr), _uniform(key, ctr + 1))
                if sc > 0.0:
                    k = INV_4PI * sc * pn / (pn + INV_4PI)
                    for c in range(C):
                        out[c] += beta[c] * alb[q, slab, c] * k
                if mirror and _uniform(key, ctr + 6) < MIRROR_CHAIN_P:
                    g, pn, pb, p_rev, x = _mirror_chain_nee(depth, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0, b_rough[q],
                                                            _uniform(key, ctr + 2), _uniform(key, ctr + 3),
                                                            _uniform(key, ctr + 4), _uniform(key, ctr + 5))
                    if g > 0.0:
                        k = INV_4PI * g * pn * p_rev / (INV_4PI * pb + INV_4PI * pn + MIRROR_CHAIN_P * pn * p_rev)
                        for c in range(C):
                            out[c] += beta[c] * alb[q, slab, c] * k * (x + b_r0[q, c] * (1.0 - x))
                if mirror:
                    ctr += 5
            elif chain and slab == 1:
                _, _, _, g, pn, p1, p_if, t1, t0 = _chain_nee(depth, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0,
                                                              rough[q, 1], ior[q, 1], sigma[q, 1], _uniform(key, ctr),
                                                              _uniform(key, ctr + 1), _uniform(key, ctr + 2),
                                                              _uniform(key, ctr + 3))
                if g > 0.0:
                    # the walk passes the flights by chance: its densities carry their survival (t1, t0)
                    k = INV_4PI * g * pn * p1 / (INV_4PI * t1 * t0 * p_if + INV_4PI * t1 * pn + pn * p1)
                    for c in range(C):
                        out[c] += beta[c] * alb[q, slab, c] * k
                ctr += 2
            ctr += 2
            for c in range(C):
                beta[c] *= alb[q, slab, c]
            zz = 1.0 - 2.0 * _uniform(key, ctr)
            ph = _uniform(key, ctr + 1)
            ctr += 2
            r = math.sqrt(max(1.0 - zz * zz, 0.0))
            cph, sph = _cos_sin_2pi(ph)
            dx, dy, dz = r * cph, r * sph, zz
            pdf_last = INV_4PI
        else:
            k_if = slab + 1 if down else slab
            depth = slab + 1.0 if down else float(slab)
            wx, wy, wz = -dx, -dy, -dz  # toward where the light came from
            if k_if == 0:
                # the top from below: exit toward wo in closed form, MIS vs NEE
                g1w = _g1_dir(wx, wy, wz, a0)
                f, pn = _exit_eval(wx, wy, wz, ox, oy, oz, g1w, g1o, a0, e0)
                if f > 0.0 and not resume:
                    if ch_prev and mirror:  # the segment by way of the base: (walk, NEE at the base, the chain)
                        p_rev = _cond_pdf(-wx, -wy, -wz, chx, chy, chz, b_rough[q])
                        k = f * chp * pdf_last / (chp * pdf_last + chp * pn + MIRROR_CHAIN_P * pn * p_rev)
                    elif ch_prev:  # the segment from slab 1: three strategies (walk, NEE at interface 1, the chain)
                        p1 = _ft_pdf(rough[q, 1], ior[q, 1], -wx, -wy, -wz, -chx, -chy, -chz)
                        t0 = _survival(tau0, 1.0, wz)  # the walk's densities carry survival
                        k = f * chp * cht1 * t0 * pdf_last / (chp * cht1 * t0 * pdf_last + chp * cht1 * pn + pn * p1)
                    else:
                        # through a medium the walk's densities carry the flights' survival (tg, tu): the
                        # connection evaluates them, the walk passes them by chance
                        tu = _survival(tau0, 1.0, wz) if conn and not scat_prev else 1.0
                        pa = pm * tg * tu * pdf_last
                        k = f * pa / (pa + pm * tg * pn + pg * pdf_last + pw * pn)
                    for c in range(C):
                        out[c] += beta[c] * k
                if forced:
                    trapped = (1.0 - wz * wz) * e0 * e0 >= 1.0
                    if trapped:
                        lm, wide = (1.0 if conn else lam if tau0 == 0.0 else 1.0), False
                    else:
                        lm, wide = lam_w, True
                    if wide or lm >= 1.0:
                        nx, ny, nz, wgt, p = _top_reflect_vndf(wx, wy, wz, a0, e0, _uniform(key, ctr),
                                                               _uniform(key, ctr + 1), _uniform(key, ctr + 2), lm,
                                                               max(a0, a_wide) if wide else a0, g1w)
                    else:
                        nx, ny, nz, wgt, p = _top_reflect(wx, wy, wz, a0, e0, _uniform(key, ctr),
                                                          _uniform(key, ctr + 1), _uniform(key, ctr + 2), lm, wide,
                                                          a_wide, ox, oy, oz)
                    if conn and not resume:
                        k, x = _mirror_connection(wx, wy, wz, a0, e0, b_rough[q], lm, wide, a_wide, agw, ox, oy,
                                                  oz, _uniform(key, ctr + 3), _uniform(key, ctr + 4),
                                                  _uniform(key, ctr + 5), _uniform(key, ctr + 6), False, tau0)
                        kd, xd = _wide_connection(wx, wy, wz, a0, e0, b_rough[q], lm, wide, a_wide, agw, ox, oy, oz,
                                                  sx, sy, sz, g1o, _uniform(key, ctr + 7), _uniform(key, ctr + 8),
                                                  _uniform(key, ctr + 9), _uniform(key, ctr + 10), False, tau0)
                        for c in range(C):
                            r0 = b_r0[q, c]
                            out[c] += beta[c] * (k * (x + r0 * (1.0 - x)) + kd * (xd + r0 * (1.0 - xd)))
                        if split:
                            iv, _ = _top_eval(wx, wy, wz, gsx, gsy, gsz, a0, e0, 1.0, False, a_wide, ox, oy, oz)
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
                                for _j in range(ks - 1):  # pending copies: this vertex, before its reflection
                                    stk[nstk, 0], stk[nstk, 1], stk[nstk, 2] = wx, wy, wz
                                    stk[nstk, 3], stk[nstk, 4], stk[nstk, 5], stk[nstk, 6] = bounces - 1, kscale, lref, ntot
                                    for c in range(C):
                                        stk[nstk, 7 + c] = beta[c] / ks
                                    nstk += 1
                                    ntot += 1
                                for c in range(C):
                                    beta[c] /= ks
                    if conn:
                        ctr += 8
                        pm = p
                        tg = _survival(tau0, 1.0, nz) if p > 0.0 else 1.0
                        pg = _ft_pdf(a0, e0, ox, oy, oz, -nx, -ny, nz) if p > 0.0 else 0.0
                        pw = _ft_pdf(agw, e0, ox, oy, oz, -nx, -ny, nz) if p > 0.0 else 0.0
                else:
                    nx, ny, nz, wgt, p = _diel_sample(wx, wy, wz, a0, e0, _uniform(key, ctr), _uniform(key, ctr + 1),
                                                      _uniform(key, ctr + 2))
                ctr += 3
                alive = p > 0.0 and nz < 0.0 and wgt > 0.0
                for c in range(C):
                    beta[c] *= wgt
            elif k_if < L:
                a, e = rough[q, k_if], ior[q, k_if]
                if k_if == 1:
                    # from slab 1: the survival of the walk's flight d1 (its MIS density and the segment's)
                    t1 = _survival(sigma[q, 1], z0 - 1.0, dz) if chain and wz < 0.0 else 1.0
                    vx, vy, vz, sc, pn = _nee(1.0, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0, _uniform(key, ctr),
                                              _uniform(key, ctr + 1))
                    if sc > 0.0:
                        f, pb = _diel_eval_pdf(wx, wy, wz, vx, vy, vz, a, e)
                        if chain and wz < 0.0:  # from slab 1: the chain's density of d1 = -w enters the weight
                            p1 = _ft_pdf(a, e, vx, vy, vz, wx, wy, wz)
                            pw1 = pdf_last * t1  # the walk's density of d1 and its survival
                            k = f * abs(vz) * sc * pw1 * pn / (pw1 * _survival(tau0, 1.0, vz) * pb + pw1 * pn + pn * p1)
                        else:
                            k = f * abs(vz) * sc * pn / (pn + pb)
                        for c in range(C):
                            out[c] += beta[c] * k
                ctr += 2
                nx, ny, nz, wgt, p = _diel_sample(wx, wy, wz, a, e, _uniform(key, ctr), _uniform(key, ctr + 1),
                                                  _uniform(key, ctr + 2))
                ctr += 3
                alive = p > 0.0 and wgt > 0.0
                if chain and alive and wz < 0.0 and nz > 0.0:  # up through interface 1: the segment starts
                    ch_on, chx, chy, chz, chp = True, -wx, -wy, -wz, pdf_last
                    cht1 = t1
                if alive and wz * nz < 0.0:  # crossed: down into slab k, up into slab k - 1
                    slab = k_if if dz < 0.0 else k_if - 1
                for c in range(C):
                    beta[c] *= wgt
            else:
                nee_on = L == 1
                if nee_on:
                    vx, vy, vz, sc, pn = _nee(1.0, sx, sy, sz, g1o, ox, oy, oz, a0, e0, tau0, _uniform(key, ctr),
                                              _uniform(key, ctr + 1))
                else:
                    sc = 0.0
                ba = b_rough[q]
                g1w = _g1_dir(wx, wy, wz, ba) if base == 0 else 0.0
                if chain and wz > 0.0:  # the base under slab 1: next-event estimation through the stack
                    d1x, d1y, d1z, g, pn, p1, p_if, t1, t0 = _chain_nee(depth, sx, sy, sz, g1o, ox, oy, oz, a0, e0,
                                                                        tau0, rough[q, 1], ior[q, 1], sigma[q, 1],
                                                                        _uniform(key, ctr), _uniform(key, ctr + 1),
                                                                        _uniform(key, ctr + 2), _uniform(key, ctr + 3))
                    if g > 0.0:
                        if base == 0:
                            fb, pb, x = _cond_eval(wx, wy, wz, d1x, d1y, d1z, ba, g1w)
                        elif base == 1:
                            fb, pb, x = INV_PI, d1z * INV_PI, 0.0
                        else:
                            fb, pb = _diel_eval_pdf(wx, wy, wz, d1x, d1y, d1z, ba, b_ior[q])
                            x = 0.0
                        if fb > 0.0:
                            k = fb * d1z * g * pn * p1 / (pb * t1 * t0 * p_if + pb * t1 * pn + pn * p1)
                            for c in range(C):
                                col = (x + b_r0[q, c] * (1.0 - x)) if base == 0 else (b_alb[q, c] if base == 1 else 1.0)
                                out[c] += beta[c] * k * col
                    ctr += 2
                ctr += 2
                if base == 0:
                    seg = mirror and scat_prev and wz > 0.0  # from a scattering: the chain made this segment too
                    if sc > 0.0:
                        f, pb, x = _cond_eval(wx, wy, wz, vx, vy, vz, ba, g1w)
                        if seg:
                            p_rev = _cond_pdf(vx, vy, vz, wx, wy, wz, ba)
                            k = f * abs(vz) * sc * pdf_last * pn / (pdf_last * pb + pdf_last * pn + MIRROR_CHAIN_P * pn * p_rev)
                        else:
                            tv = _survival(tau0, 1.0, vz) if conn else 1.0
                            k = f * abs(vz) * sc * pm * tg * pn / (pm * tg * pn + pm * tg * tv * pb + pg * pb + pw * pn)
                        for c in range(C):
                            out[c] += beta[c] * k * (x + b_r0[q, c] * (1.0 - x))
                    mx, my, mz = _sample_vndf(wx, wy, wz, ba, _uniform(key, ctr), _uniform(key, ctr + 1))
                    nx, ny, nz = _reflect(wx, wy, wz, mx, my, mz)
                    # the sampled facet is the half vector: f nz / p = G1(n) (VNDF), p = G1(w) D / (4 wz)
                    wm = wx * mx + wy * my + wz * mz
                    p = g1w * _ggx_d(mx, my, mz, ba) / (4.0 * wz) if wz > 0.0 and nz > 0.0 and wm > 0.0 else 0.0
                    wgt = _g1_dir(nx, ny, nz, ba) if p > 0.0 else 0.0
                    alive = p > 0.0 and wgt > 0.0
                    x = _schlick5(wm)
                    for c in range(C):
                        beta[c] *= wgt * (x + b_r0[q, c] * (1.0 - x))
                    if seg and alive:  # the walk's segment (d, v0) starts: keep u = -d and d's density
                        ch_on, chx, chy, chz, chp = True, wx, wy, wz, pdf_last
                elif base == 1:
                    if sc > 0.0 and wz > 0.0:
                        k = max(vz, 0.0) * INV_PI * sc * pn / (pn + max(vz, 0.0) * INV_PI)
                        for c in range(C):
                            out[c] += beta[c] * b_alb[q, c] * k
                    u0, u1 = _uniform(key, ctr), _uniform(key, ctr + 1)
                    r = math.sqrt(u0)
                    cph, sph = _cos_sin_2pi(u1)
                    nx, ny, nz = r * cph, r * sph, math.sqrt(max(1.0 - u0, 0.0))
                    p = nz * INV_PI
                    alive = wz > 0.0 and p > 0.0
                    for c in range(C):
                        beta[c] *= b_alb[q, c] if alive else 0.0
                else:
                    be = b_ior[q]
                    if sc > 0.0:
                        f, pb = _diel_eval_pdf(wx, wy, wz, vx, vy, vz, ba, be)
                        k = f * abs(vz) * sc * pn / (pn + pb)
                        for c in range(C):
                            out[c] += beta[c] * k
                    nx, ny, nz, wgt, p = _diel_sample(wx, wy, wz, ba, be, _uniform(key, ctr), _uniform(key, ctr + 1),
                                                      _uniform(key, ctr + 2))
                    alive = p > 0.0 and nz > 0.0 and wgt > 0.0  # what is transmitted leaves the stack
                    for c in range(C):
                        beta[c] *= wgt if alive else 0.0
                ctr += 3
            dx, dy, dz, pdf_last = nx, ny, nz, p
        u = _uniform(key, ctr)
        ctr += 1
        stop = not alive
        if not stop:
            bmax = 0.0
            for c in range(C):
                bmax = max(bmax, beta[c])
            if not bmax > 0.0:
                stop = True
            elif bounces >= rr_depth:
                qs = min(bmax * kscale / rr_weight, 1.0) if forced else min(bmax, 0.95)
                if u >= qs:
                    stop = True
                else:
                    for c in range(C):
                        beta[c] /= qs
        if stop:
            if nstk == 0:
                break
            bounces = max_depth  # the next pending copy of a split path
        else:
            resume = False
    return vertices


@njit(parallel=True, **_JIT)
def _run(wi, wo, spp, seed, rough, ior, sigma, alb, base, b_rough, b_r0, b_ior, b_alb, rr_depth, max_depth,
         forced, rr_weight, a_wide, lam, lam_w, agw, kmax, kstep, ifloor, block):
    """Per work item (pair, block of ``block`` paths): the sum and the sum of
    squares of the path contributions per channel, the number of vertices and
    of dropped (non-finite) paths."""
    N = wi.shape[0]
    C = alb.shape[2]
    nb = (spp + block - 1) // block
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
        stk = np.empty((max(kmax - 1, 1), 7 + C))
        for s in range(b * block, min(spp, (b + 1) * block)):
            verts[it] += _path(q, s, spp, seed, wi, wo, rough, ior, sigma, alb, base, b_rough, b_r0, b_ior, b_alb,
                               rr_depth, max_depth, forced, rr_weight, a_wide, lam, lam_w, agw, kmax, kstep, ifloor,
                               out, beta, stk)
            finite = True
            for c in range(C):
                if not math.isfinite(out[c]):
                    finite = False
            if not finite:
                dropped[it] += 1
                continue
            for c in range(C):
                s1[it, c] += out[c]
                s2[it, c] += out[c] * out[c]
    return s1, s2, verts, dropped


__all__ = ["RR_WEIGHT", "BLOCK"]
