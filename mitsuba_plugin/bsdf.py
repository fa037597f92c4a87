"""The two Mitsuba BSDF plugins of an nbrdf material (SPEC section 8).

``nbrdf``: the neural material as the previewer shows it, evaluated inside
Mitsuba's kernel (``kernel.CodeKernel``). ``nbrdf_reference``: the Monte
Carlo ground truth, a fresh unbiased estimate of f per query from the
project's walk (``training.reference.reference_eval``), called per wavefront
through numpy, so it needs Dr.Jit's evaluated mode (``wavefront_mode``).

Mitsuba's conventions: ``si.wi`` is the project's ``wo`` (toward the
viewer), the queried direction is the project's ``wi`` (toward the light);
``eval`` returns f(wi, wo) cos(theta_i). Both are one-sided reflection BSDFs.
The directions are in the hit's shading frame ``si.sh_frame``, which is SPEC
section 10's frame: its normal is z and its tangent ``s`` the material's x
axis, which an anisotropic material's ``anisotropy_rotation`` turns
counter-clockwise about the normal. Mitsuba's ``s`` is dp/du on a shape with
a uv parameterisation (a brush stroke follows u there), an arbitrary tangent
on a mesh without uvs.

What a material file builds (the kernel, the normal map, the walk) comes
from ``materials``, which needs torch: it loads with the first material.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from nbrdf.mitsuba.errors import PluginError
from nbrdf.mitsuba.kernel import Body, TexturedCodeKernel
from nbrdf.mitsuba.mix import MixedKernel
from nbrdf.mitsuba.modes import SLOW_WARNING
from nbrdf.mitsuba.normal_map import BentDirections

FLAGS_GLOSSY = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
#: A material without a coat whose proxy gives the cosine lobe more than this share is reported
#: to Mitsuba as a diffuse lobe, else as a glossy one.
DIFFUSE_W = 0.9


def _prop(props, key: str, default=None):
    return props[key] if key in props else default


def _components(kernel) -> list:
    """The uniform or textured kernels a kernel is made of: a ``MixedKernel``'s components, else itself."""
    return list(kernel.kernels) if isinstance(kernel, MixedKernel) else [kernel]


def _diffuse(kernel) -> bool:
    """Whether one (not mixed) kernel is reported as a diffuse lobe (``DIFFUSE_W``)."""
    return not kernel.textured and not kernel.coat.present and kernel.proxy.w > DIFFUSE_W


