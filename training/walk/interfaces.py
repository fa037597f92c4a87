"""The walk's interface kinds, each with its own kernels: the rough
dielectric (Walter et al. 2007; eta = index below / above), the conductor
base (its geometric part, F = 1: Schlick's factor per channel is applied by
the caller), the diffuse base and the isotropic medium. Every strategy
evaluates, samples and takes densities through these.

Where the sampled facet is known, evaluation and density share it (the top's
reflection, the conductor's sample, the forced refraction): each such fused
kernel equals the generic one it replaces up to rounding
(tests/training/test_walk_kernels.py).

Roughness is the pair (ax, ay) of ``ggx`` (alpha along x and y of the walk's
frame, equal for an isotropic interface)."""
from __future__ import annotations

import math

from numba import njit

from nbrdf.neural.layer_kinds import BASE_CODES
from nbrdf.training.walk.ggx import (
    INV_PI,
    cos_sin_2pi,
    fresnel,
    g1,
    g1_dir,
    ggx_d,
    norm3,
    reflect,
    refract,
    sample_vndf,
    schlick5,
    vndf_pdf,
    vndf_std,
)
from nbrdf.training.walk.params import JIT, JIT_INLINE

#: Base kinds as the walk's record carries them (``WalkParams.base``).
CONDUCTOR = BASE_CODES["conductor"]
DIFFUSE = BASE_CODES["diffuse"]
DIELECTRIC = BASE_CODES["dielectric"]


# --- rough dielectric ----------------------------------------------------------------------
@njit(**JIT)
def diel_setup(ix, iy, iz, ox, oy, oz, eta):
    above_i = iz > 0.0
    refl = iz * oz > 0.0
    eta_i = 1.0 if above_i else eta
    eta_o = eta_i if refl else (eta if above_i else 1.0)
    if refl:
        hx, hy, hz = norm3(ix + ox, iy + oy, iz + oz)
    else:
        hx, hy, hz = norm3(-(eta_i * ix + eta_o * ox), -(eta_i * iy + eta_o * oy), -(eta_i * iz + eta_o * oz))
    if hz < 0.0:
        hx, hy, hz = -hx, -hy, -hz
    eta_rel = eta if above_i else 1.0 / eta
    return eta_i, eta_o, hx, hy, hz, refl, eta_rel


@njit(**JIT)
def diel_eval_pdf(ix, iy, iz, ox, oy, oz, ax, ay, eta):
    """(f(wi, wo), pdf of sampling wo from wi)."""
    if iz == 0.0 or oz == 0.0:
        return 0.0, 0.0
    eta_i, eta_o, hx, hy, hz, refl, eta_rel = diel_setup(ix, iy, iz, ox, oy, oz, eta)
    ih = ix * hx + iy * hy + iz * hz
    oh = ox * hx + oy * hy + oz * hz
    F = fresnel(ih, eta_rel)
    dg = ggx_d(hx, hy, hz, ax, ay) * g1(ix, iy, iz, hx, hy, hz, ax, ay) * g1(ox, oy, oz, hx, hy, hz, ax, ay)
    cos_io = max(abs(iz * oz), 1e-30)
    pm = vndf_pdf(ix, iy, iz, hx, hy, hz, ax, ay)
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


@njit(**JIT)
def diel_sample(wx, wy, wz, ax, ay, eta, u0, u1, u2):
    """Walter sampling (Fresnel picks reflection or refraction).
    Returns (ox, oy, oz, weight = f |cos| / pdf, pdf)."""
    mx, my, mz = sample_vndf(wx, wy, wz, ax, ay, u0, u1)
    above = wz > 0.0
    eta_i = 1.0 if above else eta
    eta_t = eta if above else 1.0
    F = fresnel(wx * mx + wy * my + wz * mz, eta_t / eta_i)
    tx, ty, tz, ok_t = refract(wx, wy, wz, mx, my, mz, eta_i / eta_t)
    if u2 < F or not ok_t:
        ox, oy, oz = reflect(wx, wy, wz, mx, my, mz)
        if wz * oz <= 0.0:
            return ox, oy, oz, 0.0, 0.0
    else:
        ox, oy, oz = tx, ty, tz
        if wz * oz >= 0.0:
            return ox, oy, oz, 0.0, 0.0
    f, p = diel_eval_pdf(wx, wy, wz, ox, oy, oz, ax, ay, eta)
    if p <= 0.0:
        return ox, oy, oz, 0.0, 0.0
    return ox, oy, oz, f * abs(oz) / p, p


