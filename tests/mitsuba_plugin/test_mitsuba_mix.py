"""OpenPBR's linear mixes in the Mitsuba plugins (``neural.mix``): a material whose OpenPBR record has a
fractional base_metalness or coat_weight is held exactly, not shown by its largest component. ``nbrdf``'s
eval is the CPU ``MixedBRDF`` of the components' neural BRDFs (1e-4 relative), its samples and pdf are the
CPU mixture sampler's (the same uniforms draw the same directions), its directional albedo is the
components' albedos weighted, and its sampler passes Mitsuba's chi-square test at three incidences and
fails it when the components are drawn with the wrong weights; ``nbrdf_reference``'s eval is the CPU
``MixedBRDF`` of the components' walks (the same paths) and its mixture sampler follows its pdf; a
material that is no mix runs the code it always ran (bit for bit)."""
from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest
import torch
from chi2_adapter import sampler_and_pdf
from hits import directions, interactions

from nbrdf.neural.material import load_material
from nbrdf.neural.mix import material_mix
from nbrdf.neural.openpbr import OpenPbr, openpbr_components, openpbr_to_material

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")

N = 4096
#: Four components of unequal weights (metal coated 0.18, metal 0.12, dielectric coated 0.42, dielectric 0.28).
MIXED = OpenPbr(base_color=(0.8, 0.5, 0.3), base_metalness=0.3, coat_weight=0.6, coat_roughness=0.3)
#: Two components (a white dielectric, half of it under a coat): the cheaper walk of the reference tests.
HALF_COATED = OpenPbr(base_color=(0.7, 0.7, 0.7), coat_weight=0.5, coat_roughness=0.2)
#: An OpenPBR record that is no mix: one pure stack.
PURE = OpenPbr(base_color=(0.8, 0.5, 0.3), base_metalness=1.0, coat_weight=1.0, coat_roughness=0.3)
WEIGHTS = [0.18, 0.12, 0.42, 0.28]
INCIDENCES = (0.0, 50.0, 80.0)


def _write(path, doc: dict) -> str:
    path.write_text(json.dumps(doc))
    return str(path)


@pytest.fixture(scope="module")
def mixes(tmp_path_factory) -> dict[str, str]:
    """Material JSONs by role: the mixes, the pure record, each mix's largest component alone (its
    ``layers`` without the record: what the plugins showed before) and the components of ``MIXED``."""
    d = tmp_path_factory.mktemp("mix")
    out = {}
    for name, p in (("mixed", MIXED), ("half_coated", HALF_COATED), ("pure", PURE)):
        doc, _ = openpbr_to_material(p, name)
        out[name] = _write(d / f"{name}.json", doc)
        out[f"{name}_largest"] = _write(d / f"{name}_largest.json", {k: v for k, v in doc.items() if k != "openpbr"})
    for k, (_, doc, _) in enumerate(openpbr_components(MIXED)):
        out[f"mixed_{k}"] = _write(d / f"mixed_{k}.json", doc)
    return out


def _eval(mi, bsdf, view, light) -> np.ndarray:
    return np.array(bsdf.eval(mi.BSDFContext(), interactions(mi, view), mi.Vector3f(np.ascontiguousarray(light.T)))).T


def _pairs(seed: int, n: int = N):
    rng = np.random.default_rng(seed)
    light, view = directions(rng, n), directions(rng, n)
    light[:8, 2] *= -1  # a few below the horizon: zero on both sides
    return light, view


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    """Largest |a - b| / |b| where b is not 0 (an exact 0 must be matched by a value under 1e-7)."""
    nz = np.abs(b) > 0
    assert np.all(np.abs(a[~nz]) < 1e-7)
    return float((np.abs(a[nz] - b[nz]) / np.abs(b[nz])).max())


def test_the_mix_is_held_and_a_plain_material_is_not_one(mi, mixes):
    from nbrdf.mitsuba.kernel import CodeKernel
    from nbrdf.mitsuba.materials import ReferenceWalk, code_kernel
    from nbrdf.mitsuba.mix import MixedKernel

    kernel = code_kernel(mixes["mixed"])
    assert isinstance(kernel, MixedKernel) and len(kernel.kernels) == 4
    np.testing.assert_allclose(kernel.weights, WEIGHTS, rtol=1e-6)
    assert [w for w, _ in material_mix(load_material(mixes["mixed"]))] == kernel.weights
    assert type(code_kernel(mixes["pure"])) is CodeKernel
    assert ReferenceWalk(mixes["mixed"], 1).mix is not None and ReferenceWalk(mixes["pure"], 1).mix is None
    assert "OpenPBR mix of 0.18" in str(mi.load_dict({"type": "nbrdf", "material": mixes["mixed"]}))


