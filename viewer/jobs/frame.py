"""What the jobs draw with, without the session: ``Frame``, a plain description
of one frame (the view, the BRDFs shown, the compare and blend settings), and
``Stage``, the GPU parts every frame draws with (renderer, compositor, backdrop,
bodies).

The session (viewer/session/lookdev.py) updates first -- it picks up the
background results -- and then describes the frame (``LookDev.describe``); the
jobs (view_frames.py, screenshot.py, turntable.py) render from that
description and never call back into the session, as moderngl-window and
Filament render from a frame's description after the update.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import moderngl
import numpy as np

from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.modes import Against, CompareMode, View

if TYPE_CHECKING:
    from nbrdf.neural.material import Material
    from nbrdf.viewer.gpu.backdrop import Backdrop, BackdropSettings
    from nbrdf.viewer.gpu.body_source import BodySource
    from nbrdf.viewer.gpu.pipeline import GpuBrdf
    from nbrdf.viewer.gpu.renderer import Renderer
    from nbrdf.viewer.reference.compare import Compare
    from nbrdf.viewer.reference.materialx_view import MaterialXView
    from nbrdf.viewer.view_settings import ViewState


@dataclass(frozen=True)
class Frame:
    """One frame of the session's view, as the session describes it after its update."""

    state: "ViewState"
    """The view settings (both sides of a comparison are lit by what the view shows)."""
    material: "Material"
    """The edited material (the reference's)."""
    mesh: str
    """The mesh's name (the Monte Carlo reference's scene)."""
    brdf: "GpuBrdf | None"
    """The neural image's BRDF (None: the first latent texture is still building)."""
    ref_brdf: "GpuBrdf | None"
    """The closed form of a single layer (the reference), else None."""
    other_brdf: "GpuBrdf | None"
    """The second material of a BRDF blend when one is shown, else None."""
    blend_t: float
    """The blend's weight of ``other_brdf``."""
    compare: CompareMode
    """The compare view shown (OFF: none, also while a BRDF blend replaces it)."""
    wipe: float
    """The A/B wipe's position."""
    error_scale: float
    """The relative-error view's full scale."""
    backdrop: "BackdropSettings"
    """What is drawn behind the object."""
    against: Against = Against.REFERENCE
    """What the compare view sets beside the neural image (the stack's reference, or MaterialX's shader)."""

    @property
    def view(self) -> View:
        return View.parse(self.state.view)

    @property
    def comparing(self) -> bool:
        """Whether the view shows the reference."""
        return self.compare != CompareMode.OFF

    @property
    def blending(self) -> bool:
        """Whether the view shows a BRDF-value blend of two materials (two accumulations)."""
        return self.other_brdf is not None

    @property
    def side_by_side(self) -> bool:
        """Whether the view shows two images side by side (each half the view's width)."""
        return self.compare == CompareMode.SIDE


@dataclass(frozen=True)
class Stage:
    """The GPU parts a session's frames draw with (one of each per session)."""

    ctx: moderngl.Context
    renderer: "Renderer"
    compare: "Compare"
    """The reference and the compositor (viewer/reference/compare.py)."""
    backdrop: "Backdrop"
    bodies: "BodySource"
    """The body a frame shades with: the decoder or a baked table (viewer/gpu/body_source.py)."""
    materialx: "MaterialXView"
    """MaterialX's own shader of the material's OpenPBR inputs, the compare view's other side
    (viewer/reference/materialx_view.py)."""


def render_linear(stage: Stage, frame: Frame, size: tuple[int, int], spp: int) -> np.ndarray:
    """The linear image of the view (H, W, 3): the object over its backdrop, or
    the lobe / slice view (the lobe: SPEC section 9's array, row 0 at y = -1)."""
    if frame.brdf is None:
        raise NbrdfError("the latent texture is still building")
    if frame.view == View.OBJECT:
        return stage.backdrop.render_linear(frame.state, size, spp, frame.brdf, frame.backdrop)
    return stage.renderer.render_linear(frame.state, size, spp, frame.brdf)
