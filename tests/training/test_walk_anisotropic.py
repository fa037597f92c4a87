"""The walk's interface kernels with anisotropic roughness (SPEC section 10)
against the independent scalar reference (tests/training/scalar_reference.py,
Heitz 2014's D and Lambda written with the azimuth), at several rotations of
the tangent frame.

Directions are made in the shading frame; the kernels get them through the
walk's change of frame (``training.layered._walk_frame``: ``neural.anisotropy.to_frame``)
and OpenPBR's alphas, the reference through its own ``in_frame`` and
``openpbr_alphas``. Each comparison also runs with the anisotropy 10 % off
and with the rotation 10 degrees off and asserts that both fail: the pairs
reach where anisotropy and its orientation matter."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from scalar_reference import (
    in_frame,
    openpbr_alphas,
    ref_conductor,
    ref_dielectric,
    ref_dielectric_pdf,
    ref_reflection_pdf,
    ref_refraction_pdf,
)

from nbrdf.neural.anisotropy import alphas, from_frame, to_frame
from nbrdf.training.layered import StackParams, _walk_frame
from nbrdf.training.walk import ggx, interfaces

RTOL, ATOL = 1e-9, 1e-12
#: (roughness, anisotropy, rotation in degrees, ior)
CASES = [(0.2, 0.6, 0.0, 1.5), (0.3, 0.8, 35.0, 1.33), (0.1, 0.4, 120.0, 1.9), (0.5, 0.7, -70.0, 1.05)]


def _dirs(n: int, seed: int, side: int) -> np.ndarray:
    """n unit directions uniform on the sphere, put on ``side`` (+1 above, -1 below, 0 either), 0.02 off the horizon."""
    v = np.random.default_rng(seed).normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    z = np.maximum(np.abs(v[:, 2]), 0.02)
    v[:, 2] = side * z if side else np.where(v[:, 2] >= 0, 1, -1) * z
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _walk(w: np.ndarray, rot: float) -> np.ndarray:
    """Shading-frame directions as the walk gets them."""
    return to_frame(torch.from_numpy(w), rot).numpy()


def _shading(w: np.ndarray, rot: float) -> np.ndarray:
    return from_frame(torch.from_numpy(np.asarray(w, dtype=np.float64)), rot).numpy()


def _ref_dirs(w: np.ndarray, rot: float) -> list:
    return [in_frame(v, rot) for v in w]


def _pairs(ax: float, ay: float, eta: float, rot: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Shading-frame pairs: wi either side; wo uniform, reflected and refracted by the walk's own samplers."""
    n = 300
    rng = np.random.default_rng(seed)
    wi_f = _dirs(3 * n, seed, 0)
    refl = [ggx.reflect(*w, *ggx.sample_vndf(*w, ax, ay, rng.random(), rng.random())) for w in wi_f[n:2 * n]]
    refr = []
    for w in wi_f[2 * n:]:
        v, er = (w, eta) if w[2] > 0 else (-w, 1.0 / eta)
        t = interfaces.ft_sample(ax, ay, er, *v, rng.random(), rng.random())
        refr.append(t[:3] if w[2] > 0 else [-t[0], -t[1], -t[2]])
    wo_f = np.concatenate([_dirs(n, seed + 1, 0), np.array(refl), np.array(refr)])
    ok = np.abs(wo_f[:, 2]) > 1e-3
    return _shading(wi_f[ok], rot), _shading(wo_f[ok], rot)


def _close(got, want) -> bool:
    return bool(np.allclose(got, want, rtol=RTOL, atol=ATOL))


def _max_rel(got, want) -> float:
    return float(np.max(np.abs(np.asarray(got) - want) / np.maximum(np.abs(want), ATOL)))


def _variants(r: float, a: float, rot: float):
    """(alphas, rotation) as given, then with the anisotropy 10 % off, then with the rotation 10 degrees off."""
    yield openpbr_alphas(r, a), rot
    yield openpbr_alphas(r, 1.1 * a), rot
    yield openpbr_alphas(r, a), rot + 10.0


