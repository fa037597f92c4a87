"""The compiled walk's fused kernels (issue 14, speed): each fused
evaluation equals the generic one it replaces, the polynomial sincos matches
libm, and the spherical-cap VNDF sampler draws facets with the VNDF density
(chi-square at a fixed seed)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit
from scipy import stats
from stattools import z_threshold

from nbrdf.training.walk import ggx, interfaces, params, strategies
from nbrdf.training.walk.rng import lane_key, uniform


def _rand_dir(rng, upper: bool, lo: float = 0.02):
    z = rng.uniform(lo, 1.0)
    ph = rng.uniform(0.0, 2 * math.pi)
    r = math.sqrt(1 - z * z)
    return r * math.cos(ph), r * math.sin(ph), z if upper else -z


def test_the_walks_conductor_fresnel_is_the_f82_form():
    """``ggx.conductor_f`` (from x = (1 - cos)^5, what the samplers return) equals
    ``neural.microfacet.fresnel_f82`` over cosines, r0 and tints; b = 0 is Schlick's form."""
    import torch

    from nbrdf.neural.microfacet import f82_coefficient, fresnel_f82
    rng = np.random.default_rng(3)
    for _ in range(500):
        c, r0, tint = rng.uniform(0, 1), rng.uniform(0, 1), rng.uniform(0, 1)
        x = (1.0 - c) ** 5
        b = f82_coefficient(r0, tint)
        want = float(fresnel_f82(torch.tensor(c, dtype=torch.float64), torch.tensor(r0, dtype=torch.float64), b))
        assert ggx.conductor_f(x, r0, b) == pytest.approx(want, abs=1e-12)
        assert ggx.conductor_f(x, r0, 0.0) == pytest.approx(x + r0 * (1.0 - x), abs=1e-15)  # FMA rounding only


def test_polynomial_sincos_matches_libm():
    u = np.concatenate([np.random.default_rng(0).random(20000), np.arange(9) / 8.0, [1 - 2.0 ** -53]])
    err = max(max(abs(c - math.cos(2 * math.pi * x)), abs(s - math.sin(2 * math.pi * x)))
              for x in u for c, s in [ggx.cos_sin_2pi(x)])
    assert err < 2e-15, err


@pytest.mark.parametrize("a,eta", [(0.1, 1.5), (0.45, 1.3), (0.05, 1.9), (0.3, 1.1)])
def test_fused_next_event_equals_the_generic_evaluation(a, eta):
    """f_top(t, wo) / pdf in closed form = the full evaluation / ``_ft_pdf``."""
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(400):
        ox, oy, oz = _rand_dir(rng, True)
        sx, sy, sz = ggx.norm3(a * ox, a * oy, oz)
        g1o = ggx.g1_dir(ox, oy, oz, a, a)
        vx, vy, vz, sc, pn = strategies.nee(0.0, sx, sy, sz, g1o, ox, oy, oz, a, a, eta, 0.0, rng.random(), rng.random())
        if sc <= 0.0:
            continue
        tx, ty, tz = -vx, -vy, -vz
        f, _ = interfaces.diel_eval_pdf(tx, ty, tz, ox, oy, oz, a, a, eta)
        p = interfaces.ft_pdf(a, a, eta, ox, oy, oz, tx, ty, tz)
        assert pn == pytest.approx(p, rel=1e-9)
        assert sc == pytest.approx(f / p, rel=1e-9)
        checked += 1
    assert checked > 300


@pytest.mark.parametrize("a,eta", [(0.1, 1.5), (0.45, 1.3), (0.3, 1.1)])
def test_fused_exit_equals_the_generic_evaluation(a, eta):
    rng = np.random.default_rng(2)
    nonzero = 0
    for i in range(400):
        ox, oy, oz = _rand_dir(rng, True)
        wx, wy, wz = _rand_dir(rng, False)
        if i % 2:  # a direction refracted from wo: inside the exit lobe
            tx, ty, tz, _, p = interfaces.ft_sample(a, a, eta, ox, oy, oz, rng.random(), rng.random())
            if p > 0.0:
                wx, wy, wz = tx, ty, tz
        f, pn = interfaces.exit_eval(wx, wy, wz, ox, oy, oz, ggx.g1_dir(wx, wy, wz, a, a), ggx.g1_dir(ox, oy, oz, a, a),
                                     a, a, eta)
        f_ref, _ = interfaces.diel_eval_pdf(wx, wy, wz, ox, oy, oz, a, a, eta)
        assert f == pytest.approx(f_ref, rel=1e-9, abs=1e-300)
        if f_ref > 0.0:
            assert pn == pytest.approx(interfaces.ft_pdf(a, a, eta, ox, oy, oz, wx, wy, wz), rel=1e-9)
            nonzero += 1
    assert nonzero > 150


