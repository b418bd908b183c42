r"""Test-time symmetrization of a density surrogate over the symmetries of the unit square or cube.

The symmetries of :math:`\Omega = [0, 1]^d` are the axis reflections :math:`x_i \mapsto 1 - x_i` and the axis
permutations (the hyperoctahedral group: 8 elements in 2D, 48 in 3D); every one maps the regular grid onto itself.
The density-equalizing problem commutes with them: if :math:`u` equalizes :math:`\rho`, then
:math:`g^{-1} \circ u \circ g` equalizes :math:`\rho \circ g`, so the displacement :math:`d = u - x` of the
transformed field is the transformed displacement,

.. math::

    d_{\rho \circ g}(x) = A_g^{-1}\, d_\rho(g x), \qquad g x = A_g x + b_g,

(a reflection of axis :math:`i` negates component :math:`i` and flips the array along it; a permutation of the
axes permutes the components and transposes the array).  The boundary factor :math:`\mathcal{B}` of
:func:`rfmap.nn.apply_displacement` is invariant in the same way, so the rule holds for the network's
:math:`\psi` as well.  A trained network is equivariant only approximately: its errors on :math:`\rho` and on
:math:`\rho \circ g` differ.  The symmetrized prediction

.. math::

    \bar\psi = \frac{1}{|S|} \sum_{g \in S} A_g\, \psi(\rho \circ g) \circ g^{-1}

over a set :math:`S` of symmetries is exact wherever :math:`\psi` is, and averages out the part of the error that
changes with :math:`g`; it costs :math:`|S|` network evaluations. On the held-out validation fields (never the
paper's test fields) the average of :data:`DEFAULT_SYMMETRY` lowers the mean Std(ρ̃_map) in 2D and in 3D and folds
the steep ramps less often (the book's page :doc:`Design decisions </book/design>` gives the measurements); the
chapter on density-equalizing maps in 3D reports it on the paper's 3D tests.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

__all__ = ["Symmetry", "SYMMETRY_GROUPS", "DEFAULT_SYMMETRY", "symmetries", "transform_grid", "restore_displacement",
           "symmetrized_displacement", "resolve_symmetry", "BATCH_POINTS"]

#: The sets of symmetries offered: ``flips`` (every combination of axis reflections, 2^d), ``permutations`` (every
#: order of the axes, d!), ``cyclic`` (the d cyclic orders of the axes), ``full`` (all 2^d d! symmetries).
SYMMETRY_GROUPS = ("flips", "permutations", "cyclic", "full")
#: The set used by ``symmetrize=True``, per dimension, chosen on the held-out validation fields: all 8 symmetries in
#: 2D, the 3 cyclic axis orders in 3D (:doc:`Design decisions </book/design>`).
DEFAULT_SYMMETRY = {2: "full", 3: "cyclic"}


@dataclass(frozen=True)
class Symmetry:
    """One symmetry of the unit cube: reflect the axes in ``flips``, then order the axes as ``perm``."""

    flips: tuple[int, ...]
    perm: tuple[int, ...]


def symmetries(dim: int, group: str) -> list[Symmetry]:
    """The symmetries of ``group`` (:data:`SYMMETRY_GROUPS`) in dimension ``dim``; the identity comes first."""
    if dim not in (2, 3):
        raise ValueError(f"symmetrization is defined for 2D and 3D grids, got dim={dim}")
    ident = tuple(range(dim))
    flips = [f for r in range(dim + 1) for f in itertools.combinations(range(dim), r)]
    if group == "flips":
        return [Symmetry(f, ident) for f in flips]
    if group == "permutations":
        return [Symmetry((), p) for p in itertools.permutations(range(dim))]
    if group == "cyclic":
        return [Symmetry((), tuple((i + k) % dim for i in range(dim))) for k in range(dim)]
    if group == "full":
        return [Symmetry(f, p) for f in flips for p in itertools.permutations(range(dim))]
    raise ValueError(f"unknown symmetry group {group!r}; expected one of {', '.join(SYMMETRY_GROUPS)}")


def resolve_symmetry(symmetrize: bool | str, dim: int) -> str | None:
    """The group name for a ``symmetrize`` argument: ``False`` gives ``None``, ``True`` the
    :data:`DEFAULT_SYMMETRY` of the dimension, a name itself (checked)."""
    if symmetrize is False or symmetrize is None:
        return None
    group = DEFAULT_SYMMETRY.get(dim) if symmetrize is True else symmetrize
    if not isinstance(group, str) or group not in SYMMETRY_GROUPS:
        raise ValueError(f"symmetrize must be True, False or one of {', '.join(SYMMETRY_GROUPS)}; got {symmetrize!r}")
    symmetries(dim, group)  # checks the dimension
    return group


def _odd(perm: tuple[int, ...]) -> bool:
    """Whether a permutation is odd (an odd number of inversions)."""
    return sum(a > b for i, a in enumerate(perm) for b in perm[i + 1:]) % 2 == 1


def transform_grid(grids: np.ndarray, s: Symmetry) -> np.ndarray:
    r"""Fields on the grid seen through symmetry ``s``.

    A density is a scalar: only its samples move.  A complex array is a Beltrami coefficient (2D), whose values
    change too: for :math:`f' = g \circ f \circ g^{-1}` with :math:`g(z) = e^{i\theta} z + c` the coefficient is
    :math:`\mu_{f'} = e^{2i\theta}\,\mu_f \circ g^{-1}`, and with the reflection
    :math:`g(z) = e^{i\theta} \bar z + c` it is :math:`e^{2i\theta}\,\overline{\mu_f \circ g^{-1}}`.  A
    reflection of either axis is such a reflection with :math:`e^{2i\theta} = 1` (a conjugate), the swap of the two
    axes one with :math:`e^{2i\theta} = -1` (minus the conjugate).

    Parameters
    ----------
    grids : array, shape (B, N, ..., N), real (density) or complex (Beltrami coefficient)

    Returns
    -------
    array, shape (B, N, ..., N), contiguous
        The fields reflected along ``s.flips``, then with axes ``s.perm`` (and, for a Beltrami coefficient, its
        values transformed as above).
    """
    g = np.asarray(grids)
    for ax in s.flips:
        g = np.flip(g, axis=1 + ax)
    g = np.ascontiguousarray(np.transpose(g, (0,) + tuple(1 + p for p in s.perm)))
    if np.iscomplexobj(g):
        odd = _odd(s.perm)
        if (len(s.flips) + odd) % 2:
            g = np.conj(g)
        if odd:
            g = -g
    return g


def restore_displacement(psi: torch.Tensor, s: Symmetry) -> torch.Tensor:
    """The displacement of the untransformed fields from that of the fields of :func:`transform_grid`.

    Parameters
    ----------
    psi : Tensor, shape (B, d, N, ..., N)

    Returns
    -------
    Tensor, shape (B, d, N, ..., N)
        The displacement with its axes and components put back in order, then every reflected axis flipped back
        and its component negated.
    """
    d = psi.shape[1]
    inv = [int(i) for i in np.argsort(s.perm)]
    out = psi.permute(0, 1, *[2 + q for q in inv])[:, inv]
    if s.flips:
        out = out.flip([2 + ax for ax in s.flips])
        sign = torch.ones(d, dtype=out.dtype, device=out.device)
        sign[list(s.flips)] = -1
        out = out * sign.view(1, d, *([1] * d))
    return out.contiguous()


#: Grid points per network evaluation up to which the copies of :func:`symmetrized_displacement` are stacked into one
#: batch (a single copy larger than this is evaluated alone); the time of a map depends on it, the map only through
#: float32 rounding. :doc:`Design decisions </book/design>` gives its timings against the alternatives.
BATCH_POINTS = 2**15


def symmetrized_displacement(fn: Callable[[np.ndarray], torch.Tensor], grids: np.ndarray, group: str, *,
                             batch_points: int = BATCH_POINTS) -> torch.Tensor:
    r"""The mean of :math:`A_g\,\psi(\rho \circ g) \circ g^{-1}` over the symmetries of ``group``.

    Parameters
    ----------
    fn : callable
        The network's displacement of a batch of fields, (B, N, ..., N) -> Tensor (B, d, N, ..., N).
    grids : array, shape (B, N, ..., N)
    group : str
        One of :data:`SYMMETRY_GROUPS`.
    batch_points : int
        The transformed copies are stacked into batches of at most this many grid points (at least one copy per
        batch), so that ``fn`` runs once per batch instead of once per symmetry; memory grows with the batch.
        1 evaluates the symmetries one after another.

    Returns
    -------
    Tensor, shape (B, d, N, ..., N)
    """
    g = np.asarray(grids)
    syms = symmetries(g.ndim - 1, group)
    per_copy = max(1, int(np.prod(g.shape)))
    chunk = max(1, min(len(syms), int(batch_points) // per_copy))
    B = g.shape[0]
    total = None
    for i in range(0, len(syms), chunk):
        part = syms[i:i + chunk]
        psi = fn(np.concatenate([transform_grid(g, s) for s in part], axis=0))
        for k, s in enumerate(part):
            one = restore_displacement(psi[k * B:(k + 1) * B], s)
            total = one if total is None else total + one
    return total / len(syms)
