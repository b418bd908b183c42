r"""A map on its way to delivery: the map so far, the report of what was done to it, and what the stages need.

A :class:`Draft` is what every stage of :mod:`rfmap.finish` takes and returns.  A network's map carries its
:class:`Prediction` (the displacement :math:`\psi` on the working grid and the input there), which lets the stages
go back to the working grid: refinement of :math:`\alpha`, the repair and the judgement of a map of query points,
the smoothed start of the polish.  A classical map (:mod:`rfmap.solvers`) enters through :meth:`Draft.of`; its
displacement :math:`u - x` then plays the part of :math:`\psi`.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import torch

from ..core.geometry import grid_signed_measures
from ..core.mesh import grid_mesh, grid_points, interpolate
from ..core.result import MapResult
from ..tasks import get_task
from .report import InfoView, MapReport

__all__ = ["Draft", "Prediction", "WorkingGridMap", "displacement_at"]


def displacement_at(psi: torch.Tensor, points: np.ndarray, grid_n: int | None) -> torch.Tensor:
    r"""The displacement :math:`\psi` of a working grid at the output vertices, float64.

    Parameters
    ----------
    psi : Tensor, shape (1, d, W, ..., W)
        The displacement on the working grid.
    points : ndarray, shape (P, d)
        The output vertices.
    grid_n : int, optional
        Set when ``points`` are the working grid itself (:func:`rfmap.core.mesh.grid_points` ``(W, d)``): the values are
        read off; else they are interpolated multilinearly.

    Returns
    -------
    Tensor, float64, shape (P, d)
    """
    if grid_n is not None:
        psi_q = psi[0].reshape(psi.shape[1], -1).T
    else:
        psi_q = interpolate(psi, torch.as_tensor(points, dtype=torch.float32))[0]
    return psi_q.double()


@dataclass(frozen=True)
class Prediction:
    r"""The network's output behind a map of the output mesh.

    Attributes
    ----------
    psi : Tensor, float32, shape (1, d, W, ..., W)
        The displacement on the working grid of side ``W``.
    psi_out : Tensor, float64, shape (P, d)
        :math:`\psi` at the output vertices (:func:`displacement_at`).
    work_field : ndarray, shape (W,)*d
        The input on the working grid, as the network saw it (unit-mass density or complex :math:`\mu`).
    """

    psi: torch.Tensor
    psi_out: torch.Tensor
    work_field: np.ndarray

    @property
    def work_n(self) -> int:
        return int(self.psi.shape[-1])


@dataclass(frozen=True)
class WorkingGridMap:
    """The map of a prediction's working grid, made fold-free: what a map of query points is repaired and judged
    on (:mod:`rfmap.finish.query`).

    Attributes
    ----------
    n : int
        The working grid's side ``W``.
    points : ndarray, shape (W**d, d)
        The working grid's vertices, in :func:`rfmap.core.mesh.grid_points` order.
    mapped : ndarray, shape (W**d, d)
        The images of ``points`` under the repaired, fold-free map.
    report : dict
        The report of :func:`rfmap.finish.repair.dispatch.repair_map`.
    """

    n: int
    points: np.ndarray
    mapped: np.ndarray
    report: dict[str, Any]


@dataclass(frozen=True)
class Draft:
    """A map being finished.

    Attributes
    ----------
    result : MapResult
        The map so far (``time``: the seconds spent on it so far; ``info``: the extras of the solver that made it).
    report : MapReport
        What was done to it.
    boundary : {"fixed", "square", "free"}
        The boundary condition the map keeps.
    grid_n : int, optional
        Set when the mesh is :func:`rfmap.core.mesh.grid_mesh` ``(N, d)``; ``None`` for any other mesh (query points).
    prediction : Prediction, optional
        The network's output, for a network's map.
    work_map : WorkingGridMap, optional
        The repaired map of the working grid, once a stage has made it.
    """

    result: MapResult
    report: MapReport
    boundary: str
    grid_n: int | None = None
    prediction: Prediction | None = None
    work_map: WorkingGridMap | None = None

    @classmethod
    def of(cls, result: MapResult, boundary: str | None = None, n: int | None = None) -> "Draft":
        """Start from a computed map, e.g. a classical solver's.  ``boundary`` defaults to ``result.info
        ["boundary"]``; ``n`` to the side of the grid when the mesh is :func:`rfmap.core.mesh.grid_mesh` ``(N, d)``."""
        boundary = boundary or result.info.get("boundary")
        if boundary is None:
            raise ValueError("the map's boundary condition is not in its info: pass boundary=")
        return cls(result, MapReport(), boundary, _grid_side(result) if n is None else int(n))

    @property
    def kind(self) -> str:
        return self.result.kind

    @property
    def task(self):
        """The :class:`rfmap.tasks.base.Task` of the map's kind."""
        return get_task(self.result.kind)

    def displacement(self) -> tuple[torch.Tensor, str]:
        r"""The displacement a stretching vector scales, float64 (P, d), and the boundary of the mask that
        :func:`rfmap.nn.apply_displacement` applies to it: the network's :math:`\psi` and the map's boundary, or a
        classical map's :math:`u - x`, already masked (``"free"``)."""
        if self.prediction is not None:
            return self.prediction.psi_out, self.boundary
        res = self.result
        return torch.as_tensor(res.mapped_points - res.ref_points, dtype=torch.float64), "free"

    def folded(self) -> int:
        """Number of elements of the ``N``-grid map with non-positive measure (every vertex when one is not
        finite)."""
        mapped = self.result.mapped_points
        if not np.isfinite(mapped).all():
            return int(mapped.shape[0])
        meas = grid_signed_measures(torch.from_numpy(np.ascontiguousarray(mapped))[None], self.grid_n)[0]
        return int((meas <= 0).sum())

    def then(self, mapped: np.ndarray | None = None, seconds: float = 0.0, **report: Any) -> "Draft":
        """The next draft: the map moved to ``mapped`` (unless ``None``), ``seconds`` more spent, and the report's
        fields ``report`` set."""
        result = self.result
        result = replace(result, mapped_points=result.mapped_points if mapped is None else mapped,
                         time=result.time + seconds)
        return replace(self, result=result, report=replace(self.report, **report))

    def deliver(self) -> MapResult:
        """The finished map, with ``info`` the report's read-only view (:class:`rfmap.finish.report.InfoView`)."""
        return replace(self.result, info=InfoView(self.report, self.result.info))


def _grid_side(result: MapResult) -> int | None:
    """``N`` when the map's mesh is :func:`rfmap.core.mesh.grid_mesh` ``(N, d)``, else ``None``."""
    d, p = result.dim, result.ref_points.shape[0]
    n = round(p ** (1.0 / d))
    if n < 2 or n ** d != p or not np.array_equal(result.ref_points, grid_points(n, d)):
        return None
    return n if np.array_equal(result.elements, grid_mesh(n, d).elements) else None
