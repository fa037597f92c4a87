"""OpenPBR as MaterialX's own generated GLSL renders it: what an OpenPBR user sees today in MaterialXView-like
viewers. ``generate`` writes the shader for a document's material with MaterialXGenGlsl (a directional and a
point light bound as MaterialX's ``ND_directional_light`` and ``ND_point_light``; with ``environment``, MaterialX's
filtered-importance-sampled environment); ``render_materialx`` draws it on SPEC section 9's lit sphere (the
column ``nbrdf report openpbr`` sets beside the physical stack), viewer/reference/materialx_view.py over the
window's mesh. ``materialx_environment`` turns the previewer's environment (world z up) into MaterialX's
latitude-longitude maps (y up) and the ``u_envMatrix`` that reads them in the previewer's world.

``render_materialx`` draws one point per disk pixel, each carrying that pixel's exact normal and tangent (SPEC
section 9's frame), with the camera far along +z (an orthographic view) and the light of unit irradiance, into
a float image: the same pixels as ``training.render_report.shade``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import moderngl
import numpy as np

from nbrdf.imaging.environment import EnvironmentMap, sh9
from nbrdf.neural.errors import NbrdfError
from nbrdf.training.render_report import SphereGeometry, light_direction

#: MaterialX's light type ids bound to ``ND_directional_light`` and ``ND_point_light`` in the generated shader.
DIRECTIONAL, POINT = 1, 2
#: The previewer's world (z up) to MaterialX's environment frame (y up): x' = x, y' = z, z' = -y.
TO_MATERIALX = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class MaterialXShader:
    """A material's shader as MaterialXGenGlsl writes it."""

    vertex: str
    """The vertex stage's GLSL (attributes i_position, i_normal, i_tangent)."""
    fragment: str
    """The pixel stage's GLSL."""
    inputs: dict[str, str]
    """The surface shader's inputs (e.g. "base_color") to the public uniforms that hold them."""


def generate(document, material: str | None = None, environment: bool = False, where: str = "") -> MaterialXShader:
    """The GLSL MaterialXGenGlsl writes for ``document``'s material (the first, or ``material``); ``environment``:
    with MaterialX's filtered importance sampling of an environment (``u_envRadiance``, ``u_envIrradiance``),
    else lights alone. ``where`` names the document in errors."""
    import MaterialX as mx  # lazy: MaterialX's generators load only for this view
    import MaterialX.PyMaterialXGenGlsl as mx_glsl  # lazy, as above
    import MaterialX.PyMaterialXGenShader as mx_gen  # lazy, as above

    from nbrdf.neural.mtlx import data_library  # late: MaterialX, as above
    lib = data_library()
    document.importLibrary(lib)
    nodes = [n for n in document.getMaterialNodes() if material is None or n.getName() == material]
    if not nodes:
        raise NbrdfError(f"{where}: no material {material or ''} to generate GLSL for")
    gen = mx_glsl.GlslShaderGenerator.create()
    ctx = mx_gen.GenContext(gen)
    ctx.registerSourceCodeSearchPath(mx.getDefaultDataSearchPath())
    opts = ctx.getOptions()
    opts.hwSpecularEnvironmentMethod = (mx_gen.HwSpecularEnvironmentMethod.SPECULAR_ENVIRONMENT_FIS if environment
                                        else mx_gen.HwSpecularEnvironmentMethod.SPECULAR_ENVIRONMENT_NONE)
    opts.hwMaxActiveLightSources = 2
    mx_gen.HwShaderGenerator.bindLightShader(lib.getNodeDef("ND_directional_light"), DIRECTIONAL, ctx)
    mx_gen.HwShaderGenerator.bindLightShader(lib.getNodeDef("ND_point_light"), POINT, ctx)
    try:
        shader = gen.generate(nodes[0].getName(), nodes[0], ctx)
    except Exception as e:  # noqa: BLE001 - MaterialX's generator errors share no base class in Python
        raise NbrdfError(f"{where}: MaterialX cannot generate GLSL for it ({str(e).splitlines()[0] if str(e) else type(e).__name__})") from None
    fs = shader.getSourceCode(mx_gen.PIXEL_STAGE)
    if "u_refractionTwoSided" in fs and "uniform bool u_refractionTwoSided" not in fs:
        # MaterialX 1.39.5 drops this uniform's declaration without an environment but keeps its one use
        # (the transmission tint of its environment function): declared here with its default
        head, sep, rest = fs.partition("\n")
        fs = head + sep + "uniform bool u_refractionTwoSided = false;\n" + rest
    block = shader.getStage(mx_gen.PIXEL_STAGE).getUniformBlock(mx_gen.HW_PUBLIC_UNIFORMS)
    inputs = {block[i].getPath().rpartition("/")[2]: block[i].getVariable() for i in range(block.size())
              if "/" in block[i].getPath()}
    return MaterialXShader(shader.getSourceCode(mx_gen.VERTEX_STAGE), fs, inputs)


def materialx_shader(path: str | Path, material: str | None = None) -> MaterialXShader:
    """The shader MaterialXGenGlsl writes for a document file's material (the first, or ``material``), lights alone."""
    import MaterialX as mx  # lazy: MaterialX's generators load only for this column

    doc = mx.createDocument()
    try:
        mx.readFromXmlFile(doc, str(path))
    except Exception as e:  # noqa: BLE001 - MaterialX's parse and file errors share no base class in Python
        raise NbrdfError(f"{path}: MaterialX cannot read it ({str(e).splitlines()[0] if str(e) else type(e).__name__})") from None
    return generate(doc, material, where=str(path))


