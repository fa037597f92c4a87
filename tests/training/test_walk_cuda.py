"""The walk's CUDA kernel (training/walk_cuda.py) without a GPU: Numba's CUDA
simulator runs the kernel (one Python thread per CUDA thread, the per-path
code uncompiled) and must trace the same paths as the compiled CPU walk;
where NVIDIA's CUDA target and its compiler are installed (the ``cuda``
extra), the kernel must also compile to PTX for an H100 (sm_90)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.training.layered import StackParams, simulate
from nbrdf.training.walk_dispatch import walk_device

N = 7  # pairs: 7 x 2 blocks = 14 work items, not a multiple of the CUDA block
SPP = 48  # one full block of 32 paths and one partial block


def _dirs(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    u = rng.random((N, 2))
    r = np.sqrt(u[:, 0])
    return np.stack([r * np.cos(2 * np.pi * u[:, 1]), r * np.sin(2 * np.pi * u[:, 1]), np.sqrt(1 - u[:, 0])], -1)


def _stacks() -> dict[str, StackParams]:
    """The benchmark's stack (medium, RGB), the trapping stack (the two-bounce
    connection and splitting, RGB), a one-channel two-interface diffuse-base
    stack (next-event estimation through the stack), a medium over a sharp
    base (by way of the base) and an anisotropic coat over an anisotropic
    conductor in a turned frame (SPEC section 10)."""
    f = lambda v, *shape: torch.full(shape, float(v), dtype=torch.float64)
    return {
        "standard": StackParams(f(0.1, N, 1), f(1.5, N, 1), f(0.9, N, 1, 3), f(1.0, N, 1), "conductor", f(0.3, N),
                                base_r0=f(0.9, N, 3)),
        "trapping": StackParams(f(0.15, N, 1), f(1.5, N, 1), f(0.0, N, 1, 3), f(0.0, N, 1), "conductor", f(0.02, N),
                                base_r0=torch.tensor([[1.0, 0.7, 0.4]], dtype=torch.float64).expand(N, 3)),
        "diffuse": StackParams(f(0.3, N, 2), f(1.4, N, 2), f(0.7, N, 2), f(0.5, N, 2), "diffuse", f(1.0, N),
                               base_albedo=f(0.6, N)),
        "sharp_base": StackParams(f(0.05, N, 1), f(1.5, N, 1), f(0.9, N, 1, 3), f(1.0, N, 1), "conductor", f(0.02, N),
                                  base_r0=f(0.9, N, 3)),
        "anisotropic": StackParams(f(0.1, N, 1), f(1.5, N, 1), f(0.9, N, 1, 3), f(0.5, N, 1), "conductor", f(0.2, N),
                                   base_r0=f(0.9, N, 3), anisotropy=f(0.5, N, 1), base_anisotropy=f(0.8, N),
                                   rotation=f(30.0, N)),
    }


def _run_all(device: str) -> dict[str, list]:
    wi, wo = torch.from_numpy(_dirs(1)), torch.from_numpy(_dirs(2))
    out = {}
    for name, st in _stacks().items():
        m, e = simulate(st, wi, wo, spp=SPP, seed=11, dtype=torch.float64, device=device)
        out[name] = [m.tolist(), e.tolist()]
    return out


def test_the_simulated_cuda_kernel_traces_the_cpu_walks_paths():
    """Same seeds, same paths: the kernel (in the simulator, each path in plain
    Python) and the compiled CPU walk agree to rounding on four stack kinds,
    means and standard errors (a wrong index, a lost block or channel, or a
    scratch array shared between threads would change them at the percent level)."""
    code = textwrap.dedent("""
        import json, warnings
        warnings.simplefilter("ignore")  # uint64 wrap-around of the hash in plain Python
        from tests.training.test_walk_cuda import _run_all
        print(json.dumps(_run_all("cuda")))
    """)
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1", NUMBA_DISABLE_JIT="1")
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    res = subprocess.run([sys.executable, "-c", code], env=env, cwd=root, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    gpu = json.loads(res.stdout.strip().splitlines()[-1])
    cpu = _run_all("cpu")
    for name in cpu:
        for g, c in zip(gpu[name], cpu[name]):
            g, c = np.asarray(g), np.asarray(c)
            assert np.all(c > 0), name  # every pair carries light: the comparison is not 0 == 0
            np.testing.assert_allclose(g, c, rtol=1e-9, atol=0, err_msg=name)


def test_walk_device_is_chosen_by_the_environment(monkeypatch):
    monkeypatch.setenv("NBRDF_WALK_DEVICE", "cpu")
    assert walk_device() == "cpu"
    monkeypatch.setenv("NBRDF_WALK_DEVICE", "tpu")
    with pytest.raises(NbrdfError, match="auto, cpu or cuda"):
        walk_device()
    from nbrdf.training import walk_cuda

    monkeypatch.setattr(walk_cuda, "available", lambda: False)
    monkeypatch.setenv("NBRDF_WALK_DEVICE", "cuda")
    with pytest.raises(NbrdfError, match="no CUDA device"):
        walk_device()
    monkeypatch.setenv("NBRDF_WALK_DEVICE", "auto")
    assert walk_device() == "cpu"
    assert walk_device("cpu") == "cpu"
    with pytest.raises(NbrdfError, match="device must be auto, cpu or cuda"):
        simulate(_stacks()["standard"], torch.from_numpy(_dirs(1)), torch.from_numpy(_dirs(2)), spp=4, device="gpu")
    monkeypatch.setattr(walk_cuda, "available", lambda: True)
    assert walk_device() == "cuda"


def test_the_kernel_compiles_for_an_h100():
    """Only where the ``cuda`` extra is installed (numba-cuda with NVVM): the
    whole walk, with every strategy of the trapping stack, compiles to PTX for
    sm_90 without a device."""
    pytest.importorskip("numba_cuda", reason="the cuda extra (numba-cuda) is not installed")
    code = textwrap.dedent("""
        import types, numpy as np, numba
        from numba import cuda
        import numba.cuda.dispatcher as D
        D.get_current_device = lambda: types.SimpleNamespace(compute_capability=(9, 0))  # no device here
        from nbrdf.training import walk_cuda
        from nbrdf.training.walk import walk_params
        f = lambda *s: np.zeros(s)
        P = walk_params(f(4, 3), f(4, 3), 64, 7, f(4, 1), f(4, 1), f(4, 1), f(4, 1, 3), 0, f(4), f(4, 3), f(4, 3), f(4), f(4, 3),
                        4, 100000, True)
        args = (P, f(8, 3), f(8, 3), np.zeros(8, np.int64), np.zeros(8, np.int64))
        ptx, _ = cuda.compile_ptx(walk_cuda._run_kernel.py_func, tuple(numba.typeof(a) for a in args), cc=(9, 0))
        assert ".target sm_90" in ptx, ptx[:400]
        print(len(ptx))
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    if res.returncode != 0 and ("nvrtc" in res.stderr or "NVVM" in res.stderr or "libnvvm" in res.stderr):
        pytest.skip("the CUDA compiler libraries are not installed: " + res.stderr.strip().splitlines()[-1][:200])
    assert res.returncode == 0, res.stderr[-2000:]
    assert int(res.stdout.strip().splitlines()[-1]) > 10_000
