"""Operation networks train through the decoder, land in one checked bundle,
and drive the full neural path."""
from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest
import torch
from safetensors import safe_open
from safetensors.torch import save_file

from nbrdf.neural.decoder import DEFAULT_WEIGHTS
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import parse_material
from nbrdf.neural.model import load_model
from nbrdf.neural.neural_brdf import material_brdfs
from nbrdf.training.dataset import DataConfig, generate
from nbrdf.training.train_operations import OpsConfig, train_layering, train_leaf
from nbrdf.training.train_sampler import train_sampler

STACKS = DataConfig(counts=dict(conductor=0, dielectric=0, two_layer=6, three_layer=3, diffuse_base=3),
                    val_counts=dict(conductor=0, dielectric=0, two_layer=2, three_layer=1, diffuse_base=1),
                    pairs=64, spp=8, shard_size=6)
THREE = parse_material({"format": "nbrdf-material/1", "name": "t3", "layers": [
    {"type": "dielectric", "roughness": 0.1, "ior": 1.5}, {"type": "medium", "albedo": [0.9, 0.5, 0.2], "sigma_t": 1},
    {"type": "dielectric", "roughness": 0.3, "ior": 1.2}, {"type": "medium", "albedo": 0.8, "sigma_t": 0.5},
    {"type": "conductor", "roughness": 0.2, "r0": [0.9, 0.8, 0.4]}]})


@pytest.fixture(scope="module")
def bundles(tmp_path_factory):
    root = tmp_path_factory.mktemp("ops")
    generate(root / "data", STACKS, progress=False)
    leaf = train_leaf(OpsConfig(decoder=str(DEFAULT_WEIGHTS), out=str(root / "leaf"), steps=100, batch=16,
                                pairs=64), progress=False)
    lay = train_layering(OpsConfig(decoder=str(leaf), out=str(root / "lay"), steps=60, batch=8, pairs=32,
                                   data=str(root / "data"), recursion_steps=30, width=32), progress=False)
    smp = train_sampler(OpsConfig(decoder=str(lay), out=str(root / "smp"), steps=60, batch=16, pairs=32),
                        progress=False)
    return root, leaf, lay, smp


def test_leaf_training_lowers_the_loss(bundles):
    root, leaf, _, _ = bundles
    hist = json.loads((root / "leaf" / "leaf_metrics.json").read_text())["history"]["train"]
    assert len(hist) == 2 and hist[1] < 0.8 * hist[0]
    assert (root / "leaf" / "leaf_curves.png").stat().st_size > 1000
    m = load_model(leaf)
    assert m.leaf is not None and m.layering is None


def test_the_bundle_drives_the_full_path_for_any_stack(bundles):
    _, _, _, smp = bundles
    m = load_model(smp)
    z = m.material_latent(THREE)
    assert z.shape == (3, 34) and bool(torch.isfinite(z).all())
    assert not torch.allclose(z[0], z[2])  # colour reaches the latents
    top = THREE.layers[0]
    assert torch.allclose(z[:, 32:], torch.tensor([[top.roughness, top.ior]]).expand(3, 2))  # the exact coat
    sigma, w = m.proxy(z)
    assert 0.003 <= sigma <= 2.0 and 0.02 <= w <= 0.98
    wi = torch.nn.functional.normalize(torch.tensor([[0.3, 0.1, 0.9]]).expand(256, 3), dim=-1)
    for b in material_brdfs(THREE, m):
        s = b.sample(wi, torch.rand(256, 3, generator=torch.Generator().manual_seed(0)))
        ok = s.pdf > 0
        assert torch.allclose(s.pdf[ok], b.pdf(wi[ok], s.w[ok]), rtol=1e-5)
        assert torch.allclose(s.f[ok], b.eval(wi[ok], s.w[ok]), rtol=1e-5)


def test_missing_networks_are_named(bundles):
    _, leaf, _, _ = bundles
    with pytest.raises(NbrdfError, match="no layering network"):
        load_model(leaf).material_latent(THREE)


def test_operations_of_another_decoder_are_refused(bundles, tmp_path):
    _, _, _, smp = bundles
    with safe_open(str(smp), framework="pt") as fh:
        meta = fh.metadata()
        tensors = {k: fh.get_tensor(k) for k in fh.keys()}
    ops = json.loads(meta["operations"])
    ops["decoder_id"] = "0" * 16
    meta["operations"] = json.dumps(ops)
    save_file(tensors, str(tmp_path / "bad.safetensors"), metadata=meta)
    with pytest.raises(NbrdfError, match="trained for decoder 0000000000000000"):
        load_model(tmp_path / "bad.safetensors")


