"""Fuzzing of every file format nbrdf reads.

Each format has a loader (the project's own entry point for that file, as the
CLI or the window calls it), a set of valid seed files, and a file suffix.
Inputs are made by byte-level mutation of the seeds (bit flips, interesting
integers, inserted, deleted, duplicated and truncated ranges, seeded) or by the
structure-aware hypothesis generators in ``tests/fuzz``. Every input runs in a
separate worker process, so a hang (a per-input time limit) or a crash of a
native library (OpenEXR, safetensors, trimesh, numpy) is recorded as a finding
and the worker restarted, never taking the caller down.

An input passes when it loads or raises ``NbrdfError`` (one line, exit 2 in the
CLI); anything else -- another exception, a hang, a dead worker -- is a finding.

    python tools/fuzz.py --count 10000 --seed 1            # every format
    python tools/fuzz.py --format hdr --count 500 --seed 7 # one format
"""
from __future__ import annotations

import argparse
import io
import json
import os
import pickle
import random
import select
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parents[1]

#: Outcomes of one input: "ok" (loaded), "error" (NbrdfError, one line) pass;
#: "traceback" (another exception), "hang" and "crash" are findings.
PASSING = ("ok", "error")

#: Seconds one input may take before it counts as a hang (generous: the
#: machines running the suite are shared; a real hang never ends).
HANG_SECONDS = 30.0

#: The worker's address-space cap: a header that declares a huge size must be
#: refused before it is allocated, not found by exhausting the machine.
MEMORY_LIMIT = 6 << 30


# --------------------------------------------------------------------- loaders (run in the worker)
def _load_material(path: Path) -> None:
    from nbrdf.neural.material import load_material

    load_material(path)


def _load_session(path: Path) -> None:
    from nbrdf.viewer.session.document import SessionDoc

    SessionDoc.load(path)


def _load_mesh(path: Path) -> None:
    from nbrdf.viewer.scene.mesh import load_mesh

    load_mesh(path)


def _load_environment(path: Path) -> None:
    from nbrdf.imaging.env_presets import resolve_environment
    from nbrdf.imaging.environment import EnvironmentMap

    EnvironmentMap(resolve_environment(str(path)))


def _load_latent(path: Path) -> None:
    from nbrdf.neural.latent import load_latent

    load_latent(path)


def _load_weights(path: Path) -> None:
    from nbrdf.neural.model import load_model

    load_model(path)


def _load_pairs(path: Path) -> None:
    from nbrdf.cli.common import load_pairs

    load_pairs(str(path))


@dataclass(frozen=True)
class Format:
    """One file format: how it is loaded and what its valid files look like."""

    name: str
    """The name used on the command line and in reports."""
    suffix: str
    """The suffix fuzzed files get (loaders dispatch on it)."""
    load: Callable[[Path], None]
    """The project's loader for a file of this format."""
    text: bool = False
    """A text format: mutations also replace number tokens."""


FORMATS: dict[str, Format] = {f.name: f for f in (
    Format("material", ".json", _load_material, text=True),
    Format("session", ".json", _load_session, text=True),
    Format("glb", ".glb", _load_mesh),
    Format("gltf", ".gltf", _load_mesh, text=True),
    Format("obj", ".obj", _load_mesh, text=True),
    Format("hdr", ".hdr", _load_environment),
    Format("exr", ".exr", _load_environment),
    Format("latent", ".safetensors", _load_latent),
    Format("weights", ".safetensors", _load_weights),
    Format("pairs", ".npy", _load_pairs),
)}