def test_openpbr_alphas_and_the_walk_frame_of_an_isotropic_stack_are_exact():
    """a = 0 gives (alpha, alpha) bit for bit, and an isotropic stack's walk gets its roughness and its
    directions themselves (its walk is the one before anisotropy); an anisotropic one OpenPBR's alphas."""
    alpha = torch.tensor([0.013, 0.2, 0.77], dtype=torch.float64)
    ax, ay = alphas(alpha, torch.zeros(3, dtype=torch.float64))
    assert torch.equal(ax, alpha) and torch.equal(ay, alpha)
    n = 3
    f = lambda v, *shape: torch.full(shape, float(v), dtype=torch.float64)
    wi, wo = torch.from_numpy(_dirs(n, 1, 1)), torch.from_numpy(_dirs(n, 2, 1))
    p, _ = StackParams(alpha[:, None], f(1.5, n, 1), f(0.5, n, 1), f(1.0, n, 1), "conductor", alpha,
                       base_r0=f(0.9, n)).normalized(torch.float64)
    got = _walk_frame(p, wi, wo)
    assert all(torch.equal(g, w) for g, w in zip(got, (alpha[:, None], alpha[:, None], alpha, alpha, wi, wo)))
    p.anisotropy, p.base_anisotropy, p.rotation = f(0.5, n, 1), f(0.25, n), f(30.0, n)
    ax, ay, b_ax, b_ay, wi_w, _ = _walk_frame(p, wi, wo)
    want = [openpbr_alphas(float(x), 0.5) for x in alpha]
    assert np.allclose(torch.cat([ax, ay], 1).numpy(), want, rtol=1e-14)
    assert np.allclose(b_ay.numpy(), [openpbr_alphas(float(x), 0.25)[1] for x in alpha], rtol=1e-14)
    assert np.allclose(wi_w.numpy(), [in_frame(w, 30.0) for w in wi.numpy()], rtol=1e-14, atol=1e-15)


@pytest.mark.parametrize("r,a,rot,eta", CASES)
def test_anisotropic_dielectric_value_and_density_match_the_reference(r, a, rot, eta):
    """``diel_eval_pdf``: f(wi, wo) from either side (reflection, refraction, total internal reflection) and
    Walter sampling's density."""
    ax, ay = openpbr_alphas(r, a)
    wi, wo = _pairs(ax, ay, eta, rot, 31)
    ri, ro = _ref_dirs(wi, rot), _ref_dirs(wo, rot)
    f_ref = np.array([ref_dielectric(i, o, (ax, ay), eta) for i, o in zip(ri, ro)])
    p_ref = np.array([ref_dielectric_pdf(i, o, (ax, ay), eta) for i, o in zip(ri, ro)])
    assert (f_ref > 0).sum() > 400 and ((wi[:, 2] * wo[:, 2] < 0) & (f_ref > 0)).sum() > 150
    for k, ((kx, ky), krot) in enumerate(_variants(r, a, rot)):
        got = np.array([interfaces.diel_eval_pdf(*i, *o, kx, ky, eta)
                        for i, o in zip(_walk(wi, krot), _walk(wo, krot))])
        if k == 0:
            assert _close(got[:, 0], f_ref), _max_rel(got[:, 0], f_ref)
            assert _close(got[:, 1], p_ref), _max_rel(got[:, 1], p_ref)
        else:
            assert not _close(got[:, 0], f_ref) and not _close(got[:, 1], p_ref), k


@pytest.mark.parametrize("r,a,rot,eta", CASES)
def test_anisotropic_dielectric_sampler_weight_matches_the_reference(r, a, rot, eta):
    """``diel_sample``: the density returned is the reference's at the direction returned, the weight f |cos| / pdf."""
    ax, ay = openpbr_alphas(r, a)
    wi = _dirs(500, 32, 0)
    rng = np.random.default_rng(33)
    got, want = [], []
    for w in wi:
        ox, oy, oz, wgt, p = interfaces.diel_sample(*w, ax, ay, eta, *rng.random(3))
        if p > 0.0:
            ri, ro = in_frame(_shading(w, rot), rot), in_frame(_shading([ox, oy, oz], rot), rot)
            pr = ref_dielectric_pdf(ri, ro, (ax, ay), eta)
            got.append((wgt, p))
            want.append((ref_dielectric(ri, ro, (ax, ay), eta) * abs(oz) / pr, pr))
    got, want = np.array(got), np.array(want)
    assert len(got) > 400
    assert _close(got, want), _max_rel(got, want)


