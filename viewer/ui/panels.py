"""The previewer's panels (imgui-bundle): every widget calls a ``LookDev``
method (the panels never change the session's state themselves), so what a
panel does is exactly what the tests drive.

Two fixed side bars that never cover the 3D view: at the left, Material (the
layer stack, presets, files); at the right, the timings, View (view,
incidence, compare with its error scales, interpolation, mip-mapping, the
plane-of-incidence plot), Scene (mesh, environment, background and ground,
light, camera and field of view, exposure in EV, tone mapping) and Files
(sessions, screenshots, turntable capture).
"""
from __future__ import annotations

import numpy as np
from imgui_bundle import imgui

from nbrdf.imaging.env_presets import ENV_PRESETS
from nbrdf.neural.anisotropy import anisotropic_layers
from nbrdf.neural.layer_kinds import KINDS
from nbrdf.viewer.modes import Against, Background, BrdfMode, CompareMode, View
from nbrdf.viewer.scene.camera import FOV_RANGE
from nbrdf.viewer.session.lookdev import LookDev
from nbrdf.viewer.session.stack_editor import BASE_TYPES
from nbrdf.viewer.ui.material_widgets import DIM, MaterialWidgets
from nbrdf.viewer.ui.plots import error_bar, flip_bar, polar_plot
from nbrdf.viewer.ui.preset_browser import PresetBrowser, preset_combo
from nbrdf.viewer.view_settings import Row, rows

COMPARE_LABELS = {CompareMode.OFF: "off", CompareMode.SIDE: "side by side", CompareMode.WIPE: "A/B wipe",
                  CompareMode.ERROR: "relative error", CompareMode.FLIP: "HDR-FLIP"}
AGAINST_LABELS = {Against.REFERENCE: "reference (physical stack)", Against.MATERIALX: "MaterialX GLSL (OpenPBR)"}
MESHES = ("sphere", "testmesh")
#: The window's BRDF choices (the panel's combo) and their labels.
WINDOW_BRDFS = (BrdfMode.NEURAL, BrdfMode.BELCOUR)
BRDF_LABELS = {BrdfMode.NEURAL: "neural", BrdfMode.BELCOUR: "Belcour 2018 (analytic)"}
BACKGROUND_LABELS = {Background.ENV: "environment", Background.BLUR: "blurred environment",
                     Background.FLAT: "flat colour", Background.NONE: "none (black)"}
#: The longest side of a turntable captured from the window, pixels.
TURNTABLE_MAX_SIDE = 480
#: Side bars: a share of the window's width, clamped (pixels).
SIDEBAR_SHARE, SIDEBAR_MIN, SIDEBAR_MAX = 0.24, 240, 360
#: The widest widget label: widgets leave room for it, so no label is clipped.
WIDEST_LABEL = "background colour"
RED = imgui.ImVec4(1.0, 0.35, 0.3, 1.0)