@pytest.mark.parametrize("a,ay", [(0.12, 0.12), (0.3, 0.06), (0.5, 0.1)])
@pytest.mark.parametrize("lam,wide", [(1.0, False), (0.5, True), (0.8, True)])
def test_fused_top_reflection_equals_the_generic_one(lam, wide, a, ay):
    """Same direction, weight f |cos| / p_mix and mixture pdf as ``_top_reflect``, isotropic and anisotropic
    (the wide copy takes each alpha at least a_wide: rougher on one axis only in the last case)."""
    rng = np.random.default_rng(3)
    eta, a_wide = 1.5, 0.4
    ox, oy, oz = _rand_dir(rng, True)
    alive = 0
    for _ in range(400):
        wx, wy, wz = _rand_dir(rng, False)
        u = rng.random(3)
        awx, awy = (max(a, a_wide), max(ay, a_wide)) if wide else (a, ay)
        got = interfaces.top_reflect_vndf(wx, wy, wz, a, ay, eta, u[0], u[1], u[2], lam, awx, awy,
                                          ggx.g1_dir(wx, wy, wz, a, ay))
        ref = interfaces.top_reflect(wx, wy, wz, a, ay, eta, u[0], u[1], u[2], lam, wide, a_wide, ox, oy, oz)
        np.testing.assert_allclose(got[:3], ref[:3], rtol=1e-9, atol=1e-12)
        assert got[3] == pytest.approx(ref[3], rel=1e-9, abs=1e-300)
        assert got[4] == pytest.approx(ref[4], rel=1e-9, abs=1e-300)
        alive += got[3] > 0.0
    assert alive > 300


def test_fused_conductor_evaluation_equals_the_generic_one():
    rng = np.random.default_rng(4)
    for a in (0.02, 0.3, 0.8):
        for _ in range(300):
            ix, iy, iz = _rand_dir(rng, True)
            ox, oy, oz = _rand_dir(rng, True)
            got = interfaces.cond_eval(ix, iy, iz, ox, oy, oz, a, a, ggx.g1_dir(ix, iy, iz, a, a))
            ref = interfaces.cond_geo(ix, iy, iz, ox, oy, oz, a, a)
            np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-300)


@njit(cache=False)
def _sample_bins(wx, wy, wz, a, ay, n, nt, nphi, seed):
    """Counts of n VNDF facets in (cos theta_m, phi_m) bins."""
    counts = np.zeros((nt, nphi))
    key = lane_key(seed, 0)
    for i in range(n):
        mx, my, mz = ggx.sample_vndf(wx, wy, wz, a, ay, uniform(key, 2 * i), uniform(key, 2 * i + 1))
        ph = math.atan2(my, mx) % (2 * math.pi)
        it = min(int(mz * nt), nt - 1)
        ip = min(int(ph / (2 * math.pi) * nphi), nphi - 1)
        counts[it, ip] += 1
    return counts


@njit(cache=False)
def _bin_probs(wx, wy, wz, a, ay, nt, nphi, sub):
    """The VNDF density integrated over the same bins (midpoint rule, sub x sub per bin)."""
    probs = np.zeros((nt, nphi))
    for it in range(nt):
        for ip in range(nphi):
            acc = 0.0
            for j in range(sub):
                z = (it + (j + 0.5) / sub) / nt
                r = math.sqrt(max(1 - z * z, 0.0))
                for k in range(sub):
                    ph = (ip + (k + 0.5) / sub) / nphi * 2 * math.pi
                    acc += ggx.vndf_pdf(wx, wy, wz, r * math.cos(ph), r * math.sin(ph), z, a, ay)
            probs[it, ip] = acc * (1.0 / nt) * (2 * math.pi / nphi) / (sub * sub)
    return probs


