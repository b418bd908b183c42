r"""Function-preserving growth of a trained U-Net: a wider network that maps every field as its parent did.

Net2Net widening (Chen, Goodfellow & Shlens, 2016) adapted to :class:`rfmap.nn.MultiResUNet`. Every feature
channel of the parent becomes ``k = base_new / base_old`` identical copies in the grown network:

* a layer *producing* channels copies the parent's weights and bias of each source channel,
  :math:`W'_{j,\cdot} = W_{s(j),\cdot}`, so every copy carries the same activation as its source;
* a layer *reading* channels splits the parent's weights over the copies of each input channel,
  :math:`W'_{\cdot,j} = \omega_j W_{\cdot,s(j)}` with :math:`\sum_{j: s(j)=c} \omega_j = 1`, so its output is the
  parent's.

The split fractions :math:`\omega_j` are drawn at random (positive, independently for every reading layer), which
breaks the symmetry between copies: their gradients differ from the first step on, so training can make them
diverge.  GroupNorm is preserved exactly because the copy map keeps every new group a union of equally many copies
of the channels of one parent group (mean and biased variance are unchanged); channel statistics (the spatial
attention's mean and max over channels) are unchanged by duplication.  The grown network's output therefore equals
its parent's up to float round-off (``tests``: 1e-5 on 2D and 3D fields).
"""
from __future__ import annotations

import numpy as np
import torch
from torch import Tensor, nn

from .blocks import _groups
from .model import MultiResUNet

__all__ = ["grow_unet", "check_growth", "copy_map"]


def check_growth(parent: nn.Module, base: int) -> None:
    """``ValueError`` unless ``parent`` is a U-Net that can be widened to ``base`` channels (a strictly larger
    multiple of its own base whose GroupNorm groups nest in the parent's)."""
    if not isinstance(parent, MultiResUNet):
        raise ValueError(f"only U-Net models can be grown, not {type(parent).__name__}")
    old = parent.base
    if base <= old:
        raise ValueError(f"the grown network needs a base larger than its parent's {old}, got {base}")
    if base % old:
        raise ValueError(f"the grown base must be a multiple of the parent's base {old}, got {base}")
    for i in range(parent.depth + 1):
        copy_map(old * 2**i, base * 2**i)