@njit(**JIT)
def ft_pdf(ax, ay, er, wx, wy, wz, tx, ty, tz):
    """Density of drawing t by refracting w through a VNDF-sampled facet (no
    Fresnel choice); er = index on t's side / index on w's side."""
    if wz * tz >= 0.0:
        return 0.0
    hx, hy, hz = norm3(-(wx + er * tx), -(wy + er * ty), -(wz + er * tz))
    if hz < 0.0:
        hx, hy, hz = -hx, -hy, -hz
    wh = wx * hx + wy * hy + wz * hz
    th = tx * hx + ty * hy + tz * hz
    den = wh + er * th
    if wh * th >= 0.0 or abs(den) <= 1e-12:
        return 0.0
    return vndf_pdf(wx, wy, wz, hx, hy, hz, ax, ay) * er * er * abs(th) / (den * den)


@njit(**JIT)
def ft_sample(ax, ay, er, wx, wy, wz, u0, u1):
    """Forced refraction of w (above the interface): (tx, ty, tz, weight =
    (1 - F) G1(t), pdf)."""
    sx, sy, sz = norm3(ax * wx, ay * wy, abs(wz))
    return ft_core(sx, sy, sz, g1_dir(wx, wy, wz, ax, ay), ax, ay, er, wx, wy, wz, u0, u1)


@njit(**JIT)
def ft_core(sx, sy, sz, g1w, ax, ay, er, wx, wy, wz, u0, u1):
    """``ft_sample`` given w's stretched view direction (sx, sy, sz) and
    G1(w) (constant per pair for next-event estimation). The facet m is
    known, so the Fresnel factor reuses the refraction's cos_t and the pdf
    (that of ``ft_pdf``) is written with m instead of a recomputed half
    vector."""
    mx, my, mz = vndf_std(sx, sy, sz, ax, ay, u0, u1)
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
    p = g1w * c * ggx_d(mx, my, mz, ax, ay) / abs(wz) * er * er * (-th) / (den * den)
    if not p > 0.0:
        return tx, ty, tz, 0.0, 0.0
    rs = (c - er * ct) / (c + er * ct)
    rp = (er * c - ct) / (er * c + ct)
    F = 0.5 * (rs * rs + rp * rp)
    g1t = g1_dir(tx, ty, tz, ax, ay) if th * tz > 0.0 else 0.0
    return tx, ty, tz, (1.0 - F) * g1t, p


@njit(**JIT)
def exit_eval(wx, wy, wz, ox, oy, oz, g1w, g1o, ax, ay, eta):
    """At the top seen from below (w points down into the stack): (f(w, wo) of
    the transmission toward wo, the density ``ft_pdf`` gives w when sampled
    from wo); the two share the half vector, D and G1(wo) (g1o, per pair;
    g1w = G1(w), shared with the reflection sampled at the same vertex)."""
    if wz == 0.0 or oz == 0.0:
        return 0.0, 0.0
    hx, hy, hz = norm3(-(eta * wx + ox), -(eta * wy + oy), -(eta * wz + oz))
    if hz < 0.0:
        hx, hy, hz = -hx, -hy, -hz
    ih = wx * hx + wy * hy + wz * hz
    oh = ox * hx + oy * hy + oz * hz
    if ih * oh >= 0.0 or oh <= 0.0 or ih * wz <= 0.0:
        return 0.0, 0.0
    den = eta * ih + oh
    if abs(den) <= 1e-12:
        return 0.0, 0.0
    F = fresnel(ih, 1.0 / eta)
    common = g1o * oh * ggx_d(hx, hy, hz, ax, ay) * abs(ih) / (oz * den * den)
    return common * (1.0 - F) * g1w / abs(wz), common * eta * eta