@pytest.mark.parametrize("theta,a,ay,below", [(30.0, 0.4, 0.4, False), (75.0, 0.8, 0.8, False), (60.0, 0.5, 0.5, True),
                                              (60.0, 0.6, 0.25, False), (70.0, 0.3, 0.6, True)])
def test_spherical_cap_vndf_sampler_draws_the_vndf(theta, a, ay, below):
    """Chi-square of sampled facets against the VNDF density (bins with an
    expected count of at least 20), isotropic and anisotropic (alpha_x a,
    alpha_y ay: SPEC section 10)."""
    t = math.radians(theta)
    w = (math.sin(t) * math.cos(0.7), math.sin(t) * math.sin(0.7), math.cos(t) * (-1 if below else 1))
    n, nt, nphi = 200_000, 10, 12
    counts = _sample_bins(*w, a, ay, n, nt, nphi, 7)
    probs = _bin_probs(*w, a, ay, nt, nphi, 24)
    assert abs(probs.sum() - 1.0) < 2e-3
    exp = probs * n
    keep = exp >= 20
    obs, e = counts[keep], exp[keep]
    e = e * obs.sum() / e.sum()
    chi2 = float(((obs - e) ** 2 / e).sum())
    assert stats.chi2.sf(chi2, keep.sum() - 1) > 1e-3, chi2
    assert counts[keep].sum() > 0.99 * n


@njit(cache=False)
def _three_vertex_estimates(w, o, a0, e0, ba, lam, wide, a_wide, agw, n, seed):
    """The three-vertex path at a top vertex seen from below (internal
    reflection -> near-mirror conductor base -> exit toward o, red with r0 = 1)
    estimated n times two ways, each a balance-heuristic combination of the
    walk (A: reflection and the base's VNDF sampled, exit evaluated), B
    (next-event estimation at the base) and C (the narrow guide): without D
    (the estimator before strategy D, C's sample drawn here from the same
    building blocks as ``strategies.mirror_connection``) and with D (the walk's code:
    ``strategies.mirror_connection`` and ``strategies.wide_connection``). Returns the sums of
    each, of their squares and of their product."""
    wx, wy, wz = w
    ox, oy, oz = o
    sx, sy, sz = ggx.norm3(a0 * ox, a0 * oy, oz)
    g1o = ggx.g1_dir(ox, oy, oz, a0, a0)
    g1w = ggx.g1_dir(wx, wy, wz, a0, a0)
    key = lane_key(seed, 0)
    s = np.zeros(5)
    u = np.empty(19)
    for i in range(n):
        for j in range(19):
            u[j] = uniform(key, 19 * i + j)
        ref = 0.0
        new = 0.0
        aw = max(a0, a_wide) if wide else a0
        nx, ny, nz, wgt, pm = interfaces.top_reflect_vndf(wx, wy, wz, a0, a0, e0, u[0], u[1], u[2], lam, aw, aw, g1w)
        if pm > 0.0 and wgt > 0.0 and nz < 0.0:
            pg = interfaces.ft_pdf(a0, a0, e0, ox, oy, oz, -nx, -ny, nz)
            pw = interfaces.ft_pdf(agw, agw, e0, ox, oy, oz, -nx, -ny, nz)
            bx, by, bz = -nx, -ny, -nz  # at the base, toward where the light came from
            g1b = ggx.g1_dir(bx, by, bz, ba, ba)
            vx, vy, vz, sc, pn = strategies.nee(1.0, sx, sy, sz, g1o, ox, oy, oz, a0, a0, e0, 0.0, u[3], u[4])
            if sc > 0.0:  # B
                f, pb, _ = interfaces.cond_eval(bx, by, bz, vx, vy, vz, ba, ba, g1b)
                ref += wgt * f * vz * sc * pm * pn / (pm * pn + pm * pb + pg * pb)
                new += wgt * f * vz * sc * pm * pn / (pm * pn + pm * pb + pg * pb + pw * pn)
            mx, my, mz = ggx.sample_vndf(bx, by, bz, ba, ba, u[5], u[6])
            ux, uy, uz = ggx.reflect(bx, by, bz, mx, my, mz)
            if bz > 0.0 and uz > 0.0 and bx * mx + by * my + bz * mz > 0.0:  # A
                pc = g1b * ggx.ggx_d(mx, my, mz, ba, ba) / (4.0 * bz)
                f, pn = interfaces.exit_eval(-ux, -uy, -uz, ox, oy, oz, ggx.g1_dir(ux, uy, uz, a0, a0), g1o, a0, a0,
                                             e0)
                if f > 0.0:
                    f *= wgt * ggx.g1_dir(ux, uy, uz, ba, ba)
                    ref += f * pm * pc / (pm * pc + pm * pn + pg * pc)
                    new += f * pm * pc / (pm * pc + pm * pn + pg * pc + pw * pn)
        # C without D's density in its weight
        tx, ty, tz, _, pg = interfaces.ft_sample(a0, a0, e0, ox, oy, oz, u[7], u[8])
        if pg > 0.0:
            gx, gy, gz = -tx, -ty, tz
            fr, pm = interfaces.top_eval(wx, wy, wz, gx, gy, gz, a0, a0, e0, lam, wide, a_wide, ox, oy, oz)
            if fr > 0.0:
                mx, my, mz = ggx.sample_vndf(-gx, -gy, -gz, ba, ba, u[9], u[10])
                ux, uy, uz = ggx.reflect(-gx, -gy, -gz, mx, my, mz)
                fc, pc, _ = interfaces.cond_geo(-gx, -gy, -gz, ux, uy, uz, ba, ba)
                if fc > 0.0 and pc > 0.0:
                    fe, _ = interfaces.diel_eval_pdf(-ux, -uy, -uz, ox, oy, oz, a0, a0, e0)
                    pn = interfaces.ft_pdf(a0, a0, e0, ox, oy, oz, -ux, -uy, -uz)
                    ref += fr * fc * uz * fe / (pm * pc + pm * pn + pg * pc)
        k, _ = strategies.mirror_connection(wx, wy, wz, a0, a0, e0, ba, ba, lam, wide, a_wide, agw, ox, oy, oz, u[11],
                                            u[12], u[13], u[14], False, 0.0)
        kd, _ = strategies.wide_connection(wx, wy, wz, a0, a0, e0, ba, ba, lam, wide, a_wide, agw, ox, oy, oz, sx, sy,
                                           sz, g1o, u[15], u[16], u[17], u[18], False, 0.0)
        new += k + kd
        s[0] += ref
        s[1] += ref * ref
        s[2] += new
        s[3] += new * new
        s[4] += ref * new
    return s


