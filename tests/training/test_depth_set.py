"""The depth set: stacks of 2 to 6 layers that differ by their extra coats only."""
from __future__ import annotations

import hashlib
import json

from nbrdf.neural.layer_kinds import CONDUCTOR, DIELECTRIC, MEDIUM
from nbrdf.neural.material import material_to_dict
from nbrdf.training.evaluate import DEPTH_SEED, HELDOUT_SEED, depth_set


def test_depth_set_nests_its_stacks_and_is_fixed():
    s = depth_set(3)
    assert [c for c, _ in s] == [f"depth{d}" for d in range(2, 7) for _ in range(3)]
    by = {m.name: m for _, m in s}
    for i in range(3):
        d2, d3, d4, d5, d6 = (by[f"depth{d}-{i:03d}"].layers for d in range(2, 7))
        assert [len(x) for x in (d2, d3, d4, d5, d6)] == [3, 5, 7, 9, 11]
        assert [x.type for x in d6] == [DIELECTRIC, MEDIUM] * 5 + [CONDUCTOR]
        # one more coat just above the base: the shallower stack's coats and base are kept
        assert d3[:2] == d2[:2] and d4[:4] == d3[:4] and d5[:6] == d4[:6] and d6[:8] == d5[:8]
        assert d2[-1] == d3[-1] == d4[-1] == d5[-1] == d6[-1]
    assert depth_set(3) == s  # fixed seed
    assert depth_set(3, seed=DEPTH_SEED + 1) != s and DEPTH_SEED != HELDOUT_SEED


def test_depth_set_keeps_its_stacks_of_2_to_4_layers():
    """The stacks of 2 to 4 layers are those drawn before depths 5 and 6 were added (hashes of that code's
    output), so earlier depth figures stay comparable."""
    def digest(items):
        blob = json.dumps([(c, material_to_dict(m)) for c, m in items], sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]

    for n, want in ((3, "674670ee42f1a742"), (8, "8d771d7dafdf2f37")):
        assert digest([x for x in depth_set(n) if x[0] in ("depth2", "depth3", "depth4")]) == want