@njit(**JIT)
def top_reflect(wx, wy, wz, ax, ay, eta, u0, u1, u2, lam, wide, a_wide, ox, oy, oz):
    """Internal reflection at the top (no Fresnel choice: F goes into the
    weight), the direction drawn from the one-sample mixture
    lam p_refl + (1 - lam) p_alt. p_refl: the interface's own VNDF reflection.
    p_alt (``wide``): the VNDF reflection of a rougher copy (each alpha at
    least ``a_wide``), or (not ``wide``) the guide: a direction that an ideal
    mirror below turns into a next-event direction toward wo. Returns (dx, dy,
    dz, weight = f_r |cos| / p_mix, p_mix); lam = 1 is the plain forced
    reflection."""
    awx, awy = max(ax, a_wide), max(ay, a_wide)
    rougher = awx > ax or awy > ay
    if u2 < lam or (wide and not rougher):
        mx, my, mz = sample_vndf(wx, wy, wz, ax, ay, u0, u1)
        dx, dy, dz = reflect(wx, wy, wz, mx, my, mz)
    elif wide:
        mx, my, mz = sample_vndf(wx, wy, wz, awx, awy, u0, u1)
        dx, dy, dz = reflect(wx, wy, wz, mx, my, mz)
    else:
        tx, ty, tz, w, pg = ft_sample(ax, ay, eta, ox, oy, oz, u0, u1)
        if pg <= 0.0:
            return tx, ty, tz, 0.0, 0.0
        dx, dy, dz = -tx, -ty, tz  # -t goes up; mirrored about the plane it goes down
    fc, p = top_eval(wx, wy, wz, dx, dy, dz, ax, ay, eta, lam, wide, a_wide, ox, oy, oz)
    if p <= 0.0:
        return dx, dy, dz, 0.0, 0.0
    return dx, dy, dz, fc / p, p


@njit(**JIT)
def top_reflect_vndf(wx, wy, wz, ax, ay, eta, u0, u1, u2, lam, awx, awy, g1a):
    """``top_reflect`` without the guide: the facet from VNDF(ax, ay) with
    probability lam, else from VNDF(awx, awy) (rougher on some axis; lam = 1:
    the plain forced reflection). The sampled facet is the half vector, so f
    and the mixture pdf share D(m) and G1(w) (g1a, for roughness (ax, ay))
    instead of recomputing them (``top_eval``)."""
    rougher = awx > ax or awy > ay
    asx, asy = (ax, ay) if (u2 < lam or not rougher) else (awx, awy)
    sg = -1.0 if wz < 0.0 else 1.0  # w mirrored up for the VNDF
    vx, vy, vz = norm3(sg * asx * wx, sg * asy * wy, sg * wz)
    mx, my, mz = vndf_std(vx, vy, vz, asx, asy, u0, u1)
    wm = sg * (wx * mx + wy * my + wz * mz)
    dx, dy, dz = reflect(wx, wy, wz, mx, my, mz)
    if wz * dz <= 0.0 or wm <= 0.0:
        return dx, dy, dz, 0.0, 0.0
    d_a = ggx_d(mx, my, mz, ax, ay)
    iz4 = 1.0 / (4.0 * abs(wz))
    pa = g1a * d_a * iz4
    p = pa
    if lam < 1.0:
        alt = g1_dir(wx, wy, wz, awx, awy) * ggx_d(mx, my, mz, awx, awy) * iz4 if rougher else pa
        p = lam * pa + (1.0 - lam) * alt
    if not p > 0.0:
        return dx, dy, dz, 0.0, 0.0
    F = fresnel(wm, eta if wz > 0.0 else 1.0 / eta)
    g1d = g1_dir(dx, dy, dz, ax, ay) if (dx * mx + dy * my + dz * mz) * dz > 0.0 else 0.0
    return dx, dy, dz, F * d_a * g1a * g1d * iz4 / p, p


