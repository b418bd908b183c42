"""Building a displacement network from its stored constructor arguments, and its tensors for a weight file.

Two architectures share one interface (input ``(B, d + c, *S)``, output ``(B, d, *S)``, ``kwargs()``,
``min_size``): the multi-resolution U-Net of the paper (``arch='unet'``, the default, and the one assumed where a
model's metadata names none) and ``neuraloperator``'s FNO (``arch='fno'``).
"""
from __future__ import annotations

from typing import Callable

import torch
from torch import Tensor, nn

from .fno import FNONet
from .model import MultiResUNet

__all__ = ["ARCHS", "build_model", "tensor_state", "from_tensor_state"]


def _unet(kw: dict) -> nn.Module:
    return MultiResUNet(int(kw["dim"]), int(kw["n_params"]), int(kw["base"]), int(kw["depth"]),
                        bool(kw.get("attention", True)))


def _fno(kw: dict) -> nn.Module:
    return FNONet(int(kw["dim"]), int(kw["n_params"]), int(kw["modes"]), int(kw["width"]), int(kw["layers"]),
                  float(kw.get("padding", 0.25)))


#: The constructor of every architecture a model description may name, from its stored ``kwargs()``.
NETWORKS: dict[str, Callable[[dict], nn.Module]] = {"unet": _unet, "fno": _fno}

#: Architectures a model description may name.
ARCHS = tuple(NETWORKS)


def build_model(kwargs: dict) -> nn.Module:
    """The network described by ``kwargs`` (what its ``kwargs()`` returned); a clear ``ValueError`` otherwise."""
    kw = dict(kwargs)
    arch = kw.pop("arch", "unet")
    if arch not in NETWORKS:
        raise ValueError(f"unknown model architecture {arch!r}; expected one of {ARCHS}")
    try:
        return NETWORKS[arch](kw)
    except KeyError as e:
        raise ValueError(f"model description {kwargs} lacks {e}") from e


def tensor_state(model: nn.Module) -> dict[str, Tensor]:
    """The model's tensors for a safetensors file: non-tensor entries dropped, complex tensors (the FNO's spectral
    weights) stored as their real view of shape ``(*S, 2)``."""
    out = {}
    for k, v in model.state_dict().items():
        if isinstance(v, Tensor):
            v = v.detach().cpu()
            out[k] = (torch.view_as_real(v) if v.is_complex() else v).contiguous()
    return out


def from_tensor_state(model: nn.Module, state: dict[str, Tensor]) -> dict[str, Tensor]:
    """Undo :func:`tensor_state` for ``model``: real views of its complex entries become complex again."""
    own = {k: v for k, v in model.state_dict().items() if isinstance(v, Tensor)}
    out = {}
    for k, v in state.items():
        if k in own and own[k].is_complex() and not v.is_complex() and v.shape[-1:] == (2,):
            v = torch.view_as_complex(v.contiguous())
        out[k] = v
    return out
