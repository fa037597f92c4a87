"""Golden images: every view of the bundled materials against stored renders
(``tests/viewer/goldens.py`` says what each is, how close a render must be,
and how ``make goldens`` rewrites them; these tests only read them), and the
comparison's power: a 10 % edit of a material's roughness is rejected."""
from __future__ import annotations

import copy

import numpy as np
import pytest
from goldens import CASES, TOLERANCE, Case, figure, matches, material_doc, render_case

pytestmark = pytest.mark.gl


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_golden(gl_ctx, case: Case):
    ok, f = matches(case.view, render_case(gl_ctx, case), np.load(case.path))
    assert ok, f"{case.name}: figure {f:.3g} to the golden image (make goldens rewrites it after an intended change)"


def _scaled(value, k: float):
    """A roughness times k: a number, or a texture's range."""
    return {**value, "range": [x * k for x in value["range"]]} if isinstance(value, dict) else value * k


def _roughness_edits():
    """(case, layer index, factor) for every roughness of every golden's material, times 1.1."""
    out = []
    for c in CASES:
        doc, _ = material_doc(c)
        out += [(c, i, k) for i, layer in enumerate(doc["layers"]) if "roughness" in layer for k in (1.1,)]
    return out


EDITS = _roughness_edits()


@pytest.mark.parametrize("case,layer,factor", EDITS, ids=[f"{c.name}-layer{i}-x{k}" for c, i, k in EDITS])
def test_a_10_percent_roughness_edit_fails_the_golden(gl_ctx, case: Case, layer: int, factor: float):
    """The power of the comparison: each roughness of the material times 1.1
    (a texture's range for a textured one) moves the render outside the
    tolerance, by at least a factor 2."""
    doc, _ = material_doc(case)
    doc = copy.deepcopy(doc)
    doc["layers"][layer]["roughness"] = _scaled(doc["layers"][layer]["roughness"], factor)
    ok, f = matches(case.view, render_case(gl_ctx, case, doc), np.load(case.path))
    assert not ok, f"{case.name}: roughness of layer {layer} x{factor} passes the golden comparison ({f:.3g})"
    assert f > 2 * TOLERANCE[case.view], (case.name, f)


def test_the_figures():
    """Each view's figure on known differences."""
    ref = np.full((4, 4, 3), 2.0, np.float32)
    img = ref.copy()
    img[0, 0, 0] = 2.6
    assert figure("object", img, ref) == pytest.approx(0.6 / 48 / 2)
    assert figure("lobe", img, ref) == pytest.approx(0.6 / 3)
    assert figure("slice", ref[:2], ref) == float("inf")
    img[1, 1, 1] = np.nan
    assert figure("object", img, ref) == float("inf")