@pytest.mark.parametrize("r,a,rot,eta", CASES)
def test_anisotropic_forced_refraction_and_exit_match_the_reference(r, a, rot, eta):
    """``ft_pdf`` (the density of refracting wo into the stack), ``exit_eval`` (f of the transmission from
    below toward wo and that density) and ``ft_sample``'s weight (1 - F) G1(t)."""
    ax, ay = openpbr_alphas(r, a)
    rng = np.random.default_rng(35)
    wo_f = _dirs(400, 34, 1)
    pairs = []
    for o in wo_f:
        t = interfaces.ft_sample(ax, ay, eta, *o, rng.random(), rng.random())
        if t[4] > 0.0:
            pairs.append((o, np.array(t[:3]), t[3], t[4]))
    assert len(pairs) > 350
    wo, w = _shading(np.array([p[0] for p in pairs]), rot), _shading(np.array([p[1] for p in pairs]), rot)
    ro, rw = _ref_dirs(wo, rot), _ref_dirs(w, rot)
    p_ref = np.array([ref_refraction_pdf(o, v, (ax, ay), 1.0, eta) for o, v in zip(ro, rw)])
    f_ref = np.array([ref_dielectric(v, o, (ax, ay), eta) for o, v in zip(ro, rw)])
    wgt_ref = np.array([ref_dielectric(o, v, (ax, ay), eta) * abs(v[2]) for o, v in zip(ro, rw)]) / p_ref
    sampled = np.array([(p[3], p[2]) for p in pairs])
    assert _close(sampled, np.stack([p_ref, wgt_ref], -1)), _max_rel(sampled, np.stack([p_ref, wgt_ref], -1))
    for k, ((kx, ky), krot) in enumerate(_variants(r, a, rot)):
        got = np.array([(interfaces.ft_pdf(kx, ky, eta, *o, *v),
                         *interfaces.exit_eval(*v, *o, ggx.g1_dir(*v, kx, ky), ggx.g1_dir(*o, kx, ky), kx, ky, eta))
                        for o, v in zip(_walk(wo, krot), _walk(w, krot))])
        want = np.stack([p_ref, f_ref, p_ref], -1)
        if k == 0:
            assert _close(got, want), _max_rel(got, want)
        else:
            assert not _close(got[:, 0], p_ref) and not _close(got[:, 1], f_ref), k


@pytest.mark.parametrize("r,a,rot,eta", CASES)
def test_anisotropic_internal_reflection_at_the_top_matches_the_reference(r, a, rot, eta):
    """``top_reflect_vndf`` and ``top_eval`` (lam = 1, seen from below): f_r |cos|, the VNDF reflection's
    density and their ratio as the weight."""
    ax, ay = openpbr_alphas(r, a)
    rng = np.random.default_rng(37)
    pairs = []
    for v in _dirs(400, 36, -1):
        d = interfaces.top_reflect_vndf(*v, ax, ay, eta, *rng.random(3), 1.0, ax, ay, ggx.g1_dir(*v, ax, ay))
        if d[4] > 0.0:
            pairs.append((v, np.array(d[:3]), d[3], d[4]))
    assert len(pairs) > 250
    w, dd = _shading(np.array([p[0] for p in pairs]), rot), _shading(np.array([p[1] for p in pairs]), rot)
    rv, rd = _ref_dirs(w, rot), _ref_dirs(dd, rot)
    fr = np.array([ref_dielectric(v, d, (ax, ay), eta) * abs(d[2]) for v, d in zip(rv, rd)])
    pr = np.array([ref_reflection_pdf(v, d, (ax, ay)) for v, d in zip(rv, rd)])
    sampled = np.array([(p[2], p[3]) for p in pairs])
    assert _close(sampled, np.stack([fr / pr, pr], -1)), _max_rel(sampled, np.stack([fr / pr, pr], -1))
    for k, ((kx, ky), krot) in enumerate(_variants(r, a, rot)):
        got = np.array([interfaces.top_eval(*v, *d, kx, ky, eta, 1.0, False, 0.4, 0.0, 0.0, 1.0)
                        for v, d in zip(_walk(w, krot), _walk(dd, krot))])
        if k == 0:
            assert _close(got, np.stack([fr, pr], -1)), _max_rel(got, np.stack([fr, pr], -1))
        else:
            assert not _close(got[:, 0], fr) and not _close(got[:, 1], pr), k