class Panels(MaterialWidgets):
    """Draws the panels each frame; text fields keep their contents between frames."""

    def __init__(self, lookdev: LookDev):
        self.ld = lookdev
        self.material_path = ""
        self.session_path = "session.nbrdf.json"
        self.shot_path = "nbrdf-shot.png"
        self.turntable_path = "turntable.mp4"
        self.turntable_frames = 36
        self.mesh_path = ""
        self.env_path = lookdev.env_path or ""
        self.turntable = False
        self.visible = True
        self.expand_all = False  # opens every section (tests draw every widget)
        self.frame_view = lambda: lookdev.frame()  # the window sets its own (it knows the view's aspect)
        self.view_size = (512, 512)  # the 3D view's size, for screenshots
        self.presets = PresetBrowser(lookdev)  # the preset thumbnails (made once their header is opened)

    def _header(self, label: str, default_open: bool = False) -> bool:
        if self.expand_all:
            imgui.set_next_item_open(True)
        return imgui.collapsing_header(label, imgui.TreeNodeFlags_.default_open if default_open else 0)

    def viewport(self, size: tuple[int, int]) -> tuple[int, int, int, int]:
        """(x, y, w, h) of the 3D view in window coordinates (top-left origin): the
        window less the two side bars, the whole window when the panels are hidden."""
        w, h = size
        if not self.visible:
            return 0, 0, w, h
        side = sidebar_width(w)
        return side, 0, max(1, w - 2 * side), h

    def draw(self, size: tuple[int, int]) -> None:
        """The two side bars (fixed, full height): the material at the left, the
        view, scene and files at the right; they never cover the 3D view."""
        if not self.visible:
            return
        w, h = size
        self.view_size = self.viewport(size)[2:]
        side = sidebar_width(w)
        flags = (imgui.WindowFlags_.no_move | imgui.WindowFlags_.no_resize | imgui.WindowFlags_.no_collapse
                 | imgui.WindowFlags_.no_saved_settings | imgui.WindowFlags_.no_bring_to_front_on_focus)
        self._grouped = False
        imgui.set_next_window_pos(imgui.ImVec2(0, 0), imgui.Cond_.always)
        imgui.set_next_window_size(imgui.ImVec2(side, h), imgui.Cond_.always)
        if imgui.begin("Material", None, flags)[0]:
            imgui.push_item_width(-self._label_width())
            self._material()
            imgui.pop_item_width()
        imgui.end()
        imgui.set_next_window_pos(imgui.ImVec2(w - side, 0), imgui.Cond_.always)
        imgui.set_next_window_size(imgui.ImVec2(side, h), imgui.Cond_.always)
        if imgui.begin("Scene and view", None, flags)[0]:
            imgui.push_item_width(-self._label_width())
            self._status()
            self._view()
            self._scene()
            self._files()
            imgui.pop_item_width()
        imgui.end()
        if not self._grouped:  # no slider is held: the next edit is a new undo step
            self.ld.end_group()

    @staticmethod
    def _label_width() -> float:
        return imgui.calc_text_size(WIDEST_LABEL).x + imgui.get_style().item_inner_spacing.x

    def _held(self, group: str) -> str | None:
        """The undo group of the widget just drawn while it is held (a slider being
        dragged: all its values are one undo step), else None."""
        if imgui.is_item_active():
            self._grouped = True
            return group
        return None

    @staticmethod
    def _wrap_buttons(labels: list[str], small: bool = True) -> str | None:
        """Buttons side by side, wrapped to the panel's width; the label clicked (or None)."""
        style = imgui.get_style()
        right = imgui.get_cursor_screen_pos().x + imgui.get_content_region_avail().x
        clicked = None
        for k, label in enumerate(labels):
            text = label.split("##")[0]
            bw = imgui.calc_text_size(text).x + 2 * style.frame_padding.x
            if k:
                last = imgui.get_item_rect_max().x
                if last + style.item_spacing.x + bw <= right:
                    imgui.same_line()
            if (imgui.small_button(label) if small else imgui.button(label)):
                clicked = label
        return clicked

    # --- material ---------------------------------------------------------------------------
    def _material(self) -> None:
        ld = self.ld
        if ld.parts:
            self._part_list()
        preset_combo("preset", "choose...", ld.load_preset)
        self.presets.section()
        progress = ld.texture_progress
        if progress is not None:
            imgui.progress_bar(progress, None, "latent texture")
        imgui.text_wrapped(ld.material.name)
        self._document_materials()
        if ld.editor.openpbr is not None:
            self._openpbr(ld.editor.openpbr)
        layers = ld.layers
        for i, layer in enumerate(list(layers)):
            imgui.push_id(f"layer{i}")
            base = i == len(layers) - 1
            kind = layer["type"]
            imgui.separator()
            imgui.text(f"{i}: {kind}{' (base)' if base else ''}")
            if kind == "dielectric" and not base:
                hit = self._wrap_buttons(["up", "down", "medium", "remove"])
                if hit == "up":
                    ld.move_layer(i, -1)
                elif hit == "down":
                    ld.move_layer(i, 1)
                elif hit == "medium":
                    ld.toggle_medium(i)
                elif hit == "remove":
                    ld.remove_layer(i)
            if base:
                cur = BASE_TYPES.index(kind) if kind in BASE_TYPES else -1
                if cur >= 0:
                    changed, k = imgui.combo("base type", cur, list(BASE_TYPES))
                    if changed and k != cur:
                        ld.set_base_type(BASE_TYPES[k])
            # every parameter of the kind, optional ones a file left out at their defaults (a conductor's F82 tint)
            defaults = KINDS[kind].new_layer() if kind in KINDS else {}
            shown = {**{p.name: defaults[p.name] for p in KINDS[kind].params if p.optional and p.live}, **layer} \
                if kind in KINDS else layer
            for key, value in shown.items():
                if key in ("type", "path"):
                    if key == "path":
                        imgui.push_style_color(imgui.Col_.text, DIM)
                        imgui.text_wrapped(f"file: {value}")
                        imgui.pop_style_color()
                    continue
                self._param(i, key, value)
            imgui.pop_id()
        self._rotation()
        imgui.separator()
        hit = self._wrap_buttons(["add clear coat", "save curve"], small=False)
        if hit == "add clear coat":
            ld.add_coat()
        elif hit == "save curve":
            ld.save_curve()
        changed, self.material_path = imgui.input_text("material file", self.material_path)
        hit = self._wrap_buttons(["open material", "save material"], small=False)
        if hit == "open material":
            ld.open_material(self.material_path)
        elif hit == "save material":
            ld.save_material(self.material_path)
        hit = self._wrap_buttons(["undo (Ctrl+Z)", "redo (Ctrl+Shift+Z)"], small=False)
        if hit and hit.startswith("undo"):
            ld.undo()
        elif hit:
            ld.redo()

    def _rotation(self) -> None:
        """The brushing direction (the material's ``anisotropy_rotation``), shown once a layer is anisotropic."""
        ld = self.ld
        if not anisotropic_layers(ld.material):
            return
        imgui.separator()
        changed, v = imgui.slider_float("brushing rotation", float(ld.material.anisotropy_rotation), -180.0, 180.0,
                                        "%.1f deg")
        group = self._held("anisotropy_rotation")
        if changed:
            with ld.coalescing(group):
                ld.set_rotation(float(v))

    # --- view ---------------------------------------------------------------------------------
    def _view(self) -> None:
        ld, s = self.ld, self.ld.state
        if not self._header("View", True):
            return
        self._settings("view")
        self._brdf_choice()
        modes = list(CompareMode)
        changed, k = imgui.combo("compare", modes.index(ld.compare), [COMPARE_LABELS[m] for m in modes])
        if changed:
            ld.set_compare(modes[k])
        if ld.compare != CompareMode.OFF:
            sources = list(Against)
            changed, k = imgui.combo("against", sources.index(ld.compare_settings.against),
                                     [AGAINST_LABELS[a] for a in sources])
            if changed:
                ld.set_against(sources[k])
            imgui.push_style_color(imgui.Col_.text, DIM)
            imgui.text_wrapped(ld.reference_status())  # wrapped: the paths and the noise stay readable
            imgui.pop_style_color()
            if ld.compare == CompareMode.WIPE:
                changed, x = imgui.slider_float("wipe", ld.wipe, 0.0, 1.0)
                group = self._held("wipe")
                if changed:
                    with ld.coalescing(group):
                        ld.set_wipe(x)
            if ld.compare == CompareMode.ERROR:
                changed, x = imgui.slider_float("error scale", ld.err_scale, 0.01, 1.0, "%.2f",
                                                imgui.SliderFlags_.logarithmic)
                group = self._held("error_scale")
                if changed:
                    with ld.coalescing(group):
                        ld.set_error_scale(x)
                error_bar(ld.err_scale)
            if ld.compare == CompareMode.FLIP:
                flip_bar(ld.flip_mean)
        if ld.material.is_textured:
            changed, on = imgui.checkbox("latent mip-mapping", ld.mipmapping)
            if changed:
                ld.set_mipmapping(on)
        self._interpolation()
        if s.view == View.LOBE:
            polar_plot(ld.plane_curves())

    def _interpolation(self) -> None:
        ld = self.ld
        if not self._header("Interpolation"):
            return
        other = ld.interp.other["name"] if ld.interp.other else "off"
        preset_combo("blend with", other, ld.set_interpolation)
        if ld.interp.other is not None:
            changed, t = imgui.slider_float("weight", ld.interp.t, 0.0, 1.0)
            group = self._held("interp.t")
            if changed:
                with ld.coalescing(group):
                    ld.set_interpolation(t=t)
            if imgui.radio_button("latent blend", ld.interp.mode == "latent"):
                ld.set_interpolation(mode="latent")
            imgui.same_line()
            if imgui.radio_button("BRDF blend", ld.interp.mode == "brdf"):
                ld.set_interpolation(mode="brdf")
            if imgui.button("stop blending"):
                ld.clear_interpolation()

    # --- scene -------------------------------------------------------------------------------
    def _scene(self) -> None:
        ld, s = self.ld, self.ld.state
        if not self._header("Scene and lighting"):
            return
        cur = MESHES.index(ld.mesh) if ld.mesh in MESHES else -1
        changed, k = imgui.combo("mesh", max(cur, 0), list(MESHES))
        if changed:
            ld.set_mesh(MESHES[k])
        _, self.mesh_path = imgui.input_text("mesh file", self.mesh_path)
        if imgui.small_button("load mesh file"):
            ld.set_mesh(self.mesh_path)
        _, self.env_path = imgui.input_text("environment", self.env_path)
        # The generated environments, one click each.
        hit = self._wrap_buttons(["load##env", "built-in sky"] + list(ENV_PRESETS))
        if hit == "load##env":
            ld.set_environment(self.env_path or None)
        elif hit == "built-in sky":
            self.env_path = ""
            ld.set_environment(None)
        elif hit is not None:
            self.env_path = hit
            ld.set_environment(hit)
        bd = ld.backdrop
        kinds = list(Background)
        changed, k = imgui.combo("background", kinds.index(bd.mode), [BACKGROUND_LABELS[m] for m in kinds])
        if changed:
            ld.set_backdrop(kinds[k])
        if bd.mode == Background.FLAT:
            changed, colour = imgui.color_edit3("background colour", list(bd.flat_colour))
            if changed:
                ld.set_backdrop(flat_colour=[float(x) for x in colour])
        changed, on = imgui.checkbox("ground shadow", bd.ground)
        if changed:
            ld.set_backdrop(ground=on)
        self._settings("scene")
        c11, fov = imgui.slider_float("field of view", s.camera.fov, *FOV_RANGE, "%.0f deg")
        group = self._held("fov")
        if c11:
            with ld.coalescing(group):
                ld.set_fov(fov)
        _, self.turntable = imgui.checkbox("turntable", self.turntable)
        imgui.same_line()
        if imgui.button("frame (F)"):
            self.frame_view()

    def _settings(self, panel: str) -> None:
        """The rows of the view settings shown in ``panel`` (viewer/view_settings.py),
        in their declaration order; a row's change is one ``update_state``."""
        ld, s = self.ld, self.ld.state
        changes: dict = {}
        held: list[str] = []
        for name, row, tp in rows(panel):
            if row.when is not None and getattr(s, row.when) is None:
                continue
            value = getattr(s, name)
            if row.widget in ("choice", "radio"):
                value = tp.parse(value)  # a mode's word (scripts may set one) as its enum
            changed, value, active = setting_row(row, value)
            if active:  # a slider being dragged: its values are one undo step
                self._grouped = True
                held.append(name)
            if changed:
                changes[name] = value
        if changes:
            with ld.coalescing(held[0] if held else None):
                ld.update_state(**changes)

    def _files(self) -> None:
        ld = self.ld
        if not self._header("Files"):
            return
        _, self.session_path = imgui.input_text("session", self.session_path)
        if imgui.button("open session"):
            ld.open_session(self.session_path)
        imgui.same_line()
        if imgui.button("save session"):
            ld.save_session(self.session_path)
        _, self.shot_path = imgui.input_text("screenshot", self.shot_path)
        shot = ld.screenshot_progress
        if shot is None:
            if imgui.button("screenshot (.png/.exr)"):
                w, h = self.view_size
                ld.start_screenshot(self.shot_path, (max(w, 1), max(h, 1)), 16)
        else:
            imgui.progress_bar(shot, imgui.ImVec2(-1, 0), f"screenshot {shot * 100:.0f} %")
            if imgui.small_button("cancel screenshot"):
                ld.cancel_screenshot()
        imgui.separator()
        _, self.turntable_path = imgui.input_text("turntable file", self.turntable_path)
        _, self.turntable_frames = imgui.slider_int("frames", self.turntable_frames, 4, 240)
        progress = ld.turntable_progress
        if progress is None:
            imgui.push_style_color(imgui.Col_.text, DIM)
            imgui.text_wrapped("turntable file: .mp4, .gif or name_%03d.png")
            imgui.pop_style_color()
            if imgui.button("capture turntable"):
                w, h = self.view_size
                k = min(1.0, TURNTABLE_MAX_SIDE / max(w, h, 1))  # the view's shape, at most 480 pixels a side
                ld.start_turntable(self.turntable_path, self.turntable_frames,
                                   (max(2, round(w * k)), max(2, round(h * k))))
        else:
            imgui.progress_bar(progress, imgui.ImVec2(-1, 0), "turntable")

    def _brdf_choice(self) -> None:
        """The BRDF the material is shaded with: the neural path or Belcour 2018 (same material)."""
        ld = self.ld
        cur = WINDOW_BRDFS.index(ld.brdf_mode) if ld.brdf_mode in WINDOW_BRDFS else 0
        changed, k = imgui.combo("BRDF", cur, [BRDF_LABELS[m] for m in WINDOW_BRDFS])
        if changed:
            ld.set_brdf_mode(WINDOW_BRDFS[k])

    # --- status (top of the right side bar) -----------------------------------------------------
    def _status(self) -> None:
        ld, t = self.ld, self.ld.timings
        # Frames presented: fps and the frame time are the same measure (fps = 1000 / frame).
        imgui.text(f"{t.fps:5.1f} fps, frame {t.frame_ms:6.1f} ms")
        imgui.text(f"view {t.render_ms:6.1f} ms, passes {ld.passes}")
        imgui.text(f"latent {t.latent_ms:5.2f} ms")
        imgui.text(f"edit -> frame {t.edit_to_frame_ms:6.1f} ms")
        if ld.refine_status:  # "refined, N s" (viewer/jobs/refine_job.py)
            imgui.text(ld.refine_status)
        if ld.calibrate_status:  # "energy: the walk's" (viewer/jobs/calibrate_job.py)
            imgui.text(ld.calibrate_status)
        if ld.notice:
            imgui.text_wrapped(ld.notice)
        if ld.error:
            imgui.push_style_color(imgui.Col_.text, RED)
            imgui.text_wrapped(ld.error)
            imgui.pop_style_color()
        imgui.separator()


