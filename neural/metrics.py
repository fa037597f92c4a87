"""Standard metrics (SPEC section 9): lobe images, lobe PSNR, albedo error,
and the convergence check of a reference lobe."""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
import torch

from nbrdf.neural.geometry import incidence, lobe_grid

#: Standard incidence angles (degrees), phi_i = 0.
THETAS = (0.0, 30.0, 60.0, 75.0)
LOBE_SIZE = 64

EvalFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]  # (wi (N,3), wo (N,3)) -> (N, 3)


def lobe_image(fn: EvalFn, theta_i_deg: float, n: int = LOBE_SIZE) -> np.ndarray:
    """The standard lobe image: float32 (n, n, 3) of f(wi, wo) cos(theta_o)
    over the projected disk of wo, zeros outside (row index along y)."""
    wo, mask = lobe_grid(n)
    d = wo[mask]
    wi = incidence(theta_i_deg).expand(d.shape[0], 3)
    vals = fn(wi, d).detach().to(torch.float64) * d[:, 2:3].double()
    img = torch.zeros(n, n, 3, dtype=torch.float64)
    img[mask] = vals
    return img.numpy().astype(np.float32)


def disk_mask(n: int = LOBE_SIZE) -> np.ndarray:
    return lobe_grid(n)[1].numpy()


def tonemap(x: np.ndarray) -> np.ndarray:
    """T(x) = x / (1 + x), the compression the lobe PSNR is taken on."""
    x = np.maximum(np.asarray(x, dtype=np.float64), 0.0)
    return x / (1.0 + x)


def compressed_psnr(a: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> float:
    """10 log10(1 / MSE) of T(a) - T(ref) over the ``mask`` pixels and channels
    (the lobe PSNR on the lobe disk; the render-space PSNR on the sphere)."""
    mse = float(np.mean((tonemap(a[mask]) - tonemap(ref[mask])) ** 2))
    return float("inf") if mse == 0 else 10.0 * math.log10(1.0 / mse)


def lobe_psnr(a: np.ndarray, ref: np.ndarray) -> float:
    """10 log10(1 / MSE) of T(a) - T(ref) over disk pixels and channels."""
    return compressed_psnr(a, ref, disk_mask(a.shape[0]))


def noise_psnr(ref: np.ndarray, ref_stderr: np.ndarray, mask: np.ndarray | None = None) -> float:
    """The PSNR the reference's own noise would cost: expected MSE of T from
    its standard errors, through T'(x) = 1 / (1 + x)^2, over ``mask`` (default: the lobe disk)."""
    m = disk_mask(ref.shape[0]) if mask is None else mask
    d = 1.0 / (1.0 + np.maximum(ref[m].astype(np.float64), 0.0)) ** 2
    mse = float(np.mean((d * ref_stderr[m]) ** 2))
    return float("inf") if mse == 0 else 10.0 * math.log10(1.0 / mse)


def is_converged(ref: np.ndarray, ref_stderr: np.ndarray, measured_psnr: float) -> bool:
    """A reference is converged for a measurement when its noise sits at
    least 10 dB below the error being measured."""
    return noise_psnr(ref, ref_stderr) >= measured_psnr + 10.0


def directional_albedo(fn: EvalFn, theta_i_deg: float, n_theta: int = 64, n_phi: int = 128) -> np.ndarray:
    """a = integral of f cos over the hemisphere of wo, per channel (3,), by a
    midpoint rule in (cos^2 theta, phi), which spreads the nodes evenly in
    projected solid angle."""
    u = (torch.arange(n_theta, dtype=torch.float64) + 0.5) / n_theta  # u = sin^2 theta
    ph = (torch.arange(n_phi, dtype=torch.float64) + 0.5) / n_phi * 2 * math.pi
    U, P = torch.meshgrid(u, ph, indexing="ij")
    s = torch.sqrt(U)
    wo = torch.stack([s * torch.cos(P), s * torch.sin(P), torch.sqrt(1 - U)], -1).reshape(-1, 3)
    wi = incidence(theta_i_deg, torch.float64).expand(wo.shape[0], 3)
    f = fn(wi.float(), wo.float()).double()
    # d(projected solid angle) = cos dω = (1/2) du dphi
    return (f.sum(0) * (1.0 / n_theta) * (2 * math.pi / n_phi) * 0.5).numpy()


def albedo_error(a: np.ndarray, a_ref: np.ndarray) -> np.ndarray:
    """|a - a_ref| / a_ref per channel."""
    return np.abs(np.asarray(a) - np.asarray(a_ref)) / np.maximum(np.asarray(a_ref), 1e-12)
