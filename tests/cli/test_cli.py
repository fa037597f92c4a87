"""The nbrdf command line: SPEC section 8 outputs, and bad input of every
kind ending in one line on stderr with exit status 2 (never a traceback)."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_analytic import ref_conductor, ref_dielectric

from nbrdf.cli.main import nbrdf_main

REPO = Path(__file__).resolve().parents[2]
DEFAULT = REPO / "viewer" / "assets" / "materials" / "default.json"


def write_material(path: Path, layers, name="t") -> Path:
    path.write_text(json.dumps({"format": "nbrdf-material/1", "name": name, "layers": layers}))
    return path


def random_pairs(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(2, n, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    v[..., 2] = np.abs(v[..., 2])
    return np.concatenate([v[0], v[1]], 1).astype(np.float32)


def run(argv, capsys):
    code = nbrdf_main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def assert_one_line_error(code: int, err: str):
    assert code == 2, err
    lines = [l for l in err.splitlines() if l.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err


@pytest.mark.parametrize("layer,ref", [
    ({"type": "conductor", "roughness": 0.3, "r0": [0.9, 0.5, 0.1]}, "conductor"),
    ({"type": "dielectric", "roughness": 0.15, "ior": 1.7}, "dielectric"),
    ({"type": "diffuse", "albedo": [0.2, 0.5, 0.8]}, "diffuse"),
])
def test_eval_single_layer_matches_independent_implementation(tmp_path, capsys, layer, ref):
    """float64 closed forms re-derived in tests/training/test_analytic.py; the
    CLI writes float32, so agreement is to float32 rounding (< 1e-5 relative)."""
    mat = write_material(tmp_path / "m.json", [layer])
    pairs = random_pairs(200, 1)
    np.save(tmp_path / "p.npy", pairs)
    code, _, err = run(["eval", "--material", mat, "--pairs", tmp_path / "p.npy", "--out", tmp_path / "f.npy"], capsys)
    assert code == 0, err
    f = np.load(tmp_path / "f.npy")
    se = np.load(tmp_path / "f.stderr.npy")
    assert f.dtype == np.float32 and f.shape == (200, 3) and (se == 0).all()
    for i, row in enumerate(pairs.astype(np.float64)):
        wi, wo = list(row[:3] / np.linalg.norm(row[:3])), list(row[3:] / np.linalg.norm(row[3:]))
        for c in range(3):
            if ref == "conductor":
                want = ref_conductor(wi, wo, layer["roughness"], layer["r0"][c])
            elif ref == "dielectric":
                want = ref_dielectric(wi, wo, layer["roughness"], layer["ior"])
            else:
                want = layer["albedo"][c] / math.pi
            assert abs(f[i, c] - want) <= 1e-5 * abs(want) + 1e-30, (i, c, f[i, c], want)


def test_eval_stack_reference_writes_stderr(tmp_path, capsys):
    pairs = random_pairs(8, 2)
    np.save(tmp_path / "p.npy", pairs)
    code, _, err = run(["eval", "--material", DEFAULT, "--pairs", tmp_path / "p.npy", "--out", tmp_path / "f.npy",
                        "--spp", "64", "--seed", "3"], capsys)
    assert code == 0, err
    f, se = np.load(tmp_path / "f.npy"), np.load(tmp_path / "f.stderr.npy")
    assert f.shape == se.shape == (8, 3) and np.isfinite(f).all() and (f > 0).all() and (se > 0).all()


def test_lobe_npy_and_png(tmp_path, capsys):
    mat = write_material(tmp_path / "m.json", [{"type": "conductor", "roughness": 0.3, "r0": 0.9}])
    code, _, err = run(["lobe", "--material", mat, "--theta-i", 30, "--out", tmp_path / "l.png"], capsys)
    assert code == 0, err
    img = np.load(tmp_path / "l.npy")
    assert img.shape == (64, 64, 3) and img.dtype == np.float32
    assert (tmp_path / "l.png").stat().st_size > 1000
    # Outside the disk: zeros. Peak near the mirror direction (x < 0 for phi_i = 0).
    assert img[0, 0].sum() == 0 and img[32, 10:32].sum() > img[32, 32:54].sum()


BAD_INPUTS = [
    ([{"type": "conductor", "roughness": 0.3, "r0": [0.9, 1.3, 0.1]}], "layers[0].r0[1]"),
    ([{"type": "conductor", "roughness": 0.001, "r0": 0.5}], "layers[0].roughness"),
    ([{"type": "dielectric", "roughness": 0.1, "ior": 1.5}, {"type": "medium", "albedo": 0.5, "sigma_t": 1}],
     "layers[1]"),
    ([{"type": "conductor", "roughness": 0.3, "r0": 0.5, "colour": 1}], "layers[0].colour"),
]


@pytest.mark.parametrize("layers,place", BAD_INPUTS)
def test_bad_material_is_one_line(tmp_path, capsys, layers, place):
    mat = write_material(tmp_path / "m.json", layers)
    np.save(tmp_path / "p.npy", random_pairs(4, 0))
    code, _, err = run(["eval", "--material", mat, "--pairs", tmp_path / "p.npy", "--out", tmp_path / "f.npy"], capsys)
    assert_one_line_error(code, err)
    assert place in err


@pytest.mark.parametrize("array,needle", [
    (np.zeros((4, 5), np.float32), "(N, 6)"),
    (np.full((4, 6), np.nan, np.float32), "NaN"),
    (np.ones((4, 6), np.float32), "unit vector"),
    (np.zeros((4, 6), np.int32), "float32"),
])
def test_bad_pairs_are_one_line(tmp_path, capsys, array, needle):
    np.save(tmp_path / "p.npy", array)
    code, _, err = run(["eval", "--material", DEFAULT, "--pairs", tmp_path / "p.npy", "--out", tmp_path / "f.npy"], capsys)
    assert_one_line_error(code, err)
    assert needle in err


def test_usage_errors_are_one_line(tmp_path, capsys):
    for argv in (["eval"], ["frobnicate"], ["eval", "--material", "nope.json", "--pairs", "p.npy", "--out", "f.npy"],
                 ["lobe", "--material", DEFAULT, "--theta-i", "95", "--out", tmp_path / "x.npy"],
                 ["lobe", "--material", DEFAULT, "--theta-i", "30", "--out", tmp_path / "x.txt"],
                 ["eval", "--material", DEFAULT, "--pairs", tmp_path / "missing.npy", "--out", tmp_path / "f.npy"]):
        code, _, err = run(argv, capsys)
        assert_one_line_error(code, err)


json_scalars = st.one_of(st.none(), st.booleans(), st.integers(-10, 10), st.floats(allow_nan=True, allow_infinity=True),
                         st.text(max_size=5))
json_values = st.recursive(json_scalars, lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=6), c, max_size=4),
                           max_leaves=12)
layer_like = st.fixed_dictionaries(
    {"type": st.sampled_from(["conductor", "dielectric", "diffuse", "medium", "measured", "latent", "glass", 3])},
    optional={"roughness": json_values | st.floats(-1, 3), "ior": json_values | st.floats(0, 3),
              "r0": json_values | st.floats(-1, 2), "albedo": json_values | st.floats(-1, 2),
              "sigma_t": st.floats(-1, 8), "path": st.text(max_size=8), "junk": json_scalars})
documents = st.one_of(
    json_values,
    st.fixed_dictionaries({"format": st.sampled_from(["nbrdf-material/1", "nbrdf-material/2", 1]),
                           "name": json_values, "layers": st.lists(layer_like, max_size=6)},
                          optional={"normal_map": json_values, "extra": json_scalars}),
)


@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(doc=documents)
def test_malformed_materials_never_traceback(tmp_path, capsys, doc):
    """Random documents through the real CLI: either valid (exit 0) or one clean line with exit 2."""
    mat = tmp_path / "m.json"
    mat.write_text(json.dumps(doc, allow_nan=True))
    np.save(tmp_path / "p.npy", random_pairs(2, 0))
    code, _, err = run(["eval", "--material", mat, "--pairs", tmp_path / "p.npy", "--out", tmp_path / "f.npy",
                        "--spp", "2"], capsys)
    if code != 0:
        assert_one_line_error(code, err)


@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(raw=st.binary(max_size=64))
def test_garbage_files_never_traceback(tmp_path, capsys, raw):
    mat = tmp_path / "m.json"
    mat.write_bytes(raw)
    code, _, err = run(["lobe", "--material", mat, "--theta-i", "0", "--out", tmp_path / "l.npy"], capsys)
    assert_one_line_error(code, err)


def test_console_script_exit_status(tmp_path):
    """The installed entry point itself (a subprocess): exit 2 and one line."""
    exe = Path(sys.executable).parent / "nbrdf"
    r = subprocess.run([str(exe), "eval", "--material", str(tmp_path / "none.json"), "--pairs", "p.npy", "--out", "f.npy"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_eval_and_lobe_belcour(tmp_path, capsys):
    """``--method belcour``: a stack's values through the one factory (no
    standard-error file: the model is exact), the lobe image, and a base the
    model does not cover as one line."""
    pairs = random_pairs(16, 4)
    np.save(tmp_path / "p.npy", pairs)
    code, _, err = run(["eval", "--material", DEFAULT, "--pairs", tmp_path / "p.npy", "--out", tmp_path / "f.npy",
                        "--method", "belcour"], capsys)
    assert code == 0, err
    f = np.load(tmp_path / "f.npy")
    assert f.shape == (16, 3) and f.dtype == np.float32 and np.isfinite(f).all() and (f > 0).all()
    assert not (tmp_path / "f.stderr.npy").exists()
    code, _, err = run(["lobe", "--material", DEFAULT, "--theta-i", 30, "--method", "belcour",
                        "--out", tmp_path / "l.npy"], capsys)
    assert code == 0, err
    assert np.load(tmp_path / "l.npy").shape == (64, 64, 3)
    (tmp_path / "z.safetensors").write_bytes(b"not read: the model refuses the base first")
    latent = write_material(tmp_path / "m.json", [{"type": "dielectric", "roughness": 0.1, "ior": 1.5},
                                                  {"type": "latent", "path": "z.safetensors"}])
    code, _, err = run(["eval", "--material", latent, "--pairs", tmp_path / "p.npy", "--out", tmp_path / "g.npy",
                        "--method", "belcour"], capsys)
    assert_one_line_error(code, err)
    assert "layers[1]: a latent base has no belcour model" in err