def sidebar_width(window_w: int) -> int:
    """The width of each side bar: ``SIDEBAR_SHARE`` of the window within
    [SIDEBAR_MIN, SIDEBAR_MAX], and never more than a quarter of it (the view keeps half)."""
    return int(min(max(window_w * SIDEBAR_SHARE, SIDEBAR_MIN), SIDEBAR_MAX, window_w / 4))


def setting_row(row: Row, value) -> tuple[bool, object, bool]:
    """Draws one view setting's widget: (changed, new value, held). A direction row
    is two sliders (azimuth, elevation), a point row a switch and a position."""
    def out(result) -> tuple[bool, object, bool]:
        return result[0], result[1], imgui.is_item_active()

    if row.widget == "check":
        return out(imgui.checkbox(row.label, value))
    if row.widget == "radio":
        pick = None
        for w in type(value):
            if imgui.radio_button(w.value, value == w) and value != w:
                pick = w
            imgui.same_line()
        imgui.new_line()
        return pick is not None, pick, False
    if row.widget == "choice":
        words, names = list(type(value)), dict(row.labels)
        changed, k = imgui.combo(row.label, words.index(value), [names.get(w.value, w.value) for w in words])
        return changed, words[k], imgui.is_item_active()
    if row.widget == "direction":
        az, el = _angles(value)
        c1, az = imgui.slider_float(f"{row.label} azimuth", az, -180.0, 180.0)
        held = imgui.is_item_active()
        c2, el = imgui.slider_float(f"{row.label} elevation", el, -10.0, 90.0)
        return c1 or c2, _direction(az, el), held or imgui.is_item_active()
    if row.widget == "point":
        changed, on = imgui.checkbox(row.label, value is not None)
        if changed:
            return True, (2.0, -2.0, 2.5) if on else None, False
        if value is None:
            return False, None, False
        changed, pos = imgui.drag_float3(f"{row.label.split()[0]} position", list(value), 0.05, row.lo, row.hi)
        return changed, tuple(float(x) for x in pos), imgui.is_item_active()
    return out(imgui.slider_float(row.label, float(value), row.lo, row.hi, row.fmt))


def _angles(d) -> tuple[float, float]:
    x, y, z = (float(v) for v in d)
    r = max((x * x + y * y + z * z) ** 0.5, 1e-9)
    return float(np.degrees(np.arctan2(y, x))), float(np.degrees(np.arcsin(z / r)))


def _direction(az: float, el: float) -> tuple[float, float, float]:
    a, e = np.radians(az), np.radians(el)
    return (float(np.cos(e) * np.cos(a)), float(np.cos(e) * np.sin(a)), float(np.sin(e)))

