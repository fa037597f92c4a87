"""The previewer's modes as enums: one definition for the command line, the
panels, sessions and the shaders.

Each enum's value is the word used on the command line and in session files;
``glsl_defines`` emits the integer constants the shaders compare against, so
a shader never hard-codes a mode number.
"""
from __future__ import annotations

from nbrdf.neural.layer_kinds import PARAMETRIC_BASES
from nbrdf.neural.methods import CodedWordEnum as _Mode
from nbrdf.neural.methods import Method, WordEnum


class View(_Mode):
    """What the viewport shows."""
    OBJECT = "object"   #: the lit object (sphere or mesh)
    LOBE = "lobe"       #: the standard lobe image of SPEC section 9
    SLICE = "slice"     #: the (theta_h, theta_d) image slice


class CompareMode(_Mode):
    """How the reference is shown beside the neural image."""
    OFF = "off"         #: the neural image alone
    SIDE = "side"       #: side by side, neural left
    WIPE = "wipe"       #: an A/B wipe at a movable split
    ERROR = "error"     #: false-colour relative error with a scale bar
    FLIP = "flip"       #: HDR-FLIP error map (magma) with its mean


class Against(_Mode):
    """What the compare view sets beside the neural image."""
    REFERENCE = "reference"  #: the physical stack's reference (closed form or Monte Carlo)
    MATERIALX = "materialx"  #: the OpenPBR inputs as MaterialX's own generated GLSL shows them


class BrdfMode(WordEnum):
    """Which BRDF the previewer shades with (``--brdf``): the members of ``Method``
    (neural/methods.py, the one list of methods) the GPU can draw, with their words,
    plus ``AUTO``. ``method`` maps back; how each is shaded on the GPU is
    ``BrdfKind`` (viewer/gpu/pipeline.py ``brdf_kind``)."""
    AUTO = "auto"                       #: neural for stacks, closed form for single interfaces
    ANALYTIC = Method.ANALYTIC.value    #: closed form (single interfaces; analytic layering for stacks)
    NEURAL = Method.NEURAL.value        #: leaf encoders -> layering -> decoder
    PROJECTED = Method.PROJECTED.value  #: a latent fitted to the reference
    BELCOUR = Method.BELCOUR.value      #: Belcour 2018's analytic layered model (statistical operators)

    @property
    def method(self) -> Method | None:
        """The ``Method`` this mode draws (None: ``AUTO``, which picks one per material)."""
        return None if self is BrdfMode.AUTO else Method(self.value)


#: The base layers the closed-form shader (shaders/analytic_brdf.glsl) evaluates: conductor (GGX, Schlick
#: Fresnel), diffuse (Lambertian) and dielectric (a rough dielectric's reflection only). Members and codes
#: come from the table of layer kinds, so ``BASE_<KIND>`` equals the walk's code of that base.
BaseKind = _Mode("BaseKind", [(kind.upper(), kind) for kind in PARAMETRIC_BASES])


def glsl_defines(*enums: type[_Mode]) -> str:
    """``#define`` lines for the given enums, e.g. ``#define VIEW_LOBE 1``."""
    lines = []
    for enum in enums:
        prefix = {"View": "VIEW", "CompareMode": "COMPARE", "ToneMap": "TONEMAP",
                  "BaseKind": "BASE"}.get(enum.__name__, enum.__name__.upper())
        lines += [f"#define {prefix}_{m.name} {m.code}" for m in enum]
    return "\n".join(lines) + "\n"


class Background(_Mode):
    """What is behind the object, independent of what lights it (viewer/gpu/backdrop.py)."""
    ENV = "env"     #: the environment itself
    BLUR = "blur"   #: the environment pre-filtered (a soft backdrop that still reads as the room)
    FLAT = "flat"   #: one flat colour
    NONE = "none"   #: black (the object alone)