def env_matrix(rotation_deg: float) -> np.ndarray:
    """(4, 4) ``u_envMatrix``: a direction of the previewer's world to the frame of ``materialx_environment``'s
    maps, the environment turned by ``rotation_deg`` about z (environment.glsl ``env_rotate``)."""
    a = math.radians(rotation_deg)
    c, s = math.cos(a), math.sin(a)
    unrotate = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # env_rotate(d, -a)
    m = np.eye(4)
    m[:3, :3] = TO_MATERIALX @ unrotate
    return m


def latlong_directions(w: int, h: int) -> np.ndarray:
    """(h, w, 3): the previewer-world direction of each texel centre of a (w, h) map in MaterialX's
    latitude-longitude layout (``mx_latlong_projection``: row 0 up, y' up, longitude atan(x', -z')), before
    ``env_matrix``'s turn; row k is the texture's row k (v = (k + 0.5) / h)."""
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    lat = (0.5 - v) * math.pi  # mx: v = -asin(y') / pi + 0.5
    lon = (u - 0.5) * 2 * math.pi  # mx: u = atan(x', -z') / (2 pi) + 0.5
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    m = np.stack([np.cos(la) * np.sin(lo), np.sin(la), -np.cos(la) * np.cos(lo)], -1)
    return m @ TO_MATERIALX  # TO_MATERIALX is orthogonal: its transpose takes y' up back to z up


def materialx_environment(env: EnvironmentMap, irradiance_size: tuple[int, int] = (64, 32)
                          ) -> tuple[np.ndarray, np.ndarray]:
    """(radiance, irradiance) float32 (h, w, 3) maps of ``env`` in MaterialX's layout (``latlong_directions``):
    the radiance resampled bilinearly at the map's own size, and the irradiance over pi that MaterialX's
    diffuse lobes read (``u_envIrradiance``, as MaterialXView's ``*_irradiance.hdr``), from ``env``'s order-2
    spherical harmonics."""
    w, h = env.size
    radiance = env.lookup_bilinear(latlong_directions(w, h).reshape(-1, 3)).reshape(h, w, 3)
    iw, ih = irradiance_size
    d = latlong_directions(iw, ih).reshape(-1, 3)
    irradiance = np.maximum(sh9(d) @ env.irradiance_sh(), 0.0).reshape(ih, iw, 3)
    return radiance.astype(np.float32), irradiance.astype(np.float32)


def render_materialx(ctx: moderngl.Context, path: str | Path, geo: SphereGeometry, material: str | None = None
                     ) -> np.ndarray:
    """The lit sphere (H, W, 3) float32, linear, of the document's material through MaterialX's GLSL."""
    shader = materialx_shader(path, material)
    try:
        prog = ctx.program(vertex_shader=shader.vertex, fragment_shader=shader.fragment)
    except moderngl.Error as e:
        raise NbrdfError(f"{path}: MaterialX's GLSL does not compile here ({str(e).splitlines()[0]})") from None
    h, w = geo.mask.shape
    rows, cols = np.nonzero(geo.mask.numpy())
    frame = geo.frame.numpy()  # (P, 3, 3): rows x, y, z = n, view space
    x = (cols + 0.5) / w * 2 - 1
    y = 1 - (rows + 0.5) / h * 2
    n = frame[:, 2]
    data = np.concatenate([np.stack([x, y, n[:, 2]], 1), n, frame[:, 0]], 1).astype("f4")
    uniforms = {
        "u_viewProjectionMatrix": np.diag([1.0, 1.0, -0.5, 1.0]).astype("f4"),  # orthographic: depth from z
        "u_viewPosition": (0.0, 0.0, 1.0e6),  # the camera far along +z: V = +z at every pixel
        "u_numActiveLightSources": 1,
        "u_lightData[0].type": DIRECTIONAL,
        "u_lightData[0].direction": tuple(float(c) for c in -light_direction()),  # from the light to the scene
        "u_lightData[0].color": (1.0, 1.0, 1.0),
        "u_lightData[0].intensity": 1.0,
        "u_envLightIntensity": 0.0,
    }
    for name, value in uniforms.items():
        if name in prog:
            prog[name].value = tuple(value.T.ravel()) if isinstance(value, np.ndarray) else value
    vbo = ctx.buffer(data.tobytes())
    layout = [name for name in ("i_position", "i_normal", "i_tangent") if name in prog]
    fmt = {"i_position": "3f", "i_normal": "3f", "i_tangent": "3f"}
    vao = ctx.vertex_array(prog, [(vbo, " ".join(fmt[k] if k in layout else "12x" for k in fmt), *layout)])
    tex = ctx.texture((w, h), 4, dtype="f4")
    fbo = ctx.framebuffer(color_attachments=[tex])
    try:
        fbo.use()
        ctx.viewport = (0, 0, w, h)
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        ctx.point_size = 1.0
        vao.render(moderngl.POINTS)
        img = np.frombuffer(tex.read(), dtype="f4").reshape(h, w, 4)[::-1, :, :3].copy()
    finally:
        for obj in (vao, vbo, fbo, tex, prog):
            obj.release()
    img[~geo.mask.numpy()] = 0.0
    up = (geo.wi[:, 2] > 0).numpy()
    disk = img[geo.mask.numpy()]
    disk[~up] = 0.0
    img[geo.mask.numpy()] = disk
    return np.maximum(img, 0.0)
