r"""Dimension-generic building blocks of the multi-resolution U-Net (paper Sec. 4.2).

Every block takes ``dim`` (2 or 3) and builds the matching ``Conv2d``/``Conv3d`` layers, so the 2D and 3D models
share one implementation.
"""
from __future__ import annotations

import torch
from torch import Tensor, nn
from torch.nn import functional as F

__all__ = [
    "Conv2d",
    "Conv3d",
    "conv_cls",
    "conv_transpose_cls",
    "resize",
    "EdgeAwareConv",
    "SpatialAttention",
    "EnhancedDoubleConv",
    "MultiResolutionLift",
]


class Conv3d(nn.Conv3d):
    """``nn.Conv3d`` (same parameters and state dict) with faster inference on CPU; in training exactly ``nn.Conv3d``.

    Without gradients on CPU it takes the oneDNN kernel, with the same results to float32 round-off; with gradients
    enabled (training) the layer is exactly ``nn.Conv3d``, so training is unchanged and reproducible.
    """

    # PyTorch's CPU heuristic sends a float32 Conv3d with batch 1 and few channels (B C D H at most 20,480, e.g. 8
    # channels on a 48^3 grid), and any 1x1x1 Conv3d on one thread, to a slow native kernel; the oneDNN kernel was
    # about four times faster for the surrogate's 3D networks at batch 1.

    def _conv_forward(self, input: Tensor, weight: Tensor, bias: Tensor | None) -> Tensor:
        if (not torch.is_grad_enabled() and input.device.type == "cpu" and input.dtype == torch.float32
                and self.padding_mode == "zeros" and isinstance(self.padding, tuple)
                and torch.backends.mkldnn.is_available() and torch.backends.mkldnn.enabled):
            return torch.mkldnn_convolution(input.contiguous(), weight.contiguous(), bias, self.padding,
                                            self.stride, self.dilation, self.groups)
        return super()._conv_forward(input, weight, bias)


class Conv2d(nn.Conv2d):
    """``nn.Conv2d`` (same parameters and state dict) with faster inference on CPU; in training exactly ``nn.Conv2d``.

    Without gradients, on CPU in float32: a 1x1 convolution of a contiguous input is one matrix product
    ``W (C_out, C_in) @ x (C_in, H W)`` per sample (so a sample's output is the same in any batch), and a dilated
    convolution takes the oneDNN kernel, with the same results to float32 round-off (tested).  With gradients
    enabled (training) the layer is exactly ``nn.Conv2d``.
    """

    # PyTorch sends both to slow native kernels at batch 1; at the 51-point grid the 2D surrogate's network took
    # about 10 % less time with these paths.

    def _conv_forward(self, input: Tensor, weight: Tensor, bias: Tensor | None) -> Tensor:
        if not torch.is_grad_enabled() and input.device.type == "cpu" and input.dtype == torch.float32 \
                and self.padding_mode == "zeros" and self.groups == 1:
            if self.kernel_size == (1, 1) and self.stride == (1, 1) and self.padding == (0, 0) \
                    and input.is_contiguous():
                b, c = input.shape[:2]
                w = weight.view(weight.shape[0], c)
                y = torch.stack([torch.mm(w, xi) for xi in input.view(b, c, -1)])
                if bias is not None:
                    y = y + bias[:, None]
                return y.view(b, -1, *input.shape[2:])
            if self.dilation != (1, 1) and isinstance(self.padding, tuple) and torch.backends.mkldnn.is_available() \
                    and torch.backends.mkldnn.enabled:
                return torch.mkldnn_convolution(input.contiguous(), weight.contiguous(), bias, self.padding,
                                                self.stride, self.dilation, self.groups)
        return super()._conv_forward(input, weight, bias)


def conv_cls(dim: int) -> type[nn.Module]:
    return {2: Conv2d, 3: Conv3d}[dim]


def conv_transpose_cls(dim: int) -> type[nn.Module]:
    return {2: nn.ConvTranspose2d, 3: nn.ConvTranspose3d}[dim]


def resize(x: Tensor, size: tuple[int, ...]) -> Tensor:
    """(Bi/tri)linear interpolation of a ``(B, C, *S)`` tensor to spatial size ``size`` (identity if equal)."""
    if tuple(x.shape[2:]) == tuple(size):
        return x
    mode = "bilinear" if x.dim() == 4 else "trilinear"
    return F.interpolate(x, size=size, mode=mode, align_corners=True)


def _groups(c: int) -> int:
    for g in (8, 4, 2, 1):
        if c % g == 0 and c // g >= 2:
            return g
    return 1


