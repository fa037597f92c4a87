"""Meshes for the renderer: a UV sphere, a built-in non-sphere test mesh,
and OBJ/glTF files through trimesh. Every mesh carries positions, normals,
tangents (xyz + handedness) and uvs, interleaved float32."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.scene.gltf_import import imported_scene, material_groups


@dataclass
class Mesh:
    positions: np.ndarray  # (V, 3) float32
    normals: np.ndarray    # (V, 3)
    tangents: np.ndarray   # (V, 4)
    uvs: np.ndarray        # (V, 2)
    indices: np.ndarray    # (T*3,) uint32
    parts: tuple[tuple[int, int], ...] = ()
    """Draw ranges (first index, index count), one per material of a glTF file,
    in the order of its material list (``gltf_import.material_groups``); empty: one part."""

    @property
    def draw_ranges(self) -> tuple[tuple[int, int], ...]:
        """The (first index, count) of every part (the whole mesh when it has none)."""
        return self.parts or ((0, len(self.indices)),)

    def interleaved(self) -> np.ndarray:
        return np.hstack([self.positions, self.normals, self.tangents, self.uvs]).astype("f4")

    def normalized(self) -> "Mesh":
        """Centred on the origin, fitting the unit sphere, so every mesh frames alike."""
        lo, hi = self.positions.min(0), self.positions.max(0)
        c = (lo + hi) / 2
        r = float(np.linalg.norm(self.positions - c, axis=1).max()) or 1.0
        return Mesh(((self.positions - c) / r).astype("f4"), self.normals, self.tangents, self.uvs, self.indices,
                    self.parts)


def uv_sphere(stacks: int = 96, slices: int = 192) -> Mesh:
    th = np.linspace(0, math.pi, stacks + 1)
    ph = np.linspace(0, 2 * math.pi, slices + 1)
    T, P = np.meshgrid(th, ph, indexing="ij")
    n = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    tan = np.stack([-np.sin(P), np.cos(P), np.zeros_like(P)], -1).reshape(-1, 3)
    uv = np.stack([P / (2 * math.pi), 1 - T / math.pi], -1).reshape(-1, 2)
    idx = []
    w = slices + 1
    for i in range(stacks):
        a = np.arange(slices) + i * w
        idx.append(np.stack([a, a + w, a + 1, a + 1, a + w, a + w + 1], 1))
    ind = np.concatenate(idx).reshape(-1).astype(np.uint32)
    return Mesh(n.astype("f4"), n.astype("f4"), np.hstack([tan, np.ones((len(n), 1))]).astype("f4"),
                uv.astype("f4"), ind)


def test_mesh(u_steps: int = 256, v_steps: int = 48) -> Mesh:
    """A (3, 2) torus knot tube: concave and convex regions, self-occlusion
    and grazing angles that a sphere never shows."""
    R, r, p, q = 1.0, 0.28, 2, 3
    u = np.linspace(0, 2 * math.pi, u_steps + 1)
    v = np.linspace(0, 2 * math.pi, v_steps + 1)

    def curve(t):
        rr = 0.6 * (2 + np.cos(q * t))
        return np.stack([rr * np.cos(p * t), rr * np.sin(p * t), -0.6 * np.sin(q * t)], -1)

    c = curve(u)
    dc = np.gradient(c, u, axis=0)
    dc[-1] = dc[0]
    tng = dc / np.linalg.norm(dc, axis=1, keepdims=True)
    ref = np.array([0.0, 0.0, 1.0])
    nrm = np.cross(tng, ref)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    bin_ = np.cross(tng, nrm)
    U, V = np.meshgrid(np.arange(u_steps + 1), v, indexing="ij")
    cv, sv = np.cos(V)[..., None], np.sin(V)[..., None]
    n = cv * nrm[U] + sv * bin_[U]
    pos = c[U] + r * n * R
    tangent = tng[U]
    uv = np.stack([U / u_steps * 4, V / (2 * math.pi)], -1)
    w = v_steps + 1
    idx = []
    for i in range(u_steps):
        a = np.arange(v_steps) + i * w
        idx.append(np.stack([a, a + w, a + 1, a + 1, a + w, a + w + 1], 1))
    ind = np.concatenate(idx).reshape(-1).astype(np.uint32)
    flat = lambda x: x.reshape(-1, x.shape[-1])
    m = Mesh(flat(pos).astype("f4"), flat(n).astype("f4"),
             np.hstack([flat(tangent), np.ones((flat(n).shape[0], 1))]).astype("f4"), flat(uv).astype("f4"), ind)
    return m.normalized()


#: Mesh files read by the project's glTF importer (with their materials).
GLTF_SUFFIXES = (".gltf", ".glb")


def load_mesh(path: str | Path) -> Mesh:
    """OBJ/glTF/PLY/... through trimesh (a .gltf/.glb through the project's glTF
    importer: every primitive, turned z-up, normalised together, one draw range
    per material); normals and tangents computed when missing."""
    import trimesh  # late: trimesh costs 1.1 s and only mesh files (OBJ, glTF, PLY) need it

    p = Path(path)
    if not p.is_file():
        raise NbrdfError(f"--mesh {path}: no such file")
    parts: tuple[tuple[int, int], ...] = ()
    if p.suffix.lower() in GLTF_SUFFIXES:
        groups = material_groups(imported_scene(p))
        meshes = [m for g in groups for m in g.meshes]
        scene = trimesh.util.concatenate(meshes)
        counts = [3 * sum(len(m.faces) for m in g.meshes) for g in groups]
        if len(groups) > 1:
            parts = tuple(zip(np.cumsum([0] + counts[:-1]).tolist(), counts))
    else:
        try:
            scene = trimesh.load(p, force="mesh", process=True)
        except Exception as e:  # noqa: BLE001 - any loader failure is a bad file
            raise NbrdfError(f"--mesh {path}: cannot be read as a mesh ({type(e).__name__}: {str(e)[:80]})") from None
    if not isinstance(scene, trimesh.Trimesh) or len(scene.faces) == 0:
        raise NbrdfError(f"--mesh {path}: holds no triangles")
    v, f = np.asarray(scene.vertices), np.asarray(scene.faces)
    if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all():
        raise NbrdfError(f"--mesh {path}: vertex positions are not finite 3D points")
    if f.ndim != 2 or f.shape[1] != 3 or f.min() < 0 or f.max() >= len(v):
        raise NbrdfError(f"--mesh {path}: faces refer to vertices the file does not hold")
    try:
        m = mesh_from_trimesh(scene)
    except NbrdfError as e:
        raise NbrdfError(f"--mesh {path}: {e}") from None
    m.parts = parts
    return m.normalized()


def mesh_from_trimesh(tm) -> Mesh:
    """A trimesh.Trimesh as the renderer's arrays (uvs zero where it has none)."""
    pos = np.asarray(tm.vertices, dtype="f4")
    nrm = np.asarray(tm.vertex_normals, dtype="f4")
    flat = np.linalg.norm(nrm, axis=1) < 1e-6  # vertices of degenerate faces only: any unit normal
    nrm[flat] = (0.0, 0.0, 1.0)
    uv = getattr(tm.visual, "uv", None)
    uv = np.zeros((len(pos), 2), "f4") if uv is None or len(uv) != len(pos) else np.asarray(uv, "f4")
    if uv.ndim != 2 or uv.shape[1] != 2 or not np.isfinite(uv).all():
        raise NbrdfError("texture coordinates are not finite (u, v) pairs")
    if not np.isfinite(nrm).all():
        raise NbrdfError("vertex normals are not finite")
    ind = np.asarray(tm.faces, dtype=np.uint32).reshape(-1)
    own = _file_tangents(tm, nrm)
    return Mesh(pos, nrm, own if own is not None else _tangents(pos, nrm, uv, ind), uv, ind)


