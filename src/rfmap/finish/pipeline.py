"""The stages composed: what happens to a computed map before it is returned, for network and classical maps."""
from __future__ import annotations

from dataclasses import dataclass

from .polish import GUARD, polish_tolerance
from ..core.result import MapResult
from .draft import Draft
from .stages import judge, polish, refine, repair, shorten

__all__ = ["FinishOptions", "finish", "finish_map"]


@dataclass(frozen=True)
class FinishOptions:
    """How a computed map is finished: the options of the stages of :func:`finish`, for a network's map (part of
    :class:`rfmap.surrogate.MapOptions`, the keywords of :meth:`rfmap.Surrogate.map`) and a classical one
    (:func:`finish_map`).

    Attributes
    ----------
    refine : bool
        Weight refinement of the map's displacement (paper Sec. 4.3; :func:`rfmap.finish.stages.refine`).  In
        :meth:`rfmap.Surrogate.map` a network's map is refined as it is predicted (so is the map of every working
        grid that :func:`rfmap.finish.stages.regrid` tries), not by :func:`finish`; :func:`finish_map` refines any
        map.
    refine_bounds : (float, float), optional
        Search interval of every component of the stretching vector (default :data:`rfmap.finish.refine.REFINE`).
    repair : bool
        Make the map fold-free (:func:`rfmap.finish.stages.repair`), and shorten a density map that is still no
        more equal than its input (:func:`rfmap.finish.stages.shorten`).  ``False`` returns the raw map.
    polish : bool or float
        Finish a density map of a grid with the flow-based solver (:func:`rfmap.finish.stages.polish`); a number
        is the tolerance on Std(ρ̃_map).  A polished map is not judged or shortened: the flow equalizes it.
    guard : bool
        With ``polish``: keep the better of the warm and the cold flow (:data:`rfmap.finish.polish.GUARD`).
    """

    refine: bool = False
    refine_bounds: tuple[float, float] | None = None
    repair: bool = True
    polish: bool | float = False
    guard: bool = GUARD

    def __post_init__(self):
        if self.polish is not False:
            polish_tolerance(self.polish)  # a bad value is an error before any work

    @property
    def tol(self) -> float | None:
        """The polish's tolerance on Std(ρ̃_map) (``None``: the solver's default)."""
        return polish_tolerance(self.polish) if self.polish is not False else None

    def check(self, task, on_grid: bool) -> None:
        """``ValueError`` when these options cannot finish a map of ``task`` (a :class:`rfmap.tasks.base.Task`) of
        the output grid (``on_grid``) or of query points: the polish finishes density maps of a grid only."""
        if self.polish is not False and (not task.equalizes or not on_grid):
            raise ValueError("polish finishes density maps on the output grid; it does not apply to "
                             f"{task.kind} maps or to query points")


def finish(draft: Draft, options: FinishOptions = FinishOptions()) -> Draft:
    """The stages of :mod:`rfmap.finish` after the map is computed, but for regrid: refine, repair, then polish,
    or for a density map judge and shorten.

    The regrid stage, between refine and repair, is run by :meth:`rfmap.Surrogate.map`, which alone can evaluate the
    network on another working grid.  That method calls :func:`finish` with ``refine`` off: a network's map arrives
    refined when refinement is asked for (``FinishOptions.refine``).

    A density map of a grid without ``polish`` is judged (:func:`rfmap.finish.stages.judge`); with ``repair`` a density
    map of a grid or a network's map of query points is shortened when it is no more equal than its input.
    """
    options.check(draft.task, draft.grid_n is not None)
    if options.refine:
        draft = refine(draft, options.refine_bounds)
    if options.repair:
        draft = repair(draft, cold_polish=options.polish is not False)
    if options.polish is not False:
        return polish(draft, options.tol, options.guard)
    if draft.task.equalizes:
        if draft.grid_n is not None:
            draft = judge(draft)
        if options.repair and (draft.grid_n is not None or draft.prediction is not None):
            draft = shorten(draft)
    return draft


def finish_map(result: MapResult, options: FinishOptions = FinishOptions(), *, boundary: str | None = None,
               n: int | None = None) -> MapResult:
    """Finish a computed map, e.g. a classical solver's (:mod:`rfmap.solvers`), with the stages of :func:`finish`.

    Parameters
    ----------
    result : MapResult
    options : FinishOptions
    boundary : {"fixed", "square", "free"}, optional
        The map's boundary condition (default ``result.info["boundary"]``, which the solvers record).
    n : int, optional
        The grid side when the mesh is :func:`rfmap.core.mesh.grid_mesh` ``(N, d)`` (default: recognised).

    Returns
    -------
    MapResult
        ``info``: the solver's own extras and the stages' reports (:class:`rfmap.finish.report.InfoView`; the typed
        report is ``info.report``).
    """
    return finish(Draft.of(result, boundary, n), options).deliver()