class EdgeAwareConv(nn.Module):
    r"""Edge-aware convolution :math:`\mathcal{C}_{EA}(f) = w\,\mathcal{C}_{edge}(f) + (1-w)\,\mathcal{C}_{loc}(f)`.

    :math:`w = \sigma(\mathcal{E}(f))` is a per-point gate (paper Sec. 4.2).  The paper names a local and a
    wider-stencil convolution and leaves the edge detector :math:`\mathcal{E}` unspecified; the rest is this
    package's choice: :math:`\mathcal{C}_{loc}` is a 3-point-stencil convolution, :math:`\mathcal{C}_{edge}` a
    dilation-2 stencil, and :math:`\mathcal{E}(f) = P\,|\mathcal{C}_{edge}(f) - \mathcal{C}_{loc}(f)|` with a
    learned 1x1 projection :math:`P`: the two stencils disagree where the features vary on the grid scale, i.e. at
    edges.

    Shapes: ``(B, C_in, *S) -> (B, C_out, *S)`` for any spatial size S.
    """

    def __init__(self, cin: int, cout: int, dim: int):
        super().__init__()
        Conv = conv_cls(dim)
        self.loc = Conv(cin, cout, 3, padding=1)
        self.edge = Conv(cin, cout, 3, padding=2, dilation=2)
        self.detect = Conv(cout, 1, 1)

    def forward(self, f: Tensor) -> Tensor:
        """The edge-aware convolution of the feature map ``f``."""
        loc, edge = self.loc(f), self.edge(f)
        w = torch.sigmoid(self.detect((edge - loc).abs()))
        return w * edge + (1 - w) * loc


class SpatialAttention(nn.Module):
    r"""Spatial attention :math:`f \cdot \sigma(W [m, M, \bar m, \bar M])`.

    :math:`m = \mathrm{mean}_c f` and :math:`M = \max_c f` are channel statistics, :math:`\bar m, \bar M` their
    local means (average over ``kernel``-point blocks, interpolated back), and :math:`W` a learned 1x1 projection.
    The paper names a spatial attention module but gives no formula; this one is the package's choice.
    Shapes: ``(B, C, *S) -> (B, C, *S)``.
    """

    def __init__(self, dim: int, kernel: int = 4):
        super().__init__()
        self.dim, self.kernel = dim, kernel
        self.proj = conv_cls(dim)(4, 1, 1)

    def forward(self, f: Tensor) -> Tensor:
        """``f`` weighted by its spatial attention map (same shape)."""
        s = torch.cat([f.mean(1, keepdim=True), f.amax(1, keepdim=True)], 1)
        pool = F.avg_pool2d if self.dim == 2 else F.avg_pool3d
        # a side shorter than the kernel is averaged whole (what ceil_mode does in 2D; 3D pooling would raise)
        k = tuple(min(self.kernel, n) for n in s.shape[2:])
        coarse = pool(s, k, stride=k, ceil_mode=True)
        s = torch.cat([s, resize(coarse, tuple(s.shape[2:]))], 1)
        return f * torch.sigmoid(self.proj(s))


class EnhancedDoubleConv(nn.Module):
    """Enhanced double convolution (EDC): an edge-aware convolution and a 3-point convolution, each followed by
    GroupNorm (and SiLU), then spatial attention and a residual 1x1 projection.  The paper names the block and its
    parts but states no normalisation, activation or residual projection: those are this package's choices.
    Shapes: ``(B, C_in, *S) -> (B, C_out, *S)``."""

    def __init__(self, cin: int, cout: int, dim: int, attention: bool = True):
        super().__init__()
        self.body = nn.Sequential(
            EdgeAwareConv(cin, cout, dim), nn.GroupNorm(_groups(cout), cout), nn.SiLU(),
            conv_cls(dim)(cout, cout, 3, padding=1), nn.GroupNorm(_groups(cout), cout),
        )
        self.attn = SpatialAttention(dim) if attention else nn.Identity()
        self.skip = conv_cls(dim)(cin, cout, 1) if cin != cout else nn.Identity()
        self.act = nn.SiLU()

    def forward(self, x: Tensor) -> Tensor:
        """The block's output for ``x``, ``(B, C_in, *S) -> (B, C_out, *S)``."""
        return self.act(self.attn(self.body(x)) + self.skip(x))


class MultiResolutionLift(nn.Module):
    r"""Multi-resolution lifting (paper Sec. 4.2).

    :math:`x^{(1)}, x^{(1/2)}, x^{(1/4)}` (interpolated copies of the input) are lifted by 1x1 convolutions
    :math:`\mathcal{P}_1, \mathcal{P}_{1/2}, \mathcal{P}_{1/4}`, interpolated back to full size, concatenated and
    mixed by a 1x1 convolution :math:`\mathcal{F}`.  Shapes: ``(B, C_in, *S) -> (B, C_out, *S)``.
    """

    def __init__(self, cin: int, cout: int, dim: int, scales: tuple[int, ...] = (1, 2, 4)):
        super().__init__()
        Conv = conv_cls(dim)
        self.scales = scales
        self.lift = nn.ModuleList([Conv(cin, cout, 1) for _ in scales])
        self.mix = Conv(cout * len(scales), cout, 1)

    def forward(self, x: Tensor) -> Tensor:
        """The features of ``x`` lifted at each of the block's scales, concatenated and mixed by a 1x1 convolution."""
        size = tuple(x.shape[2:])
        feats = []
        for s, lift in zip(self.scales, self.lift):
            coarse = resize(x, tuple(max(2, -(-n // s)) for n in size))
            feats.append(resize(lift(coarse), size))
        return self.mix(torch.cat(feats, 1))
