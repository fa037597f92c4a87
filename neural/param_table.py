"""A texture-mapped material's body baked over its two varying parameters.

A material whose maps vary at most two per-channel parameters (say a medium
albedo ``a`` and a base albedo ``b``) with everything else uniform has, per
colour channel c, a body that depends only on (a_c, b_c): the leaf encoders
and the layering network run per channel (``neural.model.layered_latents``).
So one table f(theta_h, theta_d, phi_d; a, b) serves all three channels and
every texel: the full neural path (leaf encoders, layering, decoder) runs once
per node of an (a, b) grid, each node's body baked as ``neural.body_table``
bakes a uniform material's (log f over sqrt-mapped theta_h, theta_d, folded
phi_d). A renderer then reads (a_c, b_c) from the maps at a hit and
interpolates the table.

This filters the parameters, not the latents: a latent texture's mip chain
averages codes across texels, a parametric table decodes the averaged
parameters. The two agree at the finest level and differ where a footprint
straddles texels of different parameters (the body is not linear in them).

Layout: ``values`` (A, B, K, M, N) float32, log f at node (i, j) =
(lo_a + i (hi_a - lo_a) / (A - 1), lo_b + j (hi_b - lo_b) / (B - 1)) and the
angular nodes of ``body_table.TableSize``.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import torch

from nbrdf.neural.body_table import TableSize, bake_body, table_lookup
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material
from nbrdf.neural.stack import uniform_values

#: Parameters a parametric table may vary: per-channel albedos that enter the body only.
VARIABLE = {("medium", "albedo"), ("diffuse", "albedo")}
#: A layer's parameter, ``layers[i].field`` (a texture reference's place may go on with a channel).
_PLACE = re.compile(r"layers\[(\d+)\]\.(\w+)")
#: The smallest span of a parameter's nodes.
MIN_SPAN = 1e-3


@dataclass(frozen=True)
class ParamGrid:
    """Nodes of a parametric table over its two parameters."""

    a: int = 9
    """Nodes over the first varying parameter (linear over its range)."""
    b: int = 9
    """Nodes over the second (linear over its range; 1 when only one varies)."""


@dataclass(frozen=True)
class TableParams:
    """Which parameters a parametric table varies and over what range."""

    places: tuple[str, ...]
    """The varying parameters, ``layers[i].albedo``, top down (one or two)."""
    ranges: tuple[tuple[float, float], ...]
    """(lo, hi) per varying parameter: the union of its channels' texture ranges."""


def table_params(material: Material, texels=None) -> TableParams:
    """The varying parameters of a texture-mapped material a parametric table can
    hold, over the range its maps use (``texels``, a ``svbrdf.TextureValues``:
    the smallest and largest texel of each parameter's channels, as filtering
    never leaves it; None: the references' ranges), or a one-line
    ``NbrdfError`` saying what it cannot: a texture-mapped
    parameter other than a medium's or a diffuse base's albedo (roughness, ior,
    sigma_t, r0: they change more than one channel's body or the coat), more
    than two varying parameters, or a uniform material."""
    refs = material.textures()
    if not refs:
        raise NbrdfError(f"{material.name}: no texture-mapped parameter (a uniform material takes a plain body table)")
    places: list[str] = []
    ranges: dict[str, tuple[float, float]] = {}
    for place, ref in refs:
        m = _PLACE.match(place)
        if m is None:
            raise NbrdfError(f"{place}: not a layer's parameter")
        key, layer, field = m.group(0), material.layers[int(m.group(1))], m.group(2)
        if (layer.type, field) not in VARIABLE:
            raise NbrdfError(f"{key}: a texture-mapped {layer.type} {field} cannot be a parametric body table's "
                             "parameter (only a medium's or a diffuse base's albedo); use body \"decoder\"")
        if key not in places:
            places.append(key)
        if texels is not None:
            t = texels(ref, key)[:, 0]
            span = (float(t.min()), float(t.max()))
        else:
            span = (float(ref.range[0]), float(ref.range[1]))
        lo, hi = ranges.get(key, span)
        ranges[key] = (min(lo, *span), max(hi, *span))
    if len(places) > 2:
        raise NbrdfError(f"{material.name}: {len(places)} texture-mapped parameters ({', '.join(places)}); a parametric "
                         "body table holds at most two; use body \"decoder\"")
    # a constant map still gets a (tiny) span: the nodes stay distinct
    spans = tuple((lo, max(hi, lo + MIN_SPAN)) for lo, hi in (ranges[p] for p in places))
    return TableParams(tuple(places), spans)