class NbrdfBSDF(mi.BSDF):
    """``{"type": "nbrdf", "material": PATH[, "weights": BUNDLE, "pixel_angle": RADIANS, "body": "decoder"|"table",
    "calibrate": BOOL]}``: ``calibrate`` true gives a uniform layered material the walk's energy (its body scaled
    to the walk's directional albedo, ``training.calibration``; the first load walks it, later ones read the cache).
    ``body`` "table" reads a uniform material's body from a table baked once
    at load (``TableBody``: noise-free, a small interpolation bias against the
    decoder, and no weights to load, so it renders fast in symbolic mode);
    the coat and the sampler are the same either way (the sampler's pdf does
    not depend on the body). ``pixel_angle`` (texture-mapped materials) is the camera's angle per pixel,
    whose ray cone picks the latent texture's (and the normal map's) mip level
    per hit (0: the finest). A material JSON's ``normal_map`` bends the shading
    frame per hit (``normal_map.py``). A uniform material may be anisotropic,
    its x axis ``si.sh_frame.s`` (module docstring); a texture-mapped one may
    not (one line). A uniform material with OpenPBR's linear mixes is held
    exactly (``kernel.MixedKernel``: eval and pdf the weighted sums, ``sample1``
    picks the component, the weight eval cos / the mixture's pdf); it is a
    diffuse lobe only when every component is."""

    def __init__(self, props):
        from nbrdf.mitsuba.materials import code_kernel, material_normal_map  # start-up: torch loads with a material

        mi.BSDF.__init__(self, props)
        if not dr.is_jit_v(mi.Float):
            raise PluginError(f"nbrdf: the variant {mi.variant()} is not a JIT variant; use llvm_ad_rgb "
                              "or cuda_ad_rgb")
        path = _prop(props, "material")
        if path is None:
            raise PluginError('nbrdf: the property "material" (a material JSON or a code file) is missing')
        self.path = str(path)
        self.pixel_angle = float(_prop(props, "pixel_angle", 0.0))
        self.body = str(_prop(props, "body", Body.DECODER.value))
        self.kernel = code_kernel(self.path, _prop(props, "weights"), self.pixel_angle, self.body,
                                  bool(_prop(props, "calibrate", False)))
        self.normal_map = material_normal_map(self.path, "nbrdf")
        diffuse = all(_diffuse(k) for k in _components(self.kernel))
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
        SLOW_WARNING.check(self.body)
        d = BentDirections(self._frame(si), si.wi, wo)
        f = self.kernel.eval(d.wo, d.wi, si)
        return dr.select(self._enabled(ctx, active) & d.ok, f * mi.Frame3f.cos_theta(d.wo), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        d = BentDirections(self._frame(si), si.wi, wo)
        return dr.select(self._enabled(ctx, active) & d.ok, self.kernel.pdf(d.wi, d.wo, si), 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        SLOW_WARNING.check(self.body)
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

    def traverse(self, _cb):
        pass

    def to_string(self):
        if isinstance(self.kernel, MixedKernel):
            nmap = "" if self.normal_map is None else f", normal_map={self.normal_map.path!r}"
            parts = ", ".join(f"{w:.3g}: coat (roughness {k.coat.roughness:g}, ior {k.coat.ior:g}) proxy (sigma "
                              f"{k.proxy.sigma:g}, w {k.proxy.w:g})" for w, k in self.kernel.parts)
            return f"NbrdfBSDF[material={self.path!r}, body={self.body}, OpenPBR mix of {parts}{nmap}]"
        c, p = self.kernel.coat, self.kernel.proxy
        if hasattr(self.kernel, "maps"):
            return (f"NbrdfBSDF[material={self.path!r}, parametric body table {self.kernel.decoder.nodes} over "
                    f"{self.kernel.maps.size} maps, pixel_angle {self.kernel.pixel_angle:g}, proxy=(sigma {p.sigma:g}, "
                    f"w {p.w:g})]")
        if isinstance(self.kernel, TexturedCodeKernel):
            return (f"NbrdfBSDF[material={self.path!r}, latent texture {self.kernel.texture.size}, "
                    f"pixel_angle {self.kernel.pixel_angle:g}, proxy=(sigma {p.sigma:g}, w {p.w:g})]")
        nmap = "" if self.normal_map is None else f", normal_map={self.normal_map.path!r}"
        aniso = "" if c.stretch is None else ", anisotropic"
        return (f"NbrdfBSDF[material={self.path!r}, body={self.body}, coat=(roughness {c.roughness:g}, ior {c.ior:g}), "
                f"proxy=(sigma {p.sigma:g}, w {p.w:g}){aniso}{nmap}]")


# --- the Monte Carlo reference ------------------------------------------------------------
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


class NbrdfReferenceBSDF(mi.BSDF):
    """``{"type": "nbrdf_reference", "material": PATH[, "spp": N, "seed": S]}``:
    every query draws ``spp`` new walk paths per lane (an unbiased, noisy f).
    A texture-mapped material gets its layer stack per hit from its maps at
    the hit's uv (``textures.ParamMaps``); a ``normal_map`` bends the shading
    frame per hit as in ``nbrdf`` (its finest level: the ground truth is not
    filtered). A uniform material may be anisotropic, in the frame ``nbrdf``
    uses (module docstring). A uniform material with OpenPBR's linear mixes is
    held exactly (``materials.ReferenceWalk``: f the components' walks weighted,
    ``sample1`` picks the component, the pdf the mixture's)."""

    def __init__(self, props):
        from nbrdf.mitsuba.materials import ReferenceWalk, material_normal_map  # start-up: torch loads with a material

        mi.BSDF.__init__(self, props)
        path = _prop(props, "material")
        if path is None:
            raise PluginError('nbrdf_reference: the property "material" (a material JSON) is missing')
        self.path = str(path)
        self.spp = int(_prop(props, "spp", 1))
        if self.spp < 1:
            raise PluginError(f"nbrdf_reference: spp {self.spp} must be at least 1")
        self.walk = ReferenceWalk(self.path, self.spp, int(_prop(props, "seed", 0)))
        self.normal_map = material_normal_map(self.path, "nbrdf_reference")
        self.m_components = [FLAGS_GLOSSY]
        self.m_flags = FLAGS_GLOSSY

    def _uv(self, si) -> np.ndarray | None:
        """The hits' uv (N, 2) for a texture-mapped material, else None."""
        if not self.walk.textured:
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
        f = self._color(self.walk.f(_to_np(d.wo), _to_np(d.wi), self._uv(si)))
        return dr.select(active & d.ok, f * mi.Frame3f.cos_theta(d.wo), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        if _symbolic(self):
            return dr.zeros(mi.Float, dr.width(wo))
        frame = self._frame(si)
        d = BentDirections(frame, si.wi, wo)
        p = mi.Float(self.walk.pdf(_to_np(d.wi), _to_np(d.wo)))
        return dr.select(active & (d.ok if frame is not None else True), p, 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        if _symbolic(self):
            return dr.zeros(mi.BSDFSample3f, dr.width(si.wi)), dr.zeros(mi.Color3f, dr.width(si.wi))
        frame = self._frame(si)
        view = _to_np(si.wi if frame is None else frame.to_local(si.wi))
        s1, s2 = np.asarray(sample1, np.float32), np.stack([np.asarray(sample2.x, np.float32),
                                                           np.asarray(sample2.y, np.float32)], 1)
        s1 = np.broadcast_to(s1, (view.shape[0],))
        light, pdf = self.walk.sample(view, np.concatenate([s2, s1[:, None]], 1))  # u[:, 2] picks the lobe
        f = self.walk.f(light, view, self._uv(si))
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

    def traverse(self, _cb):
        pass

    def to_string(self):
        return f"NbrdfReferenceBSDF[material={self.path!r}, spp={self.spp}]"
