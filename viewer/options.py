"""The previewer's options (``nbrdf-view``'s flags, the window's and the
offscreen renderer's settings): one documented dataclass, read by the viewer
and turned into flags by ``nbrdf.cli.view``."""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material
from nbrdf.neural.material import load_material as read_material
from nbrdf.viewer.modes import Background, BrdfMode, View
from nbrdf.viewer.scene.gltf_import import MaterialGroup, imported_scene, material_groups
from nbrdf.viewer.view_settings import ViewState, check_flags

#: The material shown when none is given (varnished copper).
DEFAULT_MATERIAL = Path(__file__).parent / "assets" / "materials" / "default.json"
#: The size of an offscreen image when --size is not given.
DEFAULT_IMAGE_SIZE = (512, 512)
#: Where a window-less run writes its image when ``--out`` is not given.
HEADLESS_OUT = "nbrdf-view.png"


def parse_size(text: str) -> tuple[int, int]:
    """``WxH`` -> (W, H), each side in 1..16384; one-line error otherwise."""
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise NbrdfError(f"--size: expected WxH such as 512x512, got {text!r}") from None
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise NbrdfError(f"--size: {w}x{h} is outside 1..16384 per side")
    return w, h


@dataclass
class ViewOptions:
    """What the previewer opens and how it renders (SPEC section 8)."""

    material: Path = field(default=DEFAULT_MATERIAL, metadata={"positional": True, "shown": "varnished copper"})
    """material file: the project's JSON, or a MaterialX document (FILE.mtlx, FILE.mtlx#Material for one of several)"""
    mesh: str = "sphere"
    """sphere, testmesh, or an OBJ/glTF file (a .gltf/.glb also brings its materials, one per primitive, when no
    MATERIAL is given)"""
    env: str | None = "studio"
    """environment: a generated preset (studio, sky, softbox) or an equirectangular .hdr/.exr file"""
    state: ViewState = field(default_factory=ViewState, metadata={"nested": True})
    """the view settings (viewer/view_settings.py: each one marked ``cli`` is a flag of its own)"""
    offscreen: bool = False
    """render through EGL to --out instead of opening a window"""
    restore: bool | None = field(default=None, metadata={
        "no_help": "start afresh; a crashed session's autosave is kept aside, not offered"})
    """restore the autosaved session (after a crash, or the last one) without asking; unset: ask after a crash"""
    out: str | None = None
    """output image: .png (tone-mapped), .exr or .npy (linear float)"""
    size: tuple[int, int] | None = field(default=None, metadata={
        "parse": parse_size, "metavar": "WxH",
        "shown": "512x512 offscreen; a window opens at its last size, or 80% of the screen"})
    """image or window size in pixels"""
    spp: int = 32
    """passes accumulated per pixel (32: the default preview's relative noise under 1 %)"""
    brdf: BrdfMode = BrdfMode.AUTO
    """analytic: closed form in GLSL (single layers); neural: the shipped decoder in GLSL at the latents of leaf
    encoders and layering; projected: at latents fitted to the material's reference; belcour: Belcour 2018's
    analytic layered model in GLSL (uniform stacks; others are shown neural, said in one line); auto: analytic
    for a single layer, else neural. The window shades neural or belcour (its panel switches between them;
    other modes open neural)"""
    background: Background = Background.BLUR
    """what is seen behind the object, independent of what lights it: the environment, the environment
    blurred, a flat colour, or none (black)"""
    ground: bool = True
    """a soft contact shadow on the ground under the object (--no-ground: none)"""
    session: str | None = None
    """a look-development session file (material, camera, lights, environment, view) to open"""
    turntable: int = 0
    """offscreen: N frames of one turn of the camera around the object, written to --out as .mp4, .gif or
    a frame pattern such as frame_%03d.png (0: a single image)"""

    def __post_init__(self):
        #: The window size asked for (None: the window picks, see session.WindowPrefs).
        self.window_size: tuple[int, int] | None = self.size
        if self.size is None:
            self.size = DEFAULT_IMAGE_SIZE
        self.material = Path(self.material)
        self.brdf = BrdfMode.parse(self.brdf, "--brdf")
        self.background = Background.parse(self.background, "--background")
        # What lights the object is the environment whatever is seen behind it; "none" hides it.
        self.state = replace(self.state, background=self.background != Background.NONE)

    @property
    def window_brdf(self) -> BrdfMode:
        """The window's BRDF: belcour when asked, else neural (the window's own; the closed
        form of a single layer is its reference)."""
        return BrdfMode.BELCOUR if self.brdf == BrdfMode.BELCOUR else BrdfMode.NEURAL

    def backdrop(self):
        """The backdrop settings of these options (viewer/gpu/backdrop.py)."""
        from nbrdf.viewer.gpu.backdrop import BackdropSettings  # late: moderngl is no part of the CLI's start-up

        return BackdropSettings(self.background, ground=self.ground)

    def file_materials(self) -> list[MaterialGroup] | None:
        """When no MATERIAL is given and --mesh is a glTF file: the file's materials
        (with their notes), one per draw range of the mesh, in its order; else None."""
        if self.material == DEFAULT_MATERIAL and Path(self.mesh).suffix.lower() in (".gltf", ".glb"):
            return material_groups(imported_scene(self.mesh))
        return None

    def load_material(self) -> tuple[Material, list[str]]:
        """The material to show first and one-line notes: the MATERIAL argument, or,
        when none was given and --mesh is a glTF file, the file's first material
        (the notes of all its materials, each named when there are several)."""
        groups = self.file_materials()
        if groups is not None:
            named = len(groups) > 1  # several materials: each note names its material
            notes = [f"{self.mesh}: {g.material.name + ': ' if named else ''}{note}"
                     for g in groups for note in g.notes]
            return groups[0].material, notes
        notes: list[str] = []
        return read_material(self.material, notes), notes

    def check(self) -> "ViewOptions":
        """Raises ``NbrdfError`` (one line naming the flag) for values out of range."""
        if self.spp < 1:
            raise NbrdfError(f"--spp: {self.spp} must be at least 1")
        check_flags(self.state)
        if self.offscreen and not self.out:
            raise NbrdfError("--offscreen needs --out IMG")
        if self.turntable < 0 or self.turntable > 3600:
            raise NbrdfError(f"--turntable: {self.turntable} is outside 0..3600 frames")
        if self.turntable and self.state.view != View.OBJECT:
            raise NbrdfError("--turntable: turns the camera around the object (--view object)")
        if self.turntable and not self.offscreen:
            raise NbrdfError("--turntable needs --offscreen and --out (in the window, T toggles the turntable)")
        return self