def copy_map(c_old: int, c_new: int) -> np.ndarray:
    r"""Source channel :math:`s(j)` of each of ``c_new`` channels grown from ``c_old`` GroupNorm'ed channels.

    New channel ``j`` lies in group :math:`g = \lfloor j / n_{new} \rfloor` (group size :math:`n_{new}`); it copies
    channel ``j mod n_old`` of parent group :math:`\lfloor g\, G_{old} / G_{new} \rfloor`.  ``ValueError`` when the
    groups do not nest (each new group must hold every channel of one parent group equally often).

    Returns
    -------
    ndarray of int, shape (c_new,)
    """
    g_old, g_new = _groups(c_old), _groups(c_new)
    s_old, s_new = c_old // g_old, c_new // g_new
    if s_new % s_old or g_new % g_old:
        raise ValueError(f"cannot grow {c_old} channels ({g_old} groups) to {c_new} ({g_new} groups)")
    j = np.arange(c_new)
    src = (j // s_new * g_old // g_new) * s_old + j % s_old
    counts = np.bincount(src, minlength=c_old)
    if counts.min() != counts.max() or counts.min() * c_old != c_new:
        raise ValueError(f"cannot grow {c_old} channels ({g_old} groups) to {c_new} ({g_new} groups)")
    return src


def _split(src: np.ndarray, gen: torch.Generator) -> Tensor:
    """Positive random fractions over the copies of every source channel, summing to one per source."""
    lam = 0.5 + torch.rand(len(src), generator=gen, dtype=torch.float64)
    idx = torch.as_tensor(src)
    total = torch.zeros(int(src.max()) + 1, dtype=torch.float64).index_add_(0, idx, lam)
    return lam / total[idx]


def _grow_weight(w: Tensor, out_src, in_src, gen: torch.Generator, transposed: bool = False) -> Tensor:
    """A convolution weight ``(out, in, *k)`` (``(in, out, *k)`` when ``transposed``) with its output channels
    copied by ``out_src`` and its input channels split by ``in_src`` (``None``: unchanged)."""
    w = w.double()
    o_ax, i_ax = (1, 0) if transposed else (0, 1)
    if out_src is not None:
        w = w.index_select(o_ax, torch.as_tensor(out_src))
    if in_src is not None:
        lam = _split(np.asarray(in_src), gen)
        shape = [1] * w.dim()
        shape[i_ax] = -1
        w = w.index_select(i_ax, torch.as_tensor(in_src)) * lam.view(shape)
    return w


def _concat(*parts: tuple[np.ndarray, int]) -> np.ndarray:
    """The copy map of a concatenation of channel blocks ``(copy map, parent width)``."""
    out, offset = [], 0
    for src, width in parts:
        out.append(src + offset)
        offset += width
    return np.concatenate(out)


def _load_conv(new: nn.Module, old: nn.Module, out_src, in_src, gen, transposed: bool = False) -> None:
    new.weight.copy_(_grow_weight(old.weight, out_src, in_src, gen, transposed))
    if old.bias is not None:
        b = old.bias.double()
        new.bias.copy_(b if out_src is None else b[torch.as_tensor(out_src)])


def _load_norm(new: nn.GroupNorm, old: nn.GroupNorm, src) -> None:
    idx = torch.as_tensor(src)
    new.weight.copy_(old.weight[idx])
    new.bias.copy_(old.bias[idx])


def _load_block(new: nn.Module, old: nn.Module, out_src, in_src, gen) -> None:
    """An :class:`~rfmap.nn.blocks.EnhancedDoubleConv` grown from its parent's (input map ``in_src``)."""
    ea_new, ea_old = new.body[0], old.body[0]
    _load_conv(ea_new.loc, ea_old.loc, out_src, in_src, gen)
    _load_conv(ea_new.edge, ea_old.edge, out_src, in_src, gen)
    _load_conv(ea_new.detect, ea_old.detect, None, out_src, gen)
    _load_norm(new.body[1], old.body[1], out_src)
    _load_conv(new.body[3], old.body[3], out_src, out_src, gen)
    _load_norm(new.body[4], old.body[4], out_src)
    if isinstance(old.attn, nn.Module) and hasattr(old.attn, "proj"):
        new.attn.load_state_dict(old.attn.state_dict())
    if isinstance(old.skip, nn.Identity) != isinstance(new.skip, nn.Identity):
        raise ValueError("parent and grown blocks disagree on their residual projection")
    if not isinstance(old.skip, nn.Identity):
        _load_conv(new.skip, old.skip, out_src, in_src, gen)


@torch.no_grad()
def grow_unet(parent: MultiResUNet, base: int, seed: int = 0) -> MultiResUNet:
    r"""A :class:`~rfmap.nn.MultiResUNet` of base width ``base`` that computes the same function as ``parent``.

    Parameters
    ----------
    parent : MultiResUNet
        The trained network (any dimension, depth and attention setting).
    base : int
        Channels of the grown network's first stage: a multiple of ``parent.base`` larger than it.
    seed : int
        Seed of the random split fractions (the grown network is reproducible).

    Returns
    -------
    MultiResUNet
        Same ``dim``, ``n_params``, ``depth`` and ``attention``; for every input ``x`` of shape
        ``(B, d + c, *S)``, ``grown(x) == parent(x)`` up to float round-off.

    Raises
    ------
    ValueError
        When ``parent`` is not a U-Net or ``base`` is not a larger multiple of its base.
    """
    check_growth(parent, base)
    gen = torch.Generator().manual_seed(seed)
    child = MultiResUNet(parent.dim, parent.n_params, base, parent.depth, parent.attention)
    child = child.to(dtype=next(parent.parameters()).dtype)
    depth, old_base = parent.depth, parent.base
    maps = [copy_map(old_base * 2**i, base * 2**i) for i in range(depth + 1)]
    widths = [old_base * 2**i for i in range(depth + 1)]
    for new, old in zip(child.lift.lift, parent.lift.lift):
        _load_conv(new, old, maps[0], None, gen)
    mix_in = _concat(*[(maps[0], widths[0])] * len(parent.lift.lift))
    _load_conv(child.lift.mix, parent.lift.mix, maps[0], mix_in, gen)
    for i in range(depth + 1):
        in_map = maps[0] if i == 0 else maps[i - 1]
        _load_block(child.down[i], parent.down[i], maps[i], in_map, gen)
    for k, i in enumerate(reversed(range(depth))):
        _load_conv(child.up[k], parent.up[k], maps[i], maps[i + 1], gen, transposed=True)
        cat = _concat((maps[i], widths[i]), (maps[i], widths[i]))
        _load_block(child.dec[k], parent.dec[k], maps[i], cat, gen)
    _load_conv(child.head, parent.head, None, maps[0], gen)
    return child
