"""Small fully connected networks of the latent operations, described by a
dataclass so a weight file can record and rebuild them."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

from nbrdf.neural.errors import NbrdfError

Tensor = torch.Tensor


@dataclass(frozen=True)
class MLPSpec:
    """``depth`` hidden layers of ``width`` units between ``inputs`` and ``outputs``."""

    inputs: int
    outputs: int
    width: int = 64
    depth: int = 3
    activation: str = "silu"

    def __post_init__(self):
        if self.activation not in ("relu", "silu"):
            raise NbrdfError(f"activation {self.activation!r} is unknown (relu or silu)")
        if not (1 <= self.inputs <= 4096 and 1 <= self.outputs <= 4096 and 1 <= self.depth <= 16
                and 1 <= self.width <= 4096):
            raise NbrdfError(f"network shape {asdict(self)} is unsupported")


class MLP(nn.Module):
    def __init__(self, spec: MLPSpec):
        super().__init__()
        self.spec = spec
        dims = [spec.inputs] + [spec.width] * spec.depth + [spec.outputs]
        layers: list[nn.Module] = []
        for k, (a, b) in enumerate(zip(dims[:-1], dims[1:])):
            layers.append(nn.Linear(a, b))
            if k < len(dims) - 2:
                layers.append(nn.SiLU() if spec.activation == "silu" else nn.ReLU())
        self.net = nn.Sequential(*layers)

    def forward(self, x: Tensor) -> Tensor:
        return self.net(x)


def load_state(module: nn.Module, tensors: dict[str, Tensor], prefix: str, source: str) -> None:
    """Loads ``prefix.*`` tensors into ``module`` with checks that name the problem."""
    state = {k[len(prefix) + 1:]: v for k, v in tensors.items() if k.startswith(prefix + ".")}
    want = module.state_dict()
    for k, v in want.items():
        if k not in state:
            raise NbrdfError(f"{source}: tensor {prefix}.{k} is missing")
        if tuple(state[k].shape) != tuple(v.shape):
            raise NbrdfError(f"{source}: tensor {prefix}.{k} has shape {tuple(state[k].shape)}, "
                             f"the architecture needs {tuple(v.shape)}")
        if not torch.isfinite(state[k]).all():
            raise NbrdfError(f"{source}: tensor {prefix}.{k} holds NaN or infinite values")
    extra = set(state) - set(want)
    if extra:
        raise NbrdfError(f"{source}: unexpected tensors {sorted(prefix + '.' + k for k in extra)[:3]}")
    module.load_state_dict(state)
    module.eval()
    for p in module.parameters():
        p.requires_grad_(False)


def prefixed(module: nn.Module, prefix: str, dtype: torch.dtype = torch.float32) -> dict[str, Tensor]:
    """``module``'s tensors named ``prefix.*``, stored as ``dtype`` (loading casts them back to the module's)."""
    return {f"{prefix}.{k}": v.detach().to(dtype).contiguous() for k, v in module.state_dict().items()}
