r"""The stages that finish a computed map, one function per stage in the order that :mod:`rfmap.finish` lists them
(:func:`refine`, :func:`regrid`, :func:`repair`, :func:`polish`, :func:`judge`, :func:`shorten`), each from a
:class:`~rfmap.finish.draft.Draft` to the next.

Every stage adds its seconds to ``draft.result.time`` and its report to ``draft.report``.
"""
from __future__ import annotations

import time
from dataclasses import replace
from typing import Callable, Sequence

import numpy as np
import torch

from .polish import GUARD, OUTPUT_PASSES, SMOOTH_EDGES, PolishOptions, polish_map, smooth_displacement, \
    smooth_grid_displacement, smooth_passes
from ..nn.model import apply_displacement
from .refine import REFINE, refine_alpha
from .repair import repair_map
from .shorten import shorten_map
from .draft import Draft, displacement_at
from .quality import density_quality
from .query import repair_query, shorten_query
from .report import RefineReport, RegridReport

__all__ = ["refine", "regrid", "repair", "polish", "judge", "shorten"]


def refine(draft: Draft, bounds: tuple[float, float] | None = None) -> Draft:
    r"""Weight refinement (paper Sec. 4.3): the map :math:`x + \mathcal{B}(x) \odot (\alpha^* \odot \psi(x))` with
    :math:`\alpha^* = \arg\min_\alpha \mathcal{J}` (:func:`rfmap.finish.refine.refine_alpha`, the objective of the task,
    :meth:`rfmap.tasks.base.Task.refine_objective`, settings :data:`rfmap.finish.refine.REFINE`).  :math:`\psi` is the network's displacement, or a classical map's :math:`u - x`
    (:meth:`rfmap.finish.draft.Draft.displacement`); a given stretching vector is replaced.

    Parameters
    ----------
    draft : Draft
    bounds : (float, float), optional
        Search interval of every component of :math:`\alpha` (default ``REFINE.bounds``).

    Returns
    -------
    Draft
        With ``report.alpha`` and ``report.refine`` (:class:`rfmap.finish.report.RefineReport`).
    """
    t0 = time.perf_counter()
    res = draft.result
    ref64 = torch.as_tensor(res.ref_points, dtype=torch.float64)
    psi64, mask = draft.displacement()
    elements = torch.as_tensor(res.elements)
    obj = draft.task.refine_objective(ref64, psi64, elements, res.field, mask, draft.grid_n)
    rr = refine_alpha(obj, res.dim, bounds=bounds or REFINE.bounds, tol=REFINE.tol)
    mapped = apply_displacement(ref64, psi64, mask, torch.as_tensor(rr.alpha)).numpy()
    return draft.then(mapped, time.perf_counter() - t0, alpha=rr.alpha.tolist(),
                      refine=RefineReport(rr.objective_start, rr.objective, rr.evaluations))


def regrid(draft: Draft, remap: Callable[[int], Draft], sides: Sequence[int]) -> Draft:
    """A folded network map of a grid replaced by the first map from another working grid that is fold-free and
    (for a density map) more equal than the input; the draft itself when it is not folded.

    Parameters
    ----------
    draft : Draft
        A network's map of the ``N``-grid.
    remap : callable
        ``remap(W)``: the network's map of the same output grid from working grid ``W``, through the stages that
        made ``draft`` (e.g. :func:`refine`).
    sides : sequence of int
        The working grids to try, in order.

    Returns
    -------
    Draft
        With ``report.regrid`` (:class:`rfmap.finish.report.RegridReport`) when the map was folded.  The network's time
        is then that of the draft's and the taken map's evaluations, the map's time the draft's and every try's.
    """
    if draft.grid_n is None or not draft.folded():
        return draft
    t0, tried, taken = time.perf_counter(), [], None
    for w in sides:
        cand = remap(w)
        tried.append(w)
        if not cand.folded() and _improves(cand):
            taken = cand
            break
    seconds = time.perf_counter() - t0
    net = start = draft.report.network
    if taken is not None:
        net = replace(net, work_n=taken.report.network.work_n, time=net.time + taken.report.network.time)
        draft = replace(taken, result=replace(taken.result, time=draft.result.time))
    report = RegridReport(start.work_n, tried, None if taken is None else net.work_n, time.perf_counter() - t0)
    return draft.then(seconds=seconds, network=net, regrid=report)


def _improves(draft: Draft) -> bool:
    """Whether a fold-free map is more equal than the input: Std(ρ̃_map) < Std(ρ̃_orig) for a density map
    (always true for tasks that do not equalize a density)."""
    if not draft.task.equalizes:
        return True
    m = draft.result.metrics()
    return bool(m.std_rho_map < m.std_rho_orig)


def repair(draft: Draft, *, cold_polish: bool = False) -> Draft:
    """The map made fold-free by :func:`rfmap.finish.repair.dispatch.repair_map` (a network's map of query points through its
    working grid, :func:`rfmap.finish.query.repair_query`).

    Parameters
    ----------
    draft : Draft
    cold_polish : bool
        A polish follows: a folded map of a grid is then left as it is (``report.repair["skipped"]``), since the
        polish starts cold from the identity on a folded map (:func:`rfmap.finish.polish.polish_map`) and a repair, which
        can cost more than the whole flow, would be thrown away.

    Returns
    -------
    Draft
        With ``report.repair``.
    """
    t0 = time.perf_counter()
    res, work = draft.result, draft.work_map
    folded = draft.folded() if cold_polish and draft.grid_n is not None else 0
    if folded:
        cheap = {"n_flipped": folded}
        mapped, report = None, {"needed": True, "skipped": True, "method": "skipped (the polish starts cold)",
                                "n_flipped_before": folded, "n_flipped_after": folded, "affected": 0,
                                "time": time.perf_counter() - t0, "metrics_before": cheap,
                                "metrics_after": dict(cheap)}
    else:
        kw = {"boundary": draft.boundary, **draft.task.metric_inputs(res.field)}
        if draft.grid_n is not None:
            mapped, report = repair_map(res.ref_points, res.mapped_points, res.elements, grid_n=draft.grid_n, **kw)
        elif draft.prediction is not None:
            mapped, report, work = repair_query(draft, **kw)
        else:
            mapped, report = repair_map(res.ref_points, res.mapped_points, res.elements, **kw)
    return replace(draft.then(mapped, time.perf_counter() - t0, repair=report), work_map=work)


