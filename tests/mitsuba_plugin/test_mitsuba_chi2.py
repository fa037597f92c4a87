"""Mitsuba's own chi-square test (``mitsuba.chi2``) on the ``nbrdf``
plugin's sampler: the directions it draws follow the pdf it reports.

Each case runs at significance 1e-3 across the whole set (``test_count``:
Mitsuba's Sidak correction), with Mitsuba's default 1M samples and a 101 x 202
histogram (the power of its own BSDF tests)."""
from __future__ import annotations

import pytest
from chi2_adapter import sampler_and_pdf

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")

#: Simpson sub-intervals per cell when tabulating the pdf: the coat lobe of roughness 0.1 seen at 80 degrees
#: is a few cells wide at the horizon, where Mitsuba's default 4 overestimates its integral by 2 %.
IRES = 8
CASES = [("coated", 0.0), ("coated", 50.0), ("coated", 80.0), ("uncoated", 0.0), ("uncoated", 60.0)]
#: The same sampler with the body read from a baked table (``body: "table"``): its zero-weight
#: samples (the chi-square test's "no sample") come from the table's eval.
TABLE_CASES = [("coated", 50.0), ("uncoated", 60.0)]


def _adapter(mi, bsdf, theta_deg: float):
    import math

    import drjit as dr

    wi = [math.sin(math.radians(theta_deg)), 0.0, math.cos(math.radians(theta_deg))]

    def si(n):
        s = dr.zeros(mi.SurfaceInteraction3f, n)
        s.wi = mi.Vector3f(*wi)
        return s

    return sampler_and_pdf(mi, bsdf, si)


@pytest.mark.slow
@pytest.mark.ci_slow
@pytest.mark.parametrize("role,theta,body", [c + ("decoder",) for c in CASES] + [c + ("table",) for c in TABLE_CASES])
def test_sampler_passes_mitsubas_chi2(mi, materials, role, theta, body):
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    bsdf = mi.load_dict({"type": "nbrdf", "material": materials[role], "body": body})
    sample, pdf = _adapter(mi, bsdf, theta)
    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample, pdf_func=pdf, sample_dim=3, seed=3, ires=IRES)
    assert test.run(significance_level=1e-3, test_count=len(CASES) + len(TABLE_CASES), quiet=True), test.messages
