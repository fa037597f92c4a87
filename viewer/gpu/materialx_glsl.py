"""OpenPBR as MaterialX's own generated GLSL renders it, on SPEC section 9's lit sphere: what an OpenPBR user
sees today in MaterialXView-like viewers, the column ``nbrdf report openpbr`` sets beside the physical stack.

MaterialXGenGlsl writes the shader for the document's material (no environment, one directional light bound as
MaterialX's ``ND_directional_light``); it is drawn here as one point per disk pixel, each carrying that pixel's
exact normal and tangent (SPEC section 9's frame), with the camera far along +z (an orthographic view) and the
light of unit irradiance, into a float image: the same pixels as ``training.render_report.shade``.
"""
from __future__ import annotations

from pathlib import Path

import moderngl
import numpy as np

from nbrdf.neural.errors import NbrdfError
from nbrdf.training.render_report import SphereGeometry, light_direction

#: MaterialX's light type id bound to ``ND_directional_light`` in the generated shader.
DIRECTIONAL = 1


def materialx_shader(path: str | Path, material: str | None = None) -> tuple[str, str]:
    """(vertex, fragment) GLSL MaterialXGenGlsl writes for a document's material (the first, or ``material``)."""
    import MaterialX as mx  # lazy: MaterialX's generators load only for this column
    import MaterialX.PyMaterialXGenGlsl as mx_glsl  # lazy, as above
    import MaterialX.PyMaterialXGenShader as mx_gen  # lazy, as above

    doc, lib = mx.createDocument(), mx.createDocument()
    search = mx.getDefaultDataSearchPath()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), search, lib)
    try:
        mx.readFromXmlFile(doc, str(path))
    except Exception as e:  # noqa: BLE001 - MaterialX's parse and file errors share no base class in Python
        raise NbrdfError(f"{path}: MaterialX cannot read it ({str(e).splitlines()[0] if str(e) else type(e).__name__})") from None
    doc.importLibrary(lib)
    nodes = [n for n in doc.getMaterialNodes() if material is None or n.getName() == material]
    if not nodes:
        raise NbrdfError(f"{path}: no material {material or ''} to generate GLSL for")
    gen = mx_glsl.GlslShaderGenerator.create()
    ctx = mx_gen.GenContext(gen)
    ctx.registerSourceCodeSearchPath(search)
    opts = ctx.getOptions()
    opts.hwSpecularEnvironmentMethod = mx_gen.HwSpecularEnvironmentMethod.SPECULAR_ENVIRONMENT_NONE
    opts.hwMaxActiveLightSources = 1
    mx_gen.HwShaderGenerator.bindLightShader(lib.getNodeDef("ND_directional_light"), DIRECTIONAL, ctx)
    shader = gen.generate(nodes[0].getName(), nodes[0], ctx)
    fs = shader.getSourceCode(mx_gen.PIXEL_STAGE)
    if "u_refractionTwoSided" in fs and "uniform bool u_refractionTwoSided" not in fs:
        # MaterialX 1.39.5 drops this uniform's declaration without an environment but keeps its one use
        # (the transmission tint of its environment function): declared here with its default
        head, sep, rest = fs.partition("\n")
        fs = head + sep + "uniform bool u_refractionTwoSided = false;\n" + rest
    return shader.getSourceCode(mx_gen.VERTEX_STAGE), fs


def render_materialx(ctx: moderngl.Context, path: str | Path, geo: SphereGeometry, material: str | None = None
                     ) -> np.ndarray:
    """The lit sphere (H, W, 3) float32, linear, of the document's material through MaterialX's GLSL."""
    vs, fs = materialx_shader(path, material)
    try:
        prog = ctx.program(vertex_shader=vs, fragment_shader=fs)
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
