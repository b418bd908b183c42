r"""What the stages did to a map: a typed report, and its read-only view as ``MapResult.info``.

Each stage of :mod:`rfmap.finish` returns the map and a new :class:`MapReport` with its own field filled in; the
network's prediction fills :class:`NetworkReport` and ``alpha``.  A returned map carries the report as
``result.info``, an :class:`InfoView`: a read-only mapping with the flat keys of the reports that the stages write
(``info["work_n"]``, ``info["alpha"]``, ``info["repair"]``, ``info["polish"]``, ...) next to those of the solver
that made the map, and the typed report itself as ``result.info.report``.
"""
from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["MapReport", "NetworkReport", "RegridReport", "RefineReport", "InfoView"]


@dataclass(frozen=True)
class NetworkReport:
    """How the network made the map.

    Attributes
    ----------
    work_n : int
        Side of the working grid the network was evaluated on (``info["work_n"]``).
    time : float
        Seconds of network evaluation (``info["network_time"]``).
    symmetrize : str or None
        The symmetry group the displacement was averaged over (:mod:`rfmap.nn.symmetry`; ``info["symmetrize"]``).
    """

    work_n: int
    time: float
    symmetrize: str | None = None


@dataclass(frozen=True)
class RegridReport:
    """The coarser working grids a folded map was tried on (:func:`rfmap.finish.stages.regrid`; ``info["regrid"]``).

    Attributes
    ----------
    start : int
        The working grid whose map folded (``"from"``).
    tried : list of int
        The sides tried, in order.
    work_n : int or None
        The side whose map was taken, ``None`` when every one folded or was no more equal than the input.
    time : float
        Seconds spent on the tries.
    """

    start: int
    tried: list[int]
    work_n: int | None
    time: float

    def as_dict(self) -> dict[str, Any]:
        return {"from": self.start, "tried": self.tried, "work_n": self.work_n, "time": self.time}


@dataclass(frozen=True)
class RefineReport:
    r"""Weight refinement's search for the stretching vector :math:`\alpha` (:func:`rfmap.finish.stages.refine`).

    Attributes
    ----------
    objective_start : float
        :math:`\mathcal{J}` at :math:`\alpha = 1`, the network's unrefined map (``info["refine_objective_start"]``).
    objective : float
        :math:`\mathcal{J}` at the chosen :math:`\alpha` (``info["refine_objective"]``).
    evaluations : int
        Evaluations of :math:`\mathcal{J}` (``info["refine_evaluations"]``).
    """

    objective_start: float
    objective: float
    evaluations: int


@dataclass(frozen=True)
class MapReport:
    """What was done to a map, stage by stage; a field is ``None`` where its stage did not run.

    Attributes
    ----------
    network : NetworkReport, optional
        For a network's map.
    regrid : RegridReport, optional
    refine : RefineReport, optional
    alpha : list of float, optional
        The stretching vector applied to the network's displacement (given, refined, or ones), or found by
        refinement of a classical map's displacement.
    repair : dict, optional
        The report of :func:`rfmap.finish.repair.dispatch.repair_map` (with ``skipped`` when the repair gave way to a cold polish;
        at query points with ``grid``, the working grid's report).
    polish : dict, optional
        The report of :func:`rfmap.finish.polish.polish_map` (for a network's map with ``smooth_passes``, ``smooth_edges``
        and ``output_passes``).
    quality : dict, optional
        :func:`rfmap.finish.quality.density_quality` of the returned map of a grid (with ``shortened_from`` after
        shortening).
    shorten : dict, optional
        The report of :func:`rfmap.finish.shorten.shorten_map` when the map was shortened (at query points with
        ``decided_on``, ``work_n``, ``query_mesh`` and ``quality``, see :func:`rfmap.finish.stages.shorten`).
    """

    network: NetworkReport | None = None
    regrid: RegridReport | None = None
    refine: RefineReport | None = None
    alpha: list[float] | None = None
    repair: dict[str, Any] | None = None
    polish: dict[str, Any] | None = None
    quality: dict[str, Any] | None = None
    shorten: dict[str, Any] | None = None

    def flat(self) -> dict[str, Any]:
        """The report under the keys of ``MapResult.info``, in the order the stages write them."""
        out: dict[str, Any] = {}
        if self.network is not None:
            out.update(work_n=self.network.work_n, network_time=self.network.time,
                       symmetrize=self.network.symmetrize)
        if self.regrid is not None:
            out["regrid"] = self.regrid.as_dict()
        if self.refine is not None:
            out.update(refine_objective_start=self.refine.objective_start, refine_objective=self.refine.objective,
                       refine_evaluations=self.refine.evaluations)
        if self.alpha is not None:
            out["alpha"] = self.alpha
        for key in ("repair", "polish", "quality", "shorten"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        return out


class InfoView(Mapping):
    """``MapResult.info`` of a finished map: a read-only mapping of the solver's own extras (``base``) and the
    flat keys of :meth:`MapReport.flat`; the typed report is its ``report``."""

    def __init__(self, report: MapReport, base: Mapping[str, Any] | None = None):
        self._report = report
        self._items = {**dict(base or {}), **report.flat()}

    @property
    def report(self) -> MapReport:
        return self._report

    def __getitem__(self, key: str) -> Any:
        return self._items[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __repr__(self) -> str:
        return f"InfoView({self._items!r})"