def test_neural_eval_is_the_cpu_mix(mi, mixes):
    """eval = sum_k w_k f_k cos: the CPU ``MixedBRDF`` of ``neural_brdf`` per component within 1e-4
    relative (measured: 1.3e-6); the largest component alone is far off (the mix is not dropped)."""
    from nbrdf.training.brdfs import brdf_for

    light, view = _pairs(11)
    value = _eval(mi, mi.load_dict({"type": "nbrdf", "material": mixes["mixed"]}), view, light)
    cpu = brdf_for(load_material(mixes["mixed"]), "neural")
    assert len(cpu.parts) == 4
    ref = cpu.eval(torch.from_numpy(light), torch.from_numpy(view)).numpy() * np.clip(light[:, 2:3], 0, None)
    assert _relative(value, ref) < 1e-4, _relative(value, ref)
    assert np.all(value[:8] == 0) and ref.max() > 0.1
    largest = _eval(mi, mi.load_dict({"type": "nbrdf", "material": mixes["mixed_largest"]}), view, light)
    assert _relative(largest, ref) > 0.5 and np.abs(largest - ref).max() > 0.05


def test_neural_sample_and_pdf_are_the_cpu_mixture_sampler(mi, mixes):
    """The same uniforms (sample1 picks the component, rescaled) draw the same directions as
    ``MixedBRDF.sample`` with the same (mixture) pdf, and the weight is the mixed eval / that pdf."""
    from nbrdf.training.brdfs import brdf_for

    rng = np.random.default_rng(5)
    view = directions(rng, N, lift=0.2)
    u = rng.random((N, 3)).astype(np.float32)
    bsdf = mi.load_dict({"type": "nbrdf", "material": mixes["mixed"]})
    ctx, si = mi.BSDFContext(), interactions(mi, view)
    bs, weight = bsdf.sample(ctx, si, mi.Float(u[:, 0]), mi.Point2f(u[:, 1], u[:, 2]))
    wo, pdf = np.array(bs.wo).T, np.array(bs.pdf)
    ref = brdf_for(load_material(mixes["mixed"]), "neural").sample(torch.from_numpy(view), torch.from_numpy(u))
    ok = ref.pdf.numpy() > 0
    assert ok.mean() > 0.9
    np.testing.assert_array_equal(pdf > 0, ok)
    np.testing.assert_allclose(wo[ok], ref.w.numpy()[ok], atol=5e-5)
    p_ref = ref.pdf.numpy()[ok]
    assert float((np.abs(pdf[ok] - p_ref) / (1e-4 * (1 + p_ref))).max()) <= 1.0  # SPEC section 7's tolerance
    f, p = bsdf.eval_pdf(ctx, si, bs.wo)
    np.testing.assert_allclose(np.array(p)[ok], pdf[ok], rtol=1e-5)
    np.testing.assert_allclose(np.array(f).T[ok] / pdf[ok, None], np.array(weight).T[ok], rtol=1e-4, atol=1e-6)


def _albedo(mi, path: str, theta_deg: float, n: int, seed: int, kernel=None) -> np.ndarray:
    """The directional albedo (RGB) at ``theta_deg``: the mean sample weight of ``n`` random uniforms
    (``kernel``: one put in place of the loaded material's)."""
    rng = np.random.default_rng(seed)
    bsdf = mi.load_dict({"type": "nbrdf", "material": path})
    if kernel is not None:
        bsdf.kernel = kernel
    view = np.tile(np.array([[math.sin(math.radians(theta_deg)), 0.0, math.cos(math.radians(theta_deg))]],
                            np.float32), (n, 1))
    u = rng.random((n, 3)).astype(np.float32)
    _, weight = bsdf.sample(mi.BSDFContext(), interactions(mi, view), mi.Float(u[:, 0]), mi.Point2f(u[:, 1], u[:, 2]))
    return np.array(weight).T.mean(0)