def polish(draft: Draft, tol: float | None = None, guard: bool = GUARD) -> Draft:
    """A density map of a grid finished by the flow-based solver (:func:`rfmap.finish.polish.polish_map`).

    A network's map starts the flow from the map of its displacement smoothed on the working grid
    (:func:`rfmap.finish.polish.smooth_displacement`, :func:`rfmap.finish.polish.smooth_passes` passes, edges per
    :data:`rfmap.finish.polish.SMOOTH_EDGES`, and on a finer output grid :data:`rfmap.finish.polish.OUTPUT_PASSES` more passes
    there; all recorded in the report) where that is fold-free.

    Parameters
    ----------
    draft : Draft
        A density map of the ``N``-grid.
    tol : float, optional
        The flow's tolerance on Std(ρ̃_map) (:func:`rfmap.finish.polish.polish_tolerance`).
    guard : bool
        After a warm flow also run the cold flow and keep the better map (:data:`rfmap.finish.polish.GUARD`).

    Returns
    -------
    Draft
        With ``report.polish``; the map's time covers the map so far and the polish.
    """
    res, n = draft.result, draft.grid_n
    if not draft.task.equalizes or n is None:
        raise ValueError("polish finishes density maps on the output grid; it does not apply to "
                         f"{res.kind} maps or to query points")
    t0 = time.perf_counter()
    start, smoothing = None, {}
    pred = draft.prediction
    if pred is not None:  # the flow starts from the map of the smoothed displacement (rfmap.finish.polish)
        nw = pred.work_n
        passes = smooth_passes(res.dim, n, nw, draft.boundary)
        edges = SMOOTH_EDGES[draft.boundary]
        psi_s = displacement_at(smooth_displacement(pred.psi, passes, edges), res.ref_points, n if n == nw else None)
        out_passes = 0 if n == nw else OUTPUT_PASSES  # the resampling's kinks, smoothed on the output grid
        if out_passes:
            psi_s = smooth_grid_displacement(psi_s, n, out_passes, edges)
        alpha = torch.as_tensor(np.asarray(draft.report.alpha, dtype=np.float64))
        start = apply_displacement(torch.as_tensor(res.ref_points, dtype=torch.float64), psi_s, draft.boundary,
                                   alpha).numpy()
        smoothing = dict(smooth_passes=passes, smooth_edges=edges, output_passes=out_passes)
    before = res.time + time.perf_counter() - t0
    mapped, report = polish_map(res, n=n, boundary=draft.boundary, options=PolishOptions(tol, guard),
                                stage_time=before, start=start)
    report.update(smoothing)
    return draft.then(mapped, before - res.time + report["time"], polish=report)


def judge(draft: Draft) -> Draft:
    """Whether a density map of a grid left the density more equal than it was (:func:`rfmap.finish.quality.density_quality`;
    ``report.quality``)."""
    res = draft.result
    if not draft.task.equalizes or draft.grid_n is None:
        raise ValueError("judge needs a density map of a grid")
    t0 = time.perf_counter()
    quality = density_quality(res.mapped_points, res.field, draft.grid_n)
    return draft.then(seconds=time.perf_counter() - t0, quality=quality)


def shorten(draft: Draft) -> Draft:
    """A density map that is no more equal than its input shortened to the most equal fold-free map between the
    identity and itself (:func:`rfmap.finish.shorten.shorten_map`), so that it is never worse than no map at all.

    A map of a grid is judged there (``report.quality``, by :func:`judge` when it ran) and judged again after the
    shortening (with ``shortened_from``).  A network's map of query points is judged on its working grid and
    shortened by the same scale (:func:`rfmap.finish.query.shorten_query`).

    Returns
    -------
    Draft
        With ``report.shorten`` when the map was shortened.
    """
    res = draft.result
    if not draft.task.equalizes or (draft.grid_n is None and draft.prediction is None):
        raise ValueError("shorten needs a density map of a grid, or a network's map of query points")
    t0 = time.perf_counter()
    if draft.grid_n is None:
        mapped, report = shorten_query(draft)
        if report is None:
            return draft.then(seconds=time.perf_counter() - t0)
        return draft.then(mapped, time.perf_counter() - t0, shorten=report)
    n = draft.grid_n
    quality = draft.report.quality or density_quality(res.mapped_points, res.field, n)
    if quality["std_rho_map"] < quality["std_rho_orig"] or np.array_equal(res.mapped_points, res.ref_points):
        # more equal already, or the identity: nothing to shorten (the identity is judged, as no gain)
        return draft.then(seconds=time.perf_counter() - t0, quality=quality)
    mapped, report = shorten_map(res.ref_points, res.mapped_points, res.field, n, boundary=draft.boundary)
    after = density_quality(mapped, res.field, n)
    after["shortened_from"] = quality["std_rho_map"]
    return draft.then(mapped, time.perf_counter() - t0, shorten=report, quality=after)