def test_a_checkpoint_of_other_settings_is_refused(bundles):
    root, leaf, _, _ = bundles
    with pytest.raises(NbrdfError, match="other settings"):
        train_leaf(OpsConfig(decoder=str(DEFAULT_WEIGHTS), out=str(root / "leaf"), steps=101, batch=16, pairs=64),
                   progress=False)


def test_layering_fits_the_monte_carlo_mean_on_request(bundles):
    """``--loss mean`` trains on ``unbiased_error`` (lower on its own error than
    the start) and names a bad choice in one line."""
    root, leaf, lay, _ = bundles
    # no recursion steps: the two halves' mean losses then measure the same objective (three-layer stacks mixed
    # into the second half alone would raise it whatever the training does)
    cfg = OpsConfig(decoder=str(lay), out=str(root / "lay_mean"), steps=100, batch=8, pairs=32,
                    data=str(root / "data"), recursion_steps=0, width=32, loss="mean")
    out = train_layering(cfg, progress=False)
    metrics = json.loads((out.parent / "layering_metrics.json").read_text())
    assert all(math.isfinite(v) for v in metrics["val_loss"].values())
    assert metrics["history"]["train"][-1] < metrics["history"]["train"][0]
    with pytest.raises(NbrdfError, match="--loss"):
        train_layering(replace(cfg, out=str(root / "lay_bad"), loss="median"), progress=False)


def test_layering_shape_and_loss_scale_are_chosen(bundles):
    """``--depth`` sets the layering network's hidden layers (recorded in the
    bundle); ``--loss-scale`` must not be negative."""
    root, leaf, _, _ = bundles
    cfg = OpsConfig(decoder=str(leaf), out=str(root / "lay_deep"), steps=20, batch=8, pairs=32,
                    data=str(root / "data"), recursion_steps=10, width=16, depth=5, loss_scale=2e-4)
    model = load_model(train_layering(cfg, progress=False))
    assert model.layering.spec.depth == 5 and model.layering.spec.width == 16
    with pytest.raises(NbrdfError, match="--loss-scale"):
        train_layering(replace(cfg, out=str(root / "lay_neg"), loss_scale=-1.0), progress=False)


def test_a_basic_bundle_is_fine_tuned_onto_the_slab_features(bundles):
    """``medium="slab"`` on a bundle whose network takes the basic features
    fine-tunes that network widened (its weights, zeros on the added inputs),
    not a fresh one, and the bundle records the feature set."""
    root, _, lay, _ = bundles
    old = load_model(lay).layering
    cfg = OpsConfig(decoder=str(lay), out=str(root / "lay_slab"), steps=5, batch=8, pairs=32, lr=1e-4,
                    data=str(root / "data"), recursion_steps=2, width=32, medium="slab")
    new = load_model(train_layering(cfg, progress=False)).layering
    assert new.spec.medium == "slab" and new.spec.inputs == old.spec.inputs + 3
    w_old, w_new = old.mlp.net[0].weight, new.mlp.net[0].weight
    assert (w_new[:, :-3] - w_old).abs().max() < 1e-3 < w_old.abs().mean()  # 5 Adam steps of 1e-4 from the old
    assert w_new[:, -3:].abs().max() < 1e-3
    fast = load_model(train_layering(replace(cfg, out=str(root / "lay_slab_fast"), medium_lr_scale=10.0),
                                     progress=False)).layering.mlp.net[0].weight
    assert fast[:, -3:].abs().max() > 3 * w_new[:, -3:].abs().max()  # Adam's step on the added weights, x10
    assert (fast[:, :-3] - w_old).abs().max() < 1e-3  # the others' step unchanged
    with pytest.raises(NbrdfError, match="--medium-lr-scale"):
        train_layering(replace(cfg, out=str(root / "lay_slab_bad"), medium_lr_scale=0.0), progress=False)


@pytest.mark.slow
@pytest.mark.ci_slow
def test_moving_average_of_weights_is_shipped_and_survives_a_resume(bundles, monkeypatch):
    """``--ema``: the bundle holds the average of the weights, not the last
    step's; a run stopped at a checkpoint and resumed ends with the same
    average as one that ran through; a decay outside [0, 1) is one line."""
    root, _, lay, _ = bundles
    cfg = OpsConfig(decoder=str(lay), out=str(root / "smp_ema"), steps=500, batch=8, pairs=16, ema=0.99)
    through = load_model(train_sampler(cfg, progress=False)).sampler.state_dict()
    plain = load_model(train_sampler(replace(cfg, out=str(root / "smp_plain"), ema=0.0), progress=False))
    diff = max((through[k] - v).abs().max().item() for k, v in plain.sampler.state_dict().items())
    assert diff > 1e-4  # the average is not the last step's weights

    import nbrdf.training.train_sampler as ts

    real = ts.run_loop  # the shared loop, as the sampler's module holds it

    def stop_at_260(name, c, modules, total, step, validate, progress, rng):
        def failing(s):
            if s == 260:  # after the checkpoint at 250: steps 250-259 are lost and redone
                raise KeyboardInterrupt
            return step(s)
        return real(name, c, modules, total, failing, validate, progress, rng=rng)

    resumed = replace(cfg, out=str(root / "smp_ema_resumed"))
    monkeypatch.setattr(ts, "run_loop", stop_at_260)
    with pytest.raises(KeyboardInterrupt):
        train_sampler(resumed, progress=False)
    monkeypatch.setattr(ts, "run_loop", real)
    again = load_model(train_sampler(resumed, progress=False)).sampler.state_dict()
    for k, v in through.items():
        assert torch.allclose(again[k], v, atol=1e-6), k
    with pytest.raises(NbrdfError, match="--ema"):
        train_sampler(replace(cfg, out=str(root / "smp_bad"), ema=1.0), progress=False)