# --------------------------------------------------------------------- seeds
def write_rgbe(path: Path | io.BytesIO, img, rle: bool = True) -> None:
    """A Radiance .hdr file (RGBE, new-style run-length scanlines when ``rle``)."""
    import numpy as np

    img = np.asarray(img, np.float64)
    h, w = img.shape[:2]
    m = img.max(-1)
    e = np.where(m > 1e-32, np.floor(np.log2(np.maximum(m, 1e-32))) + 1, 0)
    scale = np.where(m > 1e-32, 256.0 / np.exp2(e), 0)
    mant = np.clip(img * scale[..., None], 0, 255).astype(np.uint8)
    rgbe = np.concatenate([mant, np.where(m > 1e-32, e + 128, 0)[..., None].astype(np.uint8)], -1)
    out = bytearray(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y {h} +X {w}\n".encode())
    for row in rgbe:
        if not rle or not 8 <= w < 32768:
            out += row.tobytes()
            continue
        out += bytes([2, 2, w >> 8, w & 255])
        for c in range(4):
            ch, i = row[:, c].tobytes(), 0
            while i < w:
                run = 1
                while i + run < w and run < 127 and ch[i + run] == ch[i]:
                    run += 1
                if run >= 3:
                    out += bytes([128 + run, ch[i]])
                    i += run
                else:
                    j = i
                    while j < w and j - i < 128 and not (j + 2 < w and ch[j] == ch[j + 1] == ch[j + 2]):
                        j += 1
                    out += bytes([j - i]) + ch[i:j]
                    i = j
    if isinstance(path, io.BytesIO):
        path.write(bytes(out))
    else:
        Path(path).write_bytes(bytes(out))


def _exr_bytes(img, pixel: str = "float", compression: str = "ZIP_COMPRESSION", split: bool = False) -> bytes:
    import numpy as np
    import OpenEXR

    arr = np.asarray(img, np.float16 if pixel == "half" else np.float32)
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "x.exr")
        channels = ({k: np.ascontiguousarray(arr[..., i]) for i, k in enumerate("RGB")} if split
                    else {"RGB": np.ascontiguousarray(arr)})
        header = {"compression": getattr(OpenEXR, compression), "type": OpenEXR.scanlineimage}
        with OpenEXR.File(header, channels) as f:
            f.write(p)
        return Path(p).read_bytes()


def seeds(name: str) -> list[bytes]:
    """Valid files of one format (deterministic)."""
    import numpy as np

    rng = np.random.default_rng(0)
    if name == "material":
        return [p.read_bytes() for p in sorted((ROOT / "viewer/assets/materials").glob("*.json"))]
    if name == "session":
        from nbrdf.neural.material import load_material
        from nbrdf.viewer.session.document import SessionDoc

        doc = SessionDoc(load_material(ROOT / "viewer/assets/materials/car_paint.json"))
        return [(ROOT / "tests/viewer/data/session_v1.json").read_bytes(),
                (json.dumps(doc.to_dict(), indent=1) + "\n").encode()]
    if name == "glb":
        return [p.read_bytes() for p in sorted((ROOT / "viewer/assets/meshes").glob("*.glb"))] + [_small_glb()]
    if name == "gltf":
        return [_small_gltf()]
    if name == "obj":
        return [_obj_text(textured=True), _obj_text(textured=False)]
    if name == "hdr":
        img = rng.uniform(0, 4, (6, 16, 3))
        return [_to_bytes(write_rgbe, img), _to_bytes(write_rgbe, img[:, :5], rle=False)]
    if name == "exr":
        img = rng.uniform(0, 4, (5, 7, 3))
        return [_exr_bytes(img), _exr_bytes(img, "half", "PIZ_COMPRESSION", split=True),
                _exr_bytes(img, "float", "NO_COMPRESSION"), _exr_bytes(img, "half", "RLE_COMPRESSION")]
    if name == "latent":
        import torch

        from nbrdf.neural.latent import MaterialLatent, save_latent

        out = []
        for shape in ((3, 34), (3, 32)):
            with tempfile.TemporaryDirectory() as d:
                p = Path(d) / "z.safetensors"
                save_latent(p, MaterialLatent(torch.randn(*shape, generator=torch.Generator().manual_seed(0)),
                                              "0123456789abcdef", {"material": "x.json"}))
                out.append(p.read_bytes())
        return out
    if name == "weights":
        import torch

        from nbrdf.neural.decoder import Decoder, DecoderSpec, save_decoder

        torch.manual_seed(0)
        with tempfile.TemporaryDirectory() as d:
            p = Path(d) / "w.safetensors"
            save_decoder(Decoder(DecoderSpec(width=4, depth=1)), p)
            return [p.read_bytes()]
    if name == "pairs":
        v = rng.normal(size=(64, 6))
        v[:, :3] /= np.linalg.norm(v[:, :3], axis=1, keepdims=True)
        v[:, 3:] /= np.linalg.norm(v[:, 3:], axis=1, keepdims=True)
        out = []
        for arr in (v.astype(np.float32), v[:3].astype(np.float64)):
            b = io.BytesIO()
            np.save(b, arr)
            out.append(b.getvalue())
        return out
    raise KeyError(name)


