"""Meshes: .glb and .gltf (the project's importer) and .obj (through trimesh):
documents edited anywhere, accessors with hostile counts, offsets and strides,
OBJ files of random records, and byte-level mutations load or end in one line."""
import json
import struct

import fuzz
import pytest
from fuzzing import FUZZ, check, check_campaign, dumps, edited_json
from hypothesis import given
from hypothesis import strategies as st

GLTF = json.loads(fuzz.seeds("gltf")[0])


@pytest.mark.parametrize("fmt", ["glb", "gltf", "obj"])
def test_byte_mutations(worker, fmt):
    check_campaign(worker, fmt)


def glb(doc: dict, binary: bytes) -> bytes:
    js = json.dumps(doc, allow_nan=True).encode()
    js += b" " * (-len(js) % 4)
    binary += b"\0" * (-len(binary) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


@FUZZ
@given(edited_json(GLTF))
def test_gltf_edited_anywhere(worker, doc):
    check(worker, "gltf", dumps(doc))


big = st.sampled_from([0, 1, 3, 4, 5, 7, 12, 255, 2**31 - 1, 2**32, 2**53, -1, -2**31]) | st.integers(-2**64, 2**64)
accessor_edit = st.fixed_dictionaries({}, optional={
    "count": big, "byteOffset": big,
    "componentType": st.sampled_from([5120, 5121, 5122, 5123, 5125, 5126, 0, 5124]) | big,
    "type": st.sampled_from(["SCALAR", "VEC2", "VEC3", "VEC4", "MAT4", "X"]),
    "bufferView": big, "normalized": st.booleans()})
view_edit = st.fixed_dictionaries({}, optional={"byteOffset": big, "byteLength": big, "byteStride": big,
                                                "buffer": big})


@FUZZ
@given(st.lists(st.tuples(st.integers(0, 3), accessor_edit), max_size=3),
       st.lists(st.tuples(st.integers(0, 2), view_edit), max_size=2),
       st.integers(0, 200))
def test_glb_hostile_accessors(worker, acc_edits, view_edits, cut):
    """Header-declared lengths: every count, offset and stride checked against the buffer it reads."""
    doc = json.loads(json.dumps(GLTF))
    del doc["buffers"][0]["uri"]
    for i, e in acc_edits:
        doc["accessors"][i].update(e)
    for i, e in view_edits:
        doc["bufferViews"][i].update(e)
    binary = fuzz._gltf_bin()
    check(worker, "glb", glb(doc, binary[:len(binary) - cut] if cut < len(binary) else binary))


number = st.sampled_from(["0", "1", "-1", "0.5", "nan", "inf", "-inf", "1e308", "x", ""]) \
    | st.floats(-10, 10).map(repr)
index = st.integers(-12, 12).map(str) | st.sampled_from(["", "a", "99999999999999999999"])
vertex_ref = st.tuples(index, st.none() | index, st.none() | index).map(
    lambda t: t[0] + ("" if t[1] is None and t[2] is None else "/" + (t[1] or "") + ("/" + t[2] if t[2] else "")))
obj_line = st.one_of(
    st.lists(number, min_size=1, max_size=4).map(lambda v: "v " + " ".join(v)),
    st.lists(number, min_size=1, max_size=3).map(lambda v: "vt " + " ".join(v)),
    st.lists(number, min_size=1, max_size=4).map(lambda v: "vn " + " ".join(v)),
    st.lists(vertex_ref, min_size=1, max_size=5).map(lambda v: "f " + " ".join(v)),
    st.sampled_from(["o x", "g", "s off", "usemtl missing", "mtllib missing.mtl", "l 1 2", "# c"]))


@FUZZ
@given(st.lists(obj_line, max_size=30))
def test_obj_random_records(worker, lines):
    cube = fuzz.seeds("obj")[0].decode().splitlines()
    check(worker, "obj", ("\n".join(cube[:10] + lines) + "\n").encode())


def test_regressions(worker):
    """Found by fuzzing: an OBJ vertex with two coordinates, a vt with one, ended in a numpy traceback."""
    cube = fuzz.seeds("obj")[0].decode()
    assert worker.run("obj", cube.replace("v 0 1 1", "v 0 1").encode())[0] == "error"
    assert worker.run("obj", cube.replace("vt 1 0", "vt 1").encode())[0] == "error"