@pytest.mark.slow
@pytest.mark.ci_slow
def test_neural_albedo_is_the_components_weighted(mi, mixes):
    """White-furnace style: the mix's directional albedo at 50 degrees by its own sampler (one-sample MIS)
    is sum_k w_k albedo_k, each by its component's plugin, within 0.5 % (measured: 0.06 %; each
    estimate's noise at 2^18 samples is ~0.1 %); a sampler drawing the components with the wrong
    weights (reversed) while reporting the mixture's pdf is biased by several %."""
    from nbrdf.mitsuba.mix import MixedKernel

    n = 1 << 18
    mix = _albedo(mi, mixes["mixed"], 50.0, n, 1)
    parts = sum(w * _albedo(mi, mixes[f"mixed_{k}"], 50.0, n, 2 + k) for k, w in enumerate(WEIGHTS))
    assert np.all(mix < 1.0) and np.all(mix > 0.1)
    assert np.abs(mix / parts - 1).max() < 0.005, (mix, parts)
    largest = _albedo(mi, mixes["mixed_largest"], 50.0, n, 7)
    assert np.abs(largest / parts - 1).max() > 0.1, (largest, parts)

    # the sampler's density must be the pdf it reports: reversed weights while reporting the mixture's
    # pdf are biased (a sampler that is right is unbiased whatever the density: one-sample MIS)
    class _Wrong(MixedKernel):
        def sample(self, w, u0, u1, u2, si=None):
            wo = MixedKernel(list(zip(self.weights[::-1], self.kernels))).sample(w, u0, u1, u2, si)[0]
            return wo, self.pdf(w, wo, si)

    base = mi.load_dict({"type": "nbrdf", "material": mixes["mixed"]}).kernel
    biased = _albedo(mi, mixes["mixed"], 50.0, n, 1, _Wrong(base.parts))
    assert np.abs(biased / parts - 1).max() > 0.03, (biased, parts)


def _chi2(mi, sample, pdf):
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    return ChiSquareTest(domain=SphericalDomain(), sample_func=sample, pdf_func=pdf, sample_dim=3, seed=3, ires=8)


def _si(mi, theta_deg: float):
    """n interactions seen from ``theta_deg`` (phi 0), wi a full-width array (the reference reads it)."""
    import drjit as dr

    wi = [math.sin(math.radians(theta_deg)), 0.0, math.cos(math.radians(theta_deg))]

    def si(n):
        s = dr.zeros(mi.SurfaceInteraction3f, n)
        s.wi = mi.Vector3f(*[dr.full(mi.Float, c, n) for c in wi])
        return s

    return si


@pytest.mark.slow
@pytest.mark.ci_slow
@pytest.mark.parametrize("theta", INCIDENCES)
def test_neural_mix_sampler_passes_mitsubas_chi2(mi, mixes, theta):
    """The mixture sampler draws what the mixture's pdf says (``test_mitsuba_chi2``'s settings: 1M
    samples, seed 3, significance 1e-3 over the three incidences; measured p 0.88, 0.24, 0.50)."""
    bsdf = mi.load_dict({"type": "nbrdf", "material": mixes["mixed"]})
    test = _chi2(mi, *sampler_and_pdf(mi, bsdf, _si(mi, theta)))
    assert test.run(significance_level=1e-3, test_count=len(INCIDENCES), quiet=True), test.messages
    assert test.p_value > 1e-3 / len(INCIDENCES)


@pytest.mark.slow
@pytest.mark.ci_slow
def test_chi2_rejects_components_drawn_with_the_wrong_weights(mi, mixes):
    """The test's power: the components drawn with their weights reversed (0.28, 0.42, 0.12, 0.18)
    against the mixture's pdf give p < 1e-6."""
    from nbrdf.mitsuba.mix import MixedKernel

    right = mi.load_dict({"type": "nbrdf", "material": mixes["mixed"]})
    wrong = mi.load_dict({"type": "nbrdf", "material": mixes["mixed"]})
    wrong.kernel = MixedKernel(list(zip(right.kernel.weights[::-1], right.kernel.kernels)))
    si = _si(mi, 50.0)
    test = _chi2(mi, sampler_and_pdf(mi, wrong, si)[0], sampler_and_pdf(mi, right, si)[1])
    assert not test.run(significance_level=1e-3, quiet=True)
    assert test.p_value < 1e-6, test.p_value


def test_reference_eval_is_the_cpu_mix_of_the_same_paths(mi, mixes):
    """``nbrdf_reference``'s eval of a mix is the CPU ``MixedBRDF`` of the components' walks with the
    seed of its call (the same paths: equal up to float rounding), not the largest component's walk."""
    from nbrdf.training.brdfs import brdf_for

    spp, seed = 16, 77
    light, view = _pairs(3, 64)
    m = load_material(mixes["half_coated"])
    bsdf = mi.load_dict({"type": "nbrdf_reference", "material": mixes["half_coated"], "spp": spp})
    bsdf.walk._seeds = itertools.count(seed)  # the seed its next call walks with
    value = _eval(mi, bsdf, view, light)
    cpu = brdf_for(m, "reference", spp=spp, seed=seed)
    assert len(cpu.parts) == 2
    ref = cpu.eval(torch.from_numpy(light), torch.from_numpy(view)).numpy() * np.clip(light[:, 2:3], 0, None)
    assert _relative(value, ref) < 1e-5 and ref.max() > 0.1
    alone = brdf_for(load_material(mixes["half_coated_largest"]), "reference", spp=spp, seed=seed)
    f_alone = alone.eval(torch.from_numpy(light), torch.from_numpy(view)).numpy() * np.clip(light[:, 2:3], 0, None)
    assert _relative(f_alone, ref) > 0.2


