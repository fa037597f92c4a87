"""A material JSON's ``normal_map`` inside the Mitsuba plugins: the shading
frame each hit is shaded in.

The convention is the previewer's (viewer/shaders/shading_frame.glsl):
a tangent-space map, OpenGL style (red along the tangent dp/du, green along
normal x tangent, i.e. up the image on an unmirrored uv layout, blue along
the normal), texel t -> m = 2 t - 1, the bent normal normalize(m.x, m.y,
max(m.z, 1e-3)), and a bent normal that faces away from the viewer pulled
back to the silhouette (n . wi = 1e-3). No strength factor: the map is used
as painted. Mitsuba's shading frame (``si.sh_frame``: s = dp/du projected,
t = n x s) is that tangent frame, so directions in it (``si.wi``, a queried
``wo``) map into the bent frame by one rotation.

The map is read like the material's other textures: row 0 = v 0 at the
image's bottom, Mitsuba's v 0 at its top (``mip.texture_rows_uv``),
repeat wrapping, bilinear, mip-mapped by the ray cone when the plugin has a
``pixel_angle`` (the previewer's map is mip-mapped too).

Directions below the surface follow Mitsuba's ``normalmap``: a direction
counts only where it is above both the unperturbed and the bent surface
(eval, pdf and sample alike), so eval, sample and pdf agree in the bent frame.
"""
from __future__ import annotations

from pathlib import Path

import drjit as dr
import mitsuba as mi

from nbrdf.imaging.image_io import read_normal_map
from nbrdf.mitsuba.mip import MipBuffer, level_of_detail, mip_chain

#: The smallest z of a map's normal (the previewer's clamp) and of its cosine with the viewer.
MIN_COS = 1e-3


class NormalMapKernel:
    """A tangent-space normal map looked up per hit (``MipBuffer`` of its RGB)."""

    def __init__(self, path: str | Path):
        """Reads ``path`` (``NbrdfError``: unreadable, or not RGB)."""
        self.path = str(path)
        self.texels = MipBuffer(mip_chain(read_normal_map(path)))
        self.size = self.texels.size

    def normal(self, si, pixel_angle: float = 0.0):
        """The bent normal in ``si``'s shading frame (local coordinates), the
        previewer's rules (module docstring); ``pixel_angle`` > 0 picks the mip
        level by the hit's ray cone (``mip.level_of_detail``)."""
        r, g, b = self.texels.lookup(si.uv, level_of_detail(si, pixel_angle, self.size))
        n = dr.normalize(mi.Vector3f(2.0 * r - 1.0, 2.0 * g - 1.0, dr.maximum(2.0 * b - 1.0, MIN_COS)))
        wi = si.wi
        nv = dr.dot(n, wi)
        pulled = dr.normalize(n + wi * (MIN_COS - nv))
        return dr.select(nv < MIN_COS, pulled, n)

    def frame(self, si, pixel_angle: float = 0.0) -> mi.Frame3f:
        """The bent shading frame, in ``si``'s local coordinates: its tangent is
        the unperturbed one made perpendicular to the bent normal (an anisotropic
        material's x axis), as Mitsuba's ``normalmap`` takes it (the same random
        numbers then sample the same directions)."""
        n = self.normal(si, pixel_angle)
        s = dr.normalize(mi.Vector3f(1.0 - n.x * n.x, -n.x * n.y, -n.x * n.z))
        return mi.Frame3f(s, dr.cross(n, s), n)


class BentDirections:
    """The queried pair of a hit in its bent frame: ``wi``, ``wo`` there and
    ``ok``, where both directions are above the unperturbed and the bent
    surface. Without a map, the pair as given."""

    def __init__(self, frame: mi.Frame3f | None, wi, wo):
        up = (mi.Frame3f.cos_theta(wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)
        if frame is None:
            self.wi, self.wo, self.ok = wi, wo, up
        else:
            self.wi, self.wo = frame.to_local(wi), frame.to_local(wo)
            self.ok = up & (self.wi.z > 0) & (self.wo.z > 0)
