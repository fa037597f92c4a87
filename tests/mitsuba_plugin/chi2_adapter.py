"""The sample and pdf functions ``mitsuba.chi2.ChiSquareTest`` takes, for a BSDF queried at
interactions from a factory (one incident direction, or hits on a textured surface)."""
from __future__ import annotations


def sampler_and_pdf(mi, bsdf, si):
    """``si(n)``: n surface interactions; returns (sample, pdf) as the chi-square test calls them.
    A sample of zero weight counts as no sample, as Mitsuba's own BSDF tests do."""
    import drjit as dr

    def sample(u):
        n = dr.width(u)
        bs, weight = bsdf.sample(mi.BSDFContext(), si(n), u[0], mi.Point2f(u[1], u[2]))
        w = dr.full(mi.Float, 1.0, n)
        w[dr.all(weight == 0)] = 0
        return bs.wo, w

    def pdf(wo):
        return bsdf.pdf(mi.BSDFContext(), si(dr.width(wo)), wo)

    return sample, pdf
