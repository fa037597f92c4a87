"""Belcour 2018's layered model on the GPU (shaders/belcour_brdf.glsl), the
previewer's analytic alternative for stacks (``--brdf belcour``).

The model is training/belcour.py's: the same tables (generated and cached by
``BelcourTables.load``) uploaded as float textures, the material's atoms as
uniforms, and what depends on the material alone -- each diffuse slab's
hemispherical reflectances above and below and its ior -- taken from the
Python's own decomposition, so the shader evaluates only what depends on the
directions.
"""
from __future__ import annotations

import moderngl
import numpy as np
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material
from nbrdf.training.belcour import Atom, BelcourTables, atoms_of, decompose, default_tables
from nbrdf.viewer import shaders

#: Atoms the shader holds: four interfaces, each over a medium, and the base.
MAX_ATOMS = 9
#: Atom kinds in the order of their shader constants (``BC_<KIND>``).
ATOM_KINDS = ("interface", "medium", "conductor", "dielectric", "diffuse")
DIELECTRIC_UNIT = 14  # texture unit of the dielectric table (R_down, T_down, R_up, T_up)
SCHLICK_UNIT = 15     # texture unit of the conductor's Schlick terms (A, B)


def kinds_snippet() -> str:
    """The shader's atom-kind constants, from ``ATOM_KINDS`` (``//@INCLUDE belcour_kinds``)."""
    lines = [f"const int BC_MAX_ATOMS = {MAX_ATOMS};"]
    lines += [f"const int BC_{k.upper()} = {i};" for i, k in enumerate(ATOM_KINDS)]
    return "\n".join(lines)


def brdf_snippet() -> str:
    """The ``brdf`` snippet of the Belcour programs."""
    return shaders.read("belcour_brdf.glsl")


def atoms_for_gpu(material: Material) -> list[Atom]:
    """The material's atoms; one-line ``NbrdfError`` for what the model or the shader does not hold."""
    atoms = atoms_of(material)
    if len(atoms) > MAX_ATOMS:
        raise NbrdfError(f"layers: the belcour shader holds at most {MAX_ATOMS} layers, got {len(atoms)}")
    return atoms


def unsupported(material: Material) -> str | None:
    """Why Belcour's model cannot shade ``material`` (one line), or None."""
    try:
        atoms_for_gpu(material)
    except NbrdfError as e:
        return str(e)
    return None


def belcour_uniforms(material: Material, tables: BelcourTables | None = None) -> dict:
    """The uniforms of shaders/belcour_brdf.glsl for a uniform material."""
    atoms = atoms_for_gpu(material)
    dec = decompose(atoms, torch.tensor([1.0], dtype=torch.float64), tables or default_tables())
    n = len(atoms)
    pad = lambda xs, v: [*xs, *[v] * (MAX_ATOMS - n)]
    slab = [0] * MAX_ATOMS
    r_above, r_below = [(0.0, 0.0, 0.0)] * MAX_ATOMS, [(0.0, 0.0, 0.0)] * MAX_ATOMS
    eta = [1.0] * MAX_ATOMS
    # the lit pass's lobe strategy: a mixture of the lobes' GGX at their normal-incidence roughness,
    # weighted by their energy there (no lobe: one of roughness 1)
    sample_w, sample_alpha = [0.0] * MAX_ATOMS, [1.0] * MAX_ATOMS
    for lobe in dec.lobes:
        k = next(i for i, a in enumerate(atoms) if a is lobe.atom)
        sample_w[k], sample_alpha[k] = float(lobe.energy.mean()), float(lobe.roughness[0])
    total = sum(sample_w)
    sample_w = [w / total for w in sample_w] if total > 0 else [1.0] + [0.0] * (MAX_ATOMS - 1)
    for s in dec.slabs:
        k = next(i for i, a in enumerate(atoms) if a is s.atom)
        slab[k], eta[k] = 1, float(s.eta)
        r_above[k] = tuple(float(x) for x in s.r_above)
        r_below[k] = tuple(float(x) for x in s.r_below)
    return {
        "u_bc_n": n,
        "u_bc_kind": pad([ATOM_KINDS.index(a.kind) for a in atoms], 0),
        "u_bc_roughness": pad([float(a.roughness) for a in atoms], 0.0),
        "u_bc_ior": pad([float(a.ior) for a in atoms], 1.0),
        "u_bc_color": pad([tuple(float(c) for c in a.color) for a in atoms], (0.0, 0.0, 0.0)),
        "u_bc_sigma_t": pad([float(a.sigma_t) for a in atoms], 0.0),
        "u_bc_slab": slab,
        "u_bc_r_above": r_above,
        "u_bc_r_below": r_below,
        "u_bc_eta": eta,
        "u_bc_sample_w": sample_w,
        "u_bc_sample_alpha": sample_alpha,
    }


class BelcourTextures:
    """The model's tables as textures of one context: the dielectric table
    (mu, alpha, eta) as RGBA = R_down, T_down, R_up, T_up and the Schlick terms
    (mu, alpha) as RG = A, B, both float32 and fetched texel by texel."""

    def __init__(self, ctx: moderngl.Context, tables: BelcourTables | None = None):
        t = {k: v.numpy().astype(np.float32) for k, v in (tables or default_tables()).t.items()}
        n_eta, n_alpha, n_mu = t["R_down"].shape
        rt = np.ascontiguousarray(np.stack([t["R_down"], t["T_down"], t["R_up"], t["T_up"]], -1))
        ab = np.ascontiguousarray(np.stack([t["A"], t["B"]], -1))
        self.dielectric = ctx.texture3d((n_mu, n_alpha, n_eta), 4, rt.tobytes(), dtype="f4")
        self.schlick = ctx.texture((n_mu, n_alpha), 2, ab.tobytes(), dtype="f4")
        for tex in (self.dielectric, self.schlick):
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            tex.repeat_x = tex.repeat_y = False

    def bindings(self) -> tuple[tuple[str, int, moderngl.Texture], ...]:
        """(sampler uniform, texture unit, texture) of each table."""
        return (("u_bc_dielectric", DIELECTRIC_UNIT, self.dielectric), ("u_bc_schlick", SCHLICK_UNIT, self.schlick))

    def release(self) -> None:
        self.dielectric.release()
        self.schlick.release()
