"""``nbrdf bench mitsuba``: one JSON object with the plugin's and torch's
throughputs (timings are reported, never asserted); bad input is one line."""
from __future__ import annotations

import json

import pytest

from nbrdf.cli.main import nbrdf_main

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")


def test_bench_mitsuba_prints_its_json(mi, materials, capsys):
    assert nbrdf_main(["bench", "mitsuba", "--material", materials["uncoated"], "--pairs", "4096",
                       "--repeats", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["variant"] == "llvm_ad_rgb" and out["pairs"] == 4096
    assert out["rgb_evals_per_s"] > 0 and out["torch_rgb_evals_per_s"] > 0 and out["rgb_samples_per_s"] > 0


def test_bench_mitsuba_bad_material_is_one_line(mi, capsys, tmp_path):
    assert nbrdf_main(["bench", "mitsuba", "--material", str(tmp_path / "none.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "none.json" in err and err.startswith("nbrdf: ") and "nbrdf: nbrdf" not in err
