"""PNG figures people would rather look at than read: lobe images, lobe
comparisons with difference maps, loss curves. matplotlib, no display."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np


def _plt():
    import matplotlib  # late: matplotlib costs ~0.5 s; only figures need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # late: after the Agg backend is chosen

    return plt


def lobe_rgb(img: np.ndarray) -> np.ndarray:
    """A lobe array -> displayable sRGB in [0, 1] via T(x) = x / (1 + x)."""
    t = np.maximum(img, 0.0) / (1.0 + np.maximum(img, 0.0))
    return np.clip(t, 0, 1) ** (1 / 2.2)


def save_lobe_png(img: np.ndarray, path: str | Path, title: str = "") -> None:
    """The lobe image with +y up, x to the right, as the projected disk is seen from above."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(4, 4.3), dpi=100)
    ax.imshow(lobe_rgb(img), origin="lower", extent=(-1, 1, -1, 1), interpolation="nearest")
    ax.set_xlabel("x = sin θo cos φo")
    ax.set_ylabel("y = sin θo sin φo")
    if title:
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def save_lobe_comparison(rows: Sequence[tuple[str, np.ndarray, np.ndarray]], path: str | Path) -> None:
    """Rows of (label, reference, estimate): reference | estimate | |T(a) - T(b)|."""
    plt = _plt()
    fig, axes = plt.subplots(len(rows), 3, figsize=(7.5, 2.5 * len(rows)), dpi=90, squeeze=False)
    for r, (label, ref, est) in enumerate(rows):
        t = lambda x: np.maximum(x, 0) / (1 + np.maximum(x, 0))
        diff = np.abs(t(est) - t(ref)).mean(-1)
        for c, (im, name) in enumerate(((lobe_rgb(ref), "reference"), (lobe_rgb(est), "neural"), (diff, "|ΔT|"))):
            ax = axes[r, c]
            kw = dict(cmap="magma", vmin=0, vmax=max(0.05, float(diff.max()))) if c == 2 else {}
            h = ax.imshow(im, origin="lower", interpolation="nearest", **kw)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(f"{label}: {name}" if c == 0 else name, fontsize=8)
            if c == 2:
                fig.colorbar(h, ax=ax, fraction=0.046)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def save_curves(curves: dict[str, Sequence[float]], path: str | Path, xlabel: str = "step",
                ylabel: str = "loss", logy: bool = True) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
    for name, ys in curves.items():
        ax.plot(np.arange(len(ys)), ys, label=name)
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def save_lobe_grid(rows: Sequence[tuple[str, Sequence[np.ndarray]]], col_titles: Sequence[str],
                   path: str | Path) -> None:
    """Rows of lobe images under shared column titles (e.g. methods or blend weights)."""
    plt = _plt()
    ncol = max(len(imgs) for _, imgs in rows)
    fig, axes = plt.subplots(len(rows), ncol, figsize=(1.9 * ncol + 0.4, 2.0 * len(rows)), dpi=90, squeeze=False)
    for r, (label, imgs) in enumerate(rows):
        for c in range(ncol):
            ax = axes[r, c]
            ax.set_xticks([])
            ax.set_yticks([])
            if c < len(imgs):
                ax.imshow(lobe_rgb(imgs[c]), origin="lower", interpolation="nearest")
            if r == 0 and c < len(col_titles):
                ax.set_title(col_titles[c], fontsize=8)
        axes[r, 0].set_ylabel(label, fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
