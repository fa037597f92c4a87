"""MERL .binary: the standard layout read and written exactly, the standard lookup."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.training.analytic import GGXConductor
from nbrdf.training.merl import RES, SCALE, MerlBRDF, angles, cell_centres, directions, indices


def conductor_rgb(a=0.2, r0=(0.9, 0.5, 0.2)):
    c = GGXConductor(a, torch.tensor(r0, dtype=torch.float64))
    return lambda wi, wo: c.eval(wi[:, None, :].expand(-1, 3, -1), wo[:, None, :].expand(-1, 3, -1))


@pytest.fixture(scope="module")
def table():
    return MerlBRDF.tabulate(conductor_rgb())


def test_layout_bytes_are_the_standard_ones(tmp_path, table):
    p = tmp_path / "t.binary"
    table.save(p)
    raw = p.read_bytes()
    assert np.frombuffer(raw[:12], "<i4").tolist() == [90, 90, 180]
    assert len(raw) == 12 + 3 * 90 * 90 * 180 * 8
    # the first stored green value is the table's value divided by the green scale
    vals = np.frombuffer(raw[12:], "<f8").reshape(3, -1)
    first = np.flatnonzero(vals[1] >= 0)[0]
    assert vals[1, first] == pytest.approx(table.table.reshape(3, -1)[1, first] / SCALE[1], rel=1e-12)
    assert (vals[:, ~np.isfinite(table.table.reshape(3, -1)).all(0)] == -1).all()  # unmeasured marker


def test_round_trip_is_exact(tmp_path, table):
    table.save(tmp_path / "t.binary")
    back = MerlBRDF.load(tmp_path / "t.binary")
    both = np.isfinite(table.table)
    assert (np.isfinite(back.table) == both).all()
    np.testing.assert_allclose(back.table[both], table.table[both], rtol=1e-13)


def test_lookup_at_cell_centres_returns_the_tabulated_brdf(table):
    th, td, pd = cell_centres()
    g = np.random.default_rng(0)
    pick = torch.from_numpy(g.choice(th.numel(), 4000, replace=False))
    wi, wo = directions(th[pick], td[pick], pd[pick])
    up = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    assert (indices(wi, wo) == pick).all()
    torch.testing.assert_close(table.eval(wi, wo)[up], conductor_rgb()(wi, wo)[up], rtol=1e-10, atol=0)


def test_angles_follow_the_merl_convention():
    th, td, pd = torch.tensor([0.3]), torch.tensor([0.5]), torch.tensor([2.0])
    wi, wo = directions(th.double(), td.double(), pd.double())
    a = angles(wi, wo)
    torch.testing.assert_close(torch.stack(a).squeeze(-1), torch.tensor([0.3, 0.5, 2.0], dtype=torch.float64))
    # reciprocity folds phi_d into [0, pi)
    b = angles(wo, wi)
    torch.testing.assert_close(b[2], torch.tensor([2.0 - math.pi + math.pi], dtype=torch.float64))


def test_samples_come_from_measured_cells(table):
    wi, wo, f = table.samples(3000, seed=1)
    assert torch.isfinite(f).all() and (wi[:, 2] > 0).all() and (wo[:, 2] > 0).all()
    torch.testing.assert_close(table.eval(wi, wo), f, rtol=0, atol=0)


@pytest.mark.parametrize("case", ["missing", "short", "dims", "size", "nan"])
def test_bad_files_give_one_clear_error(tmp_path, case):
    p = tmp_path / "bad.binary"
    n = int(np.prod(RES))
    if case == "short":
        p.write_bytes(b"\x01\x02")
    elif case == "dims":
        p.write_bytes(np.array([90, 90, 90], "<i4").tobytes() + np.zeros(3 * 90 * 90 * 90).tobytes())
    elif case == "size":
        p.write_bytes(np.array(RES, "<i4").tobytes() + np.zeros(100).tobytes())
    elif case == "nan":
        v = np.zeros(3 * n)
        v[5] = np.nan
        p.write_bytes(np.array(RES, "<i4").tobytes() + v.tobytes())
    if case == "missing":
        p = tmp_path / "nope.binary"
    with pytest.raises(NbrdfError) as e:
        MerlBRDF.load(p)
    assert "\n" not in str(e.value)
