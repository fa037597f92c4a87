"""The two Mitsuba BSDF plugins of an nbrdf material (SPEC section 8).

``nbrdf``: the neural material as the previewer shows it, evaluated inside
Mitsuba's kernel (``kernel.CodeKernel``). ``nbrdf_reference``: the Monte
Carlo ground truth, a fresh unbiased estimate of f per query from the
project's walk (``training.reference.reference_eval``), called per wavefront
through numpy, so it needs Dr.Jit's evaluated mode (``wavefront_mode``).

Mitsuba's conventions: ``si.wi`` is the project's ``wo`` (toward the
viewer), the queried direction is the project's ``wi`` (toward the light);
``eval`` returns f(wi, wo) cos(theta_i). Both are one-sided reflection BSDFs.
"""
from __future__ import annotations

import contextlib
import itertools

import drjit as dr
import mitsuba as mi
import numpy as np

from nbrdf.mitsuba.kernel import Coat, CodeKernel, DecoderKernel, Proxy, TableBody, TexturedCodeKernel
from nbrdf.mitsuba.normal_map import BentDirections, material_normal_map

FLAGS_GLOSSY = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
#: A material without a coat whose proxy gives the cosine lobe more than this share is reported
#: to Mitsuba as a diffuse lobe, else as a glossy one.
DIFFUSE_W = 0.9


class PluginError(RuntimeError):
    """Bad input to a plugin (one line: what is wrong and where)."""


def _prop(props, key: str, default=None):
    return props[key] if key in props else default


#: How the ``nbrdf`` plugin gets a material's body: the shipped decoder per query, or its baked table.
BODIES = ("decoder", "table")


def _body_table_size():
    """The grid of ``body: "table"``: 128 x 64 x 32 nodes (3 MB). Against the decoder on
    random directions (coated copper, car paint, rough gold, varnished gold): mean relative
    error 0.08-0.15 %, 99th percentile 0.8-1.5 %; the previewer's 64 x 32 x 16 is 4x that."""
    from nbrdf.neural.body_table import TableSize

    return TableSize(128, 64, 32)


def code_kernel(material: str, weights: str | None = None, pixel_angle: float = 0.0,
                body: str = "decoder") -> CodeKernel:
    """The Dr.Jit kernel of a material JSON or code file (``neural.material_code``);
    a texture-mapped material JSON gives a ``TexturedCodeKernel`` over its
    latent texture (mip-mapped by the ray cone of ``pixel_angle`` radians).
    ``body``: ``"decoder"`` (the decoder per query) or ``"table"`` (the body
    baked once into a table, ``TableBody``; uniform materials only)."""
    from nbrdf.neural.errors import NbrdfError
    from nbrdf.neural.material_code import code_parts, load_code

    if body not in BODIES:
        raise PluginError(f'nbrdf: body {body!r} is not one of {", ".join(map(repr, BODIES))}')
    try:
        if str(material).lower().endswith(".json"):
            from nbrdf.neural.material import load_material

            m = load_material(material)
            if m.is_textured:
                if body == "table":
                    raise PluginError(f'nbrdf: {material}: a texture-mapped material has a body per texel, which '
                                      'one table cannot hold; use body "decoder"')
                return _textured_kernel(m, weights, pixel_angle)
        model, code = load_code(material, weights)
        (r, ior), (sigma, w) = code_parts(model, code)
        if body == "table":
            decoder = TableBody.from_torch(model.decoder, code, _body_table_size())
        else:
            decoder = DecoderKernel.from_torch(model.decoder, code)
    except (NbrdfError, ValueError) as e:
        raise PluginError(f"nbrdf: {e}") from None
    return CodeKernel(decoder, Coat(float(r), float(ior)), Proxy(float(sigma), float(w)))


SLOW_SYMBOLIC = ("nbrdf: traced symbolically on the LLVM backend, where Dr.Jit loads every decoder weight inside a "
                 "symbolic call with a gather (about 10x slower); render inside nbrdf.mitsuba.wavefront_mode()")
