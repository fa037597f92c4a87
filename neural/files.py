"""Writing user files so that a failure never damages what was there: a full
disk or an unwritable folder ends in one NbrdfError line and the previous file
is left whole."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

from nbrdf.neural.errors import NbrdfError


def write_atomic(path: str | Path, data: str | bytes) -> None:
    """``data`` to ``path`` through a temporary file in the same folder, flushed
    to disk, then ``os.replace``: readers see the old file or the new one, never
    a part. Raises ``OSError``; the temporary file never stays behind."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data.encode("utf-8") if isinstance(data, str) else data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_text(path: str | Path, text: str) -> None:
    """``write_atomic`` for a user's file: an ``OSError`` becomes one NbrdfError line."""
    p = Path(path)
    if not p.parent.is_dir():
        raise NbrdfError(f"{path}: the folder {p.parent} does not exist")
    try:
        write_atomic(p, text)
    except OSError as e:
        raise NbrdfError(f"{path}: cannot be written ({e.strerror or type(e).__name__}); "
                         "any file already there is unchanged") from None
