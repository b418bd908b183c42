r"""The entry point of the repair: a cheap check, then the strategy that fits the mesh, then the checks again.

:func:`repair_map` first runs a cheap check (strided grid measures, :func:`rfmap.core.geometry.grid_signed_measures`, and
on a free 2D boundary a bucketed segment-crossing test) and returns the map untouched when nothing is folded.
Otherwise a 2D grid map is rebuilt by the Linear Beltrami Solver (:func:`~rfmap.finish.repair.local.local_lbs_repair`, then
:func:`~rfmap.finish.repair.lbs.lbs_repair`), any other map, or one the LBS leaves folded, by the displacement scaling
(:func:`~rfmap.finish.repair.scale.scale_repair`); a 3D free-boundary map whose surface crosses itself is shortened until it
is embedded (:func:`~rfmap.finish.repair.embedding.surface_repair`).
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from ...core.folds import map_measures, surface_crossing_count, fold_free
from ...core.geometry import grid_min_measure
from ...core.metrics import compute_metrics
from ...core.surface import boundary_crossings, boundary_loop
from .embedding import surface_repair
from .lbs import DELTA, lbs_repair
from .local import local_lbs_repair
from .scale import scale_repair

__all__ = ["repair_map", "REPAIR_METHODS"]


#: the ``method`` values of :func:`repair_map`
REPAIR_METHODS = ("auto", "local", "lbs", "scale")


def _metrics(ref, pts, elements, density, mu_ref) -> dict:
    m = compute_metrics(ref, pts, elements, density=density, mu_ref=mu_ref).to_dict()
    m.pop("time", None)
    return m


def repair_map(ref: np.ndarray, mapped: np.ndarray, elements: np.ndarray, *, boundary: str,
               grid_n: int | None = None, density: np.ndarray | None = None, mu: np.ndarray | None = None,
               method: str = "auto") -> tuple[np.ndarray, dict[str, Any]]:
    r"""Return a fold-free version of the map ``ref -> mapped`` and a report of what was done.

    Parameters
    ----------
    ref, mapped : ndarray, shape (P, d)
    elements : int ndarray, shape (m, d+1), positively oriented on ``ref``
    boundary : {"fixed", "square", "free"}
        The boundary condition the repaired map must keep.
    grid_n : int, optional
        Set when the mesh is :func:`rfmap.core.mesh.grid_mesh` ``(N, d)``: enables the fast strided check and, in 2D,
        the LBS repair.
    density : ndarray (P,), optional
        Vertex densities, for the density metrics in the report.
    mu : complex ndarray (m,), optional
        Target Beltrami coefficient, for ``mean_dmu`` in the report.
    method : {"auto", "local", "lbs", "scale"}
        ``local``: :func:`.local_lbs_repair`, falling back to ``lbs`` when no patch ends fold-free; ``lbs``:
        :func:`.lbs_repair` on the whole grid; ``scale``: :func:`.scale_repair`.  Any of them ends with
        :func:`.scale_repair` if its result is still folded.  ``auto``: ``local`` for 2D grid meshes, ``scale``
        otherwise.  The LBS repairs truncate :math:`|\mu| \le 1 - \delta` with :math:`\delta` =
        :data:`rfmap.finish.repair.lbs.DELTA`.

    Returns
    -------
    points : ndarray, shape (P, d)
        The fold-free map; ``mapped`` itself (the same object) when nothing was folded.
    report : dict
        ``needed``, ``method``, ``n_flipped_before``, ``n_flipped_after``, ``affected`` (triangles with truncated
        :math:`\mu` for the LBS, vertices with a shortened displacement for the scaling, the larger of the two
        counts when both ran), the two counts apart as ``triangles_capped`` and ``vertices_scaled``, ``local_tried``
        (True when a local LBS patch was solved, even if none ended fold-free and the global LBS then ran, so that a
        ``method`` of ``lbs`` tells whether a patch failed first or was never tried), ``time`` (s),
        ``metrics_before`` and ``metrics_after``; for a 3D free boundary also ``surface_crossings_before``/``_after``
        (intersecting pairs of boundary triangles) and, when :func:`~rfmap.finish.repair.embedding.surface_repair` ran,
        ``surface_scale``.
    """
    t0 = time.perf_counter()
    if method not in REPAIR_METHODS:
        raise ValueError(f"unknown repair method {method!r}; choose one of {REPAIR_METHODS}")
    ref = np.asarray(ref, np.float64)
    d = ref.shape[1]
    el = np.asarray(elements)
    mapped = np.asarray(mapped)
    finite = bool(np.isfinite(mapped).all())
    if grid_n and finite:
        m = grid_min_measure(mapped, grid_n)
        min_jac = m * (grid_n - 1) ** d * (2 if d == 2 else 6)
    elif finite:
        meas = map_measures(mapped, el, None) / map_measures(ref, el, None)
        m = min_jac = float(meas.min())
    ok = finite and m > 0
    if ok and boundary == "free" and d == 2 and grid_n:
        ok = len(boundary_crossings(mapped[boundary_loop(grid_n)])) == 0
    crossings = 0
    if ok and boundary == "free" and d == 3:
        crossings = surface_crossing_count(mapped, el, grid_n)
        ok = crossings == 0
    if ok:
        cheap = {"n_flipped": 0, "min_jacobian": float(min_jac)}
        return mapped, {"needed": False, "method": "none", "n_flipped_before": 0, "n_flipped_after": 0,
                        "affected": 0, "triangles_capped": 0, "vertices_scaled": 0,
                        "local_tried": False, "time": time.perf_counter() - t0, "metrics_before": cheap,
                        "metrics_after": dict(cheap)}
    mapped = np.asarray(mapped, np.float64)
    before = _metrics(ref, np.where(np.isfinite(mapped), mapped, ref), el, density, mu)
    if method == "auto":
        method = "local" if d == 2 and grid_n else "scale"
    affected = capped_n = scaled_n = 0
    local_info = {"tried": False}
    out = mapped
    used = method
    if method == "local":
        if not (d == 2 and grid_n):
            raise ValueError("the local LBS repair needs a 2D grid mesh (grid_n)")
        local = local_lbs_repair(np.where(np.isfinite(mapped), mapped, ref), grid_n, boundary, DELTA,
                                 info=local_info)
        if local is not None:
            out, capped = local
            affected = capped_n = int(capped.sum())
        else:  # no patch ended fold-free: the global rebuild
            method = used = "lbs"
    if method == "lbs":
        if not (d == 2 and grid_n):
            raise ValueError("the LBS repair needs a 2D grid mesh (grid_n)")
        out, capped = lbs_repair(np.where(np.isfinite(mapped), mapped, ref), grid_n, boundary, DELTA)
        affected = capped_n = int(capped.sum())
    if method == "scale" or not fold_free(out, el, grid_n=grid_n, boundary=boundary):
        out, info = scale_repair(ref, out, el, boundary=boundary)
        scaled_n = int(info["affected"])
        affected = max(affected, scaled_n)
        used = "scale" if method == "scale" else method + "+scale"
    report: dict[str, Any] = {}
    if boundary == "free" and d == 3:
        report["surface_crossings_before"] = crossings if crossings else surface_crossing_count(
            np.where(np.isfinite(mapped), mapped, ref), el, grid_n)
        if surface_crossing_count(out, el, grid_n):
            out, s = surface_repair(ref, out, el, grid_n=grid_n)
            used += "+surface"
            affected = len(out)
            report["surface_scale"] = s
        report["surface_crossings_after"] = surface_crossing_count(out, el, grid_n)
    after = _metrics(ref, out, el, density, mu)
    return out, {"needed": True, "method": used, "n_flipped_before": int(before["n_flipped"]),
                 "n_flipped_after": int(after["n_flipped"]), "affected": affected,
                 "triangles_capped": capped_n, "vertices_scaled": scaled_n,
                 "local_tried": local_info["tried"], "time": time.perf_counter() - t0, "metrics_before": before, "metrics_after": after, **report}