_warned_symbolic = False


def wants_wavefront(body: str = "decoder") -> bool:
    """Whether ``nbrdf`` renders faster in ``wavefront_mode()`` under the
    variant in force: on the LLVM backend, Dr.Jit's cooperative vectors
    turn each weight load inside a symbolic call into a per-lane gather,
    while an evaluated call runs the decoder at the top level of its kernel
    (broadcast loads). CUDA's cooperative vectors have no such cost. A body
    read from a table (``body="table"``) has no weights: symbolic is faster."""
    return body == "decoder" and mi.variant() is not None and mi.variant().startswith("llvm")


def _warn_if_slow(body: str) -> None:
    """One warning per process when the decoder is traced where it runs slowly."""
    global _warned_symbolic
    if not _warned_symbolic and body == "decoder" and dr.flag(dr.JitFlag.SymbolicScope) and dr.flag(dr.JitFlag.SymbolicCalls) \
            and wants_wavefront():
        _warned_symbolic = True
        mi.Log(mi.LogLevel.Warn, SLOW_SYMBOLIC)


def _textured_kernel(material, weights: str | None, pixel_angle: float) -> TexturedCodeKernel:
    """The latent texture of a texture-mapped material (``neural.svbrdf``) as a kernel."""
    from nbrdf.mitsuba.textures import LatentTextureKernel
    from nbrdf.neural.coat import NO_COAT
    from nbrdf.neural.model import default_model, load_model
    from nbrdf.neural.svbrdf import latent_texture

    model = load_model(weights) if weights else default_model()
    tex = latent_texture(model, material)
    mean = tex.levels[-1][0, 0]  # (3, 34): the 1 x 1 mip level
    spec = model.decoder.spec
    kernel = LatentTextureKernel(model.decoder, tex, spec.coat and tex.levels[0].shape[-1] == spec.code, NO_COAT)
    sigma, w = model.proxy(mean)
    return TexturedCodeKernel(DecoderKernel.from_torch(model.decoder, mean), kernel, Proxy(sigma, w), pixel_angle)