def test_relative_loss_scale_follows_each_stack_brightness(bundles):
    """``--relative-scale k``: a stack's loss scale is k times its mean body
    value f cos (darker stacks get smaller scales, so their relative errors
    count); the run trains and a negative value is one line."""
    from nbrdf.training.train_operations import _StackData

    root, leaf, _, _ = bundles
    data = _StackData(str(root / "data"), "train", 1e-3, "rusink5", relative=0.05)
    level = (data.body * data.cos_o).mean(1)
    assert torch.allclose(data.scale[:, 0], (0.05 * level).clamp_min(1e-6))
    order = level.argsort()
    assert data.scale[order[0], 0] < data.scale[order[-1], 0]
    fixed = _StackData(str(root / "data"), "train", 1e-3, "rusink5")
    assert torch.all(fixed.scale == 1e-3) and not torch.allclose(fixed.target, data.target)
    cfg = OpsConfig(decoder=str(leaf), out=str(root / "lay_rel"), steps=40, batch=8, pairs=32,
                    data=str(root / "data"), recursion_steps=20, width=16, relative_scale=0.05, loss="mean")
    metrics = json.loads((train_layering(cfg, progress=False).parent / "layering_metrics.json").read_text())
    assert all(math.isfinite(v) for v in metrics["val_loss"].values())
    with pytest.raises(NbrdfError, match="--relative-scale"):
        train_layering(replace(cfg, out=str(root / "lay_rel_bad"), relative_scale=-0.1), progress=False)


def test_the_f82_part_adds_or_fine_tunes_the_correction_and_keeps_the_rest(bundles):
    """``--part f82`` on a bundle from before the tint adds the correction (plain conductors' latents unchanged,
    the layering network kept); on a bundle that has one, it fine-tunes that one alone."""
    from nbrdf.neural.leaf import F82, LEAF_PARAMS, LeafEncoders
    from nbrdf.neural.model import save_model

    root, _, lay, _ = bundles
    m = load_model(lay)
    old = LeafEncoders({k: m.leaf.specs[k] for k in LEAF_PARAMS})
    for k in LEAF_PARAMS:
        old.nets[k].load_state_dict(m.leaf.nets[k].state_dict())
    m.leaf = old
    save_model(m, root / "no_f82.safetensors", like=lay)
    out = train_leaf(_f82_config(root / "no_f82.safetensors", root / "f82a"), progress=False)
    a = load_model(out)
    assert a.leaf.has_f82 and a.layering is not None
    assert torch.equal(a.leaf.conductor(0.3, 0.7), old.conductor(0.3, 0.7))  # a tint of 1: the old latent
    assert not torch.equal(a.leaf.conductor(0.3, 0.7, 0.2), old.conductor(0.3, 0.7))
    b = load_model(train_leaf(_f82_config(out, root / "f82b"), progress=False))
    changed = [not torch.equal(p, q) for p, q in zip(a.leaf.nets[F82].parameters(), b.leaf.nets[F82].parameters())]
    assert any(changed)  # the existing correction is trained further, not frozen
    for k in LEAF_PARAMS:
        assert all(torch.equal(p, q) for p, q in zip(a.leaf.nets[k].parameters(), b.leaf.nets[k].parameters()))


