r"""A Fourier neural operator (``neuraloperator``'s :class:`neuralop.models.FNO`) behind the U-Net's interface.

The FNO of Li et al. (2021) lifts the input channels pointwise, applies ``layers`` Fourier layers

.. math::
    v_{\ell+1} = \sigma\bigl(W_\ell v_\ell + \mathcal{F}^{-1}(R_\ell \cdot \mathcal{F} v_\ell)\bigr),

where :math:`\mathcal{F}` is the discrete Fourier transform on the grid, :math:`R_\ell` a learned complex weight on
the lowest ``modes`` frequencies per axis (all higher ones are dropped) and :math:`W_\ell` a pointwise linear map,
then projects pointwise to the ``dim`` displacement channels.  Because :math:`R_\ell` acts on frequencies, the same
weights apply on any *uniform* grid; a grid too coarse for ``modes`` frequencies simply keeps those it has.  The
transform is periodic, so the grid is zero-padded by ``padding`` (a fraction of each side) before the Fourier
layers and cropped after them, which keeps the two sides of the unit square from talking to each other.

:class:`FNONet` takes and returns the same tensors as :class:`rfmap.nn.MultiResUNet` — input channels
:math:`[x_1, \dots, x_d, p_1, \dots, p_c]`, output the displacement :math:`\psi` — so the boundary mask, the
losses, training, refinement, repair and :class:`rfmap.Surrogate` apply unchanged.  Its last projection is
zero-initialised, so the untrained model is the identity map, like the U-Net.

``neuraloperator`` is an optional dependency (``pip install rfmap[fno]``, included in ``dev``).
"""
from __future__ import annotations

import torch
from torch import Tensor, nn

from .model import check_input

__all__ = ["FNONet", "fno_available"]


def fno_available() -> bool:
    """Whether ``neuraloperator`` can be imported."""
    try:
        import neuralop  # noqa: F401
    except ImportError:
        return False
    return True


class FNONet(nn.Module):
    r"""``neuraloperator``'s FNO as a displacement network :math:`\psi = \mathcal{N}_\theta(x, p)`.

    Shapes: ``(B, d + c, *S) -> (B, d, *S)``, any uniform grid with every side >= :attr:`min_size`.

    Parameters
    ----------
    dim : int
        Spatial dimension (2 or 3).
    n_params : int
        Number of parameter channels :math:`c` (the paper's :math:`m`).
    modes : int
        Fourier modes kept per axis.
    width : int
        Hidden channels of the Fourier layers.
    layers : int
        Number of Fourier layers.
    padding : float
        Zero padding on each side before the Fourier layers, as a fraction of the side (non-periodic domain).
    """

    arch = "fno"

    def __init__(self, dim: int = 2, n_params: int = 1, modes: int = 12, width: int = 32, layers: int = 4,
                 padding: float = 0.25):
        super().__init__()
        if dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, got {dim}")
        if modes < 1 or width < 1 or layers < 1 or not 0 <= padding < 1:
            raise ValueError(f"FNO needs modes, width, layers >= 1 and 0 <= padding < 1; got modes={modes}, "
                             f"width={width}, layers={layers}, padding={padding}")
        try:
            from neuralop.models import FNO
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("the FNO model needs the neuraloperator package: pip install 'rfmap[fno]'") from e
        self.dim, self.n_params = dim, n_params
        self.modes, self.width, self.layers, self.padding = int(modes), int(width), int(layers), float(padding)
        self.in_channels = dim + n_params
        self.net = FNO(n_modes=(self.modes,) * dim, in_channels=self.in_channels, out_channels=dim,
                       hidden_channels=self.width, n_layers=self.layers, positional_embedding=None,
                       domain_padding=self.padding or None)
        last = self.net.projection.fcs[-1]
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)

    def state_dict(self, *args, **kwargs):
        """The module's tensors only (neuraloperator adds a ``_metadata`` dictionary, which is not a weight)."""
        sd = super().state_dict(*args, **kwargs)
        for k in [k for k, v in sd.items() if not isinstance(v, Tensor)]:
            del sd[k]
        return sd

    def kwargs(self) -> dict:
        """Constructor arguments (stored with the weights so the model can be rebuilt)."""
        return {"arch": self.arch, "dim": self.dim, "n_params": self.n_params, "modes": self.modes,
                "width": self.width, "layers": self.layers, "padding": self.padding}

    @property
    def min_size(self) -> int:
        """Smallest grid side accepted."""
        return 4

    def forward(self, x: Tensor) -> Tensor:
        r"""The displacement field :math:`\psi` for the encoded input ``x`` (checked first)."""
        check_input(self, x)
        return self.net(x)

