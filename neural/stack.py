"""Materials as batched layer stacks: the one translation of ``Material``.

A ``Stack`` holds N stacks of the same shape -- L interfaces top to bottom,
each a rough dielectric over a medium slab (sigma_t 0 and albedo 0: no
medium), then one base -- as tensors with C colour channels. Every consumer
reads it: the Monte Carlo simulator (``training.reference.simulator_params``),
the leaf encoders and layering network (``neural.model.layered_latents``) and
the closed-form GLSL (``viewer.materials_gpu.analytic_uniforms``).

The data sets store single-channel stacks as one flat parameter vector per
BRDF (``PARAM_NAMES``); ``params_to_stack`` / ``stack_to_params`` are its
decode / encode pair and ``params_to_material`` the material it describes.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any, Callable

import torch

from nbrdf.neural.anisotropy import anisotropy_vector, geometric_alpha
from nbrdf.neural.coat import NO_COAT
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import CONDUCTOR, DIELECTRIC, DIFFUSE, MEDIUM
from nbrdf.neural.material import FORMAT as FORMAT_MATERIAL
from nbrdf.neural.material import Conductor, Dielectric, Diffuse, LatentBase, Material, Measured, Medium, parse_material

Tensor = torch.Tensor

#: The data sets' stack classes (SPEC section 9), in the order of their class index; the paper's six,
#: then the deep stacks (3 and 4 coats over a conductor) that train the recursion past three layers (issue 40).
CLASSES = (CONDUCTOR, DIELECTRIC, "two_layer", "three_layer", "diffuse_base", "three_layer_diffuse",
           "four_layer", "five_layer")
#: The paper's classes (the sampler's and the decoder's mixtures draw from these).
PAPER_CLASSES = CLASSES[:6]
#: Classes whose base is a Lambertian (base_value = its albedo); the others end in a conductor.
DIFFUSE_BASED = ("diffuse_base", "three_layer_diffuse")
THREE_LAYERED = ("three_layer", "three_layer_diffuse")
DEEP = ("four_layer", "five_layer")
#: Interfaces (each over its medium slab) above the base, per stack class.
COATS = {"two_layer": 1, "three_layer": 2, "diffuse_base": 1, "three_layer_diffuse": 2, "four_layer": 3,
         "five_layer": 4}

#: The flat single-channel parameter vector of the data sets' files; unused columns hold 0. The first 11
#: are the paper's classes' (files written before the deep classes have only those: ``pad_params``).
PARAM_NAMES = ("class", "top_roughness", "top_ior", "albedo_1", "sigma_t_1", "mid_roughness", "mid_ior",
               "albedo_2", "sigma_t_2", "base_roughness", "base_value",
               "roughness_3", "ior_3", "albedo_3", "sigma_t_3", "roughness_4", "ior_4", "albedo_4", "sigma_t_4")
P = {n: i for i, n in enumerate(PARAM_NAMES)}
PAPER_WIDTH = 11
INTERFACE_COLUMNS = (("top_roughness", "top_ior", "albedo_1", "sigma_t_1"),
                     ("mid_roughness", "mid_ior", "albedo_2", "sigma_t_2"),
                     ("roughness_3", "ior_3", "albedo_3", "sigma_t_3"),
                     ("roughness_4", "ior_4", "albedo_4", "sigma_t_4"))

#: values(parameter, place) -> (P, 3) tensor: how a parameter becomes numbers
#: (one row for a uniform parameter, one per texel for a texture-mapped one).
ParamValues = Callable[[object, str], Tensor]


@dataclass
class Stack:
    """N stacks of one shape with C colour channels (the simulator's and the
    networks' input). Shapes: ``roughness``, ``ior`` (N, L);
    ``albedo``, ``sigma_t`` (N, L, C); ``base_roughness`` (N,); ``base_r0``,
    ``base_f82`` (a conductor's F82 tint) and ``base_albedo`` (N, C); ``base_ior`` (N,). Base parameters a base kind
    does not have are None; a latent or measured base keeps its file in
    ``base_path``. Anisotropy (SPEC section 10): ``anisotropy`` (N, L), ``base_anisotropy`` (N,) of a
    conductor or dielectric base, ``rotation`` (N,) in degrees; ``material_stack`` fills them (zeros when
    isotropic), None (stacks made elsewhere) reads as isotropic."""

    roughness: Tensor
    ior: Tensor
    albedo: Tensor
    sigma_t: Tensor
    base: str
    base_roughness: Tensor | None = None
    base_r0: Tensor | None = None
    base_f82: Tensor | None = None
    base_ior: Tensor | None = None
    base_albedo: Tensor | None = None
    base_path: Path | None = None
    anisotropy: Tensor | None = None
    """(N, L) each interface's anisotropy a (None: all 0)"""
    base_anisotropy: Tensor | None = None
    """(N,) a conductor or dielectric base's anisotropy (None: 0, or a base kind without one)"""
    rotation: Tensor | None = None
    """(N,) the material's anisotropy_rotation in degrees, shared by every interface (None: 0)"""

    @property
    def is_anisotropic(self) -> bool:
        """Whether any interface or the base has a non-zero anisotropy (the rotation alone changes nothing)."""
        return any(t is not None and bool((t != 0).any()) for t in (self.anisotropy, self.base_anisotropy))

    def without_scattering(self) -> "Stack":
        """This stack with every medium's albedo 0: its light is what never scattered in a medium."""
        return replace(self, albedo=torch.zeros_like(self.albedo))

    def body_scattering_depth(self) -> Tensor:
        """(N,) the scattering optical depth (albedo times sigma_t, means over channels) of the media above the
        highest anisotropic interface under the coat (the body's; 0 where there is none)."""
        n, dtype = self.n, self.roughness.dtype
        a_l = self.anisotropy if self.anisotropy is not None else torch.zeros_like(self.roughness)
        a_b = self.base_anisotropy if self.base_anisotropy is not None else torch.zeros(n, dtype=dtype)
        if not self.layers:
            return torch.zeros(n, dtype=dtype)
        below = [a_l[:, j] for j in range(1, self.layers)] + [a_b]  # under the coat, top down
        depth = [(self.albedo[:, j].mean(-1) * self.sigma_t[:, j].mean(-1)).to(dtype) for j in range(self.layers)]
        out = torch.zeros(n, dtype=dtype)
        for i in reversed(range(len(below))):  # the highest non-zero one wins
            out = torch.where(below[i] != 0, sum(depth[:i + 1], torch.zeros(n, dtype=dtype)), out)
        return out

    def isotropic_equivalent(self) -> tuple["Stack", Tensor, Tensor]:
        """(stack, coat vectors (N, 2), body tails (N, 3)): this stack with each anisotropic alpha replaced
        by its geometric mean (what the leaf encoders and the layering network see), and the anisotropy
        vectors of a code's tail (``neural.anisotropy``): the coat's (the top interface's, as ``coat``) and
        the body's, that of the highest anisotropic interface below the coat (a documented
        approximation, docs/decisions/116), lessened by the media's scattering above it (exp(-2 tau albedo), the
        unscattered share of a round trip), with that interface's geometric-mean alpha (its masking). A stack
        whose media scatter little may be split instead (``without_scattering``, ``neural.scattered_glow``)."""
        n, dtype = self.n, self.roughness.dtype
        rot = self.rotation if self.rotation is not None else torch.zeros(n, dtype=dtype)
        a_l = self.anisotropy if self.anisotropy is not None else torch.zeros_like(self.roughness)
        a_b = self.base_anisotropy if self.base_anisotropy is not None else torch.zeros(n, dtype=dtype)
        changes: dict[str, Any] = {"roughness": geometric_alpha(self.roughness, a_l),
                                   "anisotropy": torch.zeros_like(a_l), "base_anisotropy": torch.zeros_like(a_b)}
        if self.base_roughness is not None:
            changes["base_roughness"] = geometric_alpha(self.base_roughness, a_b)
        below = [a_l[:, j] for j in range(1, self.layers)] + [a_b]  # under the coat, top down
        if self.layers:
            coat_a = a_l[:, 0]
        else:  # a bare dielectric is all coat; any other base is all body
            coat_a = a_b if self.base == DIELECTRIC else torch.zeros(n, dtype=dtype)
            below = [torch.zeros(n, dtype=dtype)] if self.base == DIELECTRIC else [a_b]
        r_l = changes["roughness"]
        alphas_below = [r_l[:, j] for j in range(1, self.layers)] + [changes.get("base_roughness", NO_COAT[0] * torch.ones(n, dtype=dtype))]
        if not self.layers:
            alphas_below = alphas_below[-1:]
        body_a = torch.zeros(n, dtype=dtype)
        body_alpha = torch.full((n,), NO_COAT[0], dtype=dtype)
        for i in reversed(range(len(below))):  # the highest non-zero one wins
            col, alpha = below[i], alphas_below[i]
            body_a = torch.where(col != 0, col, body_a)
            body_alpha = torch.where(col != 0, alpha.to(dtype), body_alpha)
        # light scattered in a medium on its way to the interface and back comes out isotropic: the body keeps the
        # anisotropy of the unscattered share, exp(-2 tau albedo) at normal incidence (decision 116)
        body_a = body_a * torch.exp(-2.0 * self.body_scattering_depth())
        return (replace(self, **changes), anisotropy_vector(coat_a, rot).to(dtype),
                torch.cat([anisotropy_vector(body_a, rot).to(dtype), body_alpha[:, None]], -1))

    @property
    def n(self) -> int:
        """Number of stacks."""
        return self.roughness.shape[0]

    @property
    def layers(self) -> int:
        """Interfaces above the base (L)."""
        return self.roughness.shape[1]

    @property
    def channels(self) -> int:
        """Colour channels (C)."""
        return self.albedo.shape[2]

    def coat(self) -> Tensor:
        """(N, 2) (roughness, ior) of the top interface, the clear coat of the
        coat split (``neural.coat``): the first interface, a bare dielectric
        itself, ``NO_COAT`` for other bases."""
        if self.layers:
            return torch.stack([self.roughness[:, 0], self.ior[:, 0]], -1)
        if self.base == DIELECTRIC:
            return torch.stack([self.base_param("base_roughness"), self.base_param("base_ior")], -1)

        return torch.tensor(NO_COAT, dtype=self.roughness.dtype).expand(self.n, 2)

    def base_param(self, name: str) -> Tensor:
        """A parameter of the base (``base_roughness``, ``base_r0``, ``base_ior``,
        ``base_albedo``); one line when this stack's base kind has none."""
        value = getattr(self, name)
        if value is None:
            raise NbrdfError(f"a {self.base} base has no {name.removeprefix('base_')}")
        return value

    def tensors(self) -> dict[str, Tensor]:
        """The tensor fields that are set, by name."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if isinstance(getattr(self, f.name), Tensor)}

    def map(self, fn: Callable[[Tensor], Tensor]) -> "Stack":
        """A copy with ``fn`` applied to every tensor (all have N leading)."""
        changes: dict[str, Any] = {k: fn(v) for k, v in self.tensors().items()}
        return replace(self, **changes)

    def repeat_interleave(self, k: int) -> "Stack":
        """Every stack repeated k times in place (N k stacks)."""
        return self.map(lambda t: t.repeat_interleave(k, dim=0))

    def expand(self, n: int) -> "Stack":
        """n copies of a single stack (N = 1)."""
        if self.n != 1:
            raise ValueError(f"expand needs one stack, got {self.n}")
        return self.map(lambda t: t.expand(n, *t.shape[1:]).contiguous())

    def per_channel(self) -> "Stack":
        """The same stacks as N C single-channel stacks (channel fastest)."""
        C = self.channels
        out: dict[str, Any] = {}
        for k, v in self.tensors().items():
            if k in ("albedo", "sigma_t"):
                out[k] = v.permute(0, 2, 1).reshape(self.n * C, self.layers, 1)
            elif k in ("base_r0", "base_f82", "base_albedo"):
                out[k] = v.reshape(-1, 1)
            else:
                out[k] = v.repeat_interleave(C, dim=0)
        return replace(self, **out)


# --- materials -> stacks -------------------------------------------------------------------
#: What a one-line error about a texture-mapped parameter suggests by default.
UNIFORM_HINT = "evaluate a uniform material (or one texel of it)"


def uniform_values(v, place: str, hint: str = UNIFORM_HINT) -> Tensor:
    """A uniform parameter (scalar or per channel) as a (1, 3) float64 tensor;
    a texture reference is a one-line error naming ``place`` and ending in ``hint``."""
    try:
        return torch.tensor([Material.rgb(v)], dtype=torch.float64)
    except NbrdfError:
        raise NbrdfError(f"{place}: a texture-mapped parameter has no single value; {hint}") from None


def material_stack(material: Material, values: ParamValues | None = None,
                   dtype: torch.dtype = torch.float64) -> Stack:
    """A material's stack with three channels. Uniform parameters give one
    stack (N = 1); with ``values`` a texture-mapped material gives one per
    texel. Shared parameters (roughness, ior) take channel 0."""
    values = values or uniform_values
    # the base first, then the interfaces bottom up: a bad parameter is named in that order
    base, place = material.base, f"layers[{len(material.layers) - 1}]"
    kw: dict[str, Any] = {}
    if isinstance(base, Conductor):
        kw = dict(base_roughness=values(base.roughness, f"{place}.roughness")[:, 0].to(dtype),
                  base_r0=values(base.r0, f"{place}.r0").to(dtype),
                  base_f82=values(base.f82_tint, f"{place}.f82_tint").to(dtype),
                  base_anisotropy=values(base.anisotropy, f"{place}.anisotropy")[:, 0].to(dtype))
    elif isinstance(base, Diffuse):
        kw = dict(base_roughness=torch.full((1,), 0.5, dtype=dtype),
                  base_albedo=values(base.albedo, f"{place}.albedo").to(dtype))
    elif isinstance(base, Dielectric):
        kw = dict(base_roughness=values(base.roughness, f"{place}.roughness")[:, 0].to(dtype),
                  base_ior=values(base.ior, f"{place}.ior")[:, 0].to(dtype),
                  base_anisotropy=values(base.anisotropy, f"{place}.anisotropy")[:, 0].to(dtype))
    elif isinstance(base, (LatentBase, Measured)):
        kw = dict(base_path=base.resolved)
    elif isinstance(base, Medium):  # the parser forbids it; guard all the same
        raise NbrdfError("a medium cannot be the base")
    else:
        raise NbrdfError(f"{place}: unknown base {type(base).__name__}")
    kind = base.type
    interfaces = material.interfaces
    places = [i for i, layer in enumerate(material.layers) if isinstance(layer, Dielectric)][: len(interfaces)]
    cols: dict[str, list[Tensor]] = {"roughness": [], "ior": [], "albedo": [], "sigma_t": [], "anisotropy": []}
    zero = torch.zeros(1, 3, dtype=dtype)
    for (iface, med), i in reversed(list(zip(interfaces, places))):
        cols["roughness"].append(values(iface.roughness, f"layers[{i}].roughness")[:, 0].to(dtype))
        cols["ior"].append(values(iface.ior, f"layers[{i}].ior")[:, 0].to(dtype))
        cols["anisotropy"].append(values(iface.anisotropy, f"layers[{i}].anisotropy")[:, 0].to(dtype))
        if med is not None:
            cols["albedo"].append(values(med.albedo, f"layers[{i + 1}].albedo").to(dtype))
            cols["sigma_t"].append(values(med.sigma_t, f"layers[{i + 1}].sigma_t").to(dtype))
        else:
            cols["albedo"].append(zero)
            cols["sigma_t"].append(zero)
    cols = {k: v[::-1] for k, v in cols.items()}  # top down
    tensors = [t for c in cols.values() for t in c] + [v for v in kw.values() if isinstance(v, Tensor)]
    n = max([t.shape[0] for t in tensors], default=1)
    grow = lambda t: t.expand(n, *t.shape[1:])
    L = len(interfaces)
    return Stack(
        roughness=torch.stack([grow(t) for t in cols["roughness"]], 1) if L else torch.zeros(n, 0, dtype=dtype),
        ior=torch.stack([grow(t) for t in cols["ior"]], 1) if L else torch.zeros(n, 0, dtype=dtype),
        albedo=torch.stack([grow(t) for t in cols["albedo"]], 1) if L else torch.zeros(n, 0, 3, dtype=dtype),
        sigma_t=torch.stack([grow(t) for t in cols["sigma_t"]], 1) if L else torch.zeros(n, 0, 3, dtype=dtype),
        anisotropy=torch.stack([grow(t) for t in cols["anisotropy"]], 1) if L else torch.zeros(n, 0, dtype=dtype),
        rotation=torch.full((n,), float(material.anisotropy_rotation), dtype=dtype),
        base=kind, **{k: grow(v) if isinstance(v, Tensor) else v for k, v in kw.items()})


# --- the data sets' flat vectors -----------------------------------------------------------
def params_coats(params: Tensor) -> Tensor:
    """(K, 2) clear coats (``Stack.coat``) of K parameter vectors of any
    classes at once: the top interface's (roughness, ior), ``NO_COAT`` for a
    conductor (every other class stores its top interface, or the bare
    dielectric itself, in the top columns)."""
    params = torch.as_tensor(params)
    c = torch.stack([params[:, P["top_roughness"]], params[:, P["top_ior"]]], -1)
    bare = params[:, P["class"]].round().long() == CLASSES.index(CONDUCTOR)
    return torch.where(bare[:, None], torch.tensor(NO_COAT, dtype=c.dtype), c)


def pad_params(params: Tensor) -> Tensor:
    """Parameter vectors of a file written before the deep classes (K, 11), zero-padded to today's width."""
    params = torch.as_tensor(params)
    if params.dim() == 2 and params.shape[1] == PAPER_WIDTH:
        return torch.cat([params, params.new_zeros(params.shape[0], len(PARAM_NAMES) - PAPER_WIDTH)], 1)
    return params


def params_to_stack(params: Tensor) -> Stack:
    """Decodes K single-channel parameter vectors (K, 19; the paper's 11 are padded) of ONE class into
    a stack (C = 1), float64."""
    params = pad_params(params).double()
    if params.dim() != 2 or params.shape[1] != len(PARAM_NAMES):
        raise NbrdfError(f"stack parameters must be (K, {len(PARAM_NAMES)}), got {tuple(params.shape)}")
    codes = params[:, P["class"]].round().long().unique()
    if codes.numel() != 1 or not 0 <= int(codes[0]) < len(CLASSES):
        raise NbrdfError(f"stack parameters: expected one class of {', '.join(CLASSES)}, got codes {codes.tolist()}")
    cls = CLASSES[int(codes[0])]
    col = lambda c: params[:, P[c]]
    k = params.shape[0]
    empty: dict[str, Any] = dict(roughness=params.new_zeros(k, 0), ior=params.new_zeros(k, 0), albedo=params.new_zeros(k, 0, 1),
                 sigma_t=params.new_zeros(k, 0, 1))
    if cls == CONDUCTOR:
        return Stack(**empty, base=CONDUCTOR, base_roughness=col("base_roughness"),
                     base_r0=col("base_value")[:, None], base_f82=torch.ones_like(col("base_value")[:, None]))
    if cls == DIELECTRIC:
        return Stack(**empty, base=DIELECTRIC, base_roughness=col("top_roughness"), base_ior=col("top_ior"))
    used = INTERFACE_COLUMNS[: COATS[cls]]
    st = lambda j: torch.stack([col(c[j]) for c in used], -1)
    kw: dict[str, Any] = dict(roughness=st(0), ior=st(1), albedo=st(2)[..., None], sigma_t=st(3)[..., None],
              base_roughness=col("base_roughness"))
    if cls in DIFFUSE_BASED:
        return Stack(**kw, base=DIFFUSE, base_albedo=col("base_value")[:, None])
    return Stack(**kw, base=CONDUCTOR, base_r0=col("base_value")[:, None],
                 base_f82=torch.ones_like(col("base_value")[:, None]))


def stack_class(stack: Stack) -> str:
    """The data-set class of a stack's shape."""
    L = stack.layers
    if L == 0 and stack.base in (CONDUCTOR, DIELECTRIC):
        return stack.base
    if stack.base == CONDUCTOR and 1 <= L <= 4:
        return ("two_layer", "three_layer", "four_layer", "five_layer")[L - 1]
    if stack.base == DIFFUSE and L in (1, 2):
        return ("diffuse_base", "three_layer_diffuse")[L - 1]
    raise NbrdfError(f"a stack of {L} interface(s) over a {stack.base} base is none of the data-set classes")


def stack_to_params(stack: Stack) -> Tensor:
    """Encodes single-channel stacks (C = 1) as parameter vectors (N, 19), float64."""
    if stack.channels != 1:
        raise NbrdfError(f"the parameter vector holds one colour channel; the stack has {stack.channels}")
    cls = stack_class(stack)
    p = torch.zeros(stack.n, len(PARAM_NAMES), dtype=torch.float64)
    p[:, P["class"]] = CLASSES.index(cls)
    if cls == DIELECTRIC:
        p[:, P["top_roughness"]], p[:, P["top_ior"]] = stack.base_param("base_roughness"), stack.base_param("base_ior")
        return p
    for j, names in enumerate(INTERFACE_COLUMNS[: stack.layers]):
        for name, t in zip(names, (stack.roughness[:, j], stack.ior[:, j], stack.albedo[:, j, 0],
                                      stack.sigma_t[:, j, 0])):
            p[:, P[name]] = t
    if stack.base == CONDUCTOR:
        if stack.base_f82 is not None and not bool((stack.base_f82 == 1).all()):
            raise NbrdfError("the data sets' parameter vectors hold no F82 tint (a conductor with f82_tint 1 only)")
        p[:, P["base_roughness"]] = stack.base_param("base_roughness")
        p[:, P["base_value"]] = stack.base_param("base_r0")[:, 0]
    else:
        p[:, P["base_value"]] = stack.base_param("base_albedo")[:, 0]
    return p


def params_to_material(p: Tensor, name: str = "sample") -> Material:
    """The material (scalar colours) that one single-channel parameter vector describes."""
    s = params_to_stack(torch.as_tensor(p).reshape(1, -1))
    f = lambda t: float(t.reshape(-1)[0])
    layers: list[dict] = []
    for j in range(s.layers):
        layers += [{"type": DIELECTRIC, "roughness": f(s.roughness[:, j]), "ior": f(s.ior[:, j])},
                   {"type": MEDIUM, "albedo": f(s.albedo[:, j]), "sigma_t": f(s.sigma_t[:, j, 0])}]
    if s.base == CONDUCTOR:
        layers.append({"type": CONDUCTOR, "roughness": f(s.base_roughness), "r0": f(s.base_r0)})
    elif s.base == DIFFUSE:
        layers.append({"type": DIFFUSE, "albedo": f(s.base_albedo)})
    else:
        layers.append({"type": DIELECTRIC, "roughness": f(s.base_roughness), "ior": f(s.base_ior)})
    return parse_material({"format": FORMAT_MATERIAL, "name": name, "layers": layers})