@pytest.mark.parametrize("r,a,rot", [(0.05, 0.5, 15.0), (0.3, 0.8, 90.0), (0.7, 0.6, -140.0)])
def test_anisotropic_conductor_matches_the_reference(r, a, rot):
    """``cond_geo`` / ``cond_eval`` / ``cond_pdf`` times Schlick's factor, and ``cond_sample``'s weight f n_z / p
    and density, for a conductor base."""
    ax, ay = openpbr_alphas(r, a)
    rng = np.random.default_rng(39)
    wi_f = _dirs(300, 38, 1)
    refl = [ggx.reflect(*w, *ggx.sample_vndf(*w, ax, ay, rng.random(), rng.random())) for w in wi_f[150:]]
    wo_f = np.concatenate([_dirs(150, 40, 1), np.array(refl)])
    ok = wo_f[:, 2] > 1e-3
    wi, wo = _shading(wi_f[ok], rot), _shading(wo_f[ok], rot)
    ri, ro = _ref_dirs(wi, rot), _ref_dirs(wo, rot)
    r0 = 0.3
    f_ref = np.array([ref_conductor(i, o, (ax, ay), r0) for i, o in zip(ri, ro)])
    p_ref = np.array([ref_reflection_pdf(i, o, (ax, ay)) for i, o in zip(ri, ro)])
    assert (f_ref > 0).sum() > 200
    for k, ((kx, ky), krot) in enumerate(_variants(r, a, rot)):
        pairs = list(zip(_walk(wi, krot), _walk(wo, krot)))
        geo = np.array([interfaces.cond_geo(*i, *o, kx, ky) for i, o in pairs])
        ev = np.array([interfaces.cond_eval(*i, *o, kx, ky, ggx.g1_dir(*i, kx, ky)) for i, o in pairs])
        pdf = np.array([interfaces.cond_pdf(*i, *o, kx, ky) for i, o in pairs])
        f_geo = geo[:, 0] * (r0 + (1 - r0) * geo[:, 2])
        if k == 0:
            for got, want in ((f_geo, f_ref), (ev[:, 0] * (r0 + (1 - r0) * ev[:, 2]), f_ref), (geo[:, 1], p_ref),
                              (ev[:, 1], p_ref), (pdf, p_ref)):
                assert _close(got, want), _max_rel(got, want)
        else:
            assert not _close(f_geo, f_ref) and not _close(pdf, p_ref), k
    rows = []
    for w in wi_f:
        nx, ny, nz, wgt, p, _ = interfaces.cond_sample(*w, ax, ay, ggx.g1_dir(*w, ax, ay), rng.random(), rng.random())
        if p > 0.0:
            rw, rn = in_frame(_shading(w, rot), rot), in_frame(_shading([nx, ny, nz], rot), rot)
            pr = ref_reflection_pdf(rw, rn, (ax, ay))
            rows.append((wgt, p, ref_conductor(rw, rn, (ax, ay), 1.0) * nz / pr, pr))
    rows = np.array(rows)
    assert len(rows) > 200
    assert _close(rows[:, :2], rows[:, 2:]), _max_rel(rows[:, :2], rows[:, 2:])
