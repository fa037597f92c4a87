"""Material and session JSON files: every seed edited anywhere in its tree, and
byte-level mutations, load or end in one NbrdfError line."""
import json

import fuzz
from fuzzing import FUZZ, check, check_campaign, dumps, edited_json
from hypothesis import given
from hypothesis import strategies as st

MATERIALS = [json.loads(s) for s in fuzz.seeds("material")]
SESSIONS = [json.loads(s) for s in fuzz.seeds("session")]


def test_material_byte_mutations(worker):
    check_campaign(worker, "material")


def test_session_byte_mutations(worker):
    check_campaign(worker, "session")


@FUZZ
@given(st.sampled_from(MATERIALS).flatmap(edited_json))
def test_material_edited_anywhere(worker, doc):
    check(worker, "material", dumps(doc))


@FUZZ
@given(st.sampled_from(SESSIONS).flatmap(edited_json))
def test_session_edited_anywhere(worker, doc):
    check(worker, "session", dumps(doc))


def test_session_regressions(worker):
    """Found by fuzzing: bytes that are not UTF-8 and NaN tokens ended in a traceback or loaded NaN state."""
    good = fuzz.seeds("session")[0]
    assert worker.run("session", good[:40] + b"\xb0\xff" + good[40:])[0] == "error"
    doc = json.loads(good)
    doc["view"]["theta_i"] = float("nan")
    assert worker.run("session", dumps(doc))[0] == "error"
    assert worker.run("session", b"[" * 100000)[0] == "error"


def test_material_regressions(worker):
    """Found by the structure-aware fuzzer: a layer type that is a list (unhashable) and file paths holding
    a NUL character ended in a TypeError / ValueError traceback."""
    doc = json.loads(fuzz.seeds("material")[0])
    doc["layers"][0]["type"] = []
    assert worker.run("material", dumps(doc))[0] == "error"
    for layer in ({"type": "measured", "path": "a\u0000b"},
                  {"type": "conductor", "roughness": {"texture": "a\u0000b"}, "r0": [1, 1, 1]}):
        doc["layers"] = [layer]
        assert worker.run("material", dumps(doc))[0] == "error"
    doc["layers"] = [{"type": "conductor", "roughness": 0.3, "r0": [1, 1, 1]}]
    doc["normal_map"] = "n\u0000.png"
    assert worker.run("material", dumps(doc))[0] == "error"


def test_session_backdrop_regression(worker):
    """Found by the structure-aware fuzzer: a "backdrop" that is a number ended in an AttributeError."""
    doc = json.loads(fuzz.seeds("session")[1])
    doc["backdrop"] = 3
    assert worker.run("session", dumps(doc))[0] == "error"
