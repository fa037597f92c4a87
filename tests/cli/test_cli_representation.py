"""nbrdf data / train representation / project / eval --method projected."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from test_cli import assert_one_line_error, random_pairs, run, write_material

from nbrdf.neural.decoder import Decoder, DecoderSpec, save_decoder
from nbrdf.neural.latent import load_latent
from nbrdf.training.analytic import GGXConductor
from nbrdf.training.merl import MerlBRDF


@pytest.fixture(scope="module")
def decoder_file(tmp_path_factory):
    torch.manual_seed(0)
    p = tmp_path_factory.mktemp("dec") / "d.safetensors"
    save_decoder(Decoder(DecoderSpec(width=32, depth=2)), p)
    return p


@pytest.mark.slow
@pytest.mark.ci_slow
def test_data_then_train_tiny(tmp_path, capsys):
    code, out, err = run(["data", "--preset", "tiny", "--out", tmp_path / "ds", "--spp", 4], capsys)
    assert code == 0, err
    man = json.loads((tmp_path / "ds" / "manifest.json").read_text())
    assert man["preset"] == "tiny" and all((tmp_path / "ds" / s["file"]).exists() for s in man["shards"])
    assert man["config"]["spp"] == 4
    code, out, err = run(["train", "representation", "--data", tmp_path / "ds", "--out", tmp_path / "run",
                          "--epochs", 2, "--width", 16, "--depth", 2, "--batch", 1024], capsys)
    assert code == 0, err
    assert (tmp_path / "run" / "decoder.safetensors").exists()


@pytest.mark.parametrize("argv,needle", [
    (["data", "--preset", "huge", "--out", "X"], "--preset"),
    (["data", "--preset", "tiny", "--out", "X", "--spp", "0"], "--spp"),
    (["train", "representation", "--data", "/nonexistent", "--out", "R"], "manifest"),
    (["train", "representation", "--data", "D", "--out", "R", "--epochs", "0"], "--epochs"),
    (["project", "--out", "z.safetensors"], "exactly one"),
    (["project", "--samples", "s.npy", "--out", "z.npy"], ".safetensors"),
    (["project", "--merl", "/nonexistent.binary", "--out", "z.safetensors", "--decoder", "{dec}"], "no such"),
])
def test_bad_arguments_are_one_line(tmp_path, capsys, monkeypatch, decoder_file, argv, needle):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "D").mkdir()
    argv = [a.replace("{dec}", str(decoder_file)) for a in argv]
    code, _, err = run(argv, capsys)
    assert_one_line_error(code, err)
    assert needle in err


@pytest.mark.slow
def test_project_samples_and_merl(tmp_path, capsys, decoder_file):
    pairs = random_pairs(300, 4)
    f = np.abs(np.random.default_rng(1).normal(size=(300, 3))).astype(np.float32)
    np.save(tmp_path / "s.npy", np.concatenate([pairs, f], 1))
    code, out, err = run(["project", "--samples", tmp_path / "s.npy", "--out", tmp_path / "z.safetensors",
                          "--decoder", decoder_file, "--steps", 20], capsys)
    assert code == 0, err
    rep = json.loads(out)
    lat = load_latent(tmp_path / "z.safetensors", rep["decoder_id"])
    assert lat.z.shape == (3, 34)  # a code: body latent and (no) coat
    assert lat.z[:, 33].tolist() == [1.0, 1.0, 1.0]
    code, out, err = run(["project", "--samples", tmp_path / "s.npy", "--out", tmp_path / "zc.safetensors",
                          "--decoder", decoder_file, "--steps", 20, "--coat", "0.02,1.5"], capsys)
    assert code == 0, err
    coated = load_latent(tmp_path / "zc.safetensors", json.loads(out)["decoder_id"])
    assert torch.allclose(coated.z[:, 32:], torch.tensor([[0.02, 1.5]]).expand(3, 2))
    for bad in ("0.02", "0.02,9", "x,y"):
        code, _, err = run(["project", "--samples", tmp_path / "s.npy", "--out", tmp_path / "zb.safetensors",
                            "--decoder", decoder_file, "--coat", bad], capsys)
        assert_one_line_error(code, err)
        assert "--coat" in err

    c = GGXConductor(0.3, torch.tensor([0.9, 0.6, 0.3], dtype=torch.float64))
    MerlBRDF.tabulate(lambda wi, wo: c.eval(wi[:, None].expand(-1, 3, -1), wo[:, None].expand(-1, 3, -1))).save(
        tmp_path / "m.binary")
    code, out, err = run(["project", "--merl", tmp_path / "m.binary", "--out", tmp_path / "m.safetensors",
                          "--decoder", decoder_file, "--steps", 20, "--finetune", "--pairs", 512], capsys)
    assert code == 0, err
    rep = json.loads(out)
    tuned = Path(rep["decoder"])
    assert tuned.exists()
    # the latent belongs to the fine-tuned copy, not to the shared decoder
    with pytest.raises(Exception, match="belongs to decoder"):
        from nbrdf.neural.decoder import load_decoder

        load_latent(tmp_path / "m.safetensors", load_decoder(decoder_file).weights_id())
    load_latent(tmp_path / "m.safetensors", load_decoder(tuned).weights_id())


def test_bad_samples_file(tmp_path, capsys, decoder_file):
    np.save(tmp_path / "s.npy", np.zeros((10, 5), np.float32))
    code, _, err = run(["project", "--samples", tmp_path / "s.npy", "--out", tmp_path / "z.safetensors",
                        "--decoder", decoder_file], capsys)
    assert_one_line_error(code, err)
    assert "(N, 9)" in err


def test_eval_projected_with_the_shipped_weights(tmp_path, capsys):
    """The shipped decoder reproduces a rough conductor through its projected latent."""
    layer = {"type": "conductor", "roughness": 0.4, "r0": [0.95, 0.64, 0.54]}
    mat = write_material(tmp_path / "m.json", [layer])
    pairs = random_pairs(256, 9)
    np.save(tmp_path / "p.npy", pairs)
    code, _, err = run(["eval", "--material", mat, "--pairs", tmp_path / "p.npy", "--out", tmp_path / "f.npy",
                        "--method", "projected"], capsys)
    assert code == 0, err
    f = np.load(tmp_path / "f.npy")
    code, _, err = run(["eval", "--material", mat, "--pairs", tmp_path / "p.npy", "--out", tmp_path / "r.npy"], capsys)
    ref = np.load(tmp_path / "r.npy")
    cos_o = pairs[:, 5:6]
    t = lambda x: x * cos_o / (1 + x * cos_o)
    psnr = 10 * np.log10(1 / np.mean((t(f) - t(ref)) ** 2))
    assert f.shape == (256, 3) and (f >= 0).all() and psnr > 35, psnr


@pytest.mark.slow
@pytest.mark.ci_slow
def test_view_offscreen_with_the_neural_shader(tmp_path, capsys):
    from nbrdf.cli.view import main

    out = tmp_path / "lobe.npy"
    mat = write_material(tmp_path / "m.json", [{"type": "conductor", "roughness": 0.3, "r0": 0.9}])
    assert main([str(mat), "--offscreen", "--view", "lobe", "--brdf", "projected", "--out", str(out)]) == 0
    img = np.load(out)
    assert img.shape == (64, 64, 3) and img.max() > 0.1 and np.isfinite(img).all()
