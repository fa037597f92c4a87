"""`nbrdf bench reference --quick` runs and reports sane JSON."""
import json

from nbrdf.cli.main import nbrdf_main


def test_bench_reference_quick(capsys):
    assert nbrdf_main(["bench", "reference", "--quick"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["paths_per_second_eager"] > 0  # a rate was measured (its value: the benchmark's, not a test's)
    assert out["lobe_noise_psnr_db"] >= out["lobe_target_noise_psnr_db"]
    assert 1 < out["vertices_per_path"] < 50
    assert out["paths_per_cpu_second"] > 0
    assert out["machine"]["walk"] in ("numba-cpu", "numba-cuda")


def test_an_unknown_walk_device_is_one_line(capsys, monkeypatch):
    monkeypatch.setenv("NBRDF_WALK_DEVICE", "tpu")
    assert nbrdf_main(["bench", "reference", "--quick"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["nbrdf: NBRDF_WALK_DEVICE must be auto, cpu or cuda (got 'tpu')"]
