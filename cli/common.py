"""Input and output helpers shared by the ``nbrdf`` commands: checked direction
pairs, output paths, the model and material loaders, progress bars."""
from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Sequence

import numpy as np

from nbrdf.neural.errors import NbrdfError


def load_pairs(path: str) -> tuple[np.ndarray, np.ndarray]:
    """(wi, wo) float32 (N, 3) each from an (N, 6) .npy, checked."""
    p = Path(path)
    if not p.is_file():
        raise NbrdfError(f"{path}: no such file")
    try:
        arr = np.load(p, allow_pickle=False)
    except Exception as e:  # noqa: BLE001 - any unreadable file is bad input
        raise NbrdfError(f"{path}: not a readable .npy file ({e})") from None
    if arr.ndim != 2 or arr.shape[1] != 6:
        raise NbrdfError(f"{path}: expected an (N, 6) array of wi.xyz, wo.xyz, got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.floating):
        raise NbrdfError(f"{path}: expected float32 values, got {arr.dtype}")
    arr = arr.astype(np.float32)
    bad = ~np.isfinite(arr).all(1)
    if bad.any():
        raise NbrdfError(f"{path}: row {int(np.argmax(bad))} holds a NaN or infinite value")
    for name, sl in (("wi", slice(0, 3)), ("wo", slice(3, 6))):
        n = np.linalg.norm(arr[:, sl], axis=1)
        off = np.abs(n - 1) > 1e-3
        if off.any():
            i = int(np.argmax(off))
            raise NbrdfError(f"{path}: row {i}: {name} is not a unit vector (length {n[i]:.4g})")
    return arr[:, :3], arr[:, 3:]


def out_path(path: str, suffixes: Sequence[str]) -> Path:
    """``path`` checked: one of ``suffixes``, in an existing folder."""
    p = Path(path)
    if p.suffix.lower() not in suffixes:
        raise NbrdfError(f"{path}: the output must end in {' or '.join(suffixes)}")
    if p.parent and not p.parent.exists():
        raise NbrdfError(f"{path}: the folder {p.parent} does not exist")
    return p


def stderr_path(p: Path) -> Path:
    """F.npy -> F.stderr.npy"""
    return p.with_name(p.stem + ".stderr" + p.suffix)


def at_least(flag: str, value: int, least: int = 1) -> None:
    """One-line error unless ``value >= least``."""
    if value < least:
        raise NbrdfError(f"{flag}: {value} must be at least {least}")


def in_range(flag: str, value: float, low: float, high: float = math.inf, *, low_open: bool = False,
             high_open: bool = True) -> None:
    """One-line error unless ``value`` lies between ``low`` and ``high``
    (``low_open``/``high_open``: that end excluded)."""
    lo_ok = value > low if low_open else value >= low
    hi_ok = value < high if high_open else value <= high
    if not (lo_ok and hi_ok):
        lo, hi = "(" if low_open else "[", ")" if high_open else "]"
        raise NbrdfError(f"{flag}: {value} is outside {lo}{low:g}, {high:g}{hi}")


def progress(total: int, desc: str, unit: str = "pair", disable: bool | None = None):
    """A tqdm bar on stderr (``disable=None``: silent when stderr is not a terminal)."""
    from tqdm import tqdm  # late: tqdm costs ~50 ms (importlib.metadata), --help needs none

    return tqdm(total=total, desc=desc, unit=unit, disable=disable, leave=False, file=sys.stderr)


def model_or_default(path: str | None):
    """The bundle at ``path``, or the shipped one."""
    from nbrdf.neural.model import default_model, load_model  # late: torch costs ~1 s, --help needs none

    return load_model(path) if path else default_model()


def decoder_or_default(path: str | None):
    """The decoder at ``path``, or the shipped one."""
    from nbrdf.neural.decoder import default_decoder, load_decoder  # late: torch costs ~1 s, --help needs none

    return load_decoder(path) if path else default_decoder()