@njit(**JIT)
def top_eval(wx, wy, wz, dx, dy, dz, ax, ay, eta, lam, wide, a_wide, ox, oy, oz):
    """(f_r(w, d) |d_z|, the density ``top_reflect`` draws d with) for the
    internal reflection at the top seen from below."""
    if wz * dz <= 0.0:
        return 0.0, 0.0
    awx, awy = max(ax, a_wide), max(ay, a_wide)
    hx, hy, hz = norm3(wx + dx, wy + dy, wz + dz)
    if hz < 0.0:
        hx, hy, hz = -hx, -hy, -hz
    wm = abs(wx * hx + wy * hy + wz * hz)
    if wm == 0.0:
        return 0.0, 0.0
    pa = vndf_pdf(wx, wy, wz, hx, hy, hz, ax, ay) / (4.0 * wm)
    p = pa
    if lam < 1.0:
        if wide:
            alt = vndf_pdf(wx, wy, wz, hx, hy, hz, awx, awy) / (4.0 * wm) if (awx > ax or awy > ay) else pa
        else:
            alt = ft_pdf(ax, ay, eta, ox, oy, oz, -dx, -dy, dz)
        p = lam * pa + (1.0 - lam) * alt
    F = fresnel(wm, eta if wz > 0.0 else 1.0 / eta)
    f = (F * ggx_d(hx, hy, hz, ax, ay) * g1(wx, wy, wz, hx, hy, hz, ax, ay) * g1(dx, dy, dz, hx, hy, hz, ax, ay)
         / max(4.0 * abs(wz * dz), 1e-30))
    return f * abs(dz), p



@njit(**JIT_INLINE)
def top_reflection(wx, wy, wz, ax, ay, eta, tau, conn, lam, lam_w, a_wide, g1w, ox, oy, oz, u0, u1, u2):
    """The walk's internal reflection at the top seen from below (forced: F
    in the weight): beyond the critical angle (trapped light) from VNDF(a),
    mixed with the mirror guide toward wo (probability 1 - lam) over an empty
    slab without the connection (which covers the guide itself); below it
    from VNDF(a) mixed with VNDF(a_wide) (probability 1 - lam_w). Returns
    (d, weight, density, the mixture's lam and wide, for the connection's
    densities). g1w = G1(w) for roughness (ax, ay); tau: the slab's optical thickness."""
    trapped = (1.0 - wz * wz) * eta * eta >= 1.0
    if trapped:
        lm, wide = (1.0 if conn else lam if tau == 0.0 else 1.0), False
    else:
        lm, wide = lam_w, True
    if wide or lm >= 1.0:
        awx, awy = (max(ax, a_wide), max(ay, a_wide)) if wide else (ax, ay)
        dx, dy, dz, wgt, p = top_reflect_vndf(wx, wy, wz, ax, ay, eta, u0, u1, u2, lm, awx, awy, g1w)
    else:
        dx, dy, dz, wgt, p = top_reflect(wx, wy, wz, ax, ay, eta, u0, u1, u2, lm, wide, a_wide, ox, oy, oz)
    return dx, dy, dz, wgt, p, lm, wide

# --- conductor base (F = 1) ----------------------------------------------------------------
@njit(**JIT)
def cond_eval(ix, iy, iz, ox, oy, oz, ax, ay, g1i):
    """``cond_geo`` given G1(i) (shared by the base's next-event evaluation
    and its own sample at one vertex)."""
    if iz <= 0.0 or oz <= 0.0:
        return 0.0, 0.0, 0.0
    hx, hy, hz = norm3(ix + ox, iy + oy, iz + oz)
    ih = ix * hx + iy * hy + iz * hz
    if ih <= 0.0:
        return 0.0, 0.0, 0.0
    p = g1i * ggx_d(hx, hy, hz, ax, ay) / (4.0 * iz)
    return p * g1_dir(ox, oy, oz, ax, ay) / oz, p, schlick5(ih)


