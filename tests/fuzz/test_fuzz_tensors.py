"""Tensor files: material codes and weight bundles (.safetensors) with hostile
headers (dtypes, shapes, offsets, metadata), pair files (.npy) of any dtype and
shape or a lying header, and byte-level mutations load or end in one line."""
import io
import json
import struct

import fuzz
import numpy as np
import pytest
from fuzzing import FUZZ, check, check_campaign, json_values
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp


@pytest.mark.parametrize("fmt", ["latent", "weights", "pairs"])
def test_byte_mutations(worker, fmt):
    check_campaign(worker, fmt)


def safetensors(tensors: dict, metadata: dict | None, payload: bytes) -> bytes:
    header = dict(tensors)
    if metadata is not None:
        header["__metadata__"] = metadata
    js = json.dumps(header).encode()
    return struct.pack("<Q", len(js)) + js + payload


dims = st.sampled_from([0, 1, 3, 32, 34, 2**31, 2**62, -1]) | st.integers(0, 40)
tensor_entry = st.fixed_dictionaries({
    "dtype": st.sampled_from(["F32", "F16", "BF16", "F64", "I64", "U8", "BOOL", "F8_E4M3", "X"]),
    "shape": st.lists(dims, max_size=3),
    "data_offsets": st.lists(st.sampled_from([0, 4, 408, 2**40, -1]) | st.integers(0, 500), min_size=2, max_size=2),
})
meta_values = st.sampled_from(["nbrdf-latent/1", "{}", "{", "[1]", "null", "\"x\"", "NaN", ""]) | st.text(max_size=10)


@FUZZ
@given(st.dictionaries(st.sampled_from(["latent", "z", "decoder.net.0.weight"]), tensor_entry, max_size=2),
       st.none() | st.dictionaries(st.sampled_from(["format", "decoder_id", "source"]), meta_values),
       st.integers(0, 600))
def test_latent_hostile_headers(worker, tensors, metadata, n):
    payload = np.arange(n, dtype=np.uint8).tobytes()
    check(worker, "latent", safetensors(tensors, metadata, payload))


@FUZZ
@given(st.sampled_from(["format", "architecture", "latent_size", "weights_id", "operations", "trained_on"]),
       json_values.map(json.dumps) | meta_values)
def test_weights_hostile_metadata(worker, key, value):
    """Every metadata field of a valid bundle replaced by any JSON text or non-JSON."""

    raw = fuzz.seeds("weights")[0]
    hlen = struct.unpack("<Q", raw[:8])[0]
    header = json.loads(raw[8:8 + hlen])
    header["__metadata__"][key] = value
    js = json.dumps(header).encode()
    check(worker, "weights", struct.pack("<Q", len(js)) + js + raw[8 + hlen:])


@FUZZ
@given(hnp.arrays(hnp.scalar_dtypes() | st.sampled_from([np.dtype("f2"), np.dtype(">f4"), np.dtype("U3")]),
                  hnp.array_shapes(min_dims=0, max_dims=3, max_side=8)))
def test_pairs_any_dtype_and_shape(worker, arr):
    b = io.BytesIO()
    np.save(b, arr)
    check(worker, "pairs", b.getvalue())


@FUZZ
@given(st.sampled_from(["<f4", "<f8", "|O", "<c8", ">f4", "<V8", "x"]),
       st.tuples(st.sampled_from([0, 1, 3, 2**40, 2**62]), st.sampled_from([6, 0, 2**40])),
       st.booleans(), st.integers(0, 500))
def test_pairs_lying_header(worker, descr, shape, fortran, n):
    """A header declaring 2^40 rows over a few bytes, an object dtype, a bad descr: one line, no allocation."""
    head = repr({"descr": descr, "fortran_order": fortran, "shape": shape}).encode()
    head += b" " * (-(len(head) + 11) % 64) + b"\n"
    data = b"\x93NUMPY\x01\x00" + struct.pack("<H", len(head)) + head + bytes(n)
    check(worker, "pairs", data)


def test_regressions(worker):
    """Found by fuzzing: a latent whose "source" metadata is not JSON ended in a JSONDecodeError traceback."""
    raw = fuzz.seeds("latent")[0]
    hlen = struct.unpack("<Q", raw[:8])[0]
    header = json.loads(raw[8:8 + hlen])
    header["__metadata__"]["source"] = "{"
    js = json.dumps(header).encode()
    assert worker.run("latent", struct.pack("<Q", len(js)) + js + raw[8 + hlen:])[0] == "error"


def _with_metadata(raw: bytes, **meta) -> bytes:
    hlen = struct.unpack("<Q", raw[:8])[0]
    header = json.loads(raw[8:8 + hlen])
    header["__metadata__"].update(meta)
    js = json.dumps(header).encode()
    return struct.pack("<Q", len(js)) + js + raw[8 + hlen:]


def test_weights_regressions(worker):
    """Found by fuzzing: an architecture that is a JSON list, operations that are not an object, ended in
    an AttributeError; an operation network declaring 2^40 inputs was allocated (out of memory)."""
    raw = fuzz.seeds("weights")[0]
    wid = json.loads(raw[8:8 + struct.unpack("<Q", raw[:8])[0]])["__metadata__"]["weights_id"]
    assert worker.run("weights", _with_metadata(raw, architecture="[1]"))[0] == "error"
    assert worker.run("weights", _with_metadata(raw, operations="[1]"))[0] == "error"
    ops = {"format": "nbrdf-operations/2", "decoder_id": wid,
           "specs": {"layering": {"inputs": 2**40, "outputs": 34, "width": 8, "depth": 1}}}
    outcome, detail = worker.run("weights", _with_metadata(raw, operations=json.dumps(ops)))
    assert outcome == "error" and "unsupported" in detail, detail