def _file_tangents(tm, nrm: np.ndarray) -> np.ndarray | None:
    """The file's own tangents (glTF's TANGENT, which the importer keeps as the vertex attribute
    "tangent"; an anisotropic material's brushing follows them), made perpendicular to the normals;
    None where the file has none or one is unusable (then all are made from the uvs)."""
    t = getattr(tm, "vertex_attributes", {}).get("tangent")
    if t is None:
        return None
    t = np.asarray(t, np.float64)
    n = np.asarray(nrm, np.float64)
    if t.shape != (len(n), 4) or not np.isfinite(t).all():
        return None
    xyz = t[:, :3] - n * (t[:, :3] * n).sum(1, keepdims=True)
    length = np.linalg.norm(xyz, axis=1, keepdims=True)
    if len(xyz) == 0 or length.min() < 1e-8:
        return None
    return np.hstack([xyz / length, np.where(t[:, 3:] < 0, -1.0, 1.0)]).astype("f4")


def _tangents(pos, nrm, uv, ind) -> np.ndarray:
    """Per-vertex tangents from uv gradients (Lengyel), orthogonalised; any
    perpendicular where uvs are missing or degenerate."""
    tri = ind.reshape(-1, 3)
    p0, p1, p2 = pos[tri[:, 0]], pos[tri[:, 1]], pos[tri[:, 2]]
    w0, w1, w2 = uv[tri[:, 0]], uv[tri[:, 1]], uv[tri[:, 2]]
    e1, e2 = p1 - p0, p2 - p0
    d1, d2 = w1 - w0, w2 - w0
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    det = np.where(np.abs(det) < 1e-12, 1.0, det)
    t = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) / det[:, None]
    acc = np.zeros_like(pos)
    for k in range(3):
        np.add.at(acc, tri[:, k], t)
    acc -= nrm * (acc * nrm).sum(1, keepdims=True)
    bad = np.linalg.norm(acc, axis=1) < 1e-8
    alt = np.cross(nrm, np.where(np.abs(nrm[:, 2:3]) < 0.9, [[0, 0, 1]], [[1, 0, 0]]))
    acc[bad] = alt[bad]
    length = np.linalg.norm(acc, axis=1, keepdims=True)
    # A vertex without a normal (only degenerate faces) gets any unit tangent: never a NaN in the shader.
    acc = np.where(length > 1e-12, acc / np.maximum(length, 1e-12), [[1.0, 0.0, 0.0]])
    return np.hstack([acc, np.ones((len(pos), 1))]).astype("f4")


def named_mesh(name: str) -> Mesh:
    if name == "sphere":
        return uv_sphere()
    if name in ("testmesh", "knot"):
        return test_mesh()
    return load_mesh(name)
