"""Shared pieces of the fuzz tests: the example budget, the pass check, and a
hypothesis strategy that edits a JSON document anywhere in its tree."""
from __future__ import annotations

import copy
import json
import os

import fuzz
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

#: Inputs per hypothesis test and per byte-mutation campaign (``make fuzz`` raises both).
EXAMPLES = int(os.environ.get("NBRDF_FUZZ_EXAMPLES", "40"))
MUTATIONS = int(os.environ.get("NBRDF_FUZZ_MUTATIONS", "150"))

#: The settings of every structure-aware test: derandomized (the same inputs on every run), no deadline
#: (the worker is shared with a loaded machine), and the worker fixture reused across examples.
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                                       HealthCheck.data_too_large])


def check(worker, fmt: str, data: bytes) -> str:
    """Runs one input; fails on anything but a load or a one-line NbrdfError. Returns the outcome."""
    outcome, detail = worker.run(fmt, data)
    assert outcome in fuzz.PASSING, f"{fmt}: {outcome}\n{detail}"
    return outcome


def check_campaign(worker, fmt: str, seed: int = 0) -> None:
    """The seeds load, and ``MUTATIONS`` byte-level mutations of them pass."""
    for s in fuzz.seeds(fmt):
        outcome, detail = worker.run(fmt, s)
        assert outcome == "ok", f"{fmt}: a valid seed file does not load: {detail}"
    rep = fuzz.campaign(fmt, MUTATIONS, seed, worker)
    assert rep.failed == 0, "\n".join(f"{o}: {d}" for o, d, _ in rep.findings[:3])


json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-2**70, 2**70) | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=8)


@st.composite
def edited_json(draw, doc):
    """``doc`` with one to three edits at random places: a value replaced by any
    JSON value, a key or item removed, an unknown key added."""
    doc = copy.deepcopy(doc)
    for _ in range(draw(st.integers(1, 3))):
        parent, key = None, None
        node = doc
        while isinstance(node, (dict, list)) and node and draw(st.integers(0, 3)) > 0:
            keys = list(node) if isinstance(node, dict) else list(range(len(node)))
            parent, key = node, keys[draw(st.integers(0, len(keys) - 1))]
            node = node[key]
        action = draw(st.sampled_from(["replace", "delete", "add"]))
        if parent is None:
            if action == "replace":
                doc = draw(json_values)
            continue
        if action == "replace":
            parent[key] = draw(json_values)
        elif action == "delete":
            del parent[key]
        elif isinstance(parent, dict):
            parent[draw(st.text(max_size=8))] = draw(json_values)
        else:
            parent.insert(draw(st.integers(0, len(parent))), draw(json_values))
    return doc


def dumps(doc) -> bytes:
    return json.dumps(doc, allow_nan=True).encode()
