"""nbrdf eval / lobe --method neural, nbrdf sample, nbrdf bench operations,
nbrdf report interpolation, on the shipped bundle."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from test_cli import DEFAULT, assert_one_line_error, random_pairs, run, write_material

from nbrdf.neural.model import default_model
from nbrdf.neural.sampling import coated_pdf

THREE = [{"type": "dielectric", "roughness": 0.1, "ior": 1.5}, {"type": "medium", "albedo": 0.5, "sigma_t": 0.2},
         {"type": "dielectric", "roughness": 0.3, "ior": 1.3}, {"type": "medium", "albedo": 0.5, "sigma_t": 0.2},
         {"type": "diffuse", "albedo": [0.8, 0.4, 0.1]}]


def test_shipped_bundle_has_every_operation():
    m = default_model()
    assert m.leaf is not None and m.layering is not None and m.sampler is not None


def test_eval_neural_runs_the_full_path_for_a_three_layer_stack(tmp_path, capsys):
    mat = write_material(tmp_path / "m.json", THREE)
    np.save(tmp_path / "p.npy", random_pairs(500, 1))
    code, out, err = run(["eval", "--material", mat, "--pairs", tmp_path / "p.npy", "--out", tmp_path / "f.npy",
                          "--method", "neural"], capsys)
    assert code == 0, err
    f = np.load(tmp_path / "f.npy")
    assert f.shape == (500, 3) and f.dtype == np.float32 and np.isfinite(f).all() and (f >= 0).all()
    assert np.median(f[:, 0] / f[:, 2]) > 2  # away from the grey highlight, the orange base shows through


def test_lobe_neural_is_the_eval_on_the_lobe_grid(tmp_path, capsys):
    code, out, err = run(["lobe", "--material", DEFAULT, "--theta-i", 30, "--method", "neural",
                          "--out", tmp_path / "l.npy"], capsys)
    assert code == 0, err
    img = np.load(tmp_path / "l.npy")
    assert img.shape == (64, 64, 3) and img.max() > 0.1
    # the same directions through `nbrdf eval`: the lobe is f cos(theta_o) on the disk, zero outside
    from nbrdf.neural.geometry import incidence, lobe_grid

    wo, mask = (t.numpy() for t in lobe_grid(64))
    d = wo[mask]
    wi = np.broadcast_to(incidence(30.0).numpy(), d.shape)
    np.save(tmp_path / "p.npy", np.concatenate([wi, d], 1).astype(np.float32))
    code, out, err = run(["eval", "--material", DEFAULT, "--pairs", tmp_path / "p.npy", "--out", tmp_path / "f.npy",
                          "--method", "neural"], capsys)
    assert code == 0, err
    f = np.load(tmp_path / "f.npy")
    np.testing.assert_allclose(img[mask], f * d[:, 2:3], rtol=1e-4, atol=1e-6)
    assert (img[~mask] == 0).all()


def test_sample_writes_directions_and_their_pdf(tmp_path, capsys):
    """The material's sampler: the coat's lobe mixed with the body's proxy, its exact mixture pdf."""
    code, out, err = run(["sample", "--material", DEFAULT, "--theta-i", 45, "--n", 4000, "--out",
                          tmp_path / "s.npy"], capsys)
    assert code == 0, err
    s = np.load(tmp_path / "s.npy")
    assert s.shape == (4000, 4) and s.dtype == np.float32
    info = json.loads(out)
    ok = s[:, 3] > 0
    assert ok.mean() > 0.5 and np.allclose(np.linalg.norm(s[:, :3], axis=1), 1, atol=1e-5)
    import torch

    t = math.radians(45)
    wi = torch.tensor([[math.sin(t), 0.0, math.cos(t)]]).expand(int(ok.sum()), 3)
    pdf = coated_pdf(wi, torch.from_numpy(s[ok, :3]), torch.tensor(info["coat"]), torch.tensor(info["sigma"]),
                     torch.tensor(info["w"]))
    assert np.allclose(pdf.numpy(), s[ok, 3], rtol=1e-4)
    assert info["coat"][1] > 1  # the default material has a clear coat
    assert (s[~ok, 2] <= 0).all()  # a failed sample is one below the horizon


@pytest.mark.parametrize("argv,needle", [
    (["sample", "--material", DEFAULT, "--theta-i", 95, "--n", 10, "--out", "x.npy"], "--theta-i"),
    (["sample", "--material", DEFAULT, "--theta-i", 10, "--n", 0, "--out", "x.npy"], "--n"),
    (["sample", "--material", "missing.json", "--theta-i", 10, "--n", 10, "--out", "x.npy"], "missing.json"),
])
def test_sample_bad_input_is_one_line(tmp_path, capsys, argv, needle):
    code, out, err = run(argv, capsys)
    assert_one_line_error(code, err)
    assert needle in err


def test_bench_operations_reports_latencies(capsys):
    code, out, err = run(["bench", "operations", "--repeats", 40], capsys)
    assert code == 0, err
    r = json.loads(out)
    assert r["layering_rgb"]["p50_ms"] > 0 and r["leaf_conductor_rgb"]["p99_ms"] >= r["leaf_conductor_rgb"]["p50_ms"]


def test_report_interpolation_draws_the_figure(tmp_path, capsys):
    a = write_material(tmp_path / "a.json", [{"type": "conductor", "roughness": 0.05, "r0": 0.9}], "smooth")
    b = write_material(tmp_path / "b.json", [{"type": "conductor", "roughness": 0.6, "r0": 0.9}], "rough")
    code, out, err = run(["report", "interpolation", "--a", a, "--b", b, "--out", tmp_path / "i.png"], capsys)
    assert code == 0, err
    r = json.loads(out)
    assert (tmp_path / "i.png").stat().st_size > 5000
    # a latent blend narrows the highlight gradually: its peak falls monotonically from smooth to rough
    assert all(x >= y for x, y in zip(r["latent_peak"], r["latent_peak"][1:]))


@pytest.mark.parametrize("flags, words", [(["--set", "deep"], "heldout, lookdev or depth"),
                                          (["--set", "depth", "--per-depth", 0], "must be positive"),
                                          (["--max-spp", 0], "must be positive"),
                                          (["--methods", "neural,exact"], "--methods")])
def test_report_operations_rejects_a_bad_set_or_reference_setting(tmp_path, capsys, flags, words):
    code, out, err = run(["report", "operations", "--refs", tmp_path / "r", "--out", tmp_path / "o"] + flags, capsys)
    assert_one_line_error(code, err)
    assert words in err
    assert not (tmp_path / "r").exists()  # nothing built before the settings are checked
