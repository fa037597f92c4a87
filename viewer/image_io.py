"""Images in and out: .png (tone-mapped sRGB 8-bit), .exr (linear float32,
through the OpenEXR package whose native library ships inside its wheel),
.npy (linear float32); environment maps from .hdr/.exr as float32 radiance."""
from __future__ import annotations

from pathlib import Path

import numpy as np

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
    """Linear (H, W, 3) -> sRGB uint8, matching shaders/tonemap.frag (``viewer.tonemap``)."""
    from nbrdf.viewer.tonemap import to_display8

    return to_display8(np.maximum(np.asarray(img, np.float64), 0.0), mode, exposure)


def write_image(path: str | Path, img: np.ndarray, exposure: float = 0.0, mode: str = "aces") -> None:
    """Writes linear (H, W, 3) float data, row 0 at the top."""
    p = check_output(path)
    suffix = p.suffix.lower()
    img = np.ascontiguousarray(img, dtype=np.float32)
    if suffix == ".npy":
        np.save(p, img)
    elif suffix == ".png":
        import imageio.v3 as iio

        iio.imwrite(p, tonemap(img, exposure, mode))
    else:
        import OpenEXR

        channels = {"R": img[..., 0].copy(), "G": img[..., 1].copy(), "B": img[..., 2].copy()}
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        with OpenEXR.File(header, channels) as f:
            f.write(str(p))


def read_normal_map(path: str | Path) -> np.ndarray:
    """A tangent-space normal map (OpenGL convention: +y green up) as float32
    (H, W, 3) in [0, 1], row 0 = v 0."""
    from nbrdf.neural.svbrdf import read_texels

    x = read_texels(path)
    if x.shape[2] < 3:
        raise NbrdfError(f"{path}: a normal map needs RGB, the image has {x.shape[2]} channel(s)")
    return np.ascontiguousarray(x[..., :3].astype(np.float32))


def read_exr(path: str | Path) -> np.ndarray:
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        ch = f.channels()
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
    """Radiance .hdr through imageio's pillow-free reader when it keeps float
    data; the decoded array is checked to be float (never silent 8-bit)."""
    import imageio.v3 as iio

    img = iio.imread(p)
    if not np.issubdtype(img.dtype, np.floating):
        raise NbrdfError(f"--env {p}: the reader returned {img.dtype} data, not float radiance")
    return img.astype(np.float32)
