r"""The multi-resolution enhanced U-Net surrogate (paper Sec. 4.2), one implementation for 2D and 3D."""
from __future__ import annotations

import torch
from torch import Tensor, nn
from torch.nn import functional as F

from .blocks import EnhancedDoubleConv, MultiResolutionLift, conv_cls, conv_transpose_cls, resize

__all__ = ["MultiResUNet", "boundary_mask", "apply_displacement", "check_input", "BOUNDARIES"]

#: Boundary conditions: ``fixed`` (identity on the boundary), ``square`` (vertices slide along their wall,
#: the cube in 3D), ``free`` (no constraint).
BOUNDARIES = ("fixed", "square", "free")


def check_input(net: nn.Module, x: Tensor) -> None:
    """Raise a clear ``ValueError`` unless ``x`` fits the displacement network ``net`` (attributes ``dim``,
    ``n_params``, ``in_channels``, ``min_size``): shape ``(B, d + c, *S)`` with d spatial sides >= ``min_size``."""
    if x.dim() != net.dim + 2:
        raise ValueError(f"a {net.dim}D model expects input of shape (B, C, {', '.join(['N'] * net.dim)}), "
                         f"got {tuple(x.shape)}")
    if x.shape[1] != net.in_channels:
        raise ValueError(f"model expects {net.in_channels} channels ({net.dim} coordinates + {net.n_params} "
                         f"parameters), got {x.shape[1]}")
    if min(x.shape[2:]) < net.min_size:
        raise ValueError(f"grid too small for this model: sides {tuple(x.shape[2:])}, need >= {net.min_size}")


class MultiResUNet(nn.Module):
    r"""Resolution-free encoder–decoder :math:`\mathcal{N}_\theta` producing a displacement field :math:`\psi`.

    Input encoding (paper Sec. 4.1): channels :math:`[x_1, \dots, x_d, p_1, \dots, p_c]` on a grid of any size, the
    field in its task's encoding (:math:`\log p` for a density where the paper feeds :math:`p`, a departure that
    :mod:`rfmap.tasks.density` explains).
    Multi-resolution lifting, ``depth`` encoder stages of :class:`EnhancedDoubleConv` with 2x average pooling,
    transposed-convolution upsampling with interpolation wherever sizes do not match the skip connection, and a
    zero-initialised 1x1 head (so the untrained model is the identity map).

    Shapes: ``(B, d + c, *S) -> (B, d, *S)``, any grid with every side >= :attr:`min_size` (``2 ** depth + 1``).

    Parameters
    ----------
    dim : int
        Spatial dimension (2 or 3).
    n_params : int
        Number of parameter channels :math:`c` (the paper's :math:`m`).
    base : int
        Channels of the first stage (doubled at every stage).
    depth : int
        Number of poolings.
    attention : bool
        Whether every :class:`EnhancedDoubleConv` block applies its :class:`SpatialAttention` gate (without it, the
        gate is the identity).
    """

    def __init__(self, dim: int = 2, n_params: int = 1, base: int = 16, depth: int = 3, attention: bool = True):
        super().__init__()
        if dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, got {dim}")
        self.dim, self.n_params, self.base, self.depth = dim, n_params, base, depth
        self.attention = bool(attention)
        self.in_channels = dim + n_params
        Conv, ConvT = conv_cls(dim), conv_transpose_cls(dim)
        ch = [base * 2**i for i in range(depth + 1)]
        self.lift = MultiResolutionLift(self.in_channels, base, dim)
        self.down = nn.ModuleList([EnhancedDoubleConv(base if i == 0 else ch[i - 1], ch[i], dim, attention)
                                   for i in range(depth + 1)])
        self.up = nn.ModuleList([ConvT(ch[i + 1], ch[i], 2, stride=2) for i in reversed(range(depth))])
        self.dec = nn.ModuleList([EnhancedDoubleConv(2 * ch[i], ch[i], dim, attention)
                                  for i in reversed(range(depth))])
        self.head = Conv(base, dim, 1)
        nn.init.zeros_(self.head.weight)
        nn.init.zeros_(self.head.bias)

    def kwargs(self) -> dict:
        """Constructor arguments (stored with the weights so the model can be rebuilt)."""
        return {"dim": self.dim, "n_params": self.n_params, "base": self.base, "depth": self.depth,
                "attention": self.attention}

    @property
    def min_size(self) -> int:
        """Smallest grid side accepted (at least 2 points at the coarsest level)."""
        return 2 ** self.depth + 1

    def forward(self, x: Tensor) -> Tensor:
        r"""The displacement field :math:`\psi` for the encoded input ``x`` (checked first)."""
        check_input(self, x)
        pool = F.avg_pool2d if self.dim == 2 else F.avg_pool3d
        h = self.lift(x)
        skips = []
        for i, block in enumerate(self.down):
            if i > 0:
                h = pool(h, 2, ceil_mode=True)
            h = block(h)
            skips.append(h)
        h = skips.pop()
        for up, dec in zip(self.up, self.dec):
            skip = skips.pop()
            h = resize(up(h), tuple(skip.shape[2:]))
            h = dec(torch.cat([h, skip], 1))
        return self.head(h)


def boundary_mask(points: Tensor, boundary: str) -> Tensor:
    r"""The boundary mask :math:`\mathcal{B}(x)` of :math:`u = x + \mathcal{B}(x) \odot \psi(x)` (paper Sec. 4.2).

    * ``square``: :math:`\mathcal{B}_i = 4 x_i (1 - x_i)` — component :math:`i` vanishes on the walls normal to
      axis :math:`i`, so boundary vertices slide along their wall;
    * ``fixed``: :math:`\mathcal{B}_i = 4^d \prod_j x_j (1 - x_j)` — the identity on the boundary;
    * ``free``: :math:`\mathcal{B} = 1`.

    Shapes: points (..., d) -> mask (..., d).
    """
    if boundary == "square":
        return 4 * points * (1 - points)
    if boundary == "fixed":
        b = (4 * points * (1 - points)).prod(-1, keepdim=True)
        return b.expand_as(points)
    if boundary == "free":
        return torch.ones_like(points)
    raise ValueError(f"unknown boundary {boundary!r}; expected one of {BOUNDARIES}")


def apply_displacement(points: Tensor, psi: Tensor, boundary: str, alpha: Tensor | None = None) -> Tensor:
    r""":math:`u_\alpha(x) = x + \mathcal{B}(x) \odot (\alpha \odot \psi(x))` (paper Sec. 4.3).

    Parameters
    ----------
    points : Tensor, shape (..., P, d)
    psi : Tensor, shape (..., P, d)
    alpha : Tensor, shape (d,) or (..., 1, d), optional (default ones)
    """
    disp = psi if alpha is None else psi * alpha
    return points + boundary_mask(points, boundary) * disp
