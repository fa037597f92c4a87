"""Refinement (``training.refine``, ``brdf_for(material, "refined")``): the
network's code fitted further to the material's simulated body."""
from __future__ import annotations

from pathlib import Path

import pytest
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material, parse_material
from nbrdf.neural.methods import Method
from nbrdf.neural.model import default_model
from nbrdf.training import refine as R
from nbrdf.training import refined_cache as C
from nbrdf.training.brdfs import brdf_for

LOOKDEV = Path(R.__file__).parent / "sets" / "lookdev"
#: A tiny refinement: enough to exercise every part, seconds on two cores.
TINY = R.RefineConfig(budget=600.0, round_pairs=128, heldout_pairs=128, spp=8, steps=10, max_rounds=2,
                      patience=2)


@pytest.fixture(scope="module")
def model():
    return default_model()


def gold():
    return load_material(LOOKDEV / "coated-gold.json")


def test_a_cached_code_is_used_at_once(refined_cache_dir, model, monkeypatch):
    m = gold()
    z = model.material_latent(m)
    marked = z.clone()
    marked[:, 0] += 0.25  # a code no refinement makes: recognisable when read back
    st = R.RefineState(marked, network_error=1.0, error=0.5, converged=False)
    C.save_cached(m, model.decoder.weights_id(), z, st, budget=10.0)
    assert len(list(refined_cache_dir.glob("*.json"))) == 1

    def no_refinement(*a, **k):
        raise AssertionError("refined again despite a cached code")

    monkeypatch.setattr(R.Refiner, "run", no_refinement)
    b = brdf_for(m, Method.REFINED, model=model)  # default budget 10 s: served by the 10 s entry
    served = model.conserved(marked)  # a refined code's albedo is bounded as the network's (neural.energy)
    assert torch.equal(b.z, served)
    assert isinstance(b.refinement, C.CachedCode)
    # The name is not content: a renamed copy hits the same entry.
    renamed = parse_material({**_doc(m), "name": "another name"}, m.base_dir)
    assert torch.equal(brdf_for(renamed, Method.REFINED, model=model).z, served)
    # A longer budget than the entry had (and it did not converge) refines again.
    with pytest.raises(AssertionError, match="refined again"):
        brdf_for(m, Method.REFINED, model=model, budget=20.0)


def _doc(m):
    from nbrdf.neural.material import material_to_dict

    return material_to_dict(m)


def test_refinement_keeps_the_coat_and_never_returns_a_worse_code(refined_cache_dir, model):
    m = gold()
    z = model.material_latent(m)
    code, st = R.refined_code(model.decoder, m, z, TINY)
    assert code.shape == z.shape
    assert torch.equal(code[:, -2:], z[:, -2:])  # the coat is exact: never fitted
    assert st.rounds == 2 and st.error <= st.network_error  # the network's code is kept unless a round beats it
    assert len(st.history) == 3 and st.pairs == TINY.heldout_pairs + 2 * TINY.round_pairs
    assert list(refined_cache_dir.glob("*.json")), "a finished refinement is cached"


def test_a_lone_dielectric_is_its_coat_and_is_kept_exact(refined_cache_dir, model, monkeypatch):
    """A single dielectric layer is the code's coat, exact in closed form, with no body below it: the
    refinement keeps the network's code without simulating anything (it once fitted a body to the whole
    reflection on top of the coat, twice the light; held-out dielectrics HDR-FLIP 0.24 against 0.00)."""
    m = parse_material({"format": "nbrdf-material/1", "name": "glass",
                        "layers": [{"type": "dielectric", "roughness": 0.2, "ior": 1.6}]})
    monkeypatch.setattr(R, "body_values", lambda *a, **k: pytest.fail("a coat-only material was simulated"))
    z = model.material_latent(m)
    assert float(z[0, -1]) > 1.0  # the network holds the layer as the coat
    code, st = R.refined_code(model.decoder, m, z, TINY)
    assert torch.equal(code, z) and st.done and st.rounds == 0 and not st.improved
    wi = torch.nn.functional.normalize(torch.tensor([[0.3, 0.1, 0.9], [0.5, -0.2, 0.6]]), dim=-1)
    wo = torch.nn.functional.normalize(torch.tensor([[-0.3, -0.1, 0.9], [0.1, 0.4, 0.8]]), dim=-1)
    refined = brdf_for(m, Method.REFINED, model=model, budget=5.0).eval(wi, wo)
    assert torch.allclose(refined, brdf_for(m, Method.NEURAL, model=model).eval(wi, wo))
    # a conductor alone has no coat: it is refined as a body
    au = parse_material({"format": "nbrdf-material/1", "name": "au",
                         "layers": [{"type": "conductor", "roughness": 0.3, "r0": [1.0, 0.8, 0.3]}]})
    assert not R.Refiner(model.decoder, au, model.material_latent(au), TINY).coat_only


