"""Render-space report (SPEC section 9): sphere geometry, scores, the report files."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material, parse_material
from nbrdf.neural.metrics import compressed_psnr
from nbrdf.training.reference import single_layer_eval
from nbrdf.training.render_report import (
    SETS_DIR,
    RenderReportConfig,
    flip,
    light_direction,
    load_set,
    reference_render,
    run_render_report,
    shade,
    sphere_geometry,
)


def _conductor(rough: float, r0=(0.95, 0.64, 0.54)):
    return parse_material({"format": "nbrdf-material/1", "name": f"copper {rough}",
                           "layers": [{"type": "conductor", "roughness": rough, "r0": list(r0)}]})


def _closed(m):
    return lambda wi, wo: single_layer_eval(m.base, wi, wo)


def test_sphere_frame_follows_spec():
    geo = sphere_geometry(32)
    f = geo.frame
    eye = torch.eye(3, dtype=f.dtype).expand_as(f)
    assert torch.allclose(f @ f.transpose(1, 2), eye, atol=1e-12)  # orthonormal rows
    assert torch.allclose(torch.linalg.det(f), torch.ones(f.shape[0], dtype=f.dtype), atol=1e-12)  # right-handed
    # z is the sphere normal at the pixel centre: (x, y, sqrt(1 - x^2 - y^2)), row 0 at the top
    c = (torch.arange(32, dtype=torch.float64) + 0.5) / 32 * 2 - 1
    y, x = torch.meshgrid(-c, c, indexing="ij")
    n = torch.stack([x[geo.mask], y[geo.mask]], -1)
    assert torch.allclose(f[:, 2, :2], n, atol=1e-12)
    assert geo.mask[0].sum() < geo.mask[16].sum() and not geo.mask[0, 0]
    up = torch.tensor([0.0, 1.0, 0.0], dtype=f.dtype).expand(f.shape[0], 3)
    x_expected = torch.linalg.cross(up, f[:, 2])
    x_expected = x_expected / x_expected.norm(dim=-1, keepdim=True)
    assert torch.allclose(f[:, 0], x_expected, atol=1e-12)
    assert torch.allclose(f[:, 1], torch.linalg.cross(f[:, 2], f[:, 0]), atol=1e-12)
    # local directions are the view-space light and +z seen in that frame
    assert torch.allclose((f * geo.wi[:, :, None]).sum(1), light_direction().expand_as(geo.wi), atol=1e-12)
    assert torch.allclose(geo.wo[:, 2], f[:, 2, 2], atol=1e-12)


def test_pixels_below_the_horizon_are_zero():
    geo = sphere_geometry(48)
    img = shade(lambda wi, wo: torch.ones(wi.shape[0], 3), geo)  # f = 1: image = max(cos_i, 0)
    lit = (geo.wi[:, 2] > 0).numpy()
    inside = img[geo.mask.numpy()]
    assert lit.any() and (~lit).any()
    assert np.all(inside[~lit] == 0)
    assert np.allclose(inside[lit, 0], geo.wi[lit.nonzero()[0], 2].numpy(), atol=1e-6)
    assert np.all(img[~geo.mask.numpy()] == 0)


def test_closed_form_scores_itself_perfectly_and_perturbations_monotonically_worse():
    geo = sphere_geometry(48)
    mask = geo.mask.numpy()
    ref = shade(_closed(_conductor(0.2)), geo)
    fl, fmap = flip(ref, ref)
    assert fl == 0.0 and not fmap.any()
    assert math.isinf(compressed_psnr(ref, ref, mask))
    flips, psnrs = [], []
    for rough in (0.22, 0.3, 0.45):
        img = shade(_closed(_conductor(rough)), geo)
        flips.append(flip(ref, img)[0])
        psnrs.append(compressed_psnr(img, ref, mask))
    assert 0 < flips[0] < flips[1] < flips[2]
    assert psnrs[0] > psnrs[1] > psnrs[2]


def test_lookdev_set_is_complete():
    items = load_set("lookdev")
    assert len(items) >= 12
    names = {m.name for _, m in items}
    assert {"coated gold", "black lacquer"} <= names
    classes = {c for c, _ in items}
    assert {"coated_metal", "coated_diffuse", "car_paint"} <= classes
    gold = load_material(SETS_DIR / "lookdev" / "coated-gold.json")
    assert gold.interfaces[0][0].roughness == 0.02 and gold.base.r0 == (1.0, 0.78, 0.34)
    for _, m in items:
        assert m.interfaces and 0.01 <= m.interfaces[0][0].roughness <= 0.05  # sharp coats only


def test_bad_set_is_one_clear_error(tmp_path: Path):
    with pytest.raises(NbrdfError, match="not a set name"):
        load_set(str(tmp_path / "missing"))
    with pytest.raises(NbrdfError, match="no material"):
        load_set(str(tmp_path))
    with pytest.raises(NbrdfError, match="methods"):
        run_render_report(RenderReportConfig(sets=(str(tmp_path),), out=tmp_path, methods=("bogus",)))


def test_report_on_a_tiny_set_writes_json_and_figure(tmp_path: Path):
    folder = tmp_path / "set"
    folder.mkdir()
    for name in ("coated-gold", "coated-black-plastic"):
        (folder / f"{name}.json").write_text((SETS_DIR / "lookdev" / f"{name}.json").read_text())
    cfg = RenderReportConfig(sets=(str(folder),), out=tmp_path / "out", size=24, spp=4, noise_target=0.0,
                             methods=("neural",), progress=False, figure_dpi=30)
    res = run_render_report(cfg)
    data = json.loads((tmp_path / "out" / "render.json").read_text())
    rows = data["sets"]["set"]["rows"]
    assert [r["name"] for r in rows] == ["coated black plastic", "coated gold"]
    for r in rows:
        assert 0 < r["neural"]["flip"] <= 1 and r["reference"]["spp"] == 4
    summ = data["sets"]["set"]["summary"]["all"]["neural"]
    assert summ["flip_worst"] == max(r["neural"]["flip"] for r in rows)
    assert (tmp_path / "out" / "render_set.png").stat().st_size > 1000
    # references are cached and reused: a second run gives the same scores
    assert len(list((tmp_path / "out" / "references").glob("*.npz"))) == 2
    res2 = run_render_report(cfg)
    assert res2["sets"]["set"]["rows"][1]["neural"] == res["sets"]["set"]["rows"][1]["neural"]


def test_report_scores_belcour_beside_neural(tmp_path: Path):
    folder = tmp_path / "set"
    folder.mkdir()
    (folder / "gold.json").write_text((SETS_DIR / "lookdev" / "coated-gold.json").read_text())
    cfg = RenderReportConfig(sets=(str(folder),), out=tmp_path / "out", size=16, spp=4, noise_target=0.0,
                             methods=("neural", "belcour"), progress=False, figure=False)
    summ = run_render_report(cfg)["sets"]["set"]["summary"]["all"]
    assert 0 < summ["belcour"]["flip_median"] <= 1 and 0 < summ["neural"]["flip_median"] <= 1
    assert "belcour FLIP median" in (tmp_path / "out" / "render.md").read_text()


def test_reference_refinement_doubles_paths_and_pools_halves(tmp_path: Path):
    m = load_material(SETS_DIR / "lookdev" / "coated-gold.json")
    geo = sphere_geometry(16)
    one = reference_render(m, geo, 4, cache=tmp_path, progress=False)
    ref = reference_render(m, geo, 4, cache=tmp_path, progress=False, noise_target=1e-9, max_spp=32)
    assert one.spp == 4 and ref.spp == 32
    assert ref.half_flip < one.half_flip
    assert len(list(tmp_path.glob("*.npz"))) == 4  # one file per round: 4, 8, 16, 32 spp
    again = reference_render(m, geo, 4, cache=tmp_path, progress=False, noise_target=1e-9, max_spp=32)
    assert np.array_equal(again.image, ref.image)
