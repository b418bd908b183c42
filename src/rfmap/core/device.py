"""Where tensors live and how many threads work on them: the ``device`` argument of training, inference and the
command line, and a temporary torch thread count."""
from __future__ import annotations

import contextlib

import torch

__all__ = ["resolve_device", "DEVICE_CHOICES", "torch_threads"]

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


@contextlib.contextmanager
def torch_threads(n: int | None):
    """Temporarily set the torch intra-op thread count (``None``: leave it alone)."""
    if n is None:
        yield
        return
    old = torch.get_num_threads()
    torch.set_num_threads(max(1, int(n)))
    try:
        yield
    finally:
        torch.set_num_threads(old)