def test_a_round_cut_short_changes_nothing(model):
    m = gold()
    z = model.material_latent(m)
    r = R.Refiner(model.decoder, m, z, TINY)
    st = r.step(stop=lambda: True)
    assert st.rounds == 0 and torch.equal(st.code, z) and not st.done


def test_bad_requests_are_one_line_errors(model):
    with pytest.raises(NbrdfError, match="--budget"):
        R.RefineConfig(budget=0.0).check()
    with pytest.raises(NbrdfError, match="--budget"):
        R.RefineConfig(budget=float("nan")).check()
    with pytest.raises(NbrdfError, match="--budget"):
        brdf_for(gold(), Method.REFINED, model=model, budget=-1.0)
    with pytest.raises(NbrdfError, match="floats per channel"):
        R.Refiner(model.decoder, gold(), torch.zeros(3, 5), TINY)


def test_placed_pairs_are_unit_and_above_the_horizon():
    g = torch.Generator().manual_seed(3)
    for rough in (None, 0.02, 0.6):
        wi, wo = R.placed_pairs(500, g, rough)
        assert wi.shape == wo.shape == (500, 3)
        assert torch.allclose(wi.norm(dim=1), torch.ones(500), atol=1e-5)
        assert (wi[:, 2] > 0).all() and (wo[:, 2] > 0).all()


@pytest.mark.slow
@pytest.mark.parametrize("name", ["black-lacquer", "coated-gold"])
def test_refined_is_at_least_as_close_to_the_reference_as_neural(name, model, refined_cache_dir):
    """Render space (the lit sphere of ``nbrdf report render``, 32 pixels, 512
    paths per pixel): HDR-FLIP of the refined code against the reference is
    no larger than the network's. Two materials of the look-development set
    (the first in file order and the plainest stack); all 14 are measured by
    the report. Seeded; the refinement runs a fixed number of rounds, so the
    outcome does not depend on the machine's speed."""
    from nbrdf.imaging.flip import flip
    from nbrdf.neural.neural_brdf import latent_brdf
    from nbrdf.training.render_report import reference_render, shade, sphere_geometry

    m = load_material(LOOKDEV / f"{name}.json")
    geo = sphere_geometry(32)
    ref = reference_render(m, geo, spp=512, seed=5, progress=False)
    z = model.material_latent(m)
    cfg = R.RefineConfig(budget=600.0, max_rounds=2, patience=2, seed=1)
    code, st = R.refined_code(model.decoder, m, z, cfg, cache=False)
    f_neural = flip(ref.image, shade(latent_brdf(model.decoder, z, m).eval, geo))[0]
    f_refined = flip(ref.image, shade(latent_brdf(model.decoder, code, m).eval, geo))[0]
    assert f_refined <= f_neural, (f_refined, f_neural, st.history)


class WorkClock:
    """A clock that only work moves (the suite reads no wall clock): each
    simulated pair costs ``pair`` seconds, each fitting step ``step_pair``
    seconds per fitted pair; reading it costs nothing."""

    def __init__(self):
        self.t, self.pair, self.step_pair = 0.0, 0.0, 0.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def work_clock(monkeypatch):
    """A ``WorkClock`` charged by a stand-in walk (a smooth body, no paths) and by the fit's steps."""
    clock = WorkClock()
    real_project = R.project

    def simulated(material, wi, wo, spp, seed):
        clock.t += clock.pair * wi.shape[0]
        return (0.05 + 0.2 * wi[:, 2:3] * wo[:, 2:3]).expand(-1, 3).float().contiguous()

    def charged(dec, wi, wo, f, cfg, z0=None, weight=None, coat=None, stop=None):
        def hook(i):
            if stop is not None and stop(i):
                return True
            clock.t += clock.step_pair * wi.shape[1]  # the step about to run
            return False

        return real_project(dec, wi, wo, f, cfg, z0=z0, weight=weight, coat=coat, stop=hook)

    monkeypatch.setattr(R, "body_values", simulated)
    monkeypatch.setattr(R, "project", charged)
    return clock


