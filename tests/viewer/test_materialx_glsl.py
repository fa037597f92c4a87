"""OpenPBR through MaterialX's own generated GLSL (the `nbrdf report openpbr` column) on SPEC section 9's lit
sphere: a white diffuse OpenPBR is Lambert's NdotL / pi within MaterialX's own energy terms, a metal lands near
the stack's closed form (MaterialX adds multiple-scattering energy the stack leaves out), and a document
MaterialX cannot generate for is one line."""
from __future__ import annotations

import numpy as np
import pytest

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material
from nbrdf.neural.mtlx import write_mtlx
from nbrdf.neural.openpbr import OpenPbr
from nbrdf.training.brdfs import brdf_for
from nbrdf.training.render_report import load_set, shade, sphere_geometry
from nbrdf.viewer.gpu.materialx_glsl import render_materialx

pytestmark = pytest.mark.gl


@pytest.mark.parametrize("name,p,lo,hi", [
    ("white", OpenPbr(base_color=(1.0, 1.0, 1.0), specular_weight=0.0), 0.95, 1.02),
    ("metal", OpenPbr(base_metalness=1.0, base_color=(0.9, 0.6, 0.3), specular_roughness=0.5), 1.0, 1.15),
])
def test_materialx_glsl_renders_the_lit_sphere(gl_ctx, tmp_path, name, p, lo, hi):
    geo = sphere_geometry(32)
    write_mtlx(p, name, tmp_path / f"{name}.mtlx")
    img = render_materialx(gl_ctx, tmp_path / f"{name}.mtlx", geo)
    ref = shade(brdf_for(load_material(tmp_path / f"{name}.mtlx", []), "reference").eval, geo)
    m = geo.mask.numpy()
    ratio = img[m].sum(0) / ref[m].sum(0)
    assert np.all((ratio > lo) & (ratio < hi)), ratio
    assert img[~m].max() == 0.0 and np.isfinite(img).all()


def test_a_document_materialx_cannot_read_is_one_line(gl_ctx, tmp_path):
    bad = tmp_path / "bad.mtlx"
    bad.write_text("<materialx version=")
    with pytest.raises(NbrdfError, match="bad.mtlx"):
        render_materialx(gl_ctx, bad, sphere_geometry(8))


def test_the_openpbr_set_has_its_classes():
    items = load_set("openpbr")
    classes = {c for c, _ in items}
    assert len(items) >= 16 and classes == {"coated_metal", "coated_plastic", "car_paint", "lacquered_wood",
                                            "metal", "plastic"}
    assert all(m.openpbr is not None for _, m in items)
