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

from nbrdf.neural.body_table import TableSize, table_directions
from nbrdf.neural.coat import coat_eval
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material
from nbrdf.training.belcour import ALPHA_MAX, Atom, atoms_of, belcour_eval_atoms, decompose
from nbrdf.training.belcour_tables import ALPHA_MIN, BelcourTables, default_tables
from nbrdf.viewer.gpu import shaders

#: Atoms the shader holds: four interfaces, each over a medium, and the base.
MAX_ATOMS = 9
#: Atom kinds in the order of their shader constants (``BC_<KIND>``).
ATOM_KINDS = ("interface", "medium", "conductor", "dielectric", "diffuse")
DIELECTRIC_UNIT = 14  # texture unit of the dielectric table (R_down, T_down, R_up, T_up)
SCHLICK_UNIT = 15     # texture unit of the conductor's terms (A, B, C)
#: The largest ior coat.glsl holds (coat_params); a steeper top interface stays in the body.
COAT_IOR_MAX = 3.0


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
    # The lit pass estimates a coat (the top interface over more stack) apart, in closed form
    # (coat.glsl: the same GGX reflection as the model's top lobe; its ior clamp is 3).
    coated = n > 1 and atoms[0].kind == "interface" and float(atoms[0].ior) <= COAT_IOR_MAX
    coat = (min(max(float(atoms[0].roughness), ALPHA_MIN), ALPHA_MAX), float(atoms[0].ior)) if coated else (0.05, 1.0)
    body_w = [0.0 if (coated and k == 0) else w for k, w in enumerate(sample_w)]
    total, body_total = sum(sample_w), sum(body_w)
    sample_w = [w / total for w in sample_w] if total > 0 else [1.0] + [0.0] * (MAX_ATOMS - 1)
    body_w = [w / body_total for w in body_w] if body_total > 0 else [0.0] * MAX_ATOMS
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
        "u_bc_sigma_t": pad([tuple(float(c) for c in a.sigma_t) for a in atoms], (0.0, 0.0, 0.0)),
        "u_bc_f82": pad([tuple(float(c) for c in a.f82) for a in atoms], (0.0, 0.0, 0.0)),
        "u_bc_slab": slab,
        "u_bc_r_above": r_above,
        "u_bc_r_below": r_below,
        "u_bc_eta": eta,
        "u_bc_sample_w": sample_w,
        "u_bc_sample_alpha": sample_alpha,
        "u_bc_body_w": body_w,
        "u_bc_coat": coat,
    }


def coat_of(material: Material, uniforms: dict | None = None) -> tuple[float, float] | None:
    """The (roughness, ior) the lit pass estimates apart as the closed-form coat, or None (no split);
    ``uniforms``: the material's ``belcour_uniforms`` when they are at hand (its ``GpuBrdf``'s)."""
    coat = (uniforms or belcour_uniforms(material))["u_bc_coat"]
    return coat if coat[1] > 1.0 else None


@torch.no_grad()
def bake_body(material: Material, size: TableSize, tables: BelcourTables | None = None,
              uniforms: dict | None = None) -> torch.Tensor:
    """log f (K, M, N, 3) float32 of the model's body -- the whole model less the coat the
    lit pass splits off (``coat_of``) -- at the nodes of a body table of ``size``
    (neural/body_table.py; an ``ordered`` one: the model is not reciprocal): what the
    window's table program shades where the per-pixel model is too slow (viewer/gpu/body_source.py).
    ``uniforms`` as ``coat_of``."""
    if not size.ordered:
        raise NbrdfError("belcour body table: the model is not reciprocal, its table must be ordered")
    wi, wo = (d.reshape(-1, 3).double() for d in table_directions(size))
    f = belcour_eval_atoms(atoms_for_gpu(material), wi, wo, tables or default_tables())
    coat = coat_of(material, uniforms)
    if coat is not None:
        f = f - coat_eval(torch.tensor(coat, dtype=torch.float64), wi, wo)[:, None]
    return f.clamp_min(1e-30).log().clamp(-80.0, 80.0).float().reshape(*size.shape, 3).contiguous()


def table_uniforms(material: Material, uniforms: dict | None = None) -> dict:
    """The table program's uniforms for the model's baked body: the coat (``u_coat``; ior 1:
    none) and the body's lobe strategy as the proxy pdf -- a Gaussian over the projected half
    vector as wide as the strongest remaining lobe's GGX slopes (alpha / sqrt 2), plus a
    cosine share of one half where diffuse slabs scatter (all of it where no lobe is left).
    ``uniforms`` as ``coat_of``."""
    u = uniforms or belcour_uniforms(material)
    coat = u["u_bc_coat"]  # (0.05, 1): no coat
    w = u["u_bc_body_w"]
    if max(w) <= 0.0:
        sigma, cosine = 0.5, 1.0
    else:
        sigma = min(max(u["u_bc_sample_alpha"][w.index(max(w))] / 2 ** 0.5, 0.02), 1.0)
        cosine = 0.5 if any(u["u_bc_slab"]) else 0.1
    return {"u_proxy_sigma": float(sigma), "u_proxy_w": float(cosine), "u_coat": tuple(float(c) for c in coat),
            "u_body_table_ordered": 1}


class BelcourTextures:
    """The model's tables as textures of one context: the dielectric table
    (mu, alpha, eta) as RGBA = R_down, T_down, R_up, T_up and the conductor's terms
    (mu, alpha) as RGB = A, B, C (Schlick's two, the F82 tint's), both float32 and fetched texel by texel."""

    def __init__(self, ctx: moderngl.Context, tables: BelcourTables | None = None):
        t = {k: v.numpy().astype(np.float32) for k, v in (tables or default_tables()).t.items()}
        n_eta, n_alpha, n_mu = t["R_down"].shape
        rt = np.ascontiguousarray(np.stack([t["R_down"], t["T_down"], t["R_up"], t["T_up"]], -1))
        abc = np.ascontiguousarray(np.stack([t["A"], t["B"], t["C"]], -1))
        self.dielectric = ctx.texture3d((n_mu, n_alpha, n_eta), 4, rt.tobytes(), dtype="f4")
        self.schlick = ctx.texture((n_mu, n_alpha), 3, abc.tobytes(), dtype="f4")
        for tex in (self.dielectric, self.schlick):
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            tex.repeat_x = tex.repeat_y = False

    def bindings(self) -> tuple[tuple[str, int, moderngl.Texture], ...]:
        """(sampler uniform, texture unit, texture) of each table."""
        return (("u_bc_dielectric", DIELECTRIC_UNIT, self.dielectric), ("u_bc_schlick", SCHLICK_UNIT, self.schlick))

    def release(self) -> None:
        self.dielectric.release()
        self.schlick.release()
