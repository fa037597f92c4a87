"""The View panel's plots: the false-colour scales of the error and FLIP views
and the polar plot of the plane-of-incidence curves (viewer/jobs/plane_curves.py)."""
from __future__ import annotations

import numpy as np
from imgui_bundle import imgui, implot

#: (position, RGB) stops of the error view's false colours and of the FLIP map's magma.
ERROR_STOPS = [(0.0, (0, 0.35, 1)), (0.3, (0, 0.8, 1)), (0.5, (0.2, 1, 0.3)), (0.7, (1, 1, 0)), (1.0, (1, 0, 0))]
MAGMA_STOPS = [(0.0, (0.0, 0.0, 0.02)), (0.25, (0.32, 0.07, 0.5)), (0.5, (0.72, 0.21, 0.47)),
               (0.75, (0.99, 0.53, 0.38)), (1.0, (0.99, 0.99, 0.75))]


def _ramp(stops) -> None:
    """A colour ramp the panel's width through ``stops``."""
    dl = imgui.get_window_draw_list()
    p = imgui.get_cursor_screen_pos()
    w, h = imgui.get_content_region_avail().x, 12.0
    for (t0, c0), (t1, c1) in zip(stops, stops[1:]):
        a, b = imgui.ImVec2(p.x + w * t0, p.y), imgui.ImVec2(p.x + w * t1, p.y + h)
        col0 = imgui.get_color_u32(imgui.ImVec4(*c0, 1.0))
        col1 = imgui.get_color_u32(imgui.ImVec4(*c1, 1.0))
        dl.add_rect_filled_multi_color(a, b, col0, col1, col1, col0)
    imgui.dummy(imgui.ImVec2(w, h))


def error_bar(scale: float) -> None:
    """The false-colour scale: relative error 0 ... ``scale``."""
    _ramp(ERROR_STOPS)
    imgui.text("0 %")
    right = f"{scale * 100:.0f} % relative error"
    imgui.same_line(max(0.0, imgui.get_content_region_avail().x + imgui.get_cursor_pos_x()
                        - imgui.calc_text_size(right).x))
    imgui.text(right)


def flip_bar(mean: float | None) -> None:
    """The magma scale of the FLIP map and the mean FLIP (None: no reference yet)."""
    _ramp(MAGMA_STOPS)
    imgui.text_wrapped(f"FLIP 0 ... 1, mean {'(waiting for the reference)' if mean is None else f'{mean:.4f}'}")


def polar_plot(curves: dict) -> None:
    """The plane-of-incidence curves {name: (theta_o degrees, f cos)} as a polar plot."""
    if not curves:
        return
    imgui.text_wrapped("plane of incidence: f cos / (1 + f cos)")  # the title above: the plot is narrow
    if implot.begin_plot("##plane", imgui.ImVec2(-1, 220), implot.Flags_.equal):
        implot.setup_axes("", "", 0, 0)
        for name, (th, val) in curves.items():
            t = np.radians(th)
            r = np.maximum(val, 0.0)
            r = r / (1.0 + r)  # the lobe metric's compression: peaks and tails both visible
            implot.plot_line(name, np.ascontiguousarray(r * np.sin(t)), np.ascontiguousarray(r * np.cos(t)))
        implot.end_plot()
