"""The walk's interface kernels (``training.walk.interfaces``, Numba) against
the independent scalar reference of SPEC section 5 (tests/training/scalar_reference.py):
the rough dielectric's reflection and refraction from either side and its
Walter sampling density, the forced refraction and the exit evaluation with
their densities, the internal reflection at the top, the conductor's
geometric part with Schlick's factor and its VNDF density, the diffuse base.

Each comparison also runs against a kernel evaluated at a perturbed
parameter (roughness x1.1, or index +3 %) and asserts that it fails there:
the directions drawn reach the region where the parameter matters, so the
tolerance would catch such an error in the kernel."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scalar_reference import (
    ref_conductor,
    ref_dielectric,
    ref_dielectric_pdf,
    ref_reflection_pdf,
    ref_refraction_pdf,
)

from nbrdf.training.walk import ggx, interfaces

RTOL, ATOL = 1e-9, 1e-12


def _dirs(n: int, seed: int, side: int) -> np.ndarray:
    """n unit directions, uniform on the sphere, then put on ``side`` (+1
    above, -1 below, 0 either), kept 0.02 off the horizon."""
    v = np.random.default_rng(seed).normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    if side:
        v[:, 2] = side * np.maximum(np.abs(v[:, 2]), 0.02)
    else:
        v[:, 2] = np.where(v[:, 2] >= 0, 1, -1) * np.maximum(np.abs(v[:, 2]), 0.02)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _refracted(wi: np.ndarray, a: float, eta: float, seed: int) -> np.ndarray:
    """Directions drawn by refracting each wi through a rough interface (the
    walk's own sampler): pairs inside the transmission lobe, where a sharp
    interface's value is large, beside the uniform pairs where it is nearly 0."""
    rng = np.random.default_rng(seed)
    out = []
    for w in wi:
        er = eta if w[2] > 0 else 1.0 / eta
        v = w if w[2] > 0 else -w
        t = interfaces.ft_sample(a, a, er, *v, rng.random(), rng.random())
        out.append(t[:3] if w[2] > 0 else [-t[0], -t[1], -t[2]])
    return np.array(out)


def _reflected(wi: np.ndarray, a: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.array([ggx.reflect(*w, *ggx.sample_vndf(*w, a, a, rng.random(), rng.random())) for w in wi])


def _pairs(a: float, eta: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """wi on either side; wo uniform (both sides), reflected and refracted."""
    n = 300
    wi = _dirs(3 * n, seed, 0)
    wo = np.concatenate([_dirs(n, seed + 1, 0), _reflected(wi[n:2 * n], a, seed + 2),
                         _refracted(wi[2 * n:], a, eta, seed + 3)])
    ok = np.abs(wo[:, 2]) > 1e-3
    return wi[ok], wo[ok]


def _close(got: np.ndarray, want: np.ndarray) -> bool:
    return bool(np.allclose(got, want, rtol=RTOL, atol=ATOL))


def _max_rel(got: np.ndarray, want: np.ndarray) -> float:
    return float(np.max(np.abs(got - want) / np.maximum(np.abs(want), ATOL)))


DIELECTRICS = [(0.05, 1.5), (0.3, 1.05), (0.2, 1.9), (1.0, 1.33)]


@pytest.mark.parametrize("a,eta", DIELECTRICS)
def test_dielectric_value_and_density_match_the_reference(a, eta):
    """``diel_eval_pdf``: f(wi, wo) (reflection and refraction, from above and
    from below, total internal reflection included) and the density of
    ``diel_sample`` (Fresnel's choice times the VNDF Jacobian)."""
    wi, wo = _pairs(a, eta, 11)
    got = np.array([interfaces.diel_eval_pdf(*i, *o, a, a, eta) for i, o in zip(wi, wo)])
    f_ref = np.array([ref_dielectric(i, o, a, eta) for i, o in zip(wi, wo)])
    p_ref = np.array([ref_dielectric_pdf(i, o, a, eta) for i, o in zip(wi, wo)])
    assert (f_ref > 0).sum() > 400 and ((wi[:, 2] * wo[:, 2] < 0) & (f_ref > 0)).sum() > 150
    assert _close(got[:, 0], f_ref), _max_rel(got[:, 0], f_ref)
    assert _close(got[:, 1], p_ref), _max_rel(got[:, 1], p_ref)
    for a2, e2 in ((1.1 * a, eta), (a, 1.03 * eta)):
        bad = np.array([interfaces.diel_eval_pdf(*i, *o, a2, a2, e2) for i, o in zip(wi, wo)])
        assert not _close(bad[:, 0], f_ref) and not _close(bad[:, 1], p_ref), (a2, e2)


@pytest.mark.parametrize("a,eta", DIELECTRICS)
def test_dielectric_sampler_weight_matches_the_reference(a, eta):
    """``diel_sample``: the returned density is the reference density at the
    returned direction, and the weight is f |cos| / pdf."""
    wi = _dirs(600, 12, 0)
    rng = np.random.default_rng(13)
    got, want = [], []
    for w in wi:
        ox, oy, oz, wgt, p = interfaces.diel_sample(*w, a, a, eta, *rng.random(3))
        if p > 0.0:
            o = (ox, oy, oz)
            got.append((wgt, p))
            want.append((ref_dielectric(w, o, a, eta) * abs(oz) / ref_dielectric_pdf(w, o, a, eta),
                         ref_dielectric_pdf(w, o, a, eta)))
    got, want = np.array(got), np.array(want)
    assert len(got) > 500
    assert _close(got, want), _max_rel(got, want)


@pytest.mark.parametrize("a,eta", DIELECTRICS)
def test_forced_refraction_and_exit_match_the_reference(a, eta):
    """``ft_pdf`` / ``ft_sample`` (refraction of wo into the stack with no
    Fresnel choice: density, weight (1 - F) G1(t)) and ``exit_eval`` (f of
    the transmission from a direction below toward wo, and the density
    ``ft_pdf`` gives it)."""
    wo = _dirs(500, 14, 1)
    rng = np.random.default_rng(15)
    rows = []
    for o in wo:
        t = interfaces.ft_sample(a, a, eta, *o, rng.random(), rng.random())
        if t[4] <= 0.0:
            continue
        w = np.array(t[:3])
        f_exit, p_exit = interfaces.exit_eval(*w, *o, ggx.g1_dir(*w, a, a), ggx.g1_dir(*o, a, a), a, a, eta)
        p_ref = ref_refraction_pdf(o, w, a, 1.0, eta)
        f_ref = ref_dielectric(w, o, a, eta)
        rows.append((t[4], interfaces.ft_pdf(a, a, eta, *o, *w), p_exit, t[3], f_exit,
                     p_ref, p_ref, p_ref, ref_dielectric(o, w, a, eta) * abs(w[2]) / p_ref, f_ref))
    rows = np.array(rows)
    assert len(rows) > 450
    got, want = rows[:, :5], rows[:, 5:]
    assert _close(got, want), _max_rel(got, want)
    wz = []
    for o in wo[:200]:
        t = interfaces.ft_sample(a, a, eta, *o, rng.random(), rng.random())
        if t[4] > 0.0:
            wz.append((o, t[:3]))
    for a2, e2 in ((1.1 * a, eta), (a, 1.03 * eta)):
        g = np.array([(interfaces.ft_pdf(a2, a2, e2, *o, *w),
                       interfaces.exit_eval(*w, *o, ggx.g1_dir(*w, a2, a2), ggx.g1_dir(*o, a2, a2), a2, a2, e2)[0])
                      for o, w in wz])
        r = np.array([(ref_refraction_pdf(o, w, a, 1.0, eta), ref_dielectric(w, o, a, eta)) for o, w in wz])
        assert not _close(g[:, 0], r[:, 0]) and not _close(g[:, 1], r[:, 1]), (a2, e2)


@pytest.mark.parametrize("a,eta", DIELECTRICS)
def test_internal_reflection_at_the_top_matches_the_reference(a, eta):
    """``top_eval`` and ``top_reflect_vndf`` (lam = 1: the plain forced
    reflection seen from below): f_r |cos| is the reference's, the density
    the VNDF reflection's, the weight their ratio."""
    w = _dirs(400, 16, -1)
    rng = np.random.default_rng(17)
    rows, pairs = [], []
    for v in w:
        d = interfaces.top_reflect_vndf(*v, a, a, eta, *rng.random(3), 1.0, a, a, ggx.g1_dir(*v, a, a))
        if d[4] <= 0.0:
            continue
        dd = np.array(d[:3])
        fc, p = interfaces.top_eval(*v, *dd, a, a, eta, 1.0, False, 0.4, 0.0, 0.0, 1.0)
        fr, pr = ref_dielectric(v, dd, a, eta) * abs(dd[2]), ref_reflection_pdf(v, dd, a)
        rows.append((fc, p, d[3], d[4], fr, pr, fr / pr, pr))
        pairs.append((v, dd))
    rows = np.array(rows)
    assert len(rows) > 250
    assert _close(rows[:, :4], rows[:, 4:]), _max_rel(rows[:, :4], rows[:, 4:])
    for a2, e2 in ((1.1 * a, eta), (a, 1.03 * eta)):
        bad = np.array([interfaces.top_eval(*v, *dd, a2, a2, e2, 1.0, False, 0.4, 0.0, 0.0, 1.0)[0] for v, dd in pairs])
        assert not _close(bad, rows[:, 4]), (a2, e2)


@pytest.mark.parametrize("a", [0.02, 0.3, 0.8])
def test_conductor_matches_the_reference(a):
    """``cond_geo`` / ``cond_eval`` / ``cond_pdf`` / ``cond_sample``: the
    geometric part times Schlick's factor r0 + (1 - r0) x is the reference
    conductor for every r0; the density is the VNDF reflection's, and a
    sample's weight is f n_z / p (F = 1)."""
    wi = _dirs(300, 18, 1)
    wo = np.concatenate([_dirs(150, 19, 1), _reflected(wi[150:], a, 20)])
    ok = wo[:, 2] > 1e-3
    wi, wo = wi[ok], wo[ok]
    geo = np.array([interfaces.cond_geo(*i, *o, a, a) for i, o in zip(wi, wo)])
    ev = np.array([interfaces.cond_eval(*i, *o, a, a, ggx.g1_dir(*i, a, a)) for i, o in zip(wi, wo)])
    pdf = np.array([interfaces.cond_pdf(*i, *o, a, a) for i, o in zip(wi, wo)])
    p_ref = np.array([ref_reflection_pdf(i, o, a) for i, o in zip(wi, wo)])
    for r0 in (0.04, 0.5, 0.95):
        f_ref = np.array([ref_conductor(i, o, a, r0) for i, o in zip(wi, wo)])
        assert (f_ref > 0).sum() > 200
        for k in (geo, ev):
            got = k[:, 0] * (r0 + (1 - r0) * k[:, 2])
            assert _close(got, f_ref), _max_rel(got, f_ref)
        bad = np.array([interfaces.cond_geo(*i, *o, 1.1 * a, 1.1 * a) for i, o in zip(wi, wo)])
        assert not _close(bad[:, 0] * (r0 + (1 - r0) * bad[:, 2]), f_ref)
    for p in (geo[:, 1], ev[:, 1], pdf):
        assert _close(p, p_ref), _max_rel(p, p_ref)
    assert not _close(np.array([interfaces.cond_pdf(*i, *o, 1.1 * a, 1.1 * a) for i, o in zip(wi, wo)]), p_ref)
    rng = np.random.default_rng(21)
    rows = []
    for w in wi:
        nx, ny, nz, wgt, p, x = interfaces.cond_sample(*w, a, a, ggx.g1_dir(*w, a, a), rng.random(), rng.random())
        if p > 0.0:
            n = (nx, ny, nz)
            pr = ref_reflection_pdf(w, n, a)
            rows.append((wgt, p, ref_conductor(w, n, a, 1.0) * nz / pr, pr))
    rows = np.array(rows)
    assert len(rows) > 150
    assert _close(rows[:, :2], rows[:, 2:]), _max_rel(rows[:, :2], rows[:, 2:])


def test_diffuse_base_matches_the_reference():
    """``base_eval`` of a diffuse base is 1 / pi (the albedo is applied by
    the caller) with the cosine density; ``diffuse_sample`` returns that
    density at its direction and draws cosine-weighted directions (the mean
    of cos theta is 2 / 3, of cos^2 theta 1 / 2: z-tests at 1e-3, which a
    density off by 10 % in its exponent fails)."""
    wi, wo = _dirs(200, 22, 1), _dirs(200, 23, 1)
    got = np.array([interfaces.base_eval(interfaces.DIFFUSE, *i, *o, 0.5, 0.5, 1.5, 1.0)[:2] for i, o in zip(wi, wo)])
    assert _close(got, np.stack([np.full(200, 1 / math.pi), wo[:, 2] / math.pi], -1))
    rng = np.random.default_rng(24)
    s = np.array([interfaces.diffuse_sample(rng.random(), rng.random()) for _ in range(100_000)])
    assert np.allclose(np.linalg.norm(s[:, :3], axis=1), 1.0, atol=1e-12)
    assert _close(s[:, 3], s[:, 2] / math.pi)
    n = len(s)
    for k, mean in ((1, 2 / 3), (2, 1 / 2)):
        c = s[:, 2] ** k
        z = (c.mean() - mean) / (c.std() / math.sqrt(n))
        assert abs(z) < 3.29, (k, z)
        # power: the moments of cos^1.1 (a 10 % wrong exponent) are rejected by the same test
        assert abs((c.mean() - 2 / (k + 2.1)) / (c.std() / math.sqrt(n))) > 3.29