class NbrdfBSDF(mi.BSDF):
    """``{"type": "nbrdf", "material": PATH[, "weights": BUNDLE, "pixel_angle": RADIANS, "body": "decoder"|"table"]}``:
    ``body`` "table" reads a uniform material's body from a table baked once
    at load (``TableBody``: noise-free, a small interpolation bias against the
    decoder, and no weights to load, so it renders fast in symbolic mode);
    the coat and the sampler are the same either way (the sampler's pdf does
    not depend on the body). ``pixel_angle`` (texture-mapped materials) is the camera's angle per pixel,
    whose ray cone picks the latent texture's (and the normal map's) mip level
    per hit (0: the finest). A material JSON's ``normal_map`` bends the shading
    frame per hit (``normal_map.py``)."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        if not dr.is_jit_v(mi.Float):
            raise PluginError(f"nbrdf: the variant {mi.variant()} is not a JIT variant; use llvm_ad_rgb "
                              "or cuda_ad_rgb")
        path = _prop(props, "material")
        if path is None:
            raise PluginError('nbrdf: the property "material" (a material JSON or a code file) is missing')
        self.path = str(path)
        self.pixel_angle = float(_prop(props, "pixel_angle", 0.0))
        self.body = str(_prop(props, "body", "decoder"))
        self.kernel = code_kernel(self.path, _prop(props, "weights"), self.pixel_angle, self.body)
        self.normal_map = material_normal_map(self.path, "nbrdf")
        textured = isinstance(self.kernel, TexturedCodeKernel)
        diffuse = not textured and not self.kernel.coat.present and self.kernel.proxy.w > DIFFUSE_W
        self._lobe = mi.BSDFFlags.DiffuseReflection if diffuse else mi.BSDFFlags.GlossyReflection
        self.m_components = [self._lobe | mi.BSDFFlags.FrontSide]
        self.m_flags = self.m_components[0]

    def _enabled(self, ctx, active):
        """``active`` where the context asks for this BSDF's one component."""
        return active & ctx.is_enabled(self._lobe, 0)

    def _frame(self, si):
        """The hit's bent shading frame (None: no normal map)."""
        return None if self.normal_map is None else self.normal_map.frame(si, self.pixel_angle)

    def eval(self, ctx, si, wo, active=True):
        _warn_if_slow(self.body)
        d = BentDirections(self._frame(si), si.wi, wo)
        f = self.kernel.eval(d.wo, d.wi, si)
        return dr.select(self._enabled(ctx, active) & d.ok, f * mi.Frame3f.cos_theta(d.wo), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        d = BentDirections(self._frame(si), si.wi, wo)
        return dr.select(self._enabled(ctx, active) & d.ok, self.kernel.pdf(d.wi, d.wo, si), 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        _warn_if_slow(self.body)
        frame = self._frame(si)
        wi = si.wi if frame is None else frame.to_local(si.wi)
        wo_bent, pdf = self.kernel.sample(wi, sample1, sample2.x, sample2.y, si)
        wo = wo_bent if frame is None else frame.to_world(wo_bent)
        d = BentDirections(frame, si.wi, wo)
        ok = self._enabled(ctx, active) & (pdf > 0) & d.ok
        bs = dr.zeros(mi.BSDFSample3f)
        bs.wo = wo
        bs.pdf = dr.select(ok, pdf, 0.0)
        bs.eta = 1.0
        bs.sampled_component = mi.UInt32(0)
        bs.sampled_type = mi.UInt32(+self._lobe)
        f = self.kernel.eval(wo_bent, wi, si) * mi.Frame3f.cos_theta(wo_bent)
        return bs, dr.select(ok, f / dr.select(ok, pdf, 1.0), 0.0)

    def traverse(self, cb):
        pass

    def to_string(self):
        c, p = self.kernel.coat, self.kernel.proxy
        if isinstance(self.kernel, TexturedCodeKernel):
            return (f"NbrdfBSDF[material={self.path!r}, latent texture {self.kernel.texture.size}, "
                    f"pixel_angle {self.kernel.pixel_angle:g}, proxy=(sigma {p.sigma:g}, w {p.w:g})]")
        nmap = "" if self.normal_map is None else f", normal_map={self.normal_map.path!r}"
        return (f"NbrdfBSDF[material={self.path!r}, body={self.body}, coat=(roughness {c.roughness:g}, ior {c.ior:g}), "
                f"proxy=(sigma {p.sigma:g}, w {p.w:g}){nmap}]")


# --- the Monte Carlo reference ------------------------------------------------------------
@contextlib.contextmanager
def wavefront_mode():
    """Dr.Jit's evaluated (wavefront) loops and calls, which ``nbrdf_reference``
    needs to hand each wavefront to the walk; restores the flags after."""
    flags = (dr.JitFlag.SymbolicLoops, dr.JitFlag.SymbolicCalls)
    old = [dr.flag(f) for f in flags]
    try:
        for f in flags:
            dr.set_flag(f, False)
        yield
    finally:
        for f, v in zip(flags, old):
            dr.set_flag(f, v)


def _np3(v) -> np.ndarray:
    return np.stack([np.asarray(v.x, np.float32), np.asarray(v.y, np.float32), np.asarray(v.z, np.float32)], 1)


SYMBOLIC = ("nbrdf_reference: traced in a symbolic loop or call, where the walk cannot run: it reflects nothing "
            "there; render inside nbrdf.mitsuba.wavefront_mode() (Dr.Jit's evaluated loops and calls)")


def _symbolic(bsdf) -> bool:
    """True while Dr.Jit traces symbolically. A symbolic call traces every live
    BSDF of a scene's class (another scene's too: a neural render in symbolic
    mode traces the references loaded beside it), so raising here would break
    renders of scenes that do not even use this plugin: it warns (Mitsuba's
    log, once per BSDF) and reflects nothing instead."""
    if dr.flag(dr.JitFlag.SymbolicScope):
        if not getattr(bsdf, "_warned_symbolic", False):
            bsdf._warned_symbolic = True
            mi.Log(mi.LogLevel.Warn, SYMBOLIC)
        return True
    return False


def _to_np(v):
    dr.eval(v)
    return _np3(v)


def _texture_reference(material):
    """(parameter maps, sampler) of a texture-mapped material's reference: a
    layer stack per hit needs interfaces over a parametric base; the sampler
    is the walk's defensive one at the sharpest top roughness any texel has."""
    from nbrdf.mitsuba.textures import ParamMaps, sharpest_top_roughness
    from nbrdf.neural.errors import NbrdfError
    from nbrdf.neural.material import LatentBase, Measured
    from nbrdf.training.brdfs import DefensiveSampler

    if not material.interfaces or isinstance(material.base, (LatentBase, Measured)):
        raise NbrdfError(f"{material.textures()[0][0]}: a texture-mapped reference needs a layer stack (interfaces "
                         "over a conductor, diffuse or dielectric base)")
    return ParamMaps(material), DefensiveSampler(sharpest_top_roughness(material))


class NbrdfReferenceBSDF(mi.BSDF):
    """``{"type": "nbrdf_reference", "material": PATH[, "spp": N, "seed": S]}``:
    every query draws ``spp`` new walk paths per lane (an unbiased, noisy f).
    A texture-mapped material gets its layer stack per hit from its maps at
    the hit's uv (``textures.ParamMaps``); a ``normal_map`` bends the shading
    frame per hit as in ``nbrdf`` (its finest level: the ground truth is not
    filtered)."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        from nbrdf.neural.errors import NbrdfError
        from nbrdf.neural.material import load_material
        from nbrdf.training.brdfs import ReferenceBRDF

        path = _prop(props, "material")
        if path is None:
            raise PluginError('nbrdf_reference: the property "material" (a material JSON) is missing')
        self.path = str(path)
        self.spp = int(_prop(props, "spp", 1))
        if self.spp < 1:
            raise PluginError(f"nbrdf_reference: spp {self.spp} must be at least 1")
        try:
            self.material = load_material(self.path)
            if self.material.is_textured:
                self.maps, self.sampler = _texture_reference(self.material)
            else:
                self.maps, self.sampler = None, ReferenceBRDF(self.material, spp=self.spp).sampler
        except NbrdfError as e:
            raise PluginError(f"nbrdf_reference: {e}") from None
        self.normal_map = material_normal_map(self.path, "nbrdf_reference")
        self._seeds = itertools.count(int(_prop(props, "seed", 0)) * 1_000_003 + 1)
        self.m_components = [FLAGS_GLOSSY]
        self.m_flags = FLAGS_GLOSSY

    def _f(self, wi: np.ndarray, wo: np.ndarray, uv: np.ndarray | None = None) -> np.ndarray:
        """A fresh estimate of f (N, 3) at the project's (wi, wo) (and the hits' uv
        for a texture-mapped material)."""
        import torch

        from nbrdf.training.reference import reference_eval

        if self.maps is not None:
            return self._f_textured(wi, wo, uv)
        f, _ = reference_eval(self.material, torch.from_numpy(wi), torch.from_numpy(wo), spp=self.spp,
                              seed=next(self._seeds))
        return f.numpy().astype(np.float32)

    def _f_textured(self, wi: np.ndarray, wo: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """The walk over one layer stack per hit, its parameters read at ``uv``."""
        import torch

        from nbrdf.neural.stack import material_stack
        from nbrdf.training.layered import simulate
        from nbrdf.training.reference import simulator_params

        f = np.zeros((wi.shape[0], 3), np.float32)
        idx = np.nonzero((wi[:, 2] > 0) & (wo[:, 2] > 0))[0]
        if idx.size:
            stack = material_stack(self.material, self.maps.at(uv[idx]), dtype=torch.float32)
            m, _ = simulate(simulator_params(stack.expand(idx.size) if stack.n == 1 else stack),
                            torch.from_numpy(wi[idx]), torch.from_numpy(wo[idx]), spp=self.spp,
                            seed=next(self._seeds))
            f[idx] = m.numpy()
        return f

    def _uv(self, si) -> np.ndarray | None:
        """The hits' uv (N, 2) for a texture-mapped material, else None."""
        if self.maps is None:
            return None
        dr.eval(si.uv)
        return np.stack([np.asarray(si.uv.x, np.float32), np.asarray(si.uv.y, np.float32)], 1)

    @staticmethod
    def _color(f: np.ndarray):
        return mi.Color3f(mi.Float(f[:, 0]), mi.Float(f[:, 1]), mi.Float(f[:, 2]))

    def _frame(self, si):
        """The hit's bent shading frame (None: no normal map)."""
        return None if self.normal_map is None else self.normal_map.frame(si)

    def eval(self, ctx, si, wo, active=True):
        if _symbolic(self):
            return dr.zeros(mi.Color3f, dr.width(wo))
        d = BentDirections(self._frame(si), si.wi, wo)
        f = self._color(self._f(_to_np(d.wo), _to_np(d.wi), self._uv(si)))
        return dr.select(active & d.ok, f * mi.Frame3f.cos_theta(d.wo), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        import torch

        if _symbolic(self):
            return dr.zeros(mi.Float, dr.width(wo))
        frame = self._frame(si)
        d = BentDirections(frame, si.wi, wo)
        p = mi.Float(self.sampler.pdf(torch.from_numpy(_to_np(d.wi)), torch.from_numpy(_to_np(d.wo))).numpy()
                     .astype(np.float32))
        return dr.select(active & (d.ok if frame is not None else True), p, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        import torch

        if _symbolic(self):
            return dr.zeros(mi.BSDFSample3f, dr.width(si.wi)), dr.zeros(mi.Color3f, dr.width(si.wi))
        frame = self._frame(si)
        view = _to_np(si.wi if frame is None else frame.to_local(si.wi))
        s1, s2 = np.asarray(sample1, np.float32), np.stack([np.asarray(sample2.x, np.float32),
                                                           np.asarray(sample2.y, np.float32)], 1)
        s1 = np.broadcast_to(s1, (view.shape[0],))
        u = torch.from_numpy(np.ascontiguousarray(np.concatenate([s2, s1[:, None]], 1)))  # u[:, 2] picks the lobe
        w, pdf = self.sampler.sample(torch.from_numpy(view), u)
        light = w.numpy().astype(np.float32)
        pdf = pdf.numpy().astype(np.float32)
        f = self._f(light, view, self._uv(si))
        ok_np = pdf > 0
        weight = np.where(ok_np[:, None], f * light[:, 2:3] / np.where(ok_np, pdf, 1.0)[:, None], 0.0)
        bs = dr.zeros(mi.BSDFSample3f)
        bs.wo = mi.Vector3f(mi.Float(light[:, 0]), mi.Float(light[:, 1]), mi.Float(light[:, 2]))
        ok = active & mi.Bool(ok_np)
        if frame is not None:
            bs.wo = frame.to_world(bs.wo)
            ok &= BentDirections(frame, si.wi, bs.wo).ok
        bs.pdf = dr.select(ok, mi.Float(pdf), 0.0)
        bs.eta = 1.0
        bs.sampled_component = mi.UInt32(0)
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
        return bs, dr.select(ok, self._color(weight.astype(np.float32)), 0.0)

    def traverse(self, cb):
        pass

    def to_string(self):
        return f"NbrdfReferenceBSDF[material={self.path!r}, spp={self.spp}]"