#: A small refinement whose work the clock charges: held-out set 256 pairs, rounds of 128 pairs and 30 steps.
SMALL = dict(round_pairs=128, heldout_pairs=256, steps=30, fit_pairs=384, max_rounds=3, chunk_pairs=32,
             min_heldout_pairs=64, min_round_pairs=32, min_steps=10, spp=8)


def _budgeted(model, clock, budget, **cfg):
    m = load_material(LOOKDEV / "tinted-silver.json")
    config = R.RefineConfig(budget=budget, **{**SMALL, **cfg})
    r = R.Refiner(model.decoder, m, model.material_latent(m), config, clock=clock)
    return r, r.run()


@pytest.mark.parametrize("pair, budget", [(0.02, 3.0), (0.02, 6.0), (0.002, 1.0), (0.0005, 4.0), (0.05, 0.5)])
def test_a_refinement_returns_within_its_budget(model, work_clock, pair, budget):
    """Whatever the walk's speed (a long-path material under load: 20-50 ms
    a pair, 5 s for the held-out set alone; a quick one: 0.5 ms), the work is
    sized by its measured cost: the refinement returns within its budget
    plus the one unit it could not measure before running it (the first,
    small, probe chunk). A fitting step costs 10 ms at 384 pairs."""
    work_clock.pair, work_clock.step_pair = pair, 0.01 / 384
    r, st = _budgeted(model, work_clock, budget)
    margin = r.cfg.probe_pairs * pair + 0.01  # the probe chunk, and the first step of a fit that always runs
    assert st.done and st.seconds <= work_clock.t <= budget + margin, (work_clock.t, st.rounds, st.pairs)
    assert st.error <= st.network_error


def test_a_slow_walk_gets_a_smaller_held_out_set_and_smaller_rounds(model, work_clock):
    """20 ms a pair, 4 s: the held-out set (256 pairs, 5.1 s) and a round
    (128 pairs, 2.6 s) cannot both fit; the held-out set stops at its share
    of the budget (past its minimum) and a smaller round sized to the rest
    still runs."""
    work_clock.pair, work_clock.step_pair = 0.02, 0.01 / 384
    r, st = _budgeted(model, work_clock, 4.0)
    held = r._heldout.wi.shape[0]
    assert r.cfg.min_heldout_pairs <= held < r.cfg.heldout_pairs
    assert st.rounds == 1 and 0 < st.pairs - held < r.cfg.round_pairs


def test_a_quick_walk_runs_full_rounds(model, work_clock):
    """0.1 ms a pair: the full held-out set and full rounds (the sizing only bites when time is short)."""
    work_clock.pair, work_clock.step_pair = 0.0001, 0.001 / 384
    r, st = _budgeted(model, work_clock, 10.0, max_rounds=2, patience=5)
    assert r._heldout.wi.shape[0] == r.cfg.heldout_pairs
    assert st.rounds == 2 and st.pairs == r.cfg.heldout_pairs + 2 * r.cfg.round_pairs


def test_a_cancel_during_the_simulation_is_taken_between_chunks(model, work_clock):
    """A stop asked while the held-out set is simulated pauses it within one chunk; resuming finishes it."""
    work_clock.pair = 0.001
    m = gold()
    cfg = R.RefineConfig(budget=60.0, **SMALL)
    r = R.Refiner(model.decoder, m, model.material_latent(m), cfg, clock=work_clock)
    calls = []
    st = r.start(stop=lambda: calls.append(1) or len(calls) > 3)
    assert [h[0].shape[0] for h in r._held] == [8, 16, 32] and r._heldout is None and st.error == float("inf") and not st.done
    st = r.start()
    assert r._heldout.wi.shape[0] == cfg.heldout_pairs and st.error < float("inf")