def param_value(material: Material, place: str):
    """The value (number, colour or texture reference) at ``place``, ``layers[i].field``."""
    m = _PLACE.fullmatch(place)
    if m is None:
        raise NbrdfError(f"{place}: not a layer's parameter")
    return getattr(material.layers[int(m.group(1))], m.group(2))

def node_values(params: TableParams, grid: ParamGrid) -> list[torch.Tensor]:
    """The nodes (float64) of each varying parameter."""
    counts = (grid.a, grid.b)[: len(params.places)]
    return [torch.linspace(lo, hi, n, dtype=torch.float64) for (lo, hi), n in zip(params.ranges, counts)]


def node_codes(model, material: Material, params: TableParams, grid: ParamGrid) -> torch.Tensor:
    """Material codes (A, B, 34) at the grid's nodes: the material with its varying
    parameters set to each node (all channels equal), through ``model.stack_latents``
    (what ``brdf_for(uniform material, Method.NEURAL)`` computes); channel 0's code."""
    nodes = node_values(params, grid)
    while len(nodes) < 2:
        nodes.append(torch.zeros(1, dtype=torch.float64))
    ga, gb = torch.meshgrid(nodes[0], nodes[1], indexing="ij")
    cols = {params.places[0]: ga.reshape(-1)}
    if len(params.places) > 1:
        cols[params.places[1]] = gb.reshape(-1)

    def values(v, place: str) -> torch.Tensor:
        if place in cols:
            return cols[place][:, None].expand(-1, 3)
        return uniform_values(v, place)

    codes = model.stack_latents(material, values)  # (A B, 3, 34), channels equal
    return codes[:, 0].reshape(len(nodes[0]), len(nodes[1]), -1)


@torch.no_grad()
def bake_param_body(model, material: Material, params: TableParams, grid: ParamGrid | None = None,
                    size: TableSize | None = None) -> torch.Tensor:
    """(A, B, K, M, N) float32 log f: a texture-mapped material's parametric body
    table over ``params`` (``table_params``; module docstring) at ``grid`` and
    ``size`` (None: their defaults). Three nodes per decoder pass."""
    grid, size = grid or ParamGrid(), size or TableSize()
    codes = node_codes(model, material, params, grid)
    a, b = codes.shape[:2]
    flat = codes.reshape(a * b, -1)
    out = torch.empty(a * b, *size.shape, dtype=torch.float32)
    for s in range(0, a * b, 3):
        z = flat[s:s + 3]
        n = z.shape[0]
        z = torch.cat([z, z[-1:].expand(3 - n, -1)]) if n < 3 else z
        y = bake_body(model.decoder, z, size)  # (K, M, N, 3): one node per channel
        out[s:s + n] = y.permute(3, 0, 1, 2)[:n]
    return out.reshape(a, b, *size.shape)


def param_table_lookup(values: torch.Tensor, params: TableParams, x: torch.Tensor, wi: torch.Tensor,
                       wo: torch.Tensor) -> torch.Tensor:
    """f (P,) at pairs (P, 3) and parameters ``x`` (P, n_params): bilinear in the
    parameters over trilinear log-f angular lookups (``body_table.table_lookup``),
    as the Mitsuba kernel reads it (a CPU twin for tests and error measurements)."""
    A, B = values.shape[:2]
    coords = []
    for d, ((lo, hi), n) in enumerate(zip(params.ranges, (A, B))):
        t = ((x[:, d].double() - lo) / max(hi - lo, 1e-12) * (n - 1)).clamp(0, n - 1) if n > 1 else torch.zeros(len(x))
        i0 = t.floor().long().clamp(0, max(n - 2, 0))
        coords.append((i0, (t - i0).float(), n))
    if len(coords) < 2:
        coords.append((torch.zeros(len(x), dtype=torch.long), torch.zeros(len(x)), 1))
    (ia, fa, na), (ib, fb, nb) = coords
    out = torch.zeros(len(x))
    for da, wa in ((0, 1 - fa), (1, fa)):
        for db, wb in ((0, 1 - fb), (1, fb)):
            i, j = (ia + da).clamp(max=na - 1), (ib + db).clamp(max=nb - 1)
            for key in torch.unique(i * nb + j).tolist():
                sel = (i * nb + j) == key
                f = table_lookup(values[key // nb, key % nb][..., None], wi[sel], wo[sel])[:, 0]
                out[sel] += (wa * wb)[sel] * f
    return out


__all__ = ["ParamGrid", "TableParams", "bake_param_body", "node_codes", "node_values", "param_table_lookup",
           "table_params"]