@njit(**JIT)
def cond_pdf(ix, iy, iz, ox, oy, oz, ax, ay):
    """The density with which the base's VNDF sampling from i gives o (the
    reversed chain's densities in the MIS weights)."""
    return cond_eval(ix, iy, iz, ox, oy, oz, ax, ay, g1_dir(ix, iy, iz, ax, ay))[1]


@njit(**JIT)
def cond_geo(ix, iy, iz, ox, oy, oz, ax, ay):
    """(f with F = 1, pdf, Schlick's (1 - |i.h|)^5)."""
    if iz <= 0.0 or oz <= 0.0:
        return 0.0, 0.0, 0.0
    hx, hy, hz = norm3(ix + ox, iy + oy, iz + oz)
    ih = ix * hx + iy * hy + iz * hz
    f = (ggx_d(hx, hy, hz, ax, ay) * g1(ix, iy, iz, hx, hy, hz, ax, ay) * g1(ox, oy, oz, hx, hy, hz, ax, ay)
         / max(4.0 * iz * oz, 1e-30))
    p = vndf_pdf(ix, iy, iz, hx, hy, hz, ax, ay) / (4.0 * abs(ih)) if ih != 0.0 else 0.0
    return f, p, schlick5(ih)


@njit(**JIT_INLINE)
def cond_sample(wx, wy, wz, ax, ay, g1w, u0, u1):
    """The base's VNDF reflection of w (g1w = G1(w)): (n, weight f n_z / p with
    F = 1, p, Schlick's x). The sampled facet is the half vector: f n_z / p =
    G1(n), p = G1(w) D / (4 w_z)."""
    mx, my, mz = sample_vndf(wx, wy, wz, ax, ay, u0, u1)
    nx, ny, nz = reflect(wx, wy, wz, mx, my, mz)
    wm = wx * mx + wy * my + wz * mz
    p = g1w * ggx_d(mx, my, mz, ax, ay) / (4.0 * wz) if wz > 0.0 and nz > 0.0 and wm > 0.0 else 0.0
    wgt = g1_dir(nx, ny, nz, ax, ay) if p > 0.0 else 0.0
    return nx, ny, nz, wgt, p, schlick5(wm)


# --- diffuse base, isotropic medium, any base ---------------------------------------------
@njit(**JIT_INLINE)
def diffuse_sample(u0, u1):
    """A cosine-weighted direction up from the base: (n, its density)."""
    r = math.sqrt(u0)
    cph, sph = cos_sin_2pi(u1)
    nz = math.sqrt(max(1.0 - u0, 0.0))
    return r * cph, r * sph, nz, nz * INV_PI


@njit(**JIT_INLINE)
def phase_sample(u0, u1):
    """A uniform direction on the sphere (the isotropic phase function; its
    density is ggx.INV_4PI)."""
    zz = 1.0 - 2.0 * u0
    r = math.sqrt(max(1.0 - zz * zz, 0.0))
    cph, sph = cos_sin_2pi(u1)
    return r * cph, r * sph, zz


@njit(**JIT_INLINE)
def base_eval(base, wx, wy, wz, dx, dy, dz, ax, ay, eta, g1w):
    """Any base kind from w (up, toward where the light came from) to d (up):
    (f, the density of d sampled from w, Schlick's x of a conductor, else 0);
    g1w = G1(w) for a conductor."""
    if base == CONDUCTOR:
        return cond_eval(wx, wy, wz, dx, dy, dz, ax, ay, g1w)
    if base == DIFFUSE:
        return INV_PI, dz * INV_PI, 0.0
    f, p = diel_eval_pdf(wx, wy, wz, dx, dy, dz, ax, ay, eta)
    return f, p, 0.0
