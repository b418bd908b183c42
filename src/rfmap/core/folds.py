r"""Whether a map is folded: the signed element measures, and on a free boundary the embedding of its boundary.

A piecewise-linear map of a simplicial mesh is *folded* when an element has a non-positive signed measure
(:math:`\det J \le 0`).  On grid meshes the strided measures of :func:`rfmap.core.geometry.grid_signed_measures` are
used; a free 2D boundary must be a simple polygon (a bucketed segment-crossing test), a free 3D boundary a surface
without self-intersection (:func:`rfmap.core.surface.surface_intersections` on the mesh's boundary triangles).
"""
from __future__ import annotations

import numpy as np
import torch

from .geometry import grid_min_measure, grid_signed_measures, signed_measures
from .surface import boundary_crossings, boundary_faces, boundary_loop, grid_surface_intersections, \
    surface_intersections

__all__ = ["fold_free", "map_measures", "surface_crossing_count"]


def map_measures(points: np.ndarray, elements: np.ndarray, grid_n: int | None) -> np.ndarray:
    """Signed measures of the elements of a map, shape (m,): the strided measures of the ``N``-grid mesh
    (:func:`rfmap.core.geometry.grid_signed_measures`) with ``grid_n``, else of ``elements``, shape (m, d+1)."""
    p = torch.as_tensor(np.asarray(points, dtype=np.float64))
    if grid_n is not None:
        return grid_signed_measures(p[None], grid_n)[0].numpy()
    return signed_measures(p, torch.as_tensor(np.asarray(elements))).numpy()


def fold_free(points: np.ndarray, elements: np.ndarray, *, grid_n: int | None = None,
              boundary: str = "fixed") -> bool:
    """True when every element has positive measure and, on a free boundary, the boundary is embedded.

    Embedded means a simple boundary polygon for a 2D grid mesh (other 2D meshes are not checked for it) and a
    boundary surface without self-intersection in 3D.

    ``grid_n``: the mesh is :func:`grid_mesh(N, d) <rfmap.core.mesh.grid_mesh>` and the strided measures are used
    (fast path).
    """
    if not np.isfinite(points).all():
        return False
    if (grid_min_measure(points, grid_n) if grid_n else map_measures(points, elements, None).min()) <= 0:
        return False
    if boundary == "free" and points.shape[1] == 2 and grid_n is not None:
        return len(boundary_crossings(points[boundary_loop(grid_n)])) == 0
    if boundary == "free" and points.shape[1] == 3:
        return surface_crossing_count(points, elements, grid_n) == 0
    return True


def surface_crossing_count(points: np.ndarray, elements: np.ndarray, grid_n: int | None) -> int:
    """Number of intersecting pairs of boundary triangles of a 3D map (:func:`rfmap.core.surface.surface_intersections`,
    on a grid mesh :func:`rfmap.core.surface.grid_surface_intersections`)."""
    if grid_n:
        return len(grid_surface_intersections(points, grid_n))
    return len(surface_intersections(points, boundary_faces(np.asarray(elements))))
