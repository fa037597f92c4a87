"""The depth set: stacks of 2, 3 and 4 layers that differ by their extra coats only."""
from __future__ import annotations

from nbrdf.neural.layer_kinds import CONDUCTOR, DIELECTRIC, MEDIUM
from nbrdf.training.evaluate import DEPTH_SEED, HELDOUT_SEED, depth_set


def test_depth_set_nests_its_stacks_and_is_fixed():
    s = depth_set(3)
    assert [c for c, _ in s] == ["depth2"] * 3 + ["depth3"] * 3 + ["depth4"] * 3
    by = {m.name: m for _, m in s}
    for i in range(3):
        d2, d3, d4 = (by[f"depth{d}-{i:03d}"].layers for d in (2, 3, 4))
        assert (len(d2), len(d3), len(d4)) == (3, 5, 7)
        assert [x.type for x in d4] == [DIELECTRIC, MEDIUM] * 3 + [CONDUCTOR]
        # one more coat just above the base: the shallower stack's coats and base are kept
        assert d3[:2] == d2[:2] and d4[:4] == d3[:4] and d2[-1] == d3[-1] == d4[-1]
    assert depth_set(3) == s  # fixed seed
    assert depth_set(3, seed=DEPTH_SEED + 1) != s and DEPTH_SEED != HELDOUT_SEED