def test_reference_sample_pdf_is_the_mixtures(mi, mixes):
    """``nbrdf_reference``'s sample reports the mixture's pdf (``eval_pdf`` at the drawn direction), and
    its weight is its (fresh, noisy) f cos / that pdf: finite, zero only where the pdf is."""
    rng = np.random.default_rng(8)
    n = 512
    view = directions(rng, n, lift=0.2)
    u = rng.random((n, 3)).astype(np.float32)
    bsdf = mi.load_dict({"type": "nbrdf_reference", "material": mixes["half_coated"], "spp": 4})
    ctx, si = mi.BSDFContext(), interactions(mi, view)
    bs, weight = bsdf.sample(ctx, si, mi.Float(u[:, 0]), mi.Point2f(u[:, 1], u[:, 2]))
    pdf, weight = np.array(bs.pdf), np.array(weight).T
    ok = pdf > 0
    assert ok.mean() > 0.9 and np.isfinite(weight).all() and np.all(weight[~ok] == 0)
    np.testing.assert_allclose(np.array(bsdf.pdf(ctx, si, bs.wo))[ok], pdf[ok], rtol=1e-6)
    walk = bsdf.walk
    cpu = sum(w * s.pdf(torch.from_numpy(view), torch.from_numpy(np.array(bs.wo).T)).numpy() for w, _, s in walk.mix)
    np.testing.assert_allclose(pdf[ok], cpu[ok], rtol=1e-5)


@pytest.mark.slow
@pytest.mark.ci_slow
def test_reference_mix_sampler_passes_mitsubas_chi2(mi, mixes):
    """``nbrdf_reference``'s mixture sampler (``ReferenceWalk.sample``: sample1 picks the component)
    against its pdf at 50 degrees (directions only: the walk's f is not needed to draw them)."""
    import drjit as dr

    bsdf = mi.load_dict({"type": "nbrdf_reference", "material": mixes["mixed"]})
    si = _si(mi, 50.0)

    def sample(u):
        n = dr.width(u)
        view = np.array(si(n).wi).T.astype(np.float32)
        us = np.stack([np.asarray(u[1], np.float32), np.asarray(u[2], np.float32), np.asarray(u[0], np.float32)], 1)
        light, pdf = bsdf.walk.sample(view, us)
        return mi.Vector3f(np.ascontiguousarray(light.T)), mi.Float((pdf > 0).astype(np.float32))

    test = _chi2(mi, sample, sampler_and_pdf(mi, bsdf, si)[1])
    assert test.run(significance_level=1e-3, quiet=True), test.messages


def test_a_material_without_a_mix_runs_as_before(mi, mixes):
    """An OpenPBR record that is no mix (metalness 1, coat 1) changes no bit of eval, pdf or sample
    against its layers without the record, in either plugin."""
    rng = np.random.default_rng(4)
    light, view = directions(rng, N), directions(rng, N)
    u = rng.random((N, 3)).astype(np.float32)
    ctx, si = mi.BSDFContext(), interactions(mi, view)
    out = []
    for path in (mixes["pure"], mixes["pure_largest"]):
        bsdf = mi.load_dict({"type": "nbrdf", "material": path})
        bs, weight = bsdf.sample(ctx, si, mi.Float(u[:, 0]), mi.Point2f(u[:, 1], u[:, 2]))
        f, p = bsdf.eval_pdf(ctx, si, mi.Vector3f(light.T))
        ref = mi.load_dict({"type": "nbrdf_reference", "material": path, "spp": 4})
        ref.walk._seeds = itertools.count(5)
        fr, pr = ref.eval_pdf(ctx, si, mi.Vector3f(light.T))
        out.append([np.array(x) for x in (bs.wo, bs.pdf, weight, f, p, fr, pr)])
    for a, b in zip(*out):
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_a_mixs_table_body_is_its_decoder_within_the_tables_error(mi, mixes):
    """``body: "table"`` bakes a table per component (two here, ~4 s each): against the decoder's mix,
    the table's stated error (``test_mitsuba_body_table``'s bounds)."""
    light, view = _pairs(7)
    dec = _eval(mi, mi.load_dict({"type": "nbrdf", "material": mixes["half_coated"]}), view, light)
    tab = _eval(mi, mi.load_dict({"type": "nbrdf", "material": mixes["half_coated"], "body": "table"}), view, light)
    rel = np.abs(tab - dec) / (np.abs(dec) + 1e-3)
    assert rel.mean() < 3e-3 and np.quantile(rel, 0.99) < 3e-2, (rel.mean(), np.quantile(rel, 0.99))
    assert np.all(tab[:8] == 0) and dec.max() > 0.1
