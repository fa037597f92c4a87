"""`nbrdf bench reference --quick` runs and reports sane JSON."""
import json

from nbrdf.cli.main import nbrdf_main


def test_bench_reference_quick(capsys):
    assert nbrdf_main(["bench", "reference", "--quick"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["paths_per_second_eager"] > 1000
    assert out["lobe_noise_psnr_db"] >= out["lobe_target_noise_psnr_db"]
    assert 1 < out["vertices_per_path"] < 50
    assert out["paths_per_cpu_second"] > 1000
