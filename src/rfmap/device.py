"""Where tensors live: the ``device`` argument of training, inference and the command line."""
from __future__ import annotations

import torch

__all__ = ["resolve_device", "DEVICE_CHOICES"]

#: what ``--device`` accepts (``cuda:K`` picks one of several GPUs)
DEVICE_CHOICES = ("auto", "cpu", "cuda")


def resolve_device(name: str | torch.device | None = "auto") -> torch.device:
    """``'auto'`` (CUDA when available, else the CPU), ``'cpu'``, ``'cuda'`` or ``'cuda:K'``.

    Raises
    ------
    ValueError
        For an unknown name, or for CUDA on a machine without it.
    """
    if isinstance(name, torch.device):
        name = str(name)
    name = (name or "auto").strip().lower()
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cpu":
        return torch.device("cpu")
    if name == "cuda" or name.startswith("cuda:"):
        if not torch.cuda.is_available():
            raise ValueError(f"device {name!r} requested but no CUDA device is available (use --device cpu)")
        try:
            dev = torch.device(name)
        except RuntimeError as e:
            raise ValueError(f"invalid device {name!r}: {e}") from e
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise ValueError(f"device {name!r} requested but only {torch.cuda.device_count()} CUDA device(s) exist")
        return dev
    raise ValueError(f"unknown device {name!r}; expected one of {', '.join(DEVICE_CHOICES)} (or cuda:K)")
