"""Images in and out: .png (tone-mapped sRGB 8-bit), .exr (linear float32,
through the OpenEXR package whose native library ships inside its wheel),
.npy (linear float32); environment maps from .hdr/.exr as float32 radiance."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import OpenEXR
from PIL import Image, PngImagePlugin

from nbrdf.imaging.tonemap import to_display8
from nbrdf.neural.errors import NbrdfError

OUTPUT_SUFFIXES = (".png", ".exr", ".npy")


def check_output(path: str | Path) -> Path:
    """``path`` as an image to write: a known type in an existing folder (one line otherwise),
    so a render can fail before its minutes of work rather than after."""
    p = Path(path)
    if p.suffix.lower() not in OUTPUT_SUFFIXES:
        raise NbrdfError(f"{path}: unknown image type (expected {', '.join(OUTPUT_SUFFIXES)})")
    if p.parent and not p.parent.exists():
        raise NbrdfError(f"{path}: the folder {p.parent} does not exist")
    return p


def tonemap(img: np.ndarray, exposure: float = 0.0, mode: str = "aces") -> np.ndarray:
    """Linear (H, W, 3) -> sRGB uint8, matching shaders/tonemap_common.glsl (``nbrdf.imaging.tonemap``)."""
    return to_display8(np.maximum(np.asarray(img, np.float64), 0.0), mode, exposure)


def write_png8(path: str | Path, rgb8: np.ndarray) -> None:
    """Writes display-referred uint8 (H, W, 3), row 0 at the top, as a PNG tagged
    sRGB (its sRGB chunk, perceptual intent), so colour-managed viewers and
    compositors show it as the window did instead of guessing."""
    info = PngImagePlugin.PngInfo()
    info.add(b"sRGB", b"\x00")
    Image.fromarray(np.ascontiguousarray(rgb8, dtype=np.uint8)).save(path, format="PNG", pnginfo=info)


def write_image(path: str | Path, img: np.ndarray, exposure: float = 0.0, mode: str = "aces") -> None:
    """Writes linear (H, W, 3) float data, row 0 at the top, atomically: a
    full disk or an unwritable folder is one NbrdfError line and leaves any
    file already at ``path`` whole."""

    p = check_output(path)
    suffix = p.suffix.lower()
    img = np.ascontiguousarray(img, dtype=np.float32)
    tmp = p.with_name(f".{p.stem}.{os.getpid()}.tmp{suffix}")  # same folder: os.replace is atomic
    try:
        if suffix == ".npy":
            with open(tmp, "wb") as f:
                np.save(f, img)
        elif suffix == ".png":
            write_png8(tmp, tonemap(img, exposure, mode))
        else:
            channels = {"R": img[..., 0].copy(), "G": img[..., 1].copy(), "B": img[..., 2].copy()}
            header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
            with OpenEXR.File(header, channels) as f:
                f.write(str(tmp))
        os.replace(tmp, p)
    except Exception as e:  # noqa: BLE001 - OSError, or the image library's own error for the same cause
        tmp.unlink(missing_ok=True)
        reason = getattr(e, "strerror", None) or str(e).splitlines()[0][:120] or type(e).__name__
        raise NbrdfError(f"{path}: cannot be written ({reason}); any file already there is unchanged") from None


def read_normal_map(path: str | Path) -> np.ndarray:
    """A tangent-space normal map (OpenGL convention: +y green up) as float32
    (H, W, 3) in [0, 1], row 0 = v 0."""
    from nbrdf.neural.svbrdf import read_texels  # late: nbrdf.neural.svbrdf loads torch (2 s); only normal maps need it

    x = read_texels(path)
    if x.shape[2] < 3:
        raise NbrdfError(f"{path}: a normal map needs RGB, the image has {x.shape[2]} channel(s)")
    return np.ascontiguousarray(x[..., :3].astype(np.float32))


#: The largest environment read (pixels): 16k x 8k, beyond any equirectangular map
#: a GPU samples; a header declaring more is refused before anything is allocated.
MAX_ENV_PIXELS = 16384 * 8192


def read_exr(path: str | Path) -> np.ndarray:
    side = int(np.sqrt(MAX_ENV_PIXELS * 2))
    OpenEXR.setMaxImageSize(side, side)  # the library's own guard against huge declared sizes
    OpenEXR.setMaxTileSize(side, side)
    with OpenEXR.File(str(path)) as f:
        ch = f.channels()
        if not ch:
            raise NbrdfError(f"--env {path}: the file holds no channels")
        if "RGB" in ch:
            return np.asarray(ch["RGB"].pixels, dtype=np.float32)
        if all(k in ch for k in "RGB"):
            return np.stack([np.asarray(ch[k].pixels, dtype=np.float32) for k in "RGB"], -1)
        first = next(iter(ch.values())).pixels
        arr = np.asarray(first, dtype=np.float32)
        return arr if arr.ndim == 3 else np.repeat(arr[..., None], 3, -1)


def read_environment(path: str | Path) -> np.ndarray:
    """An equirectangular environment as float32 (H, W, 3) linear radiance."""
    p = Path(path)
    if not p.is_file():
        raise NbrdfError(f"--env {path}: no such file")
    suffix = p.suffix.lower()
    try:
        if suffix == ".exr":
            img = read_exr(p)
        elif suffix == ".hdr":
            img = _read_rgbe(p)
        else:
            raise NbrdfError(f"--env {path}: expected an .hdr or .exr file")
    except NbrdfError:
        raise
    except Exception as e:  # noqa: BLE001 - unreadable file
        raise NbrdfError(f"--env {path}: cannot be read ({type(e).__name__})") from None
    if img.ndim != 3 or img.shape[2] < 3 or not np.isfinite(img).all():
        raise NbrdfError(f"--env {path}: not a finite RGB image")
    return np.ascontiguousarray(img[..., :3], dtype=np.float32)


def _read_rgbe(p: Path) -> np.ndarray:
    """A Radiance .hdr (RGBE, flat or new-style run-length scanlines) as float32
    (H, W, 3), row 0 = the top of the image. Every declared size is checked
    against the file before it is used."""
    data = p.read_bytes()
    bad = f"--env {p}: not a Radiance .hdr file"
    if not data.startswith((b"#?RADIANCE", b"#?RGBE")):
        raise NbrdfError(f"{bad} (no #?RADIANCE signature)")
    end = data.find(b"\n\n")
    if end < 0 or end > 65536:
        raise NbrdfError(f"{bad} (no end of the header)")
    for line in data[:end].split(b"\n")[1:]:
        if line.startswith(b"FORMAT=") and line.strip() != b"FORMAT=32-bit_rle_rgbe":
            raise NbrdfError(f"{bad} ({line.decode('latin-1').strip()[:40]}: only 32-bit_rle_rgbe is read)")
    eol = data.find(b"\n", end + 2)
    res = data[end + 2: eol if eol >= 0 else len(data)].split()
    if len(res) != 4 or res[0] not in (b"-Y", b"+Y") or res[2] not in (b"+X", b"-X") \
            or not (res[1].isdigit() and res[3].isdigit()) or len(res[1]) > 6 or len(res[3]) > 6:
        raise NbrdfError(f"{bad} (resolution line {b' '.join(res).decode('latin-1')[:40]!r} "
                         "is not -Y H +X W or one of its flips)")
    h, w = int(res[1]), int(res[3])
    body = data[eol + 1:] if eol >= 0 else b""
    # A run-length byte pair expands to at most 127 bytes: a file this short cannot hold the image.
    if not (1 <= h and 1 <= w and h * w <= MAX_ENV_PIXELS) or h * w * 4 > 64 * len(body):
        raise NbrdfError(f"--env {p}: {w} x {h} pixels is more than the file holds (or than {MAX_ENV_PIXELS} pixels)")
    rgbe = np.empty((h, w, 4), np.uint8)
    buf = np.frombuffer(body, np.uint8)
    pos = 0
    for y in range(h):
        if 8 <= w < 32768 and pos + 4 <= len(buf) and buf[pos] == 2 and buf[pos + 1] == 2 and buf[pos + 2] < 128:
            if (int(buf[pos + 2]) << 8 | int(buf[pos + 3])) != w:
                raise NbrdfError(f"--env {p}: scanline {y} says a width other than {w}")
            pos += 4
            for c in range(4):
                x = 0
                while x < w:
                    if pos >= len(buf):
                        raise NbrdfError(f"--env {p}: the file ends inside scanline {y}")
                    n = int(buf[pos])
                    if n > 128:  # a run
                        n -= 128
                        if x + n > w or pos + 1 >= len(buf):
                            raise NbrdfError(f"--env {p}: a run overflows scanline {y}")
                        rgbe[y, x:x + n, c] = buf[pos + 1]
                        pos += 2
                    else:  # literal bytes
                        if n == 0 or x + n > w or pos + 1 + n > len(buf):
                            raise NbrdfError(f"--env {p}: bad literal run in scanline {y}")
                        rgbe[y, x:x + n, c] = buf[pos + 1: pos + 1 + n]
                        pos += 1 + n
                    x += n
        else:  # a flat scanline
            if pos + 4 * w > len(buf):
                raise NbrdfError(f"--env {p}: the file ends inside scanline {y}")
            rgbe[y] = buf[pos: pos + 4 * w].reshape(w, 4)
            pos += 4 * w
    e = rgbe[..., 3].astype(np.int32)
    img = np.where(e[..., None] > 0, np.ldexp(rgbe[..., :3].astype(np.float32) + 0.5, (e - 136)[..., None]), 0.0)
    if res[0] == b"+Y":
        img = img[::-1]
    if res[2] == b"-X":
        img = img[:, ::-1]
    return np.ascontiguousarray(img, dtype=np.float32)
