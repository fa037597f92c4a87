"""OpenPBR's linear mixes as one BRDF (neural/mix.py): a fractional base_metalness or coat_weight is
the weighted sum of its pure stacks in every method made on the CPU -- evaluation exactly, sampling
by a density that is the mixture's (unbiased albedo, pdf consistent), the Monte Carlo reference
within its noise -- and a material without a mix is itself."""
from __future__ import annotations

from pathlib import Path

import pytest
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import parse_material
from nbrdf.neural.mix import MixedBRDF, material_mix
from nbrdf.neural.openpbr import OpenPbr, mix_summary, openpbr_to_material
from nbrdf.training.brdfs import brdf_for

MIXED = OpenPbr(base_color=(0.8, 0.5, 0.3), base_metalness=0.3, coat_weight=0.6, coat_roughness=0.3)


def _material(p: OpenPbr):
    d, _ = openpbr_to_material(p, "t")
    return parse_material(d)


def _pairs(n: int = 512, seed: int = 3):
    g = torch.Generator().manual_seed(seed)
    v = torch.randn(2, n, 3, generator=g)
    v[..., 2] = v[..., 2].abs() + 0.05
    v = v / v.norm(dim=-1, keepdim=True)
    return v[0], v[1]


def test_a_mix_is_its_components_weighted():
    m = _material(MIXED)
    parts = material_mix(m)
    assert [round(w, 6) for w, _ in parts] == [0.18, 0.12, 0.42, 0.28]
    assert all(c.openpbr is None for _, c in parts)  # pure stacks
    wi, wo = _pairs()
    got = brdf_for(m, "neural").eval(wi, wo)
    want = sum(w * brdf_for(c, "neural").eval(wi, wo) for w, c in parts)
    torch.testing.assert_close(got, want)
    # and differs from the largest component alone (what the layers hold): the mix is not dropped
    layers = openpbr_to_material(MIXED, "x")[0]["layers"]
    alone = brdf_for(parse_material({"format": "nbrdf-material/1", "name": "x", "layers": layers}), "neural")
    assert float((got - alone.eval(wi, wo)).abs().max()) > 0.05


def test_sampling_a_mix_is_unbiased_and_its_pdf_is_the_mixtures():
    m = _material(MIXED)
    b = brdf_for(m, "neural")
    n = 1 << 14
    wi = torch.tensor([[0.5, 0.0, 0.866]]).expand(n, 3).contiguous()
    u = torch.quasirandom.SobolEngine(3, scramble=True, seed=1).draw(n).float()
    s = b.sample(wi, u)
    torch.testing.assert_close(b.pdf(wi, s.w), s.pdf)
    got = s.weight.mean(0)
    want = sum(w * brdf_for(c, "neural").sample(wi, u).weight.mean(0) for w, c in material_mix(m))
    # each estimate's noise at 2^14 Sobol points is well under 1 %: a 10 % error in any weight moves it more
    assert torch.allclose(got, want, rtol=0.01), (got, want)


def test_the_reference_of_a_mix_is_its_components_references():
    m = _material(OpenPbr(base_color=(0.7, 0.7, 0.7), coat_weight=0.5, coat_roughness=0.2))
    wi, wo = _pairs(64)
    f, e = brdf_for(m, "reference", spp=512).eval_with_error(wi, wo)
    parts = [(w, brdf_for(c, "reference", spp=512).eval_with_error(wi, wo)) for w, c in material_mix(m)]
    want = sum(w * fe[0] for w, fe in parts)
    assert e is not None
    # the same paths per component (same seed): equal up to float rounding, and the errors combined
    torch.testing.assert_close(f, want)
    torch.testing.assert_close(e, sum((w * fe[1]) ** 2 for w, fe in parts).sqrt())


def test_no_mix_is_the_material_itself_and_the_note_names_the_components():
    m = _material(OpenPbr(base_metalness=1.0, coat_weight=1.0))
    assert material_mix(m) == [(1.0, m)] and mix_summary(m.openpbr) is None
    note = mix_summary(_material(MIXED).openpbr)
    assert note is not None and note.startswith("OpenPBR mix (metal, coated 0.18") and "weighted sum" in note
    textured = mix_summary(_material(MIXED).openpbr, textured=True)
    assert textured is not None and "carry no textures" in textured and "largest" in textured


def test_a_texture_mapped_mix_is_its_largest_component_and_says_so(tmp_path):
    import imageio.v3 as iio
    import numpy as np

    from nbrdf.neural.material import load_material

    src = (Path(__file__).parent / "data" / "mtlx" / "image_inputs.mtlx").read_text()
    doc = tmp_path / "m.mtlx"
    doc.write_text(src.replace('<input name="base_weight" type="float" value="0.9" />',
                               '<input name="base_weight" type="float" value="0.9" />'
                               '<input name="coat_weight" type="float" value="0.5" />'))
    iio.imwrite(tmp_path / "albedo.png", np.full((4, 4, 3), 128, np.uint8))
    notes: list[str] = []
    m = load_material(doc, notes)
    assert m.is_textured and material_mix(m) == [(1.0, m)]  # not two untextured stacks in its place
    assert sum("carry no textures" in n for n in notes) == 1, notes


def test_a_mix_saved_as_json_says_so_when_loaded(tmp_path):
    import json

    from nbrdf.neural.material import load_material

    for p, expected in ((MIXED, 1), (OpenPbr(base_metalness=1.0, coat_weight=1.0), 0)):
        d, _ = openpbr_to_material(p, "t")
        path = tmp_path / "m.json"
        path.write_text(json.dumps(d))
        notes: list[str] = []
        load_material(path, notes)
        assert len(notes) == expected and all(n.startswith(f"{path}: OpenPBR mix (") for n in notes), notes


def test_bad_weights_are_one_line():
    with pytest.raises(NbrdfError, match="weights"):
        MixedBRDF([(0.5, None), (0.6, None)])  # type: ignore[list-item]
    with pytest.raises(NbrdfError, match="weights"):
        MixedBRDF([])
