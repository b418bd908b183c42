r"""Repair of 2D grid maps by the Linear Beltrami Solver on a patch around the folds, tried before the global rebuild.

The rebuild of :mod:`rfmap.finish.repair.lbs` is first tried on a patch (:func:`local_lbs_repair`): the truncated
triangles grown by 2, 4, 8, then 16 vertex rings, the patch's rim and the domain boundary held where the map put them.
Folds of a network map are usually a few small clusters, so a patch solve costs a fraction of the global one and
leaves the rest of the map exactly as the network made it.  Widespread folds (more than :data:`LOCAL_MIN_CAPPED`
truncated triangles and more than the share :data:`LOCAL_MAX_CAPPED` of all), a free boundary that crosses itself,
or a patch that stays folded go to the global rebuild.

The five constants below are tuning constants, not choices a caller makes: they decide how far a patch grows and
when it is given up for the global rebuild, so they change which rebuild runs and what it costs.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import torch

from ...core.folds import map_measures
from ...core.geometry import beltrami_coefficient
from ...core.mesh import grid_mesh
from ...core.surface import boundary_crossings, boundary_loop
from ...solvers.lbs import assemble_stiffness, beltrami_matrices
from .lbs import DELTA, cap_mu

__all__ = ["LOCAL_RINGS", "LOCAL_MAX_FRACTION", "LOCAL_MIN_GIVE_UP", "LOCAL_MAX_CAPPED", "LOCAL_MIN_CAPPED",
           "local_lbs_repair"]


#: ring counts of the successive patches of :func:`local_lbs_repair`
LOCAL_RINGS = (2, 4, 8, 16)


#: A patch is given up for the global :func:`~rfmap.finish.repair.lbs.lbs_repair` when it would solve for more
#: than max(``LOCAL_MAX_FRACTION`` · P, :data:`LOCAL_MIN_GIVE_UP`) vertices, P the grid's vertex count.
LOCAL_MAX_FRACTION = 0.25


#: The floor of the patch limit of :data:`LOCAL_MAX_FRACTION`, in vertices.
LOCAL_MIN_GIVE_UP = 2000


#: Folds go straight to the global :func:`.lbs_repair`, with no patch tried, when more than
#: max(``LOCAL_MAX_CAPPED`` · T, :data:`LOCAL_MIN_CAPPED`) triangles are truncated, T the grid's triangle count.
LOCAL_MAX_CAPPED = 0.01

#: The floor of the limit of :data:`LOCAL_MAX_CAPPED`, in triangles.
LOCAL_MIN_CAPPED = 100


def local_lbs_repair(mapped: np.ndarray, n: int, boundary: str, delta: float = DELTA, *,
                     rings: Sequence[int] = LOCAL_RINGS, max_fraction: float = LOCAL_MAX_FRACTION,
                     passes: int = 3, info: dict | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    r"""Rebuild a 2D grid map from its truncated Beltrami coefficient on a patch around the folds only.

    The triangles whose :math:`\mu` :func:`.cap_mu` changes (flipped, :math:`|\mu| > 1 - \delta`, non-finite) are
    grown by ``r`` vertex rings.  On the patch of triangles touching the grown vertices, the LBS system
    :math:`\nabla\cdot(A\nabla u) = 0` with the truncated :math:`\mu` is solved for the grown vertices off the
    domain boundary; every other vertex of the patch keeps its position (Dirichlet values).  As in
    :func:`.lbs_repair`, up to ``passes`` times the :math:`\mu` of the rebuilt patch is truncated again and the
    patch solved again while a triangle is flipped (the discrete LBS has no bijectivity theorem).  Patches of
    ``rings[0]``, ``rings[1]``, ... rings are tried until one ends fold-free (or folds remain that touch no vertex
    of the patch's rim, which a larger patch would not undo).  Outside the patch the map is not touched, and the
    cost is that of sparse solves the size of the patch.

    Parameters
    ----------
    info : dict, optional
        When given, receives ``tried``: True when at least one patch was solved, whether or not it ended
        fold-free; False when the function returned before any solve (nothing truncated, folds too widespread, a
        free boundary that crosses itself, or a first patch already too large).

    Returns
    -------
    result : tuple of (ndarray, ndarray), or None
        ``(points, capped)`` as :func:`.lbs_repair` returns them.  ``None`` when no triangle is truncated; when more
        than :data:`LOCAL_MIN_CAPPED` triangles and more than the share :data:`LOCAL_MAX_CAPPED` of all are
        truncated; when no patch of at most ``rings[-1]`` rings and at most ``max_fraction`` of the vertices (or
        :data:`LOCAL_MIN_GIVE_UP` vertices on small grids) ends fold-free; or when a free boundary crosses itself
        (boundary vertices keep their positions in a local solve, so only :func:`.lbs_repair` can untangle it).
    """
    if info is not None:
        info["tried"] = False
    mesh = grid_mesh(n, 2)
    el = mesh.elements
    n_pts = mesh.points.shape[0]
    out = np.where(np.isfinite(mapped), mapped, mesh.points).astype(np.float64)
    if boundary == "free" and len(boundary_crossings(out[boundary_loop(n)])):
        return None
    ref_t = torch.as_tensor(mesh.points)
    mu = beltrami_coefficient(ref_t, torch.as_tensor(out), torch.as_tensor(el)).numpy()
    mu_c, capped = cap_mu(mu, delta)
    capped |= map_measures(out, el, None) <= 0
    if not capped.any() or capped.sum() > max(LOCAL_MAX_CAPPED * len(el), LOCAL_MIN_CAPPED):
        return None  # nothing to do, or folds so widespread that the global rebuild costs no more than a patch
    on_edge = mesh.boundary_mask()
    grown = np.zeros(n_pts, bool)
    grown[el[capped]] = True
    done = 0
    for r in sorted(rings):
        for _ in range(r - done):  # one more ring: every vertex of a triangle touching the set
            grown[el[grown[el].any(1)]] = True
        done = r
        free = np.flatnonzero(grown & ~on_edge)
        if free.size > max(max_fraction * n_pts, LOCAL_MIN_GIVE_UP):
            return None
        patch = np.flatnonzero(grown[el].any(1))
        el_p = el[patch]
        fixed = np.setdiff1d(np.unique(el_p), free)
        is_fixed = np.zeros(n_pts, bool)
        is_fixed[fixed] = True
        mu_p = mu_c[patch]
        if info is not None:
            info["tried"] = True
        for _ in range(passes):
            K = assemble_stiffness(mesh.points, el_p, beltrami_matrices(mu_p)).tocsc()
            rhs = -(K[free][:, fixed] @ out[fixed])
            lu = spla.splu(sp.csc_matrix(K[free][:, free]), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                           options={"SymmetricMode": True})
            trial = out.copy()
            trial[free] = lu.solve(np.ascontiguousarray(rhs))
            if not np.isfinite(trial).all():
                break
            meas = map_measures(trial, el_p, None)
            if meas.min() > 0:
                hit = np.zeros(len(el), bool)
                hit[patch] = True
                return trial, capped & hit
            mu_p, more = cap_mu(beltrami_coefficient(ref_t, torch.as_tensor(trial), torch.as_tensor(el_p)).numpy(),
                                delta)
            capped[patch] |= more
        if np.isfinite(trial).all() and not is_fixed[el_p[meas <= 0]].any():
            return None  # folds left inside the patch, away from its rim: a larger patch would not help
    return None
