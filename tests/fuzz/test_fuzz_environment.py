"""Environment maps: Radiance .hdr (the project's RGBE reader) and OpenEXR
files of random shapes, channels, pixel types and compressions, hostile
headers, and byte-level mutations load or end in one line."""
import io

import fuzz
import numpy as np
import pytest
from fuzzing import FUZZ, check, check_campaign
from hypothesis import given
from hypothesis import strategies as st


@pytest.mark.parametrize("fmt", ["hdr", "exr"])
def test_byte_mutations(worker, fmt):
    check_campaign(worker, fmt)


def test_rgbe_reads_what_was_written(tmp_path):
    """The reader returns the radiance (within RGBE's 8-bit mantissa), top row first, flat or run-length."""
    from nbrdf.imaging.image_io import read_environment

    rng = np.random.default_rng(1)
    img = rng.uniform(0, 50, (9, 40, 3)) * (rng.uniform(size=(9, 40, 1)) > 0.3)
    img[0, :8] = [1000.0, 0.0, 0.001]  # the sun: a big exponent beside small channels
    for rle in (True, False):
        fuzz.write_rgbe(tmp_path / "e.hdr", img, rle=rle)
        back = read_environment(tmp_path / "e.hdr")
        assert back.shape == img.shape and back.dtype == np.float32
        err = np.abs(back - img) / np.maximum(img.max(-1, keepdims=True), 1e-30)
        assert err.max() <= 1 / 128, err.max()  # RGBE keeps 8 bits of the brightest channel's mantissa


sizes = st.sampled_from([0, 1, 7, 8, 9, 16, 32767, 32768, 65535, 10**6, 10**9]) | st.integers(0, 40)
resolution = st.tuples(st.sampled_from(["-Y", "+Y", "-X", "Y", "+X"]), sizes, st.sampled_from(["+X", "-X", "+Y"]),
                       sizes).map(lambda t: f"{t[0]} {t[1]} {t[2]} {t[3]}")


@FUZZ
@given(st.sampled_from([b"#?RADIANCE\n", b"#?RGBE\n", b"#?\n", b""]),
       st.sampled_from([b"FORMAT=32-bit_rle_rgbe\n", b"FORMAT=32-bit_rle_xyze\n", b"", b"EXPOSURE=2\n"]),
       resolution | st.text(max_size=20), st.binary(max_size=600), st.integers(1, 12), st.integers(1, 12),
       st.booleans())
def test_hdr_hostile_headers(worker, sig, fmt, res, body, h, w, real_body):
    """The declared size is checked against the file before anything is allocated or read past its end."""
    if real_body:  # a valid image's scanlines under the random header
        b = io.BytesIO()
        fuzz.write_rgbe(b, np.ones((h, w, 3)), rle=w >= 8)
        body = b.getvalue().split(b"\n", 4)[-1] + body[:20]
    check(worker, "hdr", sig + fmt + b"\n" + res.encode("utf-8", "replace") + b"\n" + body)


channels = st.sampled_from([("RGB",), ("R", "G", "B"), ("Y",), ("A",), ("R", "G"), ("R", "G", "B", "A")])
pixel = st.sampled_from([np.float16, np.float32, np.uint32])
values = st.sampled_from([0.0, 1.0, -1.0, np.inf, np.nan, 65504.0, 1e-8])


@FUZZ
@given(st.integers(1, 6), st.integers(1, 6), channels, pixel,
       st.sampled_from(["NO_COMPRESSION", "ZIP_COMPRESSION", "PIZ_COMPRESSION", "RLE_COMPRESSION",
                        "PXR24_COMPRESSION", "B44_COMPRESSION", "DWAA_COMPRESSION"]),
       values, st.integers(0, 2**16), st.integers(0, 255))
def test_exr_any_layout(worker, h, w, names, dtype, compression, special, at, byte):
    """Valid files of every layout (negative, NaN and infinite radiance included), and the same with one
    header or data byte set: load or one line."""
    import os
    import tempfile

    import OpenEXR

    rng = np.random.default_rng(h * 7 + w)
    data = {}
    for n in names:
        k = 3 if n == "RGB" else None
        a = rng.uniform(0, 4, (h, w, k) if k else (h, w)).astype(dtype)
        a.flat[0] = special if dtype != np.uint32 else 7
        data[n] = np.ascontiguousarray(a)
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "x.exr")
        with OpenEXR.File({"compression": getattr(OpenEXR, compression), "type": OpenEXR.scanlineimage},
                          data) as f:
            f.write(p)
        raw = open(p, "rb").read()
    check(worker, "exr", raw)
    mutated = bytearray(raw)
    mutated[at % len(raw)] = byte
    check(worker, "exr", bytes(mutated))


def test_regressions(worker, tmp_path):
    """Found by fuzzing: no .hdr file could be read at all (imageio has no Radiance reader without
    extra plugins); now a valid one loads, and a header declaring 10^9 x 10^9 pixels is refused."""
    assert worker.run("hdr", fuzz.seeds("hdr")[0])[0] == "ok"
    assert worker.run("hdr", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1000000 +X 1000000\n" + b"\0" * 64)[0] \
        == "error"