def _to_bytes(writer, *args, **kw) -> bytes:
    b = io.BytesIO()
    writer(b, *args, **kw)
    return b.getvalue()


def _obj_text(textured: bool) -> bytes:
    lines = ["# a unit cube", "o cube"]
    corners = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    lines += [f"v {x} {y} {z}" for x, y, z in corners]
    quads = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    if textured:
        lines += ["vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1", "vn 0 0 1"]
        lines += [f"f {a}/1/1 {b}/2/1 {c}/3/1 {d}/4/1" for a, b, c, d in quads]
    else:
        lines += [f"f {a} {b} {c}" for a, b, c, _ in quads] + [f"f {a} {c} {d}" for a, _, c, d in quads]
    return ("\n".join(lines) + "\n").encode()


def _gltf_doc(buffer_uri: str | None, nbytes: int) -> dict:
    """A textured-less triangle pair with normals, uvs and one metallic material."""
    buf = {"byteLength": nbytes} if buffer_uri is None else {"byteLength": nbytes, "uri": buffer_uri}
    return {
        "asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "translation": [0, 0.5, 0], "children": [1]}, {"mesh": 0, "scale": [2, 2, 2]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2},
                                    "indices": 3, "material": 0}]}],
        "materials": [{"name": "m", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.5, 0.2, 1],
                                                              "metallicFactor": 1.0, "roughnessFactor": 0.4}}],
        "buffers": [buf],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 96},
                        {"buffer": 0, "byteOffset": 96, "byteLength": 32},
                        {"buffer": 0, "byteOffset": 128, "byteLength": 12}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 0, "byteOffset": 48, "componentType": 5126, "count": 4, "type": "VEC3"},
                      {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}],
    }


def _gltf_bin() -> bytes:
    pos = [0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0]
    nrm = [0, 0, 1] * 4
    pos_nrm = struct.pack("<12f", *pos) + struct.pack("<12f", *nrm)
    return pos_nrm + struct.pack("<8f", 0, 0, 1, 0, 1, 1, 0, 1) + struct.pack("<6H", 0, 1, 2, 0, 2, 3)


def _small_glb() -> bytes:
    binary = _gltf_bin()
    doc = json.dumps(_gltf_doc(None, len(binary))).encode()
    doc += b" " * (-len(doc) % 4)
    binary += b"\0" * (-len(binary) % 4)
    body = struct.pack("<II", len(doc), 0x4E4F534A) + doc + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def _small_gltf() -> bytes:
    import base64

    binary = _gltf_bin()
    uri = "data:application/octet-stream;base64," + base64.b64encode(binary).decode()
    return json.dumps(_gltf_doc(uri, len(binary)), indent=1).encode()


# --------------------------------------------------------------------- byte-level mutation
_INTERESTING = (0, 1, 2, 3, 4, 7, 8, 16, 127, 128, 255, 256, 1023, 1024, 4096, 32767, 32768, 65535, 65536,
                2**31 - 1, 2**31, 2**32 - 1, 2**32, 2**40, 2**63 - 1, 2**64 - 1)
_TOKENS = (b"0", b"-1", b"1e308", b"-1e308", b"1e-320", b"NaN", b"Infinity", b"-0", b"99999999999999999999",
           b"4294967296", b"2147483648", b"0.5", b"null", b"true", b"[]", b"{}", b'""', b"[[[[[[[[", b"\"\\ud800\"")


