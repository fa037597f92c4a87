"""Anisotropic interfaces in the material schema, the stack and the paths that refuse them (SPEC section 10):
``anisotropy`` on dielectric and conductor layers, the material's ``anisotropy_rotation``, their one-line
errors, the files an isotropic material writes (unchanged), and the one-line refusal of every consumer that
cannot take anisotropy yet (the projection onto the decoder's latents, the closed-form GLSL shader, Belcour,
the analytic layering, the Mitsuba plugins' texture-mapped materials; the neural path, the refinement and the
uniform Mitsuba plugins take it: tests/neural/test_anisotropic_code.py)."""
from __future__ import annotations

import json

import pytest
import torch

from nbrdf.neural.anisotropy import anisotropic_layers, require_isotropic
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import FORMAT, KINDS
from nbrdf.neural.leaf import LEAF_PARAMS
from nbrdf.neural.material import material_to_dict, parse_material
from nbrdf.neural.stack import material_stack

COAT = {"type": "dielectric", "roughness": 0.05, "ior": 1.5}
MEDIUM = {"type": "medium", "albedo": 0.9, "sigma_t": 0.5}
METAL = {"type": "conductor", "roughness": 0.3, "r0": [0.9, 0.6, 0.5]}


def _doc(*layers, **top) -> dict:
    return {"format": FORMAT, "name": "m", "layers": list(layers), **top}


def test_an_isotropic_material_parses_and_writes_as_before():
    """No anisotropy key and no rotation: the layers hold 0, the written document is the one read."""
    doc = _doc(COAT, MEDIUM, METAL)
    m = parse_material(doc)
    assert m.anisotropy_rotation == 0 and all(getattr(x, "anisotropy", 0.0) == 0.0 for x in m.layers)
    assert material_to_dict(m) == doc
    assert anisotropic_layers(m) == []
    require_isotropic(m, "anything")  # no error
    assert {"roughness", "ior"} == set(LEAF_PARAMS["dielectric"]) and "anisotropy" not in LEAF_PARAMS["conductor"]


def test_anisotropy_and_rotation_parse_and_write_back():
    doc = _doc(dict(COAT, anisotropy=0.5), MEDIUM, dict(METAL, anisotropy=0.95), anisotropy_rotation=30)
    m = parse_material(doc)
    assert m.layers[0].anisotropy == 0.5 and m.layers[2].anisotropy == 0.95 and m.anisotropy_rotation == 30
    assert material_to_dict(m) == doc
    assert anisotropic_layers(m) == [0, 2]
    zero = parse_material(_doc(dict(COAT, anisotropy=0.0), METAL, anisotropy_rotation=0))
    assert material_to_dict(zero) == _doc(COAT, METAL)  # zeros are not written
    assert KINDS["dielectric"].new_layer()["anisotropy"] == 0.0


@pytest.mark.parametrize("doc,message", [
    (_doc(dict(COAT, anisotropy=0.96), METAL), r"^layers\[0\]\.anisotropy: 0\.96 is outside \[0, 0\.95\]$"),
    (_doc(COAT, dict(METAL, anisotropy=-0.1)), r"^layers\[1\]\.anisotropy: -0\.1 is outside \[0, 0\.95\]$"),
    (_doc(COAT, dict(METAL, anisotropy="high")), r'^layers\[1\]\.anisotropy: expected a number, got the string "high"$'),
    (_doc(COAT, dict(METAL, anisotropy=[0.1, 0.2, 0.3])), r"^layers\[1\]\.anisotropy: anisotropy is shared by the"),
    (_doc(COAT, dict(MEDIUM, anisotropy=0.1), METAL), r"^layers\[1\]\.anisotropy: unknown key$"),
    (_doc({"type": "diffuse", "albedo": 0.5, "anisotropy": 0.2}), r"^layers\[0\]\.anisotropy: unknown key$"),
    (_doc(METAL, anisotropy_rotation="45"), r'^anisotropy_rotation: expected a number, got the string "45"$'),
    (_doc(METAL, anisotropy_rotation=400), r"^anisotropy_rotation: 400 is outside \[-360, 360\]$"),
    (_doc(METAL, anisotropy_rotation=None), r"^anisotropy_rotation: expected a number, got null$"),
    (_doc(METAL, anisotropy_rotation=True), r"^anisotropy_rotation: expected a number, got a boolean$"),
])
def test_bad_anisotropy_is_one_line_naming_the_place(doc, message):
    with pytest.raises(NbrdfError, match=message):
        parse_material(doc)


