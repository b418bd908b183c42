r"""Repair of 3D free-boundary maps whose boundary surface crosses itself: the displacement shortened until embedded.

When the boundary surface of a fold-free 3D map crosses itself, :func:`surface_repair` shortens the whole displacement,
:math:`u_s = x + s\,(u - x)`, to the largest ``s`` found by halving and bisection at which the map is fold-free and its
surface embedded (``s = 0``, the identity, always is). This is blunt (the whole map moves back, not only the crossing
region), and it is rare: a network or solver map would have to push one side of the cube through another.
"""
from __future__ import annotations

import numpy as np

from ...core.folds import fold_free

__all__ = ["surface_repair"]


def surface_repair(ref: np.ndarray, mapped: np.ndarray, elements: np.ndarray, *, grid_n: int | None = None,
                   rounds: int = 8) -> tuple[np.ndarray, float]:
    r"""Shorten the displacement of a fold-free 3D free-boundary map until its boundary surface is embedded.

    :math:`u_s = x + s\,(u - x)`: ``s = 1`` is the input, ``s = 0`` the identity (embedded).  ``s`` is halved until
    :math:`u_s` is fold-free with an embedded boundary, then raised by bisection (``rounds`` steps) between the
    last passing and the first failing value; every returned state is verified by :func:`~rfmap.core.folds.fold_free`.

    Returns
    -------
    points : ndarray, shape (P, 3)
        The map :math:`u_s`.
    s : float
        The scale kept: below 1 (the first scale tried is 1/2), and 0, the identity, when no halving passes.
    """
    ref = np.asarray(ref, np.float64)
    disp = np.asarray(mapped, np.float64) - ref

    def ok(s: float) -> bool:
        return fold_free(ref + s * disp, elements, grid_n=grid_n, boundary="free")

    hi, lo = 1.0, 0.0
    s = 0.5
    while s > 1e-3:
        if ok(s):
            lo = s
            break
        hi, s = s, s / 2
    for _ in range(rounds if lo > 0 else 0):
        mid = 0.5 * (lo + hi)
        if ok(mid):
            lo = mid
        else:
            hi = mid
    return ref + lo * disp, lo