def mutate(data: bytes, rng: random.Random, text: bool = False) -> bytes:
    """One to four stacked random edits of ``data``."""
    b = bytearray(data)
    for _ in range(rng.choice((1, 1, 2, 3, 4))):
        n = len(b)
        op = rng.randrange(9 if text else 8)
        if n == 0:
            b += bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        elif op == 0:  # flip bits
            for _ in range(rng.randint(1, 8)):
                i = rng.randrange(n)
                b[i] ^= 1 << rng.randrange(8)
        elif op == 1:  # an interesting byte
            b[rng.randrange(n)] = rng.choice((0, 1, 0x7F, 0x80, 0xFF, ord("-"), ord("9"), ord("\n")))
        elif op == 2:  # an interesting integer, little-endian, 2/4/8 bytes
            width = rng.choice((2, 4, 8))
            v = rng.choice(_INTERESTING) % (1 << (8 * width))
            i = rng.randrange(max(1, n - width + 1))
            b[i:i + width] = v.to_bytes(width, "little")
        elif op == 3:  # insert random bytes
            i = rng.randrange(n + 1)
            b[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
        elif op == 4:  # delete a range
            i = rng.randrange(n)
            del b[i:i + rng.randint(1, max(1, min(64, n - i)))]
        elif op == 5:  # truncate
            del b[rng.randrange(n):]
        elif op == 6:  # duplicate a range somewhere else
            i = rng.randrange(n)
            chunk = b[i:i + rng.randint(1, 256)]
            j = rng.randrange(n + 1)
            b[j:j] = chunk
        elif op == 7:  # overwrite a range with random bytes
            i = rng.randrange(n)
            k = rng.randint(1, 8)
            b[i:i + k] = bytes(rng.randrange(256) for _ in range(k))
        else:  # text: a number token replaced by an interesting one
            digits = [i for i in range(n) if 48 <= b[i] <= 57]
            if digits:
                i = rng.choice(digits)
                j = i
                while j < n and (48 <= b[j] <= 57 or b[j] in b".eE+-"):
                    j += 1
                while i > 0 and (48 <= b[i - 1] <= 57 or b[i - 1] in b".-"):
                    i -= 1
                b[i:j] = rng.choice(_TOKENS)
    return bytes(b)


# --------------------------------------------------------------------- the worker process
def _worker_main() -> None:
    """Reads (format, bytes) requests on stdin, answers (outcome, detail) on stdout."""
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    workdir = Path(tempfile.mkdtemp(prefix="nbrdf-fuzz-"))
    os.environ["XDG_CACHE_HOME"] = str(workdir / "cache")  # the glTF importer's converted materials
    shutil.copytree(ROOT / "viewer/assets/materials/maps", workdir / "maps")  # what seed materials refer to
    import torch

    torch.set_num_threads(1)
    from nbrdf.neural.errors import NbrdfError

    inp, out = sys.stdin.buffer, sys.stdout.buffer
    sys.stdout = sys.stderr  # nothing a loader prints may corrupt the answers
    n = 0
    while True:
        head = inp.read(4)
        if len(head) < 4:
            break
        fmt_name, data = pickle.loads(inp.read(struct.unpack("<I", head)[0]))
        fmt = FORMATS[fmt_name]
        n += 1
        path = workdir / f"in{n}{fmt.suffix}"
        path.write_bytes(data)
        try:
            fmt.load(path)
            answer = ("ok", "")
        except NbrdfError as e:
            msg = str(e)
            answer = ("error", msg) if msg and "\n" not in msg else ("traceback", f"NbrdfError not one line: {msg!r}")
        except BaseException as e:  # noqa: BLE001 - every other exception is a finding
            answer = ("traceback", "".join(traceback.format_exception(e)[-6:]))
        finally:
            path.unlink(missing_ok=True)
            if n % 200 == 0:
                shutil.rmtree(workdir / "cache", ignore_errors=True)
        msg = pickle.dumps(answer)
        out.write(struct.pack("<I", len(msg)) + msg)
        out.flush()


class Worker:
    """A worker process that runs inputs one at a time; restarted after a hang or crash."""

    def __init__(self, hang_seconds: float = HANG_SECONDS):
        self.hang_seconds = hang_seconds
        self.proc: subprocess.Popen | None = None

    def _start(self) -> None:
        env = dict(os.environ, PYTHONFAULTHANDLER="1", OMP_NUM_THREADS="1")
        self.proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--worker"],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     env=env, cwd=str(ROOT))

    def run(self, fmt: str, data: bytes) -> tuple[str, str]:
        """(outcome, detail) of one input; outcome in ok, error, traceback, hang, crash."""
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        assert self.proc and self.proc.stdin and self.proc.stdout
        msg = pickle.dumps((fmt, data))
        try:
            self.proc.stdin.write(struct.pack("<I", len(msg)) + msg)
            self.proc.stdin.flush()
        except BrokenPipeError:
            return self._dead()
        fd = self.proc.stdout.fileno()
        first = 120.0 + self.hang_seconds  # the worker's first input also pays for its imports
        ready, _, _ = select.select([fd], [], [], first if not getattr(self, "_warm", False) else self.hang_seconds)
        if not ready:
            self.proc.kill()
            self.proc.wait()
            self.proc = None
            return "hang", f"no answer within {self.hang_seconds:g} s"
        head = self.proc.stdout.read(4)
        if len(head) < 4:
            return self._dead()
        self._warm = True
        return pickle.loads(self.proc.stdout.read(struct.unpack("<I", head)[0]))

    def _dead(self) -> tuple[str, str]:
        assert self.proc is not None
        code = self.proc.wait()
        self.proc, self._warm = None, False
        return "crash", f"the worker died (exit status {code})"

    def close(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.stdin.close()  # type: ignore[union-attr]
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc = None

    def __enter__(self) -> "Worker":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# --------------------------------------------------------------------- campaigns
@dataclass
class Report:
    """The outcome counts of one format's campaign and its findings."""

    fmt: str
    counts: dict[str, int] = field(default_factory=lambda: {k: 0 for k in ("ok", "error", "traceback", "hang", "crash")})
    findings: list[tuple[str, str, bytes]] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def failed(self) -> int:
        return sum(v for k, v in self.counts.items() if k not in PASSING)


def campaign(fmt: str, count: int, seed: int, worker: Worker, keep: Path | None = None) -> Report:
    """``count`` mutated inputs of one format (the seeds themselves first)."""
    rng = random.Random(f"{fmt}:{seed}")
    base = seeds(fmt)
    text = FORMATS[fmt].text
    rep = Report(fmt)
    t0 = time.perf_counter()
    for i in range(count):
        data = base[i] if i < len(base) else mutate(rng.choice(base), rng, text)
        outcome, detail = worker.run(fmt, data)
        rep.counts[outcome] += 1
        if outcome not in PASSING:
            rep.findings.append((outcome, detail, data))
            if keep is not None:
                keep.mkdir(parents=True, exist_ok=True)
                (keep / f"{fmt}-{seed}-{i}{FORMATS[fmt].suffix}").write_bytes(data)
    rep.seconds = time.perf_counter() - t0
    return rep


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--format", action="append", choices=sorted(FORMATS), help="format(s) to fuzz (default: all)")
    ap.add_argument("--count", type=int, default=10000, help="inputs per format")
    ap.add_argument("--seed", type=int, default=1, help="the mutation seed")
    ap.add_argument("--keep", type=Path, default=Path("fuzz-findings"), help="folder for inputs that fail")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        _worker_main()
        return 0
    failed = 0
    print(f"fuzz: seed {a.seed}, {a.count} inputs per format", flush=True)
    with Worker() as w:
        for fmt in a.format or list(FORMATS):
            rep = campaign(fmt, a.count, a.seed, w, a.keep)
            c = rep.counts
            print(f"{fmt:9s} {a.count:6d} inputs {rep.seconds:8.1f} s  loaded {c['ok']:6d}  one-line error "
                  f"{c['error']:6d}  traceback {c['traceback']}  hang {c['hang']}  crash {c['crash']}", flush=True)
            for outcome, detail, _ in rep.findings[:3]:
                print(f"  {outcome}: {detail.strip().splitlines()[-1] if detail.strip() else ''}", flush=True)
            failed += rep.failed
    print(f"fuzz: {failed} finding(s)" + (f", inputs kept in {a.keep}" if failed else ""), flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
