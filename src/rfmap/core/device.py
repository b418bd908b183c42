"""Where tensors live and how many threads work on them: the ``device`` argument of training, inference and the
command line, and a temporary torch thread count."""
from __future__ import annotations

import contextlib

import torch

from .wording import counted

__all__ = ["resolve_device", "DEVICE_CHOICES", "torch_threads", "PRECISIONS", "check_precision", "autocast"]

#: what ``--device`` accepts (``cuda:K`` picks one of several GPUs)
DEVICE_CHOICES = ("auto", "cpu", "cuda")
#: what ``--precision`` accepts: the network's arithmetic in training (losses and Jacobians stay in float32)
PRECISIONS = ("fp32", "bf16")


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
            raise ValueError(f"device {name!r} requested, but this machine has "
                             f"{counted(torch.cuda.device_count(), 'CUDA device')}")
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


def bf16_supported(device: torch.device) -> bool:
    """Whether ``device`` runs bfloat16 matrix products natively (CUDA: ``torch.cuda.is_bf16_supported``; CPU:
    oneDNN's bf16 kernels, i.e. AVX512-BF16 or AMX)."""
    if device.type == "cuda":
        return bool(torch.cuda.is_bf16_supported())
    if device.type == "cpu":
        try:
            return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
        except (AttributeError, RuntimeError):
            return False
    return False


def check_precision(precision: str, device: torch.device) -> str:
    """``precision`` checked against :data:`PRECISIONS` and the device.

    Raises
    ------
    ValueError
        For an unknown name, or ``'bf16'`` on a device without native bfloat16 arithmetic.
    """
    p = str(precision).strip().lower()
    if p not in PRECISIONS:
        raise ValueError(f"unknown precision {precision!r}; expected one of {', '.join(PRECISIONS)}")
    if p == "bf16" and not bf16_supported(device):
        raise ValueError(f"precision 'bf16' requested but device {device} has no native bfloat16 arithmetic "
                         "(use --precision fp32)")
    return p


def autocast(precision: str, device: torch.device):
    """The context in which the network runs: ``torch.autocast(device.type, torch.bfloat16)`` for ``'bf16'``, a
    no-op for ``'fp32'``.  Only the network goes inside it; its output is cast back to float32 before the losses."""
    if precision == "bf16":
        return torch.autocast(device.type, dtype=torch.bfloat16)
    return contextlib.nullcontext()
