"""The window's idle warm-up of shader variants (viewer/ui/program_warmup.py): after it,
no view of any BRDF kind builds a program (the live GL programs stay as they are
over a session), and it builds nothing before the window has been idle."""
from __future__ import annotations

import pytest

from nbrdf.neural.latent_texture import LatentTexture
from nbrdf.neural.material import load_material, parse_material
from nbrdf.viewer.gpu.body_table_gpu import INTERACTIVE, BodyTables
from nbrdf.viewer.gpu.pipeline import BrdfKind, MaterialPipeline, gpu_brdf
from nbrdf.viewer.gpu.renderer import Renderer, ViewState
from nbrdf.viewer.modes import View
from nbrdf.viewer.options import DEFAULT_MATERIAL
from nbrdf.viewer.ui.program_warmup import ProgramWarmup, WarmupSettings, reachable

pytestmark = pytest.mark.gl

ROUGH_GOLD = {"format": "nbrdf-material/1", "name": "rough gold",
              "layers": [{"type": "conductor", "roughness": 0.4, "r0": [1.0, 0.78, 0.34]}]}


@pytest.fixture(scope="module")
def kinds(gl_ctx):
    """A BRDF of every kind the window draws: closed form, decoder at a latent, decoder
    at a latent texture, baked body table, Belcour's model."""
    pipe = MaterialPipeline(gl_ctx)
    neural = pipe.build(load_material(DEFAULT_MATERIAL), "neural")
    z = neural.latent
    flat = LatentTexture(z.expand(4, 4, 3, z.shape[-1]).clone())
    textured = gpu_brdf(gl_ctx, neural.material, pipe.decoder, latent=z, latent_texture=flat)
    table = BodyTables(gl_ctx).brdf(neural, INTERACTIVE)
    out = [pipe.build(parse_material(ROUGH_GOLD), "analytic"), neural, textured, table,
           pipe.build(neural.material, "belcour")]
    assert [b.kind for b in out] == [BrdfKind.ANALYTIC, BrdfKind.NEURAL, BrdfKind.TEXTURED, BrdfKind.TABLE,
                                     BrdfKind.BELCOUR]
    return pipe, out


@pytest.mark.parametrize("compute,window", [(True, False), (False, False), (True, True)],
                         ids=["deferred", "fragment", "window-settings"])
def test_after_the_warmup_no_view_builds_a_program(gl_ctx, kinds, compute, window):
    from nbrdf.viewer.gpu.body_source import table_sampling
    from nbrdf.viewer.gpu.env_prefilter import PrefilterSettings

    pipe, brdfs = kinds
    r = Renderer(gl_ctx, mesh="sphere", compute=compute)
    if window:  # the window's still view on software OpenGL: the table's estimator and the body map
        r.table_sampling = table_sampling(r.sampling)
        r.settings.prefilter = PrefilterSettings(size=16, draws=1)
    warm = ProgramWarmup(r, lambda: reachable(r, pipe.loaded_decoder, True, brdfs[0].material,
                                              pipe.belcour_loaded), WarmupSettings(idle_s=0.0))
    while warm.frame(False) is not None:
        pass
    assert warm.done and not warm.failed and warm.built
    built = len(r.programs)
    for b in brdfs:
        for view in View:
            if b.kind == BrdfKind.TABLE and view != View.OBJECT:
                continue  # a baked table shades the object view only (viewer/gpu/body_source.py)
            r.render_linear(ViewState(view=view, background=False), (8, 8), 1, b)
    assert len(r.programs) == built, "a view built a variant the warm-up does not list"


def test_nothing_is_built_before_the_window_is_idle(gl_ctx, kinds):
    pipe, brdfs = kinds
    r = Renderer(gl_ctx, mesh="sphere")
    warm = ProgramWarmup(r, lambda: reachable(r, pipe.loaded_decoder, False, brdfs[0].material),
                         WarmupSettings(idle_s=1.0))
    before = len(r.programs)
    assert warm.frame(True, now=100.0) is None  # an edit
    assert warm.frame(False, now=100.9) is None  # not idle for long enough
    assert len(r.programs) == before
    assert warm.frame(False, now=101.0) is not None  # idle: one variant per frame
    assert len(r.programs) == before + 1
    assert warm.frame(True, now=101.1) is None and warm.frame(False, now=101.5) is None  # input again
    warm.settings.enabled = False
    assert warm.frame(False, now=200.0) is None
    # without a decoder on the GPU the neural kinds wait for one, Belcour's model for its tables
    assert all(k.kind in (None, BrdfKind.ANALYTIC)
               for k, _ in reachable(r, None, True, brdfs[0].material))