def test_the_bare_part_trains_a_lone_conductors_pair_and_keeps_every_other_network(bundles):
    """``--part bare`` (decision 124) starts a lone conductor's pair at the conductor's own (the same latents),
    trains only that pair, and keeps the layering network; a bundle without the F82 correction is refused in
    one line."""
    from nbrdf.neural.leaf import BARE, BARE_F82, LEAF_PARAMS, LeafEncoders
    from nbrdf.neural.model import save_model
    from nbrdf.training.bare_conductor import bare_encoders

    root, _, lay, _ = bundles
    m = load_model(lay)
    start = bare_encoders(m)
    assert torch.equal(start.conductor(0.3, 0.7, 0.4, bare=True), m.leaf.conductor(0.3, 0.7, 0.4))
    a = load_model(train_leaf(_f82_config(lay, root / "bare_a", part="bare"), progress=False))
    assert a.leaf.has_bare and a.layering is not None
    assert torch.equal(a.leaf.conductor(0.3, 0.7, 0.4), m.leaf.conductor(0.3, 0.7, 0.4))
    assert not torch.equal(a.leaf.conductor(0.3, 0.7, 0.4, bare=True), m.leaf.conductor(0.3, 0.7, 0.4))
    for k in m.leaf.nets:
        assert all(torch.equal(p, q) for p, q in zip(a.leaf.nets[k].parameters(), m.leaf.nets[k].parameters()))
    for name, p in m.layering.state_dict().items():
        assert torch.equal(p, a.layering.state_dict()[name]), name
    assert {BARE, BARE_F82} <= set(a.leaf.nets)
    old = LeafEncoders({k: m.leaf.specs[k] for k in LEAF_PARAMS})
    m.leaf = old
    save_model(m, root / "no_f82_bare.safetensors", like=lay)
    with pytest.raises(NbrdfError, match="^a bare pair needs encoders with the F82 correction"):
        train_leaf(_f82_config(root / "no_f82_bare.safetensors", root / "bare_b", part="bare"), progress=False)


def _f82_config(decoder, out, part="f82"):
    from nbrdf.training.train_operations import LeafConfig

    return LeafConfig(decoder=str(decoder), out=str(out), steps=20, batch=8, pairs=32, part=part)


def test_the_energy_term_measures_band_albedos():
    """``energy_quadrature`` turns a data set's pairs into band albedos: a Lambertian body of albedo 0.4
    reads 0.4 in every incidence band (within 3 %, 2^15 pairs), and a decoded body 10 % too bright costs
    about (0.04 / (0.4 + 0.01))^2; equal values cost 0."""
    from nbrdf.training.dataset import sample_pairs
    from nbrdf.training.train_operations import ENERGY_BANDS, energy_error, energy_quadrature

    wi, wo = sample_pairs(1 << 15, torch.Generator().manual_seed(5))
    w, band = energy_quadrature(wi[None], wo[None])
    f = torch.full((1, wi.shape[0]), 0.4 / math.pi)
    for k in range(len(ENERGY_BANDS) - 1):
        sel = band[0] == k
        est = (w[0] * f[0] * sel).sum() / wi.shape[0]
        assert abs(est.item() - 0.4) < 0.012, (k, est.item())
    assert energy_error(f, f, f, w, band).item() == 0.0
    e = energy_error(1.1 * f, f, f, w, band).item()
    assert abs(e - (0.04 / 0.41) ** 2) < 0.1 * (0.04 / 0.41) ** 2, e


def test_deep_stacks_join_the_recursion_and_the_energy_term_trains(bundles):
    """With a data set of deep stacks (3 and 4 coats) beside the usual ones, the recursion phase trains on
    them too (validated per class), and ``--energy-weight`` adds the energy term, reported per class;
    a negative weight is one line."""
    root, leaf, _, _ = bundles
    deep = DataConfig(counts=dict(four_layer=3, five_layer=3), val_counts=dict(four_layer=1, five_layer=1),
                      pairs=64, spp=8, shard_size=6)
    generate(root / "deep", deep, progress=False)
    cfg = OpsConfig(decoder=str(leaf), out=str(root / "lay_energy"), steps=20, batch=8, pairs=32,
                    data=f"{root / 'data'},{root / 'deep'}", recursion_steps=10, width=32, energy_weight=0.5)
    out = train_layering(cfg, progress=False)
    val = json.loads((out.parent / "layering_metrics.json").read_text())["val_loss"]
    assert {"four_layer", "five_layer", "four_layer_energy", "two_layer_energy"} <= set(val)
    assert all(math.isfinite(v) for v in val.values())
    with pytest.raises(NbrdfError, match="--energy-weight"):
        train_layering(replace(cfg, out=str(root / "lay_neg_e"), energy_weight=-1.0), progress=False)


def test_a_new_layering_network_takes_every_depth(bundles):
    # A layering run from a depth-routed bundle (route_depth) layers every depth with its new
    # network: the old deep network was trained beside the old one, not beside this one.
    from nbrdf.training.train_operations import route_depth

    root, _, lay, _ = bundles
    routed = route_depth(lay, lay, root / "routed.safetensors")
    assert load_model(routed).layering_deep is not None
    cfg = OpsConfig(decoder=str(routed), out=str(root / "lay_from_routed"), steps=4, batch=4, pairs=16,
                    data=str(root / "data"), recursion_steps=0, width=32)
    m = load_model(train_layering(cfg, progress=False))
    assert m.layering is not None and m.layering_deep is None and "layering_deep" not in m.trained_on
