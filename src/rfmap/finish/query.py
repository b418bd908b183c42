r"""Maps of query points, finished through their working grid.

A network's map of arbitrary query points is interpolated from its working grid, which has the grid's strided
measures and a side the network knows; the query mesh (a Delaunay triangulation of the points) has neither.  So
the map of the working grid is made fold-free first and its displacement interpolated (:func:`repair_query`), and
whether a density map is worth shortening is judged there too (:func:`shorten_query`): grid and points then deliver
one map, evaluated at different points.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ..core.folds import fold_free
from ..core.mesh import element_measures, grid_mesh, grid_points, interpolate
from ..nn.model import apply_displacement
from .repair import repair_map
from .shorten import shorten_map
from .draft import Draft, WorkingGridMap, displacement_at
from .quality import density_quality

__all__ = ["working_grid_map", "repair_query", "shorten_query"]


def working_grid_map(draft: Draft) -> WorkingGridMap:
    r"""The map of the working grid of a network's map, :math:`x + \mathcal{B}(x) \odot (\alpha \odot \psi(x))`
    with the draft's :math:`\alpha`, made fold-free by :func:`rfmap.finish.repair.dispatch.repair_map`; ``draft.work_map`` when a
    stage made it already."""
    if draft.work_map is not None:
        return draft.work_map
    psi, boundary = draft.prediction.psi, draft.boundary
    nw, d = psi.shape[-1], draft.result.dim
    grid = grid_points(nw, d)
    u = apply_displacement(torch.as_tensor(grid), displacement_at(psi, grid, nw), boundary,
                           torch.as_tensor(np.asarray(draft.report.alpha, dtype=np.float64))).numpy()
    u_rep, report = repair_map(grid, u, grid_mesh(nw, d).elements, boundary=boundary, grid_n=nw)
    return WorkingGridMap(nw, grid, u_rep, report)


def repair_query(draft: Draft, **kw: Any) -> tuple[np.ndarray, dict[str, Any], WorkingGridMap]:
    """:func:`rfmap.finish.repair.dispatch.repair_map` of a network's map of query points: the working grid's map is repaired first
    (:func:`working_grid_map`) and its displacement interpolated, then any fold left on the query mesh is repaired
    there.  ``kw``: the keywords of :func:`rfmap.finish.repair.dispatch.repair_map`.

    Returns
    -------
    (points, report, work)
        ``report`` as :func:`rfmap.finish.repair.dispatch.repair_map`'s, with ``grid`` (the working grid's report) and
        ``n_flipped_before`` counted on the query mesh.
    """
    res = draft.result
    ref, mapped, elements = res.ref_points, res.mapped_points, res.elements
    work = working_grid_map(draft)
    nw, d = work.n, res.dim
    n_raw = int((element_measures(mapped, elements) <= 0).sum())
    if work.report["needed"]:
        disp = torch.as_tensor((work.mapped - work.points).T.reshape(1, d, *([nw] * d)))
        mapped = ref + interpolate(disp, torch.as_tensor(ref))[0].numpy()
    out, report = repair_map(ref, mapped, elements, **kw)
    report.update(needed=report["needed"] or work.report["needed"], n_flipped_before=n_raw, grid=work.report)
    if work.report["needed"] and report["method"] == "none":
        report["method"] = "grid " + work.report["method"]
    return out, report, work


def shorten_query(draft: Draft) -> tuple[np.ndarray, dict[str, Any] | None]:
    r"""Shorten a network's density map of query points as its working grid's map would be shortened.

    The returned map of an output grid is shortened (:func:`rfmap.finish.shorten.shorten_map`) when it leaves the density
    no more equal than it was.  Query points have no grid to judge on, so the judgement is made on the working grid:
    its repaired map (:func:`working_grid_map`) and the input density there.  When that map is shortened to
    :math:`u_s = x + s\,(u - x)`, the query map is shortened by the same :math:`s` unless that folds an element of
    the query mesh; then the scale is chosen on the query mesh itself (``report["query_mesh"]``).

    Returns
    -------
    (points, report or None)
        ``report`` (``None`` when the working grid's map is more equal than the input) is that of
        :func:`rfmap.finish.shorten.shorten_map` with ``decided_on``, ``work_n``, ``query_mesh`` and ``quality``
        (:func:`rfmap.finish.quality.density_quality` of the working grid's returned map, with ``shortened_from``).
    """
    res = draft.result
    ref, mapped, elements = res.ref_points, res.mapped_points, res.elements
    work = working_grid_map(draft)
    nw, grid, u = work.n, work.points, work.mapped
    dens = draft.prediction.work_field.reshape(-1)
    q = density_quality(u, dens, nw)
    if q["std_rho_map"] < q["std_rho_orig"] or np.array_equal(u, grid):  # more equal, or the identity
        return mapped, None
    u_s, report = shorten_map(grid, u, dens, nw, boundary=draft.boundary)
    q_after = density_quality(u_s, dens, nw)
    q_after["shortened_from"] = q["std_rho_map"]
    s = report["scale"]
    out = ref + s * (mapped - ref)
    report.update(decided_on="working grid", work_n=nw, query_mesh=False, quality=q_after)
    if s > 0.0 and not fold_free(out, elements, boundary=draft.boundary):
        out, mesh_report = shorten_map(ref, mapped, res.field, elements=elements, boundary=draft.boundary)
        report.update(query_mesh=True, scale=mesh_report["scale"], query_report=mesh_report)
    return out, report
