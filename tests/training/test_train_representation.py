"""Auto-decoder training: it learns, checkpoints, and resumes to the same result."""
from __future__ import annotations

import json
from dataclasses import replace

import pytest
import torch

from nbrdf.neural.decoder import DecoderSpec, load_decoder
from nbrdf.neural.errors import NbrdfError
from nbrdf.training.dataset import DataConfig, generate
from nbrdf.training.train_representation import TrainConfig, train

TINY = DataConfig(counts=dict(conductor=4, dielectric=4, two_layer=4, three_layer=1, diffuse_base=1),
                  val_counts=dict(conductor=1, dielectric=1, two_layer=1), pairs=128, spp=8, shard_size=4)
SPEC = DecoderSpec(width=16, depth=2)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    out = tmp_path_factory.mktemp("data")
    generate(out, TINY, progress=False)
    return out


def test_training_lowers_the_loss_and_writes_its_outputs(data, tmp_path):
    cfg = TrainConfig(data=str(data), out=str(tmp_path / "run"), spec=SPEC, epochs=6, batch=128, val_every=3)
    bundle = train(cfg, progress=False)
    m = json.loads((tmp_path / "run" / "metrics.json").read_text())
    hist = m["history"]["train"]
    assert len(hist) == 6 and hist[-1] < 0.7 * hist[0]
    assert m["macs_per_eval"] == SPEC.macs()
    dec = load_decoder(bundle)
    assert dec.spec == SPEC and (tmp_path / "run" / "curves.png").stat().st_size > 1000
    assert (tmp_path / "run" / "latents.safetensors").exists()
    assert not torch.all(dec.latent_mean == 0)  # projection starts from the training latents' mean


@pytest.mark.slow
@pytest.mark.ci_slow
def test_interrupted_run_resumes_to_the_same_weights(data, tmp_path):
    cfg = TrainConfig(data=str(data), out=str(tmp_path / "a"), spec=SPEC, epochs=3, batch=512, val_every=3)
    whole = load_decoder(train(cfg, progress=False)).weights_id()
    cfg_b = replace(cfg, out=str(tmp_path / "b"))
    train(cfg_b, progress=False, stop_after=1)
    assert not (tmp_path / "b" / "decoder.safetensors").exists()
    resumed = load_decoder(train(cfg_b, progress=False)).weights_id()
    assert resumed == whole


def test_a_checkpoint_of_other_settings_is_refused(data, tmp_path):
    cfg = TrainConfig(data=str(data), out=str(tmp_path / "r"), spec=SPEC, epochs=1, batch=512)
    train(cfg, progress=False)
    with pytest.raises(NbrdfError, match="other settings"):
        train(replace(cfg, lr=1e-4), progress=False)


def test_several_data_sets_train_one_latent_table(data, tmp_path):
    other = tmp_path / "other"
    generate(other, replace(TINY, counts=dict(two_layer=3), val_counts=dict(two_layer=1), pairs=64, seed=5),
             progress=False)
    cfg = TrainConfig(data=f"{data},{other}", out=str(tmp_path / "run"), spec=SPEC, epochs=2, batch=256)
    train(cfg, progress=False)
    from safetensors.torch import load_file

    from nbrdf.training.dataset import load_split

    table = load_file(str(tmp_path / "run" / "latents.safetensors"))
    params = torch.cat([load_split(data, "train").params, load_split(other, "train").params])
    assert table["latents"].shape == (params.shape[0], SPEC.latent)
    assert torch.equal(table["params"], params)