@pytest.mark.parametrize("theta,phi,lam,wide", [(80.0, 30.0, 1.0, False), (55.0, 150.0, 1.0, False),
                                                (30.0, 60.0, 0.5, True), (20.0, 170.0, 0.5, True)])
def test_wide_guide_connection_keeps_the_estimate(theta, phi, lam, wide):
    """Adding strategy D (wide guide + next-event estimation at the base) and
    its density to the other strategies' balance weights leaves the
    expectation of the three-vertex path unchanged (paired z-test against the
    three-strategy estimator) on the trapping stack's coat and mirror, from
    trapped grazing, trapped and below-critical states, and lowers its
    variance (measured 2.4-3.9x)."""
    t, p = math.radians(theta), math.radians(phi)
    w = (-math.sin(t) * math.cos(p), -math.sin(t) * math.sin(p), -math.cos(t))  # points down into the stack
    o = (math.sin(math.radians(20.0)), 0.0, math.cos(math.radians(20.0)))
    n = 400_000
    s = _three_vertex_estimates(w, o, 0.15, 1.5, 0.02, lam, wide, 0.4, params.WIDE_GUIDE_ROUGHNESS, n, 7)
    m_ref, m_new = s[0] / n, s[2] / n
    v_ref, v_new = s[1] / n - m_ref ** 2, s[3] / n - m_new ** 2
    v_diff = v_ref + v_new - 2.0 * (s[4] / n - m_ref * m_new)
    assert m_new > 0.0
    z = (m_ref - m_new) / math.sqrt(v_diff / n)
    assert abs(z) < z_threshold(1e-3, 4), (z, m_ref, m_new)
    assert 2.0 * v_new < v_ref, (v_new / m_new ** 2, v_ref / m_ref ** 2)
