"""Walk albedos of drawn stacks (training/albedo_data.py) and the albedo network's training
(training/train_albedo.py): draws that depend on the index alone, chunks that are never recomputed, a set that
may grow but not change its settings, and a trained network that the bundle carries."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from nbrdf.neural.energy import EnergySettings
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.model import load_model
from nbrdf.training import albedo_data
from nbrdf.training.albedo_data import AlbedoDataConfig, draw_stack
from nbrdf.training.train_albedo import AlbedoTrainConfig, train_albedo

#: A set the tests can make in seconds (few, noisy paths: the files' mechanics, not the walk's accuracy).
TINY = AlbedoDataConfig(stacks=5, chunk=2, paths=64, max_paths=128, target=0.5)


def test_draws_depend_on_the_index_alone_and_cover_the_range():
    cfg = AlbedoDataConfig()
    assert draw_stack(7, cfg) == draw_stack(7, cfg)
    assert draw_stack(7, cfg) != draw_stack(8, cfg)
    drawn = [draw_stack(i, cfg) for i in range(200)]
    depths = {len(m.layers) // 2 + 1 for m in drawn}
    assert depths == {2, 3, 4, 5}
    lossless = sum(m.name.startswith("lossless") for m in drawn) / len(drawn)
    assert 0.3 < lossless < 0.5  # the configured share 0.4, 200 draws: 3.4 standard deviations either side
    assert all(m.name.startswith("absorbing") or all(x == 1.0 for x in m.layers[1].albedo) for m in drawn)


@pytest.fixture(scope="module")
def tiny_set(tmp_path_factory):
    folder = tmp_path_factory.mktemp("albedo")
    albedo_data.generate(folder, TINY, progress=False)
    return folder


def test_a_set_is_made_in_chunks_that_are_kept(tiny_set):
    mats, mean, se = albedo_data.load(tiny_set)
    T = len(EnergySettings().thetas)
    assert len(mats) == 5 and mean.shape == (5, T, 3) and se.shape == (5, T, 3)
    assert np.isfinite(mean).all() and (mean >= 0).all() and (mean < 1.2).all()
    assert [m.name for m in mats] == [draw_stack(i, TINY).name for i in range(5)]
    chunk = tiny_set / "chunk-0000.safetensors"
    stamp = chunk.stat().st_mtime_ns
    albedo_data.generate(tiny_set, dataclasses.replace(TINY, stacks=6), progress=False)  # grows: one more stack
    assert chunk.stat().st_mtime_ns == stamp  # a finished chunk is never recomputed
    assert len(albedo_data.load(tiny_set)[0]) == 6


def test_other_settings_and_missing_data_are_one_line_errors(tiny_set, tmp_path):
    with pytest.raises(NbrdfError, match="other settings"):
        albedo_data.generate(tiny_set, dataclasses.replace(TINY, paths=128), progress=False)
    with pytest.raises(NbrdfError, match="no albedo data"):
        albedo_data.load(tmp_path)


def test_the_trained_network_goes_into_the_bundle(tiny_set, tmp_path):
    out = tmp_path / "bundle.safetensors"
    figures = train_albedo(AlbedoTrainConfig(data=str(tiny_set), out=str(out), steps=20, val_share=0.2),
                           log=lambda _s: None)
    assert set(figures) >= {"decoded", "predicted", "settled"}
    model = load_model(out)
    assert model.albedo is not None and model.albedo.incidences == len(EnergySettings().thetas)
    assert model.trained_on["albedo"]["stacks"] == 6
    code = torch.zeros(2, 34)
    assert torch.isfinite(model.albedo(code, torch.full((2, model.albedo.incidences), 0.3))).all()