def test_the_stack_carries_anisotropy_and_rotation():
    iso = material_stack(parse_material(_doc(COAT, MEDIUM, METAL)))
    assert iso.anisotropy.tolist() == [[0.0]] and iso.base_anisotropy.tolist() == [0.0]
    assert iso.rotation.tolist() == [0.0] and not iso.is_anisotropic
    m = parse_material(_doc(dict(COAT, anisotropy=0.5), MEDIUM, COAT, dict(METAL, anisotropy=0.25),
                            anisotropy_rotation=-20.0))
    s = material_stack(m)
    assert s.anisotropy.tolist() == [[0.5, 0.0]] and s.base_anisotropy.tolist() == [0.25]
    assert s.rotation.tolist() == [-20.0] and s.is_anisotropic
    pc = s.per_channel()
    assert pc.anisotropy.shape == (3, 2) and pc.rotation.tolist() == [-20.0] * 3
    bare = material_stack(parse_material(_doc(dict(COAT, anisotropy=0.3))))
    assert bare.base_anisotropy.tolist() == [0.3] and bare.layers == 0


def test_the_reference_takes_anisotropy_where_the_others_refuse_it_in_one_line():
    """The closed-form reference of a lone anisotropic layer differs from the isotropic one; the GLSL shader,
    Belcour, the analytic layering and the projection name the layer and say it is not supported yet; the
    refinement and the neural path take it."""
    from nbrdf.neural.model import default_model, layered_latents
    from nbrdf.training.analytic_layering import check_analytic
    from nbrdf.training.belcour import atoms_of
    from nbrdf.training.project import material_samples
    from nbrdf.training.reference import reference_eval
    from nbrdf.training.refine import check_refinable
    from nbrdf.viewer.gpu.materials_gpu import analytic_uniforms

    wi = torch.tensor([[0.3, 0.1, 0.9]], dtype=torch.float64)
    wo = torch.tensor([[-0.2, 0.35, 0.9]], dtype=torch.float64)
    wi, wo = wi / wi.norm(dim=-1, keepdim=True), wo / wo.norm(dim=-1, keepdim=True)
    aniso = parse_material(_doc(dict(METAL, anisotropy=0.8), anisotropy_rotation=45))
    f_a, _ = reference_eval(aniso, wi, wo, dtype=torch.float64)
    f_i, _ = reference_eval(parse_material(_doc(METAL)), wi, wo, dtype=torch.float64)
    assert not torch.allclose(f_a, f_i, rtol=1e-2)
    coated = parse_material(_doc(COAT, MEDIUM, dict(METAL, anisotropy=0.8)))
    for call, path in ((analytic_uniforms, "the closed-form GLSL shader"), (atoms_of, "Belcour's model"),
                       (check_analytic, "the analytic layering model"),
                       (material_samples, "the projection onto the decoder's latents")):
        with pytest.raises(NbrdfError, match=rf"^layers\[2\]\.anisotropy: anisotropy is not yet supported by {path}$"):
            call(coated)
    check_refinable(coated)
    # the neural path takes it (its isotropic equivalent): what it lacks here is its networks, not anisotropy
    with pytest.raises(NbrdfError, match="^an anisotropic stack over a scattering medium needs the decoder for its glow$"):
        layered_latents(None, None, material_stack(coated))
    with pytest.raises(NbrdfError, match="^a conductor base needs the leaf encoders$"):
        layered_latents(None, None, material_stack(coated), decoder=default_model().decoder)


def test_the_mitsuba_plugins_take_a_uniform_anisotropic_material_and_refuse_a_mapped_one(tmp_path):
    mitsuba = pytest.importorskip("nbrdf.mitsuba.materials", exc_type=ImportError)
    import imageio.v3 as iio
    import numpy as np

    path = tmp_path / "m.json"
    path.write_text(json.dumps(_doc(COAT, MEDIUM, dict(METAL, anisotropy=0.4))))
    mitsuba.ReferenceWalk(str(path), spp=4)  # no error
    iio.imwrite(tmp_path / "a.png", np.full((4, 4, 3), 128, np.uint8))
    path.write_text(json.dumps(_doc(COAT, dict(MEDIUM, albedo=[{"texture": "a.png", "channel": c, "range": [0, 1]}
                                                              for c in "rgb"]), dict(METAL, anisotropy=0.4))))
    with pytest.raises(mitsuba.PluginError, match=r"layers\[2\]\.anisotropy: anisotropy is not yet supported by "
                                                  r"the Mitsuba plugins' texture-mapped materials"):
        mitsuba.ReferenceWalk(str(path), spp=4)
