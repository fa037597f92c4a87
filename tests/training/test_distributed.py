"""Shards as Ray tasks: identical to local shards, resumable, and an
unreachable address fails in one line. Starts a local Ray instance."""
from __future__ import annotations

import numpy as np
import pytest
from safetensors.numpy import load_file

from nbrdf.neural.errors import NbrdfError
from nbrdf.training.dataset import DataConfig, generate, plan

ray = pytest.importorskip("ray")

CFG = DataConfig(counts=dict(conductor=1, two_layer=2, diffuse_base=1), val_counts=dict(two_layer=1),
                 pairs=32, spp=8, shard_size=1)


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    yield
    ray.shutdown()


def _same(a, b):
    for s in plan(CFG):
        x, y = load_file(str(a / s.file)), load_file(str(b / s.file))
        assert x.keys() == y.keys()
        for k in x:
            np.testing.assert_array_equal(x[k], y[k], err_msg=f"{s.file}:{k}")


def test_ray_shards_equal_local_shards_and_resume(tmp_path, local_ray):
    generate(tmp_path / "local", CFG, progress=False)
    generate(tmp_path / "ray", CFG, progress=False, ray="auto")
    _same(tmp_path / "local", tmp_path / "ray")
    # resume: a lost shard is recomputed on Ray, the others are kept as they are
    gone = tmp_path / "ray" / plan(CFG)[2].file
    kept = tmp_path / "ray" / plan(CFG)[1].file
    stamp = kept.stat().st_mtime_ns
    gone.unlink()
    generate(tmp_path / "ray", CFG, progress=False, ray="auto")
    assert gone.exists() and kept.stat().st_mtime_ns == stamp
    _same(tmp_path / "local", tmp_path / "ray")


def test_unreachable_address_is_one_line(tmp_path):
    if ray.is_initialized():
        ray.shutdown()
    with pytest.raises(NbrdfError, match="cannot reach") as e:
        generate(tmp_path / "x", CFG, progress=False, ray="127.0.0.1:9")
    assert "\n" not in str(e.value)
    with pytest.raises(NbrdfError, match="not a Ray address"):
        generate(tmp_path / "y", CFG, progress=False, ray="nowhere")
