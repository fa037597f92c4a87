"""``nbrdf eval --method refined`` and its ``--budget`` flag."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from test_cli import DEFAULT, assert_one_line_error, random_pairs, run


@pytest.mark.parametrize("budget", ["nan", "inf", "-inf", "0", "-3", "ten"])
def test_a_bad_budget_is_one_line_and_exit_2(tmp_path, capsys, budget):
    np.save(tmp_path / "p.npy", random_pairs(4, 0))
    code, _, err = run(["eval", "--material", DEFAULT, "--pairs", tmp_path / "p.npy", "--out", tmp_path / "f.npy",
                        "--method", "refined", f"--budget={budget}"], capsys)
    assert_one_line_error(code, err)
    assert "--budget" in err
    assert not (tmp_path / "f.npy").exists()


def test_eval_refined_writes_the_cached_code_values(tmp_path, capsys, monkeypatch):
    """With a cached refined code for the material, ``eval --method refined``
    writes that code's values at once (no refinement: the cache serves the budget)."""
    from nbrdf.neural.material import load_material
    from nbrdf.neural.model import default_model
    from nbrdf.training import refine as R
    from nbrdf.training import refined_cache as C

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    model = default_model()
    m = load_material(DEFAULT)
    start = model.material_latent(m)
    z = start.clone()
    z[:, 3] -= 0.3
    C.save_cached(m, model.decoder.weights_id(), start, R.RefineState(z, 1.0, 0.5, converged=True), budget=2.0)
    monkeypatch.setattr(R.Refiner, "run", lambda *a, **k: pytest.fail("refined again despite a converged code"))
    pairs = random_pairs(64, 2)
    np.save(tmp_path / "p.npy", pairs)
    code, _, err = run(["eval", "--material", DEFAULT, "--pairs", tmp_path / "p.npy", "--out", tmp_path / "f.npy",
                        "--method", "refined", "--budget", "30"], capsys)
    assert code == 0, err
    got = np.load(tmp_path / "f.npy")
    want = model.decoder.eval_rgb(z, torch.from_numpy(pairs[:, :3]), torch.from_numpy(pairs[:, 3:])).numpy()
    assert np.allclose(got, want, rtol=1e-5, atol=1e-7)
