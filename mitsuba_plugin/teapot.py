"""The Utah teapot as a triangle mesh, tessellated from its public-domain
Bezier patches (``data/teapot.bpt``: Newell's 32 bicubic patches over 306
control points, z up, with the later bottom that closes it).

Each patch is evaluated on an (n + 1) x (n + 1) grid of (u, v); vertices that
coincide (shared patch edges, the lid's and bottom's poles) are welded so the
mesh is one connected surface whose smooth normals Mitsuba can average, and
triangles that collapse at the poles are dropped. Meshes are cached as PLY
under ``$XDG_CACHE_HOME/nbrdf/meshes``.
"""
from __future__ import annotations

import os
import tempfile
from collections import defaultdict, deque
from pathlib import Path

import numpy as np

from nbrdf.neural.errors import NbrdfError

DATA = Path(__file__).resolve().parent / "data" / "teapot.bpt"
#: The patch count of the data set (rim 4, body 8, handle 4, spout 4, lid 8, bottom 4).
N_PATCHES = 32
#: Bumped when the tessellation changes, so old cached meshes are not reused.
VERSION = 1


def load_patches(path: str | Path = DATA) -> np.ndarray:
    """Control points (P, 4, 4, 3) of every patch in a ``.bpt`` table (a count,
    that many rows of 16 one-based indices, a count, that many x,y,z rows;
    ``#`` starts a comment)."""
    lines = [ln.split("#", 1)[0].strip() for ln in Path(path).read_text().splitlines()]
    lines = [ln for ln in lines if ln]
    try:
        n_p = int(lines[0])
        idx = np.array([[int(t) for t in ln.split(",")] for ln in lines[1:1 + n_p]], np.int64)
        n_v = int(lines[1 + n_p])
        verts = np.array([[float(t) for t in ln.split(",")] for ln in lines[2 + n_p:2 + n_p + n_v]], np.float64)
    except (ValueError, IndexError) as e:
        raise NbrdfError(f"{path}: not a Bezier patch table ({e})") from None
    if idx.shape != (n_p, 16) or verts.shape != (n_v, 3) or idx.min() < 1 or idx.max() > n_v:
        raise NbrdfError(f"{path}: not a Bezier patch table (patches {idx.shape}, points {verts.shape})")
    return verts[idx - 1].reshape(n_p, 4, 4, 3)


def _bernstein(t: np.ndarray) -> np.ndarray:
    s = 1.0 - t
    return np.stack([s ** 3, 3 * t * s * s, 3 * t * t * s, t ** 3], -1)


def tessellate(patches: np.ndarray, n: int = 12, weld: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) float32 and triangles (F, 3) int32 of the patches on an
    n x n grid of quads each, welded within ``weld`` and without degenerate
    triangles. Triangles wind so that their normals point out of the teapot."""
    if n < 1:
        raise NbrdfError(f"teapot tessellation: n must be at least 1, got {n}")
    t = np.linspace(0.0, 1.0, n + 1)
    b = _bernstein(t)  # (n+1, 4)
    grid = np.einsum("ui,vj,pijc->puvc", b, b, patches)  # (P, n+1, n+1, 3)
    pts = grid.reshape(-1, 3)
    key = np.round(pts / weld).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    verts = pts[first]
    k = np.arange(grid.shape[0] * (n + 1) * (n + 1)).reshape(grid.shape[0], n + 1, n + 1)
    a, b_, c, d = k[:, :-1, :-1], k[:, 1:, :-1], k[:, 1:, 1:], k[:, :-1, 1:]
    tris = np.concatenate([np.stack([a, b_, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    tris = inverse[tris]
    keep = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])
    tris = tris[keep]
    v0, v1, v2 = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    area = np.linalg.norm(np.cross(v1 - v0, v2 - v0), axis=1)
    tris = tris[area > 1e-12]
    # Newell's patches are wound inward on some parts: orient every triangle away from the teapot's axis
    # (the body, lid and bottom) or from the centre line of the handle/spout, using the face centre.
    tris = _orient_outward(verts, tris)
    return verts.astype(np.float32), tris.astype(np.int32)


def _orient_outward(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Flips the triangles whose normal points toward the inside: the one
    convention a ray tracer's one-sided BSDF needs. Orientation is propagated
    over shared edges from a seed face whose normal is checked against the
    direction from the mesh's centre."""
    tris = tris.copy()
    edge_faces: dict[tuple[int, int], list[int]] = defaultdict(list)
    for f, (i, j, k) in enumerate(tris):
        for e in ((i, j), (j, k), (k, i)):
            edge_faces[(min(e), max(e))].append(f)
    seen = np.zeros(len(tris), bool)
    for start in range(len(tris)):
        if seen[start]:
            continue
        # seed each connected part: its face farthest from the centre must face away from it
        comp, queue = [start], deque([start])
        seen[start] = True
        while queue:
            f = queue.popleft()
            tri = tris[f]
            for e in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
                for g in edge_faces[(min(e), max(e))]:
                    if seen[g]:
                        continue
                    gt = list(tris[g])
                    # consistent winding: the shared edge runs the other way in the neighbour
                    for m in range(3):
                        if gt[m] == e[0] and gt[(m + 1) % 3] == e[1]:
                            tris[g] = tris[g][::-1]
                    seen[g] = True
                    comp.append(g)
                    queue.append(g)
        comp_a = np.array(comp)
        c = verts[tris[comp_a]].mean(1)
        far = comp_a[np.argmax(np.linalg.norm(c - verts.mean(0), axis=1))]
        v0, v1, v2 = verts[tris[far]]
        nrm = np.cross(v1 - v0, v2 - v0)
        if np.dot(nrm, v0 - verts.mean(0)) < 0:
            tris[comp_a] = tris[comp_a][:, ::-1]
    return tris


def boundary_edges(tris: np.ndarray) -> int:
    """How many edges belong to one triangle only (0 for a closed mesh)."""
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), 1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return int((counts == 1).sum())


def write_ply(path: str | Path, verts: np.ndarray, tris: np.ndarray) -> None:
    """A binary little-endian PLY of positions and triangles."""
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(verts)}\n"
            "property float x\nproperty float y\nproperty float z\n"
            f"element face {len(tris)}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    faces = np.zeros(len(tris), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"], faces["i"] = 3, tris
    with open(path, "wb") as f:
        f.write(head)
        f.write(np.ascontiguousarray(verts, "<f4").tobytes())
        f.write(faces.tobytes())


def cache_dir() -> Path:
    """Where generated meshes are kept: $XDG_CACHE_HOME/nbrdf/meshes."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "nbrdf" / "meshes"


def teapot_ply(n: int = 12) -> Path:
    """The teapot's PLY (made once per tessellation level, then cached)."""
    path = cache_dir() / f"teapot-n{n}-v{VERSION}.ply"
    if path.is_file():
        return path
    verts, tris = tessellate(load_patches(), n)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=".ply", dir=path.parent)
    os.close(fd)
    write_ply(tmp, verts, tris)
    os.replace(tmp, path)
    return path
