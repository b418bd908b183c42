r"""Making a computed map bijective: detect folded elements and repair them, in 2D and 3D.

A piecewise-linear map of a simplicial mesh is *folded* when an element has a non-positive signed measure
(:math:`\det J \le 0`).  With every element positively oriented, a map that keeps the boundary of the unit square or
cube on itself (``fixed`` or ``square`` boundary conditions) is a bijection of the domain onto itself (degree
argument); with a ``free`` boundary the image of the boundary must also be embedded: a simple polygon in 2D, a
surface without self-intersection in 3D (:func:`rfmap.core.surface.surface_intersections` on the mesh's boundary
triangles, an extra pass on every free 3D map: two far-apart parts of the surface pushed through each other leave
every tetrahedron positive).

:func:`.repair_map` (:mod:`~rfmap.finish.repair.dispatch`) is the entry point; one strategy per module:

* :mod:`~rfmap.finish.repair.lbs` -- 2D grid meshes: μ-truncation and the Linear Beltrami Solver on the whole grid;
* :mod:`~rfmap.finish.repair.local` -- the same rebuild on a patch around the folds, tried first;
* :mod:`~rfmap.finish.repair.scale` -- any mesh in 2D or 3D: fold-free displacement scaling, vertex by vertex;
* :mod:`~rfmap.finish.repair.embedding` -- 3D free boundary: the displacement shortened until the surface is embedded;

and :mod:`rfmap.core.folds` says whether a map is folded.  :func:`.shorten_map`, which trades a map for the most
equal fold-free map between the identity and itself, is not a repair; it lives in :mod:`rfmap.finish.shorten`.
"""
from __future__ import annotations

from ..shorten import SHORTEN_SAMPLES, shorten_map
from ...core.folds import fold_free
from .dispatch import REPAIR_METHODS, repair_map
from .embedding import surface_repair
from .lbs import DELTA, cap_mu, lbs_repair, untangle_boundary
from .local import LOCAL_RINGS, local_lbs_repair
from .scale import ETA, LOCAL_START_RINGS, scale_repair, vertex_classes

__all__ = ["repair_map", "fold_free", "cap_mu", "untangle_boundary", "scale_repair", "surface_repair", "lbs_repair",
           "local_lbs_repair", "shorten_map", "vertex_classes", "DELTA", "SHORTEN_SAMPLES", "REPAIR_METHODS", "ETA",
           "LOCAL_RINGS", "LOCAL_START_RINGS"]
